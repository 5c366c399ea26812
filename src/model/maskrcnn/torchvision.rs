//! torchvision state dicts → this Mask R-CNN's keys: an ImageNet ResNet
//! (`torchvision.models.resnet50().state_dict()`: `conv1.weight`, `bn1.*`,
//! `layer1.0.conv1.weight`, …; `fc.*` dropped) into the backbone, or a whole
//! `maskrcnn_resnet50_fpn` (v1) state dict (`backbone.body.*`, `backbone.fpn.*`, `rpn.head.*`,
//! `roi_heads.*`) into the model. The result goes through the one loader,
//! [`crate::model::weights::apply`]. The export ([`torchvision_state_dict`], behind
//! `export --format safetensors`) reads the same rule table backwards.
//!
//! One concept: the map between torchvision's state-dict keys and layouts and this Mask
//! R-CNN's, read both ways from one rule table (about 570 lines of code, 210 of tests).
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

use super::MaskRcnn;
use crate::model::weights::{collect, snapshot_data, snapshot_f32, Snapshot};
use crate::weights::host::HostTensor;

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

/// One naming rule, read in both directions (import maps torchvision → chicktrain, export
/// chicktrain → torchvision), so there is one map. Keys are `.`-separated; a segment may
/// end in one field:
/// - `{n}`: a number, the same on both sides; on the torchvision side `{n+k}` means
///   torchvision's number is chicktrain's + k (`layer1` is stage 0, `fc6` is FC 0) and
///   `{n+k<m}` that it is also below m;
/// - `{bn}`: a BatchNorm tensor, `weight`/`bias`/`running_mean`/`running_var` ↔
///   `gamma`/`beta`/`running_mean`/`running_var`;
/// - `{p}`: `weight` or `bias`, the same on both sides.
struct Rule {
    tv: &'static str,
    ours: &'static str,
    op: Op,
    /// An older torchvision name: read, never written.
    alias: bool,
}

const fn rule(tv: &'static str, ours: &'static str, op: Op) -> Rule {
    Rule {
        tv,
        ours,
        op,
        alias: false,
    }
}

const fn alias(tv: &'static str, ours: &'static str) -> Rule {
    Rule {
        tv,
        ours,
        op: Op::Copy,
        alias: true,
    }
}

/// A ResNet's keys, relative to the ResNet on both sides (`backbone.body.` /
/// `backbone.` in a Mask R-CNN).
const RESNET_RULES: &[Rule] = &[
    rule("conv1.weight", "stem.conv.weight", Op::Copy),
    rule("bn1.{bn}", "stem.bn.{bn}", Op::Copy),
    rule(
        "layer{s+1<5}.{b}.conv{n+1<4}.weight",
        "stages.{s}.blocks.{b}.convs.{n}.conv.weight",
        Op::Copy,
    ),
    rule(
        "layer{s+1<5}.{b}.bn{n+1<4}.{bn}",
        "stages.{s}.blocks.{b}.convs.{n}.bn.{bn}",
        Op::Copy,
    ),
    rule(
        "layer{s+1<5}.{b}.downsample.0.weight",
        "stages.{s}.blocks.{b}.down.conv.weight",
        Op::Copy,
    ),
    rule(
        "layer{s+1<5}.{b}.downsample.1.{bn}",
        "stages.{s}.blocks.{b}.down.bn.{bn}",
        Op::Copy,
    ),
];

