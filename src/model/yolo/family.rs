//! YOLO-seg as a [`Family`]: what the trainer, the checkpoints, `model.init`, `--smoke`
//! and `bench models` need of it, in one place (the blocks, loss and postprocess are its
//! siblings; this file only wires them to the shared interface).

use std::collections::HashSet;
use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use crate::annotations::targets::Targets;
use crate::model::detection::Detection;
use crate::model::family::{Exporter, Family, ForeignInit, StepLoss, TrainingLoss};
use crate::model::summary::ModelSummary;
use crate::model::weights::{self, Format};
use crate::util::tensor::to_host;

use super::export;
use super::loss::{yolo_loss, LossTerms, LossWeights};
use super::postprocess::postprocess;
use super::{
    class_dependent, ultralytics, HeadLevels, Scale, YoloModelConfig, YoloSeg, YoloSegConfig,
};

/// Validation postprocess settings of YOLO (ultralytics' val defaults).
pub const VAL_IOU: f32 = 0.7;
pub const VAL_MAX_DET: usize = 300;

impl Family for YoloSeg {
    type Config = YoloSegConfig;
    type Section = YoloModelConfig;
    type Loss = LossTerms;

    const NAME: &'static str = "YOLO-seg";
    const LOSS_NAMES: &'static [&'static str] = &LossTerms::NAMES;
    const VARIANT_HELP: &'static str =
        "yolo-n / yolo-s with optional -p45 -nopsa -w<f> -m<k> (e.g. yolo-n-p45-w0.5)";

    fn config(section: &YoloModelConfig, input_size: usize, num_classes: usize) -> YoloSegConfig {
        YoloSegConfig::from_config(section, input_size, num_classes)
    }
    fn build(config: &YoloSegConfig, device: &Device) -> Self {
        config.init(device)
    }
    fn num_classes_of(config: &YoloSegConfig) -> usize {
        config.num_classes
    }
    fn input_size_of(config: &YoloSegConfig) -> usize {
        config.input_size
    }
    fn set_input_size(config: &mut YoloSegConfig, size: usize) {
        config.input_size = size;
    }
    fn describe(c: &YoloSegConfig) -> String {
        format!(
            "YOLO-seg {} {:?}, c2psa {}, width ×{}, {} classes",
            c.scale.name(),
            c.levels,
            c.c2psa,
            c.width_mult,
            c.num_classes
        )
    }

    fn frozen_prefixes(n: usize) -> Result<Vec<String>> {
        stage_prefixes(n)
    }
    fn class_dependent(path: &str) -> bool {
        class_dependent(path)
    }
    /// YOLO keeps its table: `data.image_size = 64` is what shrinks it.
    fn smoke(_section: &mut YoloModelConfig) {}

    fn train_loss(&self, images: Tensor<4>, targets: &Targets, _rng: &mut ChaCha8Rng) -> LossTerms {
        yolo_loss(&self.forward(images), targets, &LossWeights::default())
    }
    /// The network's seconds are its forward pass up to the output tensors (box decoding
    /// and NMS excluded, ultralytics' "inference" time).
    fn predict_timed(&self, images: Tensor<4>, conf: f32) -> (Vec<Vec<Detection>>, f64) {
        let t = std::time::Instant::now();
        let out = self.forward(images);
        let fwd = t.elapsed().as_secs_f64();
        (postprocess(&out, conf, VAL_IOU, VAL_MAX_DET), fwd)
    }
    /// YOLO's own postprocess runs at the given NMS IoU and cap.
    fn predict_nms(
        &self,
        images: Tensor<4>,
        conf: f32,
        iou: f32,
        max_det: usize,
    ) -> Vec<Vec<Detection>> {
        postprocess(&self.forward(images), conf, iou, max_det)
    }
    fn summary_at(&self, input: usize) -> ModelSummary {
        self.summary(input)
    }

    /// An ultralytics `.pt` (its `ema`, else `model`), a state dict or safetensors under
    /// ultralytics' key names; a detection checkpoint has no mask head, which keeps its
    /// fresh init like a class head of another class count.
    fn load_foreign(
        self,
        config: &YoloSegConfig,
        path: &Path,
        format: Format,
        origin: &str,
    ) -> Result<ForeignInit<Self>> {
        if format == Format::Chicktrain {
            bail!("{origin}: a chicktrain checkpoint is not a foreign weights file");
        }
        let w = ultralytics::read_ultralytics(path, config).with_context(|| origin.to_string())?;
        let fresh_why = if w.missing.is_empty() {
            "the file's class count differs there"
        } else {
            "a class count that differs, or a detection checkpoint without a mask head"
        };
        let what = format!(
            "{}, ultralytics ({} classes)",
            format.name(),
            w.file_classes
        );
        let missing: HashSet<String> = w.missing.iter().cloned().collect();
        let keep = |p: &str| class_dependent(p) || missing.contains(p);
        let (model, applied) = weights::apply(self, w.snapshots, &keep, origin)?;
        Ok(ForeignInit {
            model,
            applied,
            what,
            fresh_why,
        })
    }

    const ONNX: Option<Exporter<Self>> = Some(export::onnx);
    const SAFETENSORS: Option<Exporter<Self>> = Some(export::safetensors);

    /// BatchNorm folded into the convs, as deployed.
    fn bench_model(&self) -> Self {
        self.valid().fuse()
    }
    fn bench_forward(&self, image: Tensor<4>) -> Result<()> {
        let out = self.forward(image);
        let _ = to_host(out.cls_logits);
        let _ = to_host(out.proto);
        Ok(())
    }
    fn probe(&self) -> Tensor<1> {
        self.head.boxes[0].out.weight.val().sum()
    }

    /// `yolo-<n|s>` with optional suffixes `-p45` (heads on P4–P5 only), `-nopsa` (no
    /// C2PSA attention), `-w<f>` (width multiplier), `-m<k>` (mask prototypes).
    fn parse_variant(s: &str) -> Option<Result<YoloSegConfig>> {
        let mut parts = s.split('-');
        match (parts.next(), parts.next()) {
            (Some("yolo"), Some(sc)) => Some(parse_options(s, sc, parts)),
            _ => None,
        }
    }
    fn variant_config(c: &YoloSegConfig) -> YoloSegConfig {
        YoloSegConfig::new(c.scale, 1)
            .with_levels(c.levels)
            .with_c2psa(c.c2psa)
            .with_width_mult(c.width_mult)
            .with_num_masks(c.num_masks)
    }
    fn variant_name(c: &YoloSegConfig) -> String {
        let mut s = format!("yolo-{}", c.scale.name());
        if c.levels == HeadLevels::P4P5 {
            s.push_str("-p45");
        }
        if !c.c2psa {
            s.push_str("-nopsa");
        }
        if c.width_mult != 1.0 {
            s.push_str(&format!("-w{}", c.width_mult));
        }
        if c.num_masks != 32 {
            s.push_str(&format!("-m{}", c.num_masks));
        }
        s
    }
}

