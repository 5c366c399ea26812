//! torchvision state dicts → this Mask R-CNN's keys: an ImageNet ResNet
//! (`torchvision.models.resnet50().state_dict()`: `conv1.weight`, `bn1.*`,
//! `layer1.0.conv1.weight`, …; `fc.*` dropped) into the backbone, or a whole
//! `maskrcnn_resnet50_fpn` (v1) state dict (`backbone.body.*`, `backbone.fpn.*`, `rpn.head.*`,
//! `roi_heads.*`) into the model. The result goes through the one loader,
//! [`crate::model::weights::apply`].
//!
//! What changes on the way:
//! - BatchNorm `weight`/`bias` are Burn's `gamma`/`beta`; `num_batches_tracked` is dropped.
//!   torchvision's detection backbones use `FrozenBatchNorm2d` (the same four tensors).
//! - Linear weights are transposed (PyTorch `[out, in]`, Burn `[in, out]`).
//! - torchvision puts the background class first and regresses boxes and predicts masks
//!   for it too; here background is the last logit and boxes/masks are class-specific
//!   without it. With `K = nc + 1` classes in the file the class logits are reordered and
//!   the background rows dropped; with another `K` the class-dependent tensors are left
//!   out and [`class_dependent`] lets them keep their initialisation.
//! - Older key names (`inner_blocks.0.weight`, `rpn.head.conv.weight`,
//!   `mask_head.mask_fcn1.weight`, before torchvision's `Conv2dNormActivation`) are read too.

use std::collections::HashMap;

use anyhow::{bail, Result};

use crate::model::weights::{snapshot_data, snapshot_f32, Snapshot};

/// What a torchvision state dict holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TorchvisionKind {
    /// An ImageNet classifier: backbone only.
    ResNet,
    /// `maskrcnn_resnet50_fpn` (v1): the whole model.
    MaskRcnn,
}

/// A mapped state dict.
pub struct Mapped {
    pub kind: TorchvisionKind,
    /// Tensors under chicktrain's keys.
    pub snapshots: Vec<Snapshot>,
    /// chicktrain key → the file's key, for error messages.
    pub file_keys: HashMap<String, String>,
    /// Classes (background included) of the file's box predictor, for a Mask R-CNN.
    pub file_classes: Option<usize>,
}

/// Tensors that may keep their initialisation after importing a `kind` file: the
/// classifiers sized by the class count, and for an ImageNet ResNet everything outside
/// the backbone.
pub fn class_dependent(kind: TorchvisionKind) -> fn(&str) -> bool {
    fn heads(p: &str) -> bool {
        super::class_dependent(p)
    }
    fn not_backbone(p: &str) -> bool {
        !p.starts_with("backbone.")
    }
    match kind {
        TorchvisionKind::ResNet => not_backbone,
        TorchvisionKind::MaskRcnn => heads,
    }
}

fn bn(x: &str) -> Option<&'static str> {
    Some(match x {
        "weight" => "gamma",
        "bias" => "beta",
        "running_mean" => "running_mean",
        "running_var" => "running_var",
        _ => return None,
    })
}

/// A torchvision ResNet key (relative to the ResNet) → ours (relative to the ResNet).
fn resnet_key(k: &str) -> Option<String> {
    let p: Vec<&str> = k.split('.').collect();
    match p[..] {
        ["conv1", "weight"] => Some("stem.conv.weight".into()),
        ["bn1", x] => Some(format!("stem.bn.{}", bn(x)?)),
        [layer, block, part, x] | [layer, block, part, _, x] if layer.starts_with("layer") => {
            let stage: usize = layer.strip_prefix("layer")?.parse().ok()?;
            if !(1..=4).contains(&stage) {
                return None;
            }
            let block: usize = block.parse().ok()?;
            let base = format!("stages.{}.blocks.{block}", stage - 1);
            if part == "downsample" {
                return match (p.get(3).copied(), p.len()) {
                    (Some("0"), 5) if x == "weight" => Some(format!("{base}.down.conv.weight")),
                    (Some("1"), 5) => Some(format!("{base}.down.bn.{}", bn(x)?)),
                    _ => None,
                };
            }
            if p.len() != 4 {
                return None;
            }
            if let Some(n) = part.strip_prefix("conv") {
                let n: usize = n.parse().ok()?;
                return (x == "weight" && (1..=3).contains(&n))
                    .then(|| format!("{base}.convs.{}.conv.weight", n - 1));
            }
            if let Some(n) = part.strip_prefix("bn") {
                let n: usize = n.parse().ok()?;
                return (1..=3)
                    .contains(&n)
                    .then(|| bn(x).map(|b| format!("{base}.convs.{}.bn.{b}", n - 1)))
                    .flatten();
            }
            None
        }
        _ => None,
    }
}

