//! Mask R-CNN as a [`Family`]: what the trainer, the checkpoints, `model.init`, `--smoke`
//! and `bench models` need of it, in one place (this file only wires its siblings to the
//! shared interface). [`parse_resnet_variant`] is the `<prefix>-r<depth>[-paper]` naming
//! Mask2Former shares.

use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use crate::annotations::targets::Targets;
use crate::model::detection::Detection;
use crate::model::family::{
    one_result, timed_infer, Exporter, Family, ForeignInit, StepLoss, TrainingLoss,
};
use crate::model::summary::ModelSummary;
use crate::model::weights::{self, Format};

use super::export;
use super::torchvision::{self, TorchvisionKind};
use super::{class_dependent, MaskRcnn, MaskRcnnConfig, MaskRcnnLosses, MaskRcnnModelConfig};

impl Family for MaskRcnn {
    type Config = MaskRcnnConfig;
    type Loss = MaskRcnnLosses;
    type Section = MaskRcnnModelConfig;

    const NAME: &'static str = "Mask R-CNN";
    const LOSS_NAMES: &'static [&'static str] = &MaskRcnnLosses::NAMES;
    const VARIANT_HELP: &'static str = "mrcnn-r18 / r34 / r50 / r101 with optional -paper";

    fn config(
        section: &MaskRcnnModelConfig,
        input_size: usize,
        num_classes: usize,
    ) -> Self::Config {
        MaskRcnnConfig::from_config(section, input_size, num_classes)
    }
    fn build(config: &MaskRcnnConfig, device: &Device) -> Self {
        config.init(device)
    }
    fn num_classes_of(config: &MaskRcnnConfig) -> usize {
        config.num_classes
    }
    fn input_size_of(config: &MaskRcnnConfig) -> usize {
        config.input_size
    }
    fn set_input_size(config: &mut MaskRcnnConfig, size: usize) {
        config.input_size = size;
    }
    fn describe(c: &MaskRcnnConfig) -> String {
        format!(
            "Mask R-CNN R{}-FPN, width ×{}, FPN {}, RoIs {}/image, {} classes",
            c.depth, c.width_mult, c.fpn_channels, c.roi.batch_per_image, c.num_classes
        )
    }

    fn frozen_prefixes(n: usize) -> Result<Vec<String>> {
        resnet_stage_prefixes(n)
    }
    fn class_dependent(path: &str) -> bool {
        class_dependent(path)
    }
    /// Keeps its depth (so the R101 code paths run) but gets quarter widths, anchors sized
    /// for 64 px and a few dozen proposals and RoIs.
    fn smoke(m: &mut MaskRcnnModelConfig) {
        m.width_mult = m.width_mult.min(0.25);
        m.fpn_channels = Some(32);
        m.anchor_sizes = Some(vec![12.0, 24.0, 48.0, 96.0, 192.0]);
        m.rpn_batch = Some(64);
        m.rpn_pre_nms_topk_train = Some(200);
        m.rpn_post_nms_topk_train = Some(50);
        m.rpn_pre_nms_topk_test = Some(200);
        m.rpn_post_nms_topk_test = Some(50);
        m.roi_batch = Some(32);
        m.box_fc_dim = Some(64);
        m.mask_conv_dim = Some(32);
    }

    /// `rng` drives the anchor and RoI sampling.
    fn train_loss(
        &self,
        images: Tensor<4>,
        targets: &Targets,
        rng: &mut ChaCha8Rng,
    ) -> MaskRcnnLosses {
        self.forward_train(images, &targets.images, rng)
    }
    /// Applies its own score threshold (`roi.score_thresh`, 0.05) first; the seconds are
    /// `forward_infer` whole (its proposal, NMS and head stages interleave with the network).
    fn predict_timed(&self, images: Tensor<4>, conf: f32) -> (Vec<Vec<Detection>>, f64) {
        timed_infer(images, conf, |x| self.forward_infer(x))
    }
    fn summary_at(&self, input: usize) -> ModelSummary {
        self.summary(input)
    }

    /// A torchvision ImageNet ResNet (backbone) or `maskrcnn_resnet50_fpn` state dict.
    fn load_foreign(
        self,
        _config: &MaskRcnnConfig,
        path: &Path,
        format: Format,
        origin: &str,
    ) -> Result<ForeignInit<Self>> {
        let mapped = read_torchvision(path, format, origin, self.num_classes())?;
        let fresh_why = if mapped.kind == TorchvisionKind::ResNet {
            "an ImageNet ResNet file holds the backbone only"
        } else {
            "the file's class count differs there"
        };
        let what = match (mapped.kind, mapped.file_classes) {
            (TorchvisionKind::ResNet, _) => {
                format!("{}, torchvision ResNet (backbone only)", format.name())
            }
            (_, Some(k)) => format!(
                "{}, torchvision Mask R-CNN ({} classes with background)",
                format.name(),
                k
            ),
            (_, None) => format!("{}, torchvision Mask R-CNN", format.name()),
        };
        let (model, applied) = weights::apply_named(
            self,
            mapped.snapshots,
            &torchvision::class_dependent(mapped.kind),
            origin,
            &mapped.file_keys,
        )?;
        Ok(ForeignInit {
            model,
            applied,
            what,
            fresh_why,
        })
    }

    const ONNX: Option<Exporter<Self>> = Some(export::onnx);
    const SAFETENSORS: Option<Exporter<Self>> = Some(export::safetensors);

    /// `forward_infer` (proposals, boxes, mask probabilities).
    fn bench_forward(&self, image: Tensor<4>) -> Result<()> {
        one_result(self.forward_infer(image).len(), Self::NAME)
    }
    fn probe(&self) -> Tensor<1> {
        self.box_head.cls_score.weight.val().sum()
    }

    /// `mrcnn-r<depth>` (the compact preset, [`MaskRcnnConfig::new`]) or
    /// `mrcnn-r<depth>-paper` ([`MaskRcnnConfig::paper`]).
    fn parse_variant(s: &str) -> Option<Result<MaskRcnnConfig>> {
        parse_resnet_variant(s, "mrcnn").map(|r| r.map(|(depth, paper)| preset(depth, paper)))
    }
    /// The preset of its depth that its FPN width matches: `-paper` when `fpn_channels` is
    /// the paper preset's (256), the compact model otherwise. The FPN width is the size that
    /// tells the presets apart and costs the most; other per-field overrides (proposal
    /// counts, head widths) are not reproduced.
    fn variant_name(c: &MaskRcnnConfig) -> String {
        resnet_variant_name("mrcnn", c.depth, is_paper(c))
    }
    fn variant_config(c: &MaskRcnnConfig) -> MaskRcnnConfig {
        preset(c.depth, is_paper(c))
    }
}