/// The rest of a v1 `maskrcnn_resnet50_fpn`, canonical names before their aliases.
const MASKRCNN_RULES: &[Rule] = &[
    rule(
        "backbone.fpn.inner_blocks.{i}.0.{p}",
        "fpn.lateral.{i}.{p}",
        Op::Copy,
    ),
    alias("backbone.fpn.inner_blocks.{i}.{p}", "fpn.lateral.{i}.{p}"),
    rule(
        "backbone.fpn.layer_blocks.{i}.0.{p}",
        "fpn.output.{i}.{p}",
        Op::Copy,
    ),
    alias("backbone.fpn.layer_blocks.{i}.{p}", "fpn.output.{i}.{p}"),
    rule("rpn.head.conv.0.0.{p}", "rpn.conv.{p}", Op::Copy),
    alias("rpn.head.conv.{p}", "rpn.conv.{p}"),
    rule("rpn.head.cls_logits.{p}", "rpn.objectness.{p}", Op::Copy),
    rule("rpn.head.bbox_pred.{p}", "rpn.deltas.{p}", Op::Copy),
    rule(
        "roi_heads.box_head.fc{n+6}.{p}",
        "box_head.fcs.{n}.{p}",
        Op::Transpose,
    ),
    rule(
        "roi_heads.box_predictor.cls_score.{p}",
        "box_head.cls_score.{p}",
        Op::ClassLogits,
    ),
    rule(
        "roi_heads.box_predictor.bbox_pred.{p}",
        "box_head.bbox_pred.{p}",
        Op::DropBackgroundBox,
    ),
    rule(
        "roi_heads.mask_head.{n}.0.{p}",
        "mask_head.convs.{n}.{p}",
        Op::Copy,
    ),
    alias(
        "roi_heads.mask_head.mask_fcn{n+1}.{p}",
        "mask_head.convs.{n}.{p}",
    ),
    rule(
        "roi_heads.mask_predictor.conv5_mask.{p}",
        "mask_head.deconv.{p}",
        Op::Copy,
    ),
    rule(
        "roi_heads.mask_predictor.mask_fcn_logits.{p}",
        "mask_head.predictor.{p}",
        Op::DropBackgroundMask,
    ),
];

const BN_NAMES: [(&str, &str); 4] = [
    ("weight", "gamma"),
    ("bias", "beta"),
    ("running_mean", "running_mean"),
    ("running_var", "running_var"),
];

/// A field's value: a number (chicktrain's count) or a parameter name (torchvision's).
#[derive(Clone, PartialEq)]
enum Field {
    Num(usize),
    Name(&'static str),
}

/// `layer{s+1<5}` → (`layer`, `s`, offset 1, bound 5).
fn field_of(seg: &'static str) -> Option<(&'static str, &'static str, usize, Option<usize>)> {
    let open = seg.find('{')?;
    let spec = seg[open + 1..].strip_suffix('}')?;
    let (spec, below) = match spec.split_once('<') {
        Some((s, m)) => (s, Some(m.parse().expect("rule bound is a number"))),
        None => (spec, None),
    };
    let (name, plus) = match spec.split_once('+') {
        Some((n, k)) => (n, k.parse().expect("rule offset is a number")),
        None => (spec, 0),
    };
    Some((&seg[..open], name, plus, below))
}

/// The fields of `key` under `pattern` (`tv`: the torchvision side), if it matches.
fn bind(pattern: &'static str, key: &str, tv: bool) -> Option<Vec<(&'static str, Field)>> {
    let (ps, ks): (Vec<&'static str>, Vec<&str>) =
        (pattern.split('.').collect(), key.split('.').collect());
    if ps.len() != ks.len() {
        return None;
    }
    let mut fields = Vec::new();
    for (p, k) in ps.into_iter().zip(ks) {
        let Some((lit, name, plus, below)) = field_of(p) else {
            if p != k {
                return None;
            }
            continue;
        };
        let rest = k.strip_prefix(lit)?;
        let f = match name {
            "bn" => BN_NAMES
                .iter()
                .find(|(t, o)| rest == if tv { *t } else { *o })
                .map(|(t, _)| Field::Name(*t))?,
            "p" => ["weight", "bias"]
                .into_iter()
                .find(|t| rest == *t)
                .map(Field::Name)?,
            _ => {
                if rest.is_empty() || !rest.bytes().all(|b| b.is_ascii_digit()) {
                    return None;
                }
                let v: usize = rest.parse().ok()?;
                if tv {
                    if below.is_some_and(|m| v >= m) {
                        return None;
                    }
                    Field::Num(v.checked_sub(plus)?)
                } else {
                    Field::Num(v)
                }
            }
        };
        fields.push((name, f));
    }
    Some(fields)
}

/// `pattern` with `fields` filled in (`tv`: the torchvision side); `None` if a number
/// falls outside the pattern's bound.
fn fill(pattern: &'static str, fields: &[(&'static str, Field)], tv: bool) -> Option<String> {
    let mut segs = Vec::new();
    for p in pattern.split('.') {
        let Some((lit, name, plus, below)) = field_of(p) else {
            segs.push(p.to_string());
            continue;
        };
        let f = &fields.iter().find(|(n, _)| *n == name)?.1;
        let v = match f {
            Field::Name(t) if name == "bn" && !tv => BN_NAMES
                .iter()
                .find(|(x, _)| x == t)
                .map(|(_, o)| o.to_string())?,
            Field::Name(t) => t.to_string(),
            Field::Num(n) if tv => {
                let v = n + plus;
                if below.is_some_and(|m| v >= m) {
                    return None;
                }
                v.to_string()
            }
            Field::Num(n) => n.to_string(),
        };
        segs.push(format!("{lit}{v}"));
    }
    Some(segs.join("."))
}

