//! ultralytics YOLO11-seg / YOLO11 weights in and out: chicktrain's module paths ↔
//! ultralytics 8.4 `state_dict()` keys (`model.0.conv.weight`, …, `model.23.proto.cv3.bn.bias`).
//!
//! In: [`read_ultralytics`] reads an ultralytics `.pt` (the pickled model object as its trainer
//! saves it, `ema` if present else `model`, like `attempt_load_one_weight`), a plain state-dict
//! `.pt` / `.pth`, or a safetensors file with ultralytics key names, and returns burn-pack
//! snapshots keyed by our module paths (what burn-store's `ModuleSnapshot::apply` takes).
//! Like ultralytics' `intersect_dicts`, class-dependent tensors of another class count and the
//! mask head of a detection checkpoint are left out and listed, so the caller re-initialises
//! them and says so; any other mismatch is an error naming the file and the first key.
//!
//! Out: [`ultralytics_state_dict`] gives the state dict under ultralytics' names, BatchNorm
//! `num_batches_tracked` and the fixed DFL conv included, so `load_state_dict` takes it.
//!
//! The mapping covers the layout ultralytics' `yolo11-seg.yaml` builds: heads on P3–P5 and
//! C2PSA on (any scale and width: its `scales` rule is ours, see `scale.rs`).

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, TensorData};

use crate::model::weights;

use super::head::REG_MAX;
use super::{HeadLevels, YoloSeg, YoloSegConfig};
use crate::weights::host::{HostData, HostTensor};
use crate::weights::state_dict::{read_state_dict, StateDict};

/// One of our tensors and its ultralytics name.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyPair {
    /// Module path as burn names it (`backbone.l2.m.0.Bottleneck.cv1.bn.gamma`).
    pub ours: String,
    /// ultralytics key (`model.2.m.0.cv1.bn.weight`).
    pub theirs: String,
    pub shape: Vec<usize>,
}

/// A tensor of the file that does not fit the model because the class count differs.
#[derive(Debug, Clone, PartialEq)]
pub struct Unfit {
    pub ours: String,
    pub theirs: String,
    pub file_shape: Vec<usize>,
    pub model_shape: Vec<usize>,
}

/// Weights read from an ultralytics file, ready for `ModuleSnapshot::apply` on a
/// [`YoloSeg`] built from the same config.
#[derive(Debug, Clone)]
pub struct UltralyticsWeights {
    /// f32 snapshots named by our module paths; exactly the tensors that fit.
    pub snapshots: Vec<burn_pack::Tensor>,
    /// Class-dependent tensors (under `model.23.cv3`) whose shape differs: re-initialise.
    pub class_unfit: Vec<Unfit>,
    /// Our paths the file has no tensor for: the mask head (`proto`, `cv4`) of a detection
    /// checkpoint. Keep their fresh init.
    pub missing: Vec<String>,
    /// Classes of the checkpoint (rows of `model.23.cv3.0.2.weight`).
    pub file_classes: usize,
    /// What was read and what was left out, one line each, for the run log.
    pub notes: Vec<String>,
}

/// Why a config cannot use ultralytics' layout, if it cannot.
pub fn layout_error(cfg: &YoloSegConfig) -> Option<String> {
    if cfg.levels != HeadLevels::P3P5 {
        return Some(format!(
            "ultralytics' YOLO11-seg has heads on P3–P5; this model has {:?} (model.levels = [4, 5]): \
             no ultralytics weights fit it",
            cfg.levels
        ));
    }
    if !cfg.c2psa {
        return Some(
            "ultralytics' YOLO11-seg has C2PSA at layer 10; this model has none (model.c2psa = false), \
             so its layer numbers differ: no ultralytics weights fit it"
                .into(),
        );
    }
    // ultralytics gives C2PSA `c // 64` attention heads (c = half the P5 width) and cannot
    // build the model below one; chicktrain keeps one head there.
    let c = super::scale::Scaler::new(cfg.scale, cfg.width_mult).ch(1024) / 2;
    if c < 64 {
        return Some(format!(
            "ultralytics builds C2PSA with (P5 width / 2) // 64 attention heads, 0 at this width \
             (scale {}, width ×{}: C2PSA width {c}); it needs a P5 width of at least 128 \
             (scale n: model.width_mult >= 0.5)",
            cfg.scale.name(),
            cfg.width_mult
        ));
    }
    None
}

