//! Mask2Former as a [`Family`]: what the trainer, the checkpoints, `model.init`, `--smoke`
//! and `bench models` need of it, in one place (this file only wires its siblings to the
//! shared interface).

use std::path::Path;

use anyhow::Result;
use burn::tensor::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use crate::annotations::targets::Targets;
use crate::model::detection::Detection;
use crate::model::family::{one_result, timed_infer, Family, ForeignInit, StepLoss, TrainingLoss};
use crate::model::maskrcnn::family::{
    parse_resnet_variant, read_torchvision, resnet_stage_prefixes, resnet_variant_name,
};
use crate::model::maskrcnn::torchvision::TorchvisionKind;
use crate::model::summary::ModelSummary;
use crate::model::weights::{self, Format};

use super::{
    class_dependent, Mask2Former, Mask2FormerConfig, Mask2FormerLosses, Mask2FormerModelConfig,
};

impl Family for Mask2Former {
    type Config = Mask2FormerConfig;
    type Loss = Mask2FormerLosses;
    type Section = Mask2FormerModelConfig;

    const NAME: &'static str = "Mask2Former";
    const LOSS_NAMES: &'static [&'static str] = &Mask2FormerLosses::NAMES;
    const VARIANT_HELP: &'static str = "m2f-r18 / r34 / r50 / r101 with optional -paper";

    fn config(s: &Mask2FormerModelConfig, input_size: usize, num_classes: usize) -> Self::Config {
        Mask2FormerConfig::from_config(s, input_size, num_classes)
    }
    fn build(config: &Mask2FormerConfig, device: &Device) -> Self {
        config.init(device)
    }
    fn num_classes_of(config: &Mask2FormerConfig) -> usize {
        config.num_classes
    }
    fn input_size_of(config: &Mask2FormerConfig) -> usize {
        config.input_size
    }
    fn set_input_size(config: &mut Mask2FormerConfig, size: usize) {
        config.input_size = size;
    }
    fn describe(c: &Mask2FormerConfig) -> String {
        format!(
            "Mask2Former R{} (FPN pixel decoder), width ×{}, {} queries, {} layers × {} wide, {} points, {} classes",
            c.depth,
            c.width_mult,
            c.queries,
            c.dec_layers,
            c.hidden_dim,
            c.criterion.points,
            c.num_classes
        )
    }

    /// Mask R-CNN's ResNet under the same module paths, so its stages.
    fn frozen_prefixes(n: usize) -> Result<Vec<String>> {
        resnet_stage_prefixes(n)
    }
    fn class_dependent(path: &str) -> bool {
        class_dependent(path)
    }
    /// Keeps its depth, gets quarter widths, a 32-wide 3-layer decoder, ≤ 10 queries and
    /// 256 points.
    fn smoke(m: &mut Mask2FormerModelConfig) {
        m.width_mult = m.width_mult.min(0.25);
        m.conv_dim = Some(32);
        m.mask_dim = Some(32);
        m.hidden_dim = Some(32);
        m.heads = Some(4);
        m.ffn_dim = Some(64);
        m.dec_layers = Some(m.dec_layers.unwrap_or(3).min(3));
        m.queries = Some(m.queries.unwrap_or(10).min(10));
        m.points = Some(256);
    }

    /// `rng` drives the point sampling.
    fn train_loss(
        &self,
        images: Tensor<4>,
        targets: &Targets,
        rng: &mut ChaCha8Rng,
    ) -> Mask2FormerLosses {
        self.forward_train(images, &targets.images, rng)
    }
    /// The seconds are `forward_infer` whole (network and top-k postprocess).
    fn predict_timed(&self, images: Tensor<4>, conf: f32) -> (Vec<Vec<Detection>>, f64) {
        timed_infer(images, conf, |x| self.forward_infer(x))
    }
    fn summary_at(&self, input: usize) -> ModelSummary {
        self.summary(input)
    }

    /// The backbone is the Mask R-CNN family's ResNet under the same paths: a torchvision
    /// ResNet or Mask R-CNN file loads into it, the rest stays fresh.
    fn load_foreign(
        self,
        _config: &Mask2FormerConfig,
        path: &Path,
        format: Format,
        origin: &str,
    ) -> Result<ForeignInit<Self>> {
        let mapped = read_torchvision(path, format, origin, self.num_classes())?;
        let what = match mapped.kind {
            TorchvisionKind::ResNet => format!("{}, torchvision ResNet (backbone)", format.name()),
            _ => format!("{}, torchvision Mask R-CNN (its backbone)", format.name()),
        };
        let snapshots = mapped
            .snapshots
            .into_iter()
            .filter(|s| s.name.starts_with("backbone."))
            .collect();
        let (model, applied) = weights::apply_named(
            self,
            snapshots,
            &|p: &str| !p.starts_with("backbone."),
            origin,
            &mapped.file_keys,
        )?;
        Ok(ForeignInit {
            model,
            applied,
            what,
            fresh_why: "a torchvision file holds the ResNet backbone only",
        })
    }

    /// `forward_infer` (network and top-k postprocess).
    fn bench_forward(&self, image: Tensor<4>) -> Result<()> {
        one_result(self.forward_infer(image).len(), Self::NAME)
    }
    fn probe(&self) -> Tensor<1> {
        self.transformer_decoder.class_embed.weight.val().sum()
    }

    /// `m2f-r<depth>` (the compact preset, [`Mask2FormerConfig::new`]) or
    /// `m2f-r<depth>-paper` ([`Mask2FormerConfig::paper`]).
    fn parse_variant(s: &str) -> Option<Result<Mask2FormerConfig>> {
        parse_resnet_variant(s, "m2f").map(|r| r.map(|(depth, paper)| preset(depth, paper)))
    }
    /// As for Mask R-CNN: the decoder width tells the presets apart.
    fn variant_name(c: &Mask2FormerConfig) -> String {
        resnet_variant_name("m2f", c.depth, is_paper(c))
    }
    fn variant_config(c: &Mask2FormerConfig) -> Mask2FormerConfig {
        preset(c.depth, is_paper(c))
    }
}

impl TrainingLoss for Mask2FormerLosses {
    fn into_total(self) -> Tensor<1> {
        self.total
    }
    fn into_step(self) -> StepLoss {
        let v = self.values();
        StepLoss::new(self.total, &v)
    }
}

/// The one-class preset of `depth` that `bench models` times: the paper's or the compact.
fn preset(depth: usize, paper: bool) -> Mask2FormerConfig {
    if paper {
        Mask2FormerConfig::paper(depth, 1)
    } else {
        Mask2FormerConfig::new(depth, 1)
    }
}

/// Whether a Mask2Former is timed as the paper preset of its depth (its decoder width is
/// the paper's).
fn is_paper(c: &Mask2FormerConfig) -> bool {
    c.hidden_dim == Mask2FormerConfig::paper(c.depth, 1).hidden_dim
}