/// Module-path prefixes of the Mask R-CNN stem and the first `n − 1` ResNet stages
/// (detectron2's `FREEZE_AT = n`): 1 the stem, 2 the stem and res2 (torchvision's
/// `trainable_backbone_layers = 3`, both libraries' default for fine-tuning), … 5 the whole
/// ResNet (torchvision's `trainable_backbone_layers = 0`). Mask2Former's backbone is the
/// same ResNet under the same paths.
pub fn resnet_stage_prefixes(n: usize) -> Result<Vec<String>> {
    if n > 5 {
        bail!(
            "train.freeze = {n} must be at most 5 for a Mask R-CNN (the stem and 4 ResNet stages)"
        );
    }
    let mut p = Vec::new();
    if n >= 1 {
        p.push("backbone.stem".to_string());
    }
    for s in 0..n.saturating_sub(1) {
        p.push(format!("backbone.stages.{s}"));
    }
    Ok(p)
}

/// A torchvision file (an ImageNet ResNet or `maskrcnn_resnet50_fpn` state dict) under
/// chicktrain's keys for a model of `num_classes`: what `model.init` of both ResNet
/// families reads (`origin` names it in errors).
pub fn read_torchvision(
    path: &Path,
    format: Format,
    origin: &str,
    num_classes: usize,
) -> Result<torchvision::Mapped> {
    if format == Format::Chicktrain {
        bail!("{origin}: a chicktrain checkpoint is not a foreign weights file");
    }
    let tensors =
        weights::read_file(path, &["model", "state_dict"]).with_context(|| origin.to_string())?;
    torchvision::map_state_dict(tensors, num_classes).with_context(|| origin.to_string())
}

/// The one-class preset of `depth` that `bench models` times: the paper's or the compact.
fn preset(depth: usize, paper: bool) -> MaskRcnnConfig {
    if paper {
        MaskRcnnConfig::paper(depth, 1)
    } else {
        MaskRcnnConfig::new(depth, 1)
    }
}

/// Whether a Mask R-CNN is timed as the paper preset of its depth (its FPN width is the
/// paper's).
fn is_paper(c: &MaskRcnnConfig) -> bool {
    c.fpn_channels == MaskRcnnConfig::paper(c.depth, c.num_classes).fpn_channels
}

/// `<prefix>-r<depth>` or `<prefix>-r<depth>-paper` as (depth, paper); `None` when `s`
/// does not start with `<prefix>-`.
pub fn parse_resnet_variant(s: &str, prefix: &str) -> Option<Result<(usize, bool)>> {
    let mut parts = s.split('-');
    if parts.next() != Some(prefix) {
        return None;
    }
    let r = parts.next()?;
    Some(resnet_depth_and_preset(s, r, parts))
}

/// The depth of `r` (`r50`) and whether the remaining `parts` say `paper`.
fn resnet_depth_and_preset<'a>(
    s: &str,
    r: &str,
    mut parts: impl Iterator<Item = &'a str>,
) -> Result<(usize, bool)> {
    let paper = match (parts.next(), parts.next()) {
        (None, _) => false,
        (Some("paper"), None) => true,
        (Some(p), _) => bail!("variant {s:?}: unknown option {p:?}"),
    };
    let depth = r
        .strip_prefix('r')
        .and_then(|d| d.parse().ok())
        .filter(|d| [18, 34, 50, 101].contains(d))
        .with_context(|| format!("variant {s:?}: unknown depth"))?;
    Ok((depth, paper))
}

/// The name [`parse_resnet_variant`] reads back.
pub fn resnet_variant_name(prefix: &str, depth: usize, paper: bool) -> String {
    format!("{prefix}-r{depth}{}", if paper { "-paper" } else { "" })
}

impl TrainingLoss for MaskRcnnLosses {
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

    #[test]
    fn stage_table() {
        assert!(resnet_stage_prefixes(0).unwrap().is_empty());
        assert_eq!(
            resnet_stage_prefixes(2).unwrap(),
            vec!["backbone.stem", "backbone.stages.0"]
        );
        assert_eq!(resnet_stage_prefixes(5).unwrap().len(), 5);
        assert!(resnet_stage_prefixes(6).is_err());
    }
}