/// ultralytics key of one of our module paths (`None` for a path outside its layout).
pub fn ultralytics_key(path: &str) -> Option<String> {
    let parts: Vec<&str> = path.split('.').collect();
    let (layer, rest): (String, &[&str]) = match parts.as_slice() {
        ["backbone", l, rest @ ..] => {
            let n = match *l {
                "sppf" => 9,
                "psa" => 10,
                l => l
                    .strip_prefix('l')?
                    .parse::<usize>()
                    .ok()
                    .filter(|&n| n <= 8)?,
            };
            (format!("model.{n}"), rest)
        }
        ["neck", "p3", l, rest @ ..] => {
            let n = match *l {
                "td_p3" => 16,
                "down_p3" => 17,
                "bu_p4" => 19,
                _ => return None,
            };
            (format!("model.{n}"), rest)
        }
        ["neck", l, rest @ ..] => {
            let n = match *l {
                "td_p4" => 13,
                "down_p4" => 20,
                "bu_p5" => 22,
                _ => return None,
            };
            (format!("model.{n}"), rest)
        }
        ["head", "proto", rest @ ..] => ("model.23.proto".to_string(), rest),
        ["head", branch, level, conv, rest @ ..] => {
            let level: usize = level.parse().ok()?;
            let (cv, idx) = match (*branch, *conv) {
                ("boxes", "c1") => ("cv2", "0"),
                ("boxes", "c2") => ("cv2", "1"),
                ("boxes", "out") => ("cv2", "2"),
                ("cls", "dw1") => ("cv3", "0.0"),
                ("cls", "pw1") => ("cv3", "0.1"),
                ("cls", "dw2") => ("cv3", "1.0"),
                ("cls", "pw2") => ("cv3", "1.1"),
                ("cls", "out") => ("cv3", "2"),
                ("coef", "c1") => ("cv4", "0"),
                ("coef", "c2") => ("cv4", "1"),
                ("coef", "out") => ("cv4", "2"),
                _ => return None,
            };
            (format!("model.23.{cv}.{level}.{idx}"), rest)
        }
        _ => return None,
    };
    let mut out = vec![layer];
    let mut i = 0;
    while i < rest.len() {
        let seg = rest[i];
        match seg {
            // Enum variants of C3k2's inner block: ultralytics' `m` holds the block itself.
            "Bottleneck" | "C3k" => {}
            // PSABlock.ffn = Sequential(Conv, Conv).
            "ffn1" => out.push("ffn.0".into()),
            "ffn2" => out.push("ffn.1".into()),
            "gamma" if i + 1 == rest.len() => out.push("weight".into()),
            "beta" if i + 1 == rest.len() => out.push("bias".into()),
            s => out.push(s.to_string()),
        }
        i += 1;
    }
    Some(out.join("."))
}

/// Every tensor of `model` (burn's module paths, shapes, f32 data on request), through the
/// weight loader's own visitors so the names are the ones `model.init` applies by.
fn tensors(model: &YoloSeg, data: bool) -> Vec<(String, Vec<usize>, Option<Vec<f32>>)> {
    if !data {
        return weights::shapes(model)
            .into_iter()
            .map(|(p, s)| (p, s, None))
            .collect();
    }
    weights::collect(model)
        .into_iter()
        .map(|snap| {
            let name = snap.name.clone();
            let shape = snap.shape.to_vec();
            let v = weights::snapshot_data(snap)
                .ok()
                .and_then(|d| d.try_to_vec::<f32>().ok());
            (name, shape, v)
        })
        .collect()
}