/// How a tensor changes on its way in.
#[derive(Clone, Copy, PartialEq)]
enum Op {
    Copy,
    /// Linear weight `[out, in]` → `[in, out]`.
    Transpose,
    /// Class logits: background first → last (weight transposed too).
    ClassLogits,
    /// Box deltas: drop the background's 4 rows (weight transposed too).
    DropBackgroundBox,
    /// Mask logits: drop the background channel.
    DropBackgroundMask,
}

/// A Mask R-CNN key → (ours, op); `None` for keys that have no counterpart.
fn maskrcnn_key(k: &str) -> Option<(String, Op)> {
    if let Some(r) = k.strip_prefix("backbone.body.") {
        return resnet_key(r).map(|o| (format!("backbone.{o}"), Op::Copy));
    }
    let p: Vec<&str> = k.split('.').collect();
    let lin = |x: &str| {
        if x == "weight" {
            Op::Transpose
        } else {
            Op::Copy
        }
    };
    match p[..] {
        ["backbone", "fpn", blocks, i, "0", x] | ["backbone", "fpn", blocks, i, x]
            if (x == "weight" || x == "bias") =>
        {
            let to = match blocks {
                "inner_blocks" => "lateral",
                "layer_blocks" => "output",
                _ => return None,
            };
            let i: usize = i.parse().ok()?;
            Some((format!("fpn.{to}.{i}.{x}"), Op::Copy))
        }
        ["rpn", "head", "conv", "0", "0", x] | ["rpn", "head", "conv", x] => {
            Some((format!("rpn.conv.{x}"), Op::Copy))
        }
        ["rpn", "head", "cls_logits", x] => Some((format!("rpn.objectness.{x}"), Op::Copy)),
        ["rpn", "head", "bbox_pred", x] => Some((format!("rpn.deltas.{x}"), Op::Copy)),
        ["roi_heads", "box_head", fc, x] if fc.starts_with("fc") => {
            let n: usize = fc.strip_prefix("fc")?.parse().ok()?;
            (n >= 6).then(|| (format!("box_head.fcs.{}.{x}", n - 6), lin(x)))
        }
        ["roi_heads", "box_predictor", "cls_score", x] => {
            Some((format!("box_head.cls_score.{x}"), Op::ClassLogits))
        }
        ["roi_heads", "box_predictor", "bbox_pred", x] => {
            Some((format!("box_head.bbox_pred.{x}"), Op::DropBackgroundBox))
        }
        ["roi_heads", "mask_head", i, "0", x] => {
            let i: usize = i.parse().ok()?;
            Some((format!("mask_head.convs.{i}.{x}"), Op::Copy))
        }
        ["roi_heads", "mask_head", fcn, x] if fcn.starts_with("mask_fcn") => {
            let n: usize = fcn.strip_prefix("mask_fcn")?.parse().ok()?;
            (n >= 1).then(|| (format!("mask_head.convs.{}.{x}", n - 1), Op::Copy))
        }
        ["roi_heads", "mask_predictor", "conv5_mask", x] => {
            Some((format!("mask_head.deconv.{x}"), Op::Copy))
        }
        ["roi_heads", "mask_predictor", "mask_fcn_logits", x] => {
            Some((format!("mask_head.predictor.{x}"), Op::DropBackgroundMask))
        }
        _ => None,
    }
}

/// Keys that carry nothing this model uses.
fn dropped(k: &str) -> bool {
    k.ends_with("num_batches_tracked") || k.starts_with("fc.")
}