/// How a tensor changes on its way in; the export applies the inverse ([`untransform`]).
#[derive(Clone, Copy, PartialEq, Debug)]
enum Op {
    Copy,
    /// Linear weight `[out, in]` → `[in, out]` (a bias is copied).
    Transpose,
    /// Class logits: background first → last (weight transposed too).
    ClassLogits,
    /// Box deltas: drop the background's 4 rows (weight transposed too).
    DropBackgroundBox,
    /// Mask logits: drop the background channel.
    DropBackgroundMask,
}

/// One direction of the rule tables: a key on side `tv` → the other side's key and the
/// rule's op. Keys under `resnet_prefix` (torchvision's, chicktrain's) are the ResNet's;
/// `full`: also the rest of a Mask R-CNN.
fn translate(k: &str, tv: bool, resnet_prefix: (&str, &str), full: bool) -> Option<(String, Op)> {
    let (from_prefix, to_prefix) = if tv {
        resnet_prefix
    } else {
        (resnet_prefix.1, resnet_prefix.0)
    };
    let side = |r: &Rule| if tv { (r.tv, r.ours) } else { (r.ours, r.tv) };
    if let Some(rel) = k.strip_prefix(from_prefix) {
        for r in RESNET_RULES {
            let (from, to) = side(r);
            if let Some(f) = bind(from, rel, tv) {
                return fill(to, &f, !tv).map(|o| (format!("{to_prefix}{o}"), r.op));
            }
        }
    }
    if !full {
        return None;
    }
    for r in MASKRCNN_RULES.iter().filter(|r| tv || !r.alias) {
        let (from, to) = side(r);
        if let Some(f) = bind(from, k, tv) {
            let bias = f
                .iter()
                .any(|(n, v)| *n == "p" && *v == Field::Name("bias"));
            let op = if r.op == Op::Transpose && bias {
                Op::Copy
            } else {
                r.op
            };
            return fill(to, &f, !tv).map(|o| (o, op));
        }
    }
    None
}

/// A torchvision ResNet key (relative to the ResNet) → ours (relative to the ResNet).
fn resnet_key(k: &str) -> Option<String> {
    translate(k, true, ("", ""), false).map(|(o, _)| o)
}

/// A Mask R-CNN key → (ours, op); `None` for keys that have no counterpart.
fn maskrcnn_key(k: &str) -> Option<(String, Op)> {
    translate(k, true, ("backbone.body.", "backbone."), true)
}

