//! `model.init = "PATH"`: start training from weights in a file. The format is read from
//! the first bytes ([`weights::sniff_file`]), never the extension, and every source goes
//! through the same loader ([`weights::apply`]) with the same checks:
//!
//! | file | model | what is loaded |
//! |---|---|---|
//! | chicktrain checkpoint (`.bpk`, any family) | same family | its `ema` weights (what it evaluates and ships), every tensor; with another class count the class-dependent ones are re-initialised and named |
//! | PyTorch zip / safetensors | the family's own reader | what its `Family::load_foreign` (`model/<family>/family.rs`) reads: torchvision ResNet / Mask R-CNN state dicts (two-stage and query-based families, backbone or more), ultralytics checkpoints (YOLO); a family without one refuses by name |
//!
//! `--resume` ignores `model.init`: the run's `last.bpk` wins.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::tensor::Device;

use crate::model::family::ForeignInit;
use crate::model::weights::{self, Applied, Format};

use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::{Detector, DetectorConfig};

/// `model`, with the weights of `path` loaded; the second value says what was loaded
/// (printed by the trainer). `config` is `model`'s own (the ultralytics mapping needs
/// its scale and width); `device` builds the source model of a checkpoint. A file of
/// another framework is read by the family ([`crate::model::family::Family::load_foreign`]).
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
    let ForeignInit {
        model,
        applied,
        what,
        fresh_why,
    } = match format {
        Format::Chicktrain => {
            let ck = Checkpoint::load(path).with_context(|| origin.clone())?;
            let src = &ck.header.model;
            let want = config.kind();
            if src.kind() != want {
                bail!(
                    "{origin}: it holds a model.kind = \"{}\" model ({}), the config asks for model.kind = \"{}\": weights of one family cannot start the other",
                    src.kind().name(),
                    src.describe(),
                    want.name()
                );
            }
            let what = format!(
                "{} ({}, epoch {})",
                format.name(),
                src.describe(),
                ck.header.epoch
            );
            let source = ck.model("ema", device).with_context(|| origin.clone())?;
            let (model, applied) = model.apply_same_family(&source, &origin)?;
            ForeignInit {
                model,
                applied,
                what,
                fresh_why: "the file's class count differs there",
            }
        }
        Format::TorchLegacy | Format::TorchZip | Format::Safetensors => {
            model.load_foreign(config, path, format, &origin)?
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
    use crate::model::maskrcnn::torchvision;
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
