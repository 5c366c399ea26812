//! `model.init = "PATH"`: start training from weights in a file. The format is read from
//! the first bytes ([`weights::sniff_file`]), never the extension, and every source goes
//! through the same loader ([`weights::apply`]) with the same checks:
//!
//! | file | model | what is loaded |
//! |---|---|---|
//! | chicktrain checkpoint (`.bpk`, any family) | same family | its `ema` weights (what it evaluates and ships), every tensor; with another class count the class-dependent ones are re-initialised and named |
//! | PyTorch zip / safetensors | Mask R-CNN | a torchvision ImageNet ResNet (backbone) or `maskrcnn_resnet50_fpn` state dict ([`torchvision`]) |
//! | PyTorch zip / safetensors | Mask2Former | the ResNet backbone of a torchvision ImageNet ResNet or Mask R-CNN state dict; the rest keeps its initialisation |
//! | PyTorch zip / safetensors | YOLO | an ultralytics checkpoint or state dict ([`ultralytics`]); the class head is re-initialised for another class count, the mask head for a detection checkpoint |
//!
//! `--resume` ignores `model.init`: the run's `last.bpk` wins.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::tensor::Device;

use crate::model::mask2former;
use crate::model::maskrcnn::{self, torchvision};
use crate::model::weights::{self, Applied, Format};
use crate::model::yolo::{self, ultralytics};

use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::{Detector, DetectorConfig};

/// `model`, with the weights of `path` loaded; the second value says what was loaded
/// (printed by the trainer). `config` is `model`'s own (the ultralytics mapping needs
/// its scale and width); `device` builds the source model of a checkpoint.
pub fn load_init(
    model: Detector,
    config: &DetectorConfig,
    path: &Path,
    device: &Device,
) -> Result<(Detector, String)> {
    let origin = format!("model.init {}", path.display());
    let (format, head) =
        weights::sniff_file(path).with_context(|| format!("{origin}: cannot read the file"))?;
    let Some(format) = format else {
        bail!(
            "{origin}: not a chicktrain checkpoint, PyTorch file or safetensors file (first bytes {:02x?})",
            &head[..head.len().min(8)]
        );
    };
    // Why tensors may keep their initialisation, for the message.
    let mut fresh_why = "the file's class count differs there";
    let (model, applied, what) = match (format, model) {
        (Format::Chicktrain, model) => {
            let ck = Checkpoint::load(path).with_context(|| origin.clone())?;
            let src = &ck.header.model;
            let want = config.kind();
            if src.kind() != want {
                let name = |k| match k {
                    crate::config::ModelKind::Yolo => "model.kind = \"yolo\"",
                    crate::config::ModelKind::Maskrcnn => "model.kind = \"maskrcnn\"",
                    crate::config::ModelKind::Mask2former => "model.kind = \"mask2former\"",
                };
                bail!(
                    "{origin}: it holds a {} model ({}), the config asks for {}: weights of one family cannot start the other",
                    name(src.kind()),
                    src.describe(),
                    name(want)
                );
            }
            let what = format!(
                "{} ({}, epoch {})",
                format.name(),
                src.describe(),
                ck.header.epoch
            );
            let source = ck.model("ema", device).with_context(|| origin.clone())?;
            let (model, applied) = match (model, source) {
                (Detector::Yolo(m), Detector::Yolo(s)) => {
                    let (m, a) =
                        weights::apply(m, weights::collect(&s), &yolo::class_dependent, &origin)?;
                    (Detector::Yolo(m), a)
                }
                (Detector::MaskRcnn(m), Detector::MaskRcnn(s)) => {
                    let (m, a) = weights::apply(
                        m,
                        weights::collect(&s),
                        &maskrcnn::class_dependent,
                        &origin,
                    )?;
                    (Detector::MaskRcnn(m), a)
                }
                (Detector::Mask2Former(m), Detector::Mask2Former(s)) => {
                    let (m, a) = weights::apply(
                        m,
                        weights::collect(&s),
                        &mask2former::class_dependent,
                        &origin,
                    )?;
                    (Detector::Mask2Former(m), a)
                }
                _ => unreachable!("kinds checked above"),
            };
            (model, applied, what)
        }
        (Format::TorchLegacy | Format::TorchZip | Format::Safetensors, Detector::MaskRcnn(m)) => {
            let tensors = weights::read_file(path, &["model", "state_dict"])
                .with_context(|| origin.clone())?;
            let nc = m.num_classes();
            let mapped =
                torchvision::map_state_dict(tensors, nc).with_context(|| origin.clone())?;
            if mapped.kind == torchvision::TorchvisionKind::ResNet {
                fresh_why = "an ImageNet ResNet file holds the backbone only";
            }
            let what = match (mapped.kind, mapped.file_classes) {
                (torchvision::TorchvisionKind::ResNet, _) => {
                    format!("{}, torchvision ResNet (backbone only)", format.name())
                }
                (_, Some(k)) => format!(
                    "{}, torchvision Mask R-CNN ({} classes with background)",
                    format.name(),
                    k
                ),
                (_, None) => format!("{}, torchvision Mask R-CNN", format.name()),
            };
            let (m, a) = weights::apply_named(
                m,
                mapped.snapshots,
                &torchvision::class_dependent(mapped.kind),
                &origin,
                &mapped.file_keys,
            )?;
            (Detector::MaskRcnn(m), a, what)
        }
        (
            Format::TorchLegacy | Format::TorchZip | Format::Safetensors,
            Detector::Mask2Former(m),
        ) => {
            // The backbone is the Mask R-CNN family's ResNet under the same paths: a
            // torchvision ResNet or Mask R-CNN file loads into it, the rest stays fresh.
            let tensors = weights::read_file(path, &["model", "state_dict"])
                .with_context(|| origin.clone())?;
            let mapped = torchvision::map_state_dict(tensors, m.num_classes())
                .with_context(|| origin.clone())?;
            fresh_why = "a torchvision file holds the ResNet backbone only";
            let what = match mapped.kind {
                torchvision::TorchvisionKind::ResNet => {
                    format!("{}, torchvision ResNet (backbone)", format.name())
                }
                _ => format!("{}, torchvision Mask R-CNN (its backbone)", format.name()),
            };
            let snapshots = mapped
                .snapshots
                .into_iter()
                .filter(|s| s.name.starts_with("backbone."))
                .collect();
            let (m, a) = weights::apply_named(
                m,
                snapshots,
                &|p: &str| !p.starts_with("backbone."),
                &origin,
                &mapped.file_keys,
            )?;
            (Detector::Mask2Former(m), a, what)
        }
        (Format::TorchLegacy | Format::TorchZip | Format::Safetensors, Detector::Yolo(m)) => {
            // ultralytics `.pt` (its `ema`, else `model`), a state dict or safetensors under
            // ultralytics' key names; a detection checkpoint has no mask head, which keeps its
            // fresh init like a class head of another class count.
            let DetectorConfig::Yolo(cfg) = config else {
                bail!("{origin}: the model config is not a YOLO config");
            };
            let w = ultralytics::read_ultralytics(path, cfg).with_context(|| origin.clone())?;
            if !w.missing.is_empty() {
                fresh_why =
                    "a class count that differs, or a detection checkpoint without a mask head";
            }
            let what = format!(
                "{}, ultralytics ({} classes)",
                format.name(),
                w.file_classes
            );
            let missing: std::collections::HashSet<String> = w.missing.iter().cloned().collect();
            let keep = |p: &str| yolo::class_dependent(p) || missing.contains(p);
            let (m, a) = weights::apply(m, w.snapshots, &keep, &origin)?;
            (Detector::Yolo(m), a, what)
        }
    };
    Ok((model, describe(path, &what, &applied, fresh_why)))
}