/// Applies `op` to a tensor of shape `shape` (host f32 values) from a file with `k`
/// classes (background included); `None` if the shape does not fit `op` and `k`.
fn transform(op: Op, v: Vec<f32>, shape: &[usize], k: usize) -> Option<(Vec<f32>, Vec<usize>)> {
    let fits = match (op, shape) {
        (Op::Copy, _) => true,
        (Op::Transpose, s) => s.len() == 2,
        (Op::ClassLogits, s) => s.first() == Some(&k) && s.len() <= 2,
        (Op::DropBackgroundBox, s) => s.first() == Some(&(4 * k)) && s.len() <= 2,
        (Op::DropBackgroundMask, s) => s.first() == Some(&k) && (s.len() == 1 || s.len() == 4),
    };
    (fits && k >= 2 && v.len() == shape.iter().product::<usize>())
        .then(|| transform_fitted(op, v, shape))
}

fn transform_fitted(op: Op, v: Vec<f32>, shape: &[usize]) -> (Vec<f32>, Vec<usize>) {
    let transpose = |v: &[f32], r: usize, c: usize| {
        let mut t = vec![0f32; v.len()];
        for i in 0..r {
            for j in 0..c {
                t[j * r + i] = v[i * c + j];
            }
        }
        t
    };
    match (op, shape) {
        (Op::Copy, _) => (v, shape.to_vec()),
        (Op::Transpose, &[o, i]) => (transpose(&v, o, i), vec![i, o]),
        // [K, in] with background row 0 → rows 1..K then 0, transposed to [in, K].
        (Op::ClassLogits, &[k, i]) => {
            let mut r = v[i..].to_vec();
            r.extend_from_slice(&v[..i]);
            (transpose(&r, k, i), vec![i, k])
        }
        (Op::ClassLogits, &[k]) => {
            let mut r = v[1..].to_vec();
            r.push(v[0]);
            (r, vec![k])
        }
        (Op::DropBackgroundBox, &[k4, i]) => (transpose(&v[4 * i..], k4 - 4, i), vec![i, k4 - 4]),
        (Op::DropBackgroundBox, &[k4]) => (v[4..].to_vec(), vec![k4 - 4]),
        (Op::DropBackgroundMask, &[k, c, h, w]) => (v[c * h * w..].to_vec(), vec![k - 1, c, h, w]),
        (Op::DropBackgroundMask, &[k]) => (v[1..].to_vec(), vec![k - 1]),
        (_, s) => (v, s.to_vec()),
    }
}