/// Our tensors ↔ ultralytics keys for `model`, in module order.
pub fn key_map(model: &YoloSeg) -> Result<Vec<KeyPair>> {
    tensors(model, false)
        .into_iter()
        .map(|(ours, shape, _)| {
            let theirs = ultralytics_key(&ours)
                .with_context(|| format!("module path {ours} has no ultralytics name"))?;
            Ok(KeyPair {
                ours,
                theirs,
                shape,
            })
        })
        .collect()
}

/// `model.23.dfl.conv.weight`: the fixed 1×1 conv that takes the expectation of the DFL bins.
pub const DFL_KEY: &str = "model.23.dfl.conv.weight";

/// The ultralytics state dict of `model` (built from `cfg`): our tensors under ultralytics'
/// names, plus `num_batches_tracked` (int64, 0: Burn does not count batches, and with
/// ultralytics' fixed BN momentum the count is never read) after each BatchNorm and the DFL
/// conv weight `arange(16)`. Takes an unfused model (checkpoints hold unfused weights).
pub fn ultralytics_state_dict(
    model: &YoloSeg,
    cfg: &YoloSegConfig,
) -> Result<Vec<(String, HostTensor)>> {
    if let Some(e) = layout_error(cfg) {
        bail!("{e}");
    }
    let mut out = Vec::new();
    for (ours, shape, data) in tensors(model, true) {
        let theirs = ultralytics_key(&ours)
            .with_context(|| format!("module path {ours} has no ultralytics name"))?;
        let bn_end = theirs
            .ends_with(".bn.running_var")
            .then(|| theirs.trim_end_matches("running_var").to_string() + "num_batches_tracked");
        out.push((theirs, HostTensor::f32(shape, data.unwrap_or_default())));
        if let Some(k) = bn_end {
            out.push((
                k,
                HostTensor {
                    shape: vec![],
                    data: HostData::I64(vec![0]),
                    source_dtype: "int64",
                },
            ));
        }
    }
    out.push((
        DFL_KEY.to_string(),
        HostTensor::f32(
            vec![1, REG_MAX, 1, 1],
            (0..REG_MAX).map(|i| i as f32).collect(),
        ),
    ));
    Ok(out)
}

/// Orders keys as ultralytics lists them: numeric segments by value (`model.2` < `model.10`).
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let mut x = a.split('.');
    let mut y = b.split('.');
    loop {
        match (x.next(), y.next()) {
            (None, None) => return Ordering::Equal,
            (None, _) => return Ordering::Less,
            (_, None) => return Ordering::Greater,
            (Some(p), Some(q)) => {
                let o = match (p.parse::<u64>(), q.parse::<u64>()) {
                    (Ok(m), Ok(n)) => m.cmp(&n),
                    _ => p.cmp(q),
                };
                if o != Ordering::Equal {
                    return o;
                }
            }
        }
    }
}

fn describe(cfg: &YoloSegConfig) -> String {
    format!(
        "YOLO11{}-seg (width ×{}, {} classes, {} prototypes)",
        cfg.scale.name(),
        cfg.width_mult,
        cfg.num_classes,
        cfg.num_masks
    )
}

/// Reads an ultralytics weights file for the model of `cfg` (see the module docs).
pub fn read_ultralytics(path: &Path, cfg: &YoloSegConfig) -> Result<UltralyticsWeights> {
    if let Some(e) = layout_error(cfg) {
        bail!("cannot load {} into this model: {e}", path.display());
    }
    let sd = read_state_dict(path, &["ema", "model"])
        .with_context(|| format!("cannot read ultralytics weights from {}", path.display()))?;
    from_state_dict(&sd, path, cfg)
}