/// Module-path prefixes of YOLO layers `0..n` (ultralytics indices), what
/// `train.freeze = n` freezes: ultralytics' layer indices of `yolo11-seg.yaml`, layers
/// `0..N` (`model.0` … `model.{N-1}`): 0–8 the backbone convs and C3k2s, 9 SPPF, 10 C2PSA,
/// 13/16/17/19/20/22 the neck's C3k2s and convs (11, 12, 14, 15, 18, 21 are upsamples and
/// concatenations without weights), 23 the head. `freeze = 10` is the backbone without
/// C2PSA, `11` the whole backbone.
pub fn stage_prefixes(n: usize) -> Result<Vec<String>> {
    const LAYERS: [Option<&str>; 24] = [
        Some("backbone.l0"),
        Some("backbone.l1"),
        Some("backbone.l2"),
        Some("backbone.l3"),
        Some("backbone.l4"),
        Some("backbone.l5"),
        Some("backbone.l6"),
        Some("backbone.l7"),
        Some("backbone.l8"),
        Some("backbone.sppf"),
        Some("backbone.psa"),
        None,
        None,
        Some("neck.td_p4"),
        None,
        None,
        Some("neck.p3.td_p3"),
        Some("neck.p3.down_p3"),
        None,
        Some("neck.p3.bu_p4"),
        Some("neck.down_p4"),
        None,
        Some("neck.bu_p5"),
        Some("head"),
    ];
    if n >= LAYERS.len() {
        bail!(
            "train.freeze = {n} would freeze the whole YOLO model (layers 0..{}); use at most {}",
            LAYERS.len(),
            LAYERS.len() - 1
        );
    }
    Ok(LAYERS[..n]
        .iter()
        .flatten()
        .map(|s| s.to_string())
        .collect())
}

/// `yolo-<sc>` followed by the option `parts` (`s` is the whole name, for messages).
fn parse_options<'a>(
    s: &str,
    sc: &str,
    parts: impl Iterator<Item = &'a str>,
) -> Result<YoloSegConfig> {
    let scale: Scale = sc
        .parse()
        .map_err(|e: String| anyhow::anyhow!("variant {s:?}: {e}"))?;
    let mut c = YoloSegConfig::new(scale, 1);
    for p in parts {
        match p {
            "p45" => c.levels = HeadLevels::P4P5,
            "nopsa" => c.c2psa = false,
            _ if p.starts_with('w') => {
                c.width_mult = p[1..]
                    .parse()
                    .ok()
                    .filter(|w: &f64| w.is_finite() && *w > 0.0)
                    .with_context(|| format!("variant {s:?}: bad width {p:?}"))?
            }
            _ if p.starts_with('m') => {
                c.num_masks = p[1..]
                    .parse()
                    .ok()
                    .filter(|&k| k > 0)
                    .with_context(|| format!("variant {s:?}: bad prototype count {p:?}"))?
            }
            _ => bail!("variant {s:?}: unknown option {p:?}"),
        }
    }
    Ok(c)
}

impl TrainingLoss for LossTerms {
    fn into_total(self) -> Tensor<1> {
        self.total
    }
    fn into_step(self) -> StepLoss {
        let v = self.values();
        StepLoss::new(self.total, &v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::freeze::is_frozen;

    #[test]
    fn stage_table() {
        assert!(stage_prefixes(0).unwrap().is_empty());
        assert_eq!(
            stage_prefixes(2).unwrap(),
            vec!["backbone.l0", "backbone.l1"]
        );
        let b = stage_prefixes(11).unwrap();
        assert_eq!(b.len(), 11);
        assert_eq!(b.last().unwrap(), "backbone.psa");
        assert_eq!(stage_prefixes(14).unwrap().last().unwrap(), "neck.td_p4");
        assert!(format!("{}", stage_prefixes(24).unwrap_err()).contains("at most 23"));
        let p = stage_prefixes(2).unwrap();
        assert!(is_frozen("backbone.l1.conv.weight", &p));
        assert!(!is_frozen("backbone.l10.conv.weight", &p));
    }
}