/// Maps a torchvision state dict (keys as in the file) for a model with `num_classes`
/// classes. Errors name the first key that has no counterpart.
pub fn map_state_dict(tensors: Vec<Snapshot>, num_classes: usize) -> Result<Mapped> {
    let kind = if tensors.iter().any(|t| t.name.starts_with("backbone.body.")) {
        TorchvisionKind::MaskRcnn
    } else if tensors.iter().any(|t| t.name == "conv1.weight") {
        TorchvisionKind::ResNet
    } else {
        let first = tensors.first().map(|t| t.name.as_str()).unwrap_or("none");
        bail!(
            "not a torchvision ResNet or Mask R-CNN state dict: no conv1.weight or backbone.body.* key (first key {first})"
        );
    };
    let file_classes = tensors
        .iter()
        .find(|t| t.name == "roi_heads.box_predictor.cls_score.weight")
        .map(|t| t.shape[0]);
    let classes_fit = file_classes == Some(num_classes + 1);
    let mut snapshots = Vec::new();
    let mut file_keys = HashMap::new();
    for t in tensors {
        if dropped(&t.name) {
            continue;
        }
        let mapped = match kind {
            TorchvisionKind::ResNet => {
                resnet_key(&t.name).map(|k| (format!("backbone.{k}"), Op::Copy))
            }
            TorchvisionKind::MaskRcnn => maskrcnn_key(&t.name),
        };
        let Some((ours, op)) = mapped else {
            bail!(
                "torchvision key {} has no counterpart in chicktrain's Mask R-CNN",
                t.name
            );
        };
        let class_op = matches!(
            op,
            Op::ClassLogits | Op::DropBackgroundBox | Op::DropBackgroundMask
        );
        if class_op && !classes_fit {
            // Another class count: these keep their initialisation.
            continue;
        }
        let name = t.name.clone();
        let shape = t.shape.to_vec();
        let snap = if op == Op::Copy {
            let mut t = t;
            t.name = ours.clone();
            t
        } else {
            let v: Vec<f32> = snapshot_data(t)?
                .try_to_vec::<f32>()
                .map_err(|e| anyhow::anyhow!("tensor {name}: {e:?}"))?;
            let k = file_classes.unwrap_or(num_classes + 1);
            let Some((v, s)) = transform(op, v, &shape, k) else {
                bail!("torchvision key {name} has shape {shape:?}, which does not fit {k} classes");
            };
            snapshot_f32(ours.clone(), v, s)
        };
        snapshots.push(snap);
        file_keys.insert(ours, name);
    }
    Ok(Mapped {
        kind,
        snapshots,
        file_keys,
        file_classes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_map_both_ways_of_naming() {
        assert_eq!(resnet_key("conv1.weight").unwrap(), "stem.conv.weight");
        assert_eq!(
            resnet_key("bn1.running_var").unwrap(),
            "stem.bn.running_var"
        );
        assert_eq!(
            resnet_key("layer3.5.conv2.weight").unwrap(),
            "stages.2.blocks.5.convs.1.conv.weight"
        );
        assert_eq!(
            resnet_key("layer1.0.bn3.bias").unwrap(),
            "stages.0.blocks.0.convs.2.bn.beta"
        );
        assert_eq!(
            resnet_key("layer2.0.downsample.1.weight").unwrap(),
            "stages.1.blocks.0.down.bn.gamma"
        );
        assert_eq!(resnet_key("layer5.0.conv1.weight"), None);
        assert_eq!(resnet_key("layer1.0.conv4.weight"), None);
        for (k, o) in [
            (
                "backbone.fpn.inner_blocks.2.0.weight",
                "fpn.lateral.2.weight",
            ),
            ("backbone.fpn.inner_blocks.2.bias", "fpn.lateral.2.bias"),
            ("backbone.fpn.layer_blocks.0.0.bias", "fpn.output.0.bias"),
            ("rpn.head.conv.0.0.weight", "rpn.conv.weight"),
            ("rpn.head.conv.bias", "rpn.conv.bias"),
            ("roi_heads.box_head.fc7.weight", "box_head.fcs.1.weight"),
            ("roi_heads.mask_head.3.0.weight", "mask_head.convs.3.weight"),
            (
                "roi_heads.mask_head.mask_fcn1.bias",
                "mask_head.convs.0.bias",
            ),
        ] {
            assert_eq!(maskrcnn_key(k).unwrap().0, o, "{k}");
        }
    }

    #[test]
    fn background_moves_last_and_unknown_keys_are_named() {
        // cls_score.bias of K = 3 (bg, a, b) → (a, b, bg); bbox_pred.bias drops bg's 4.
        assert_eq!(
            transform(Op::ClassLogits, vec![9.0, 1.0, 2.0], &[3], 3)
                .unwrap()
                .0,
            vec![1.0, 2.0, 9.0]
        );
        let (w, s) = transform(
            Op::ClassLogits,
            vec![9.0, 9.5, 1.0, 1.5, 2.0, 2.5],
            &[3, 2],
            3,
        )
        .unwrap();
        assert_eq!(s, vec![2, 3]);
        assert_eq!(w, vec![1.0, 2.0, 9.0, 1.5, 2.5, 9.5]);
        let b: Vec<f32> = (0..8).map(|x| x as f32).collect();
        assert_eq!(
            transform(Op::DropBackgroundBox, b.clone(), &[8], 2)
                .unwrap()
                .0,
            vec![4.0, 5.0, 6.0, 7.0]
        );
        // A box predictor that does not hold 4 per class is refused, not sliced.
        assert!(transform(Op::DropBackgroundBox, b, &[8], 3).is_none());
        assert!(transform(Op::DropBackgroundBox, vec![0.0; 2], &[2], 2).is_none());
        let e = map_state_dict(
            vec![
                snapshot_f32("conv1.weight", vec![0.0], vec![1]),
                snapshot_f32("layer1.0.weird.weight", vec![0.0], vec![1]),
            ],
            1,
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("layer1.0.weird.weight"), "{e}");
        let e = map_state_dict(vec![snapshot_f32("foo", vec![0.0], vec![1])], 1)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("first key foo"), "{e}");
    }
}