/// [`read_ultralytics`] on a state dict already in memory (`file` names it in messages).
pub fn from_state_dict(
    sd: &StateDict,
    file: &Path,
    cfg: &YoloSegConfig,
) -> Result<UltralyticsWeights> {
    let f = file.display();
    if let Some(e) = layout_error(cfg) {
        bail!("cannot load {f} into this model: {e}");
    }
    let t = &sd.tensors;
    if !t.contains_key("model.0.conv.weight") {
        let mut keys: Vec<&String> = t.keys().collect();
        keys.sort_by(|a, b| natural_cmp(a, b));
        let first: Vec<&str> = keys.iter().take(4).map(|s| s.as_str()).collect();
        bail!(
            "{f}: not an ultralytics YOLO state dict (no key model.0.conv.weight; its first keys: {})",
            first.join(", ")
        );
    }
    // Build the model once for its shapes (random init is cheap next to reading the file).
    let model = cfg.init(&Device::flex());
    let map = key_map(&model)?;
    let read = read_mapped(t, &map, file, cfg)?;
    check_dfl(t, file)?;
    check_unused(t, &read.used, file, cfg)?;
    let file_classes = t
        .get("model.23.cv3.0.2.weight")
        .map(|w| w.shape[0])
        .unwrap_or(0);
    let fp = t
        .get("model.0.conv.weight")
        .map(|w| w.source_dtype)
        .unwrap_or("float32");
    let mut notes = vec![format!(
        "read {} ultralytics tensors ({}, {fp}) from the {} of {f}",
        read.snapshots.len(),
        describe(cfg),
        sd.origin
    )];
    if !read.class_unfit.is_empty() {
        notes.push(format!(
            "the checkpoint has {file_classes} classes, the model {}: {} class-head tensors (model.23.cv3) \
             do not fit and are re-initialised",
            cfg.num_classes,
            read.class_unfit.len()
        ));
    }
    if !read.missing.is_empty() {
        notes.push(format!(
            "{f} is a detection checkpoint (no mask head): the {} tensors of proto and the mask \
             coefficients (model.23.proto, cv4) keep their fresh init",
            read.missing.len()
        ));
    }
    Ok(UltralyticsWeights {
        snapshots: read.snapshots,
        class_unfit: read.class_unfit,
        missing: read.missing,
        file_classes,
        notes,
    })
}

/// What [`read_mapped`] took from the file: the fitting tensors as snapshots, the
/// file's keys it used, and the model's tensors it could not fill.
struct Mapped<'a> {
    snapshots: Vec<burn_pack::Tensor>,
    used: Vec<&'a str>,
    class_unfit: Vec<Unfit>,
    missing: Vec<String>,
}

/// Each tensor of the key map from the file, in the map's order: a snapshot when it fits;
/// an [`Unfit`] class-head tensor of another class count; a missing mask-head tensor of a
/// detection checkpoint; an error for anything else.
fn read_mapped<'a>(
    t: &'a BTreeMap<String, HostTensor>,
    map: &'a [KeyPair],
    file: &Path,
    cfg: &YoloSegConfig,
) -> Result<Mapped<'a>> {
    let f = file.display();
    let has_seg_head = t.keys().any(|k| k.starts_with("model.23.proto."));
    let mut out = Mapped {
        snapshots: Vec::new(),
        used: Vec::new(),
        class_unfit: Vec::new(),
        missing: Vec::new(),
    };
    for kp in map {
        let seg_head =
            kp.theirs.starts_with("model.23.proto.") || kp.theirs.starts_with("model.23.cv4.");
        let Some(ft) = t.get(&kp.theirs) else {
            if seg_head && !has_seg_head {
                out.missing.push(kp.ours.clone());
                continue;
            }
            bail!(
                "{f}: no tensor {} (chicktrain's {}, shape {:?}) — not a {} checkpoint",
                kp.theirs,
                kp.ours,
                kp.shape,
                describe(cfg)
            );
        };
        out.used.push(&kp.theirs);
        if ft.shape != kp.shape {
            if kp.theirs.starts_with("model.23.cv3.") {
                out.class_unfit.push(Unfit {
                    ours: kp.ours.clone(),
                    theirs: kp.theirs.clone(),
                    file_shape: ft.shape.clone(),
                    model_shape: kp.shape.clone(),
                });
                continue;
            }
            bail!(
                "{f}: {} has shape {:?} in the file, {} needs {:?} (chicktrain's {}) — a checkpoint of \
                 another scale or width? Set model.scale / model.width_mult to the checkpoint's",
                kp.theirs,
                ft.shape,
                describe(cfg),
                kp.shape,
                kp.ours
            );
        }
        let HostData::F32(v) = &ft.data else {
            bail!(
                "{f}: {} is {}, a float tensor was expected",
                kp.theirs,
                ft.source_dtype
            );
        };
        let (bytes, shape, dtype) = TensorData::new(v.clone(), kp.shape.clone()).into_parts();
        out.snapshots.push(burn_pack::Tensor::new(
            kp.ours.clone(),
            dtype,
            shape,
            None,
            bytes,
        ));
    }
    Ok(out)
}