/// One line (two with re-initialised tensors) saying what was loaded.
fn describe(path: &Path, what: &str, a: &Applied, fresh_why: &str) -> String {
    let mut s = format!(
        "model.init: loaded {} tensors from {} ({what})",
        a.loaded,
        path.display()
    );
    if !a.reinitialised.is_empty() {
        // Group by module (path without the tensor name) so a head is one entry.
        let mut groups: BTreeMap<String, usize> = BTreeMap::new();
        for p in &a.reinitialised {
            let m = p.rsplit_once('.').map(|x| x.0).unwrap_or(p);
            *groups.entry(m.to_string()).or_default() += 1;
        }
        let list: Vec<&str> = groups.keys().map(|k| k.as_str()).collect();
        s.push_str(&format!(
            "\nmodel.init: {} tensors keep their fresh initialisation ({fresh_why}): {}",
            a.reinitialised.len(),
            if list.len() > 12 {
                format!("{} … ({} modules)", list[..12].join(", "), list.len())
            } else {
                list.join(", ")
            }
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::mask2former::Mask2FormerConfig;
    use crate::util::tensor::to_host;

    /// A torchvision ResNet or Mask R-CNN file loads the Mask2Former backbone (the same
    /// ResNet under the same paths) with the file's values; everything else keeps its
    /// fresh initialisation.
    #[test]
    fn torchvision_files_load_the_mask2former_backbone_only() {
        let dev = Device::flex();
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/torchvision");
        for (file, depth) in [("resnet18_w8.pth", 18), ("maskrcnn_r50_w8.pth", 50)] {
            let mut c = Mask2FormerConfig::new(depth, 1);
            c.width_mult = 0.125;
            c.input_size = 64;
            let cfg = DetectorConfig::Mask2former(c);
            let fresh = cfg.init(&dev);
            let Detector::Mask2Former(f) = &fresh else {
                unreachable!()
            };
            let head_before = to_host(f.transformer_decoder.class_embed.weight.val());
            let (m, msg) = load_init(fresh, &cfg, &root.join(file), &dev)
                .unwrap_or_else(|e| panic!("{file}: {e:#}"));
            assert!(msg.contains("backbone"), "{msg}");
            let Detector::Mask2Former(m) = m else {
                panic!("{file}: not a Mask2Former")
            };
            let mapped = torchvision::map_state_dict(
                weights::read_file(&root.join(file), &["model", "state_dict"]).unwrap(),
                1,
            )
            .unwrap();
            let stem = mapped
                .snapshots
                .into_iter()
                .find(|s| s.name == "backbone.stem.conv.weight")
                .expect("the file has a stem");
            let want = weights::snapshot_data(stem)
                .unwrap()
                .try_to_vec::<f32>()
                .unwrap();
            assert_eq!(to_host(m.backbone.stem.conv.weight.val()), want, "{file}");
            assert_eq!(
                to_host(m.transformer_decoder.class_embed.weight.val()),
                head_before,
                "{file}: the decoder keeps its initialisation"
            );
        }
    }
}