/// chicktrain's module path → (torchvision's `maskrcnn_resnet50_fpn` key, the import's op).
fn torchvision_key(ours: &str) -> Option<(String, Op)> {
    translate(ours, false, ("backbone.body.", "backbone."), true)
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

/// The inverse of [`transform`] for a model with `nc` classes: chicktrain's tensor →
/// torchvision's, background put back first. The background's box deltas and mask logits
/// are written as zeros: torchvision's inference never reads them (its postprocess drops
/// the background's boxes, and each detection takes the mask of its own class), and the
/// import drops them again, so export → import is exact. `None` if the shape does not fit.
fn untransform(op: Op, v: Vec<f32>, shape: &[usize], nc: usize) -> Option<(Vec<f32>, Vec<usize>)> {
    if v.len() != shape.iter().product::<usize>() {
        return None;
    }
    let transpose = |v: &[f32], r: usize, c: usize| {
        let mut t = vec![0f32; v.len()];
        for i in 0..r {
            for j in 0..c {
                t[j * r + i] = v[i * c + j];
            }
        }
        t
    };
    let k = nc + 1;
    Some(match (op, shape) {
        (Op::Copy, _) => (v, shape.to_vec()),
        (Op::Transpose, &[i, o]) => (transpose(&v, i, o), vec![o, i]),
        // [in, K] with background last → [K, in] with background row 0.
        (Op::ClassLogits, &[i, kk]) if kk == k => {
            let t = transpose(&v, i, k);
            let mut r = t[(k - 1) * i..].to_vec();
            r.extend_from_slice(&t[..(k - 1) * i]);
            (r, vec![k, i])
        }
        (Op::ClassLogits, &[kk]) if kk == k => {
            let mut r = vec![v[k - 1]];
            r.extend_from_slice(&v[..k - 1]);
            (r, vec![k])
        }
        (Op::DropBackgroundBox, &[i, n4]) if n4 == 4 * nc => {
            let mut r = vec![0.0; 4 * i];
            r.extend(transpose(&v, i, n4));
            (r, vec![n4 + 4, i])
        }
        (Op::DropBackgroundBox, &[n4]) if n4 == 4 * nc => {
            let mut r = vec![0.0; 4];
            r.extend(v);
            (r, vec![n4 + 4])
        }
        (Op::DropBackgroundMask, &[n, c, h, w]) if n == nc => {
            let mut r = vec![0.0; c * h * w];
            r.extend(v);
            (r, vec![k, c, h, w])
        }
        (Op::DropBackgroundMask, &[n]) if n == nc => {
            let mut r = vec![0.0];
            r.extend(v);
            (r, vec![k])
        }
        _ => return None,
    })
}

/// chicktrain's Mask R-CNN as a torchvision `maskrcnn_resnet50_fpn` (v1) state dict: the
/// same rules as the import read backwards, `nc + 1` classes with background first,
/// BatchNorm as the four tensors of `FrozenBatchNorm2d` (no `num_batches_tracked`:
/// `FrozenBatchNorm2d` has none, and `BatchNorm2d.load_state_dict` fills it in when a
/// plain dict lacks it). In torchvision's key order. Class-agnostic heads have no
/// torchvision layout and are refused.
pub fn torchvision_state_dict(model: &MaskRcnn) -> Result<Vec<(String, HostTensor)>> {
    let cfg = &model.config;
    if cfg.roi.class_agnostic_box || cfg.mask.class_agnostic {
        bail!(
            "torchvision's box and mask predictors are class-specific; this model's {} is class-agnostic, which has no torchvision layout",
            if cfg.roi.class_agnostic_box {
                "box regression"
            } else {
                "mask head (model.mask_class_agnostic = true)"
            }
        );
    }
    let nc = cfg.num_classes;
    let mut out = Vec::new();
    for snap in collect(model) {
        let ours = snap.name.clone();
        let Some((theirs, op)) = torchvision_key(&ours) else {
            bail!("module path {ours} has no torchvision name");
        };
        let shape = snap.shape.to_vec();
        let v: Vec<f32> = snapshot_data(snap)?
            .try_to_vec::<f32>()
            .map_err(|e| anyhow::anyhow!("tensor {ours}: {e:?}"))?;
        let Some((v, s)) = untransform(op, v, &shape, nc) else {
            bail!("module path {ours} has shape {shape:?}, which does not fit {nc} classes");
        };
        out.push((theirs, HostTensor::f32(s, v)));
    }
    Ok(out)
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

    /// A small two-class model whose every tensor holds distinct values.
    fn tiny(depth: usize) -> MaskRcnn {
        use crate::model::maskrcnn::mask_head::MaskHeadConfig;
        use crate::model::maskrcnn::roi_heads::RoiHeadsConfig;
        use crate::model::maskrcnn::MaskRcnnConfig;
        use burn::tensor::Device;
        MaskRcnnConfig::new(depth, 2)
            .with_width_mult(0.125)
            .with_fpn_channels(8)
            .with_input_size(64)
            .with_roi(RoiHeadsConfig {
                fc_dim: 16,
                ..RoiHeadsConfig::compact()
            })
            .with_mask(MaskHeadConfig {
                conv_dim: 8,
                ..MaskHeadConfig::compact()
            })
            .init(&Device::flex())
    }

    #[test]
    fn every_module_path_has_a_torchvision_name_that_maps_back() {
        for depth in [18, 50] {
            let m = tiny(depth);
            for (ours, _) in crate::model::weights::shapes(&m) {
                let (theirs, op) = torchvision_key(&ours).unwrap_or_else(|| panic!("{ours}"));
                let (back, op_back) = maskrcnn_key(&theirs).unwrap();
                assert_eq!((back.as_str(), op_back), (ours.as_str(), op), "{theirs}");
            }
        }
        for (ours, theirs) in [
            (
                "backbone.stages.0.blocks.0.convs.0.bn.gamma",
                "backbone.body.layer1.0.bn1.weight",
            ),
            (
                "backbone.stages.3.blocks.0.down.bn.running_var",
                "backbone.body.layer4.0.downsample.1.running_var",
            ),
            ("backbone.stem.conv.weight", "backbone.body.conv1.weight"),
            (
                "fpn.lateral.0.weight",
                "backbone.fpn.inner_blocks.0.0.weight",
            ),
            ("rpn.conv.bias", "rpn.head.conv.0.0.bias"),
            ("box_head.fcs.1.bias", "roi_heads.box_head.fc7.bias"),
            ("mask_head.convs.3.weight", "roi_heads.mask_head.3.0.weight"),
            (
                "mask_head.predictor.weight",
                "roi_heads.mask_predictor.mask_fcn_logits.weight",
            ),
        ] {
            assert_eq!(torchvision_key(ours).unwrap().0, theirs, "{ours}");
        }
        assert_eq!(
            torchvision_key("box_head.fcs.0.weight").unwrap().1,
            Op::Transpose
        );
        assert_eq!(torchvision_key("box_head.fcs.0.bias").unwrap().1, Op::Copy);
        assert_eq!(
            torchvision_key("backbone.stages.4.blocks.0.convs.0.conv.weight"),
            None
        );
        assert_eq!(torchvision_key("backbone.stem.bn.weight"), None);
    }

    #[test]
    fn export_then_import_is_bit_identical() {
        let m = tiny(18);
        let sd = torchvision_state_dict(&m).unwrap();
        // torchvision's layout: background first, 4 deltas and one mask per class with it.
        let get = |k: &str| &sd.iter().find(|(n, _)| n == k).unwrap().1;
        assert_eq!(
            get("roi_heads.box_predictor.cls_score.weight").shape,
            [3, 16]
        );
        assert_eq!(
            get("roi_heads.box_predictor.bbox_pred.weight").shape,
            [12, 16]
        );
        assert_eq!(
            get("roi_heads.mask_predictor.mask_fcn_logits.weight").shape,
            [3, 8, 1, 1]
        );
        assert_eq!(get("roi_heads.box_head.fc6.weight").shape, [16, 8 * 7 * 7]);
        assert!(!sd.iter().any(|(n, _)| n.contains("num_batches_tracked")));
        let snaps: Vec<Snapshot> = sd
            .into_iter()
            .map(|(n, t)| match t.data {
                crate::weights::host::HostData::F32(v) => snapshot_f32(n, v, t.shape),
                _ => panic!("{n}: not f32"),
            })
            .collect();
        let mapped = map_state_dict(snaps, 2).unwrap();
        assert_eq!(mapped.kind, TorchvisionKind::MaskRcnn);
        assert_eq!(mapped.file_classes, Some(3));
        let fresh = tiny(18);
        let (back, applied) = crate::model::weights::apply(
            fresh,
            mapped.snapshots,
            &class_dependent(mapped.kind),
            "test",
        )
        .unwrap();
        assert!(applied.reinitialised.is_empty());
        let bits = |m: &MaskRcnn| -> Vec<(String, Vec<u32>)> {
            collect(m)
                .into_iter()
                .map(|s| {
                    let n = s.name.clone();
                    let v = snapshot_data(s).unwrap().try_to_vec::<f32>().unwrap();
                    (n, v.iter().map(|x| x.to_bits()).collect())
                })
                .collect()
        };
        let (a, b) = (bits(&m), bits(&back));
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert!(x == y, "{} differs after export → import", x.0);
        }
    }
}