/// The file's DFL projection, if it has one, must be the fixed `arange(16)` ours is.
fn check_dfl(t: &BTreeMap<String, HostTensor>, file: &Path) -> Result<()> {
    if let Some(dfl) = t.get(DFL_KEY) {
        let expect: Vec<f32> = (0..REG_MAX).map(|i| i as f32).collect();
        if dfl.shape != [1, REG_MAX, 1, 1] || dfl.to_f32() != expect {
            bail!(
                "{}: {DFL_KEY} is not the fixed arange({REG_MAX}) projection ultralytics builds (shape {:?}); \
                 chicktrain decodes boxes with that projection",
                file.display(),
                dfl.shape
            );
        }
    }
    Ok(())
}

/// Every key of the file must have been `used` (BatchNorm's `num_batches_tracked` and the
/// DFL projection aside): a key left over is another architecture.
fn check_unused(
    t: &BTreeMap<String, HostTensor>,
    used: &[&str],
    file: &Path,
    cfg: &YoloSegConfig,
) -> Result<()> {
    let mut extra: Vec<&String> = t
        .keys()
        .filter(|k| {
            !used.contains(&k.as_str())
                && k.as_str() != DFL_KEY
                && !(k.ends_with(".num_batches_tracked")
                    && used.contains(
                        &(k.trim_end_matches("num_batches_tracked").to_string() + "running_var")
                            .as_str(),
                    ))
        })
        .collect();
    extra.sort_by(|a, b| natural_cmp(a, b));
    if let Some(k) = extra.first() {
        bail!(
            "{}: key {k} (shape {:?}) has no place in {} — {} keys do not fit; a checkpoint of \
             another architecture (YOLOv8, YOLO26, a larger head)?",
            file.display(),
            t[*k].shape,
            describe(cfg),
            extra.len()
        );
    }
    Ok(())
}

/// Applies weights that cover the whole model, strictly (every tensor present, none unused,
/// shapes checked) through the one loader every weight source takes
/// ([`crate::model::weights::apply`], with no tensor allowed to stay fresh). For partial
/// weights (another class count, a detection checkpoint) `model.init` lets the class head
/// or mask head keep its initialisation.
pub fn apply_all(model: YoloSeg, w: &UltralyticsWeights) -> Result<YoloSeg> {
    if let Some(u) = w.class_unfit.first() {
        bail!(
            "{} of the weights has shape {:?}, the model needs {:?}",
            u.theirs,
            u.file_shape,
            u.model_shape
        );
    }
    if let Some(m) = w.missing.first() {
        bail!("the weights have no tensor for {m}");
    }
    let (model, _) = weights::apply(
        model,
        w.snapshots.clone(),
        &|_| false,
        "ultralytics weights",
    )?;
    Ok(model)
}

/// The ultralytics keys (and shapes) a model of `cfg` exports, sorted the way ultralytics
/// lists them; for comparisons against ultralytics' own key lists.
pub fn exported_keys(cfg: &YoloSegConfig) -> Result<BTreeMap<String, Vec<usize>>> {
    if let Some(e) = layout_error(cfg) {
        bail!("{e}");
    }
    let model = cfg.init(&Device::flex());
    let mut out = BTreeMap::new();
    for kp in key_map(&model)? {
        if kp.theirs.ends_with(".bn.running_var") {
            out.insert(
                kp.theirs.trim_end_matches("running_var").to_string() + "num_batches_tracked",
                vec![],
            );
        }
        out.insert(kp.theirs, kp.shape);
    }
    out.insert(DFL_KEY.to_string(), vec![1, REG_MAX, 1, 1]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_paths_of_every_block_kind() {
        for (ours, theirs) in [
            ("backbone.l0.conv.weight", "model.0.conv.weight"),
            ("backbone.l0.bn.gamma", "model.0.bn.weight"),
            ("backbone.l0.bn.beta", "model.0.bn.bias"),
            (
                "backbone.l2.m.0.Bottleneck.cv1.bn.running_mean",
                "model.2.m.0.cv1.bn.running_mean",
            ),
            (
                "backbone.l8.m.0.C3k.m.1.cv2.conv.weight",
                "model.8.m.0.m.1.cv2.conv.weight",
            ),
            ("backbone.sppf.cv2.conv.weight", "model.9.cv2.conv.weight"),
            (
                "backbone.psa.m.0.attn.qkv.bn.running_var",
                "model.10.m.0.attn.qkv.bn.running_var",
            ),
            (
                "backbone.psa.m.0.ffn1.conv.weight",
                "model.10.m.0.ffn.0.conv.weight",
            ),
            (
                "backbone.psa.m.0.ffn2.bn.gamma",
                "model.10.m.0.ffn.1.bn.weight",
            ),
            ("neck.td_p4.cv1.conv.weight", "model.13.cv1.conv.weight"),
            ("neck.p3.td_p3.cv2.conv.weight", "model.16.cv2.conv.weight"),
            ("neck.p3.down_p3.conv.weight", "model.17.conv.weight"),
            ("neck.p3.bu_p4.cv1.conv.weight", "model.19.cv1.conv.weight"),
            ("neck.down_p4.bn.beta", "model.20.bn.bias"),
            (
                "neck.bu_p5.m.0.C3k.cv3.conv.weight",
                "model.22.m.0.cv3.conv.weight",
            ),
            ("head.boxes.2.out.bias", "model.23.cv2.2.2.bias"),
            (
                "head.cls.1.dw2.conv.weight",
                "model.23.cv3.1.1.0.conv.weight",
            ),
            ("head.cls.0.pw1.bn.gamma", "model.23.cv3.0.0.1.bn.weight"),
            ("head.cls.0.out.weight", "model.23.cv3.0.2.weight"),
            ("head.coef.1.c2.conv.weight", "model.23.cv4.1.1.conv.weight"),
            (
                "head.proto.upsample.weight",
                "model.23.proto.upsample.weight",
            ),
            (
                "head.proto.cv3.bn.running_mean",
                "model.23.proto.cv3.bn.running_mean",
            ),
        ] {
            assert_eq!(ultralytics_key(ours).as_deref(), Some(theirs), "{ours}");
        }
        assert_eq!(ultralytics_key("backbone.l9.conv.weight"), None);
        assert_eq!(ultralytics_key("head.cls.0.zz.weight"), None);
    }

    #[test]
    fn natural_order_is_ultralytics_order() {
        let mut v = vec![
            "model.10.cv1",
            "model.2.cv1",
            "model.2.m.0",
            "model.23.cv2.0",
        ];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            [
                "model.2.cv1",
                "model.2.m.0",
                "model.10.cv1",
                "model.23.cv2.0"
            ]
        );
    }

    #[test]
    fn refuses_layouts_ultralytics_cannot_build() {
        let c = YoloSegConfig::new(super::super::Scale::N, 1).with_c2psa(false);
        assert!(layout_error(&c).unwrap().contains("model.c2psa = false"));
        let c = YoloSegConfig::new(super::super::Scale::N, 1).with_levels(HeadLevels::P4P5);
        assert!(exported_keys(&c).unwrap_err().to_string().contains("P3–P5"));
        let c = YoloSegConfig::new(super::super::Scale::N, 1).with_width_mult(0.25);
        assert!(layout_error(&c).unwrap().contains("C2PSA width 32"));
        let c = YoloSegConfig::new(super::super::Scale::N, 1).with_width_mult(0.5);
        assert_eq!(layout_error(&c), None);
    }
}
