//! The models the trainer can train, behind one closed interface (an enum, like pbrt's
//! tagged unions): build from the run config, loss of a batch with named terms, inference
//! to [`Detection`]s for the shared COCO evaluation, summary. Everything else the trainer
//! does (optimiser, EMA, clipping, checkpoints) works on any Burn [`Module`], so it serves
//! every variant unchanged.
//!
//! The families are registered in `model/mod.rs` (`model::with_families!`, which hands its
//! list to [`families!`] here): each family's [`Detector`] variant names its Burn record in
//! checkpoints, and its [`DetectorConfig`] variant is its `model.kind` and its `[model]`
//! table's `ModelConfig` variant. Every method here dispatches to the family's [`Family`]
//! implementation in `model/<family>/family.rs`; nothing else in the crate matches on the
//! families.

use std::path::Path;

use anyhow::{bail, Result};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::annotations::targets::Targets;
use crate::config::{Config, ModelConfig, ModelKind};
use crate::model::detection::Detection;
pub use crate::model::family::StepLoss;
use crate::model::family::{
    exporter, seeded_loss, ExportFormat, ExportRequest, Family, ForeignInit,
};
use crate::model::summary::ModelSummary;
use crate::model::weights::{self, Applied, Format};
pub use crate::model::yolo::family::{VAL_IOU, VAL_MAX_DET};

/// Validation score threshold (ultralytics' val default; Mask R-CNN applies its own,
/// higher threshold first). YOLO's NMS IoU and detection cap are [`VAL_IOU`] and
/// [`VAL_MAX_DET`].
pub const VAL_CONF: f32 = 0.001;

/// A generic function over one family, called with the family of a [`DetectorConfig`]
/// ([`DetectorConfig::visit`]): how code above the models (`bench::measure`) runs
/// family-generic code without matching on the families.
pub trait ConfigVisitor {
    type Out;
    fn visit<F: Family>(self, config: &F::Config) -> Self::Out;
}

/// Called with the registration list of `model/mod.rs` (`model::with_families!`): defines
/// [`DetectorConfig`] (each family's `Family::Config`) and [`Detector`] (each family's
/// model type) and the dispatch of every method below to the family's [`Family`]
/// implementation; the arms are one-liners on purpose (the logic is the family's, or in
/// the plain methods after the list).
macro_rules! families {
    ($($m:ident: $C:ident($T:ident) = $name:literal, $V:ident($M:ident);)+) => {
        families! { @ $($V(crate::model::$m::$M), $C;)+ }
    };
    (@ $($V:ident($M:ty), $C:ident;)+) => {
        /// Model config of a checkpoint: the kind and everything needed to rebuild the
        /// weights.
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(tag = "kind", rename_all = "lowercase")]
        pub enum DetectorConfig {
            $($C(<$M as Family>::Config),)+
        }

        /// A trainable instance-segmentation model.
        #[derive(Module, Debug)]
        pub enum Detector {
            $($V($M),)+
        }

        impl DetectorConfig {
            /// Calls `v` with this config's family.
            pub fn visit<V: ConfigVisitor>(&self, v: V) -> V::Out {
                match self { $(DetectorConfig::$C(c) => v.visit::<$M>(c),)+ }
            }
            fn of_section(m: &ModelConfig, input: usize, nc: usize) -> Self {
                match m { $(ModelConfig::$C(m) => DetectorConfig::$C(<$M>::config(m, input, nc)),)+ }
            }
            pub fn kind(&self) -> ModelKind {
                match self { $(DetectorConfig::$C(_) => ModelKind::$C,)+ }
            }
            /// The family's name in messages (`"Mask R-CNN"`).
            pub fn family_name(&self) -> &'static str {
                match self { $(DetectorConfig::$C(_) => <$M>::NAME,)+ }
            }
            pub fn num_classes(&self) -> usize {
                match self { $(DetectorConfig::$C(c) => <$M>::num_classes_of(c),)+ }
            }
            /// Square inference input size (px).
            pub fn input_size(&self) -> usize {
                match self { $(DetectorConfig::$C(c) => <$M>::input_size_of(c),)+ }
            }
            pub fn set_input_size(&mut self, size: usize) {
                match self { $(DetectorConfig::$C(c) => <$M>::set_input_size(c, size),)+ }
            }
            pub fn init(&self, device: &Device) -> Detector {
                match self { $(DetectorConfig::$C(c) => Detector::$V(<$M>::build(c, device)),)+ }
            }
            /// Module-path prefixes of the stages `train.freeze = n` freezes (see
            /// `model::freeze`).
            pub fn frozen_prefixes(&self, n: usize) -> Result<Vec<String>> {
                match self { $(DetectorConfig::$C(_) => <$M>::frozen_prefixes(n),)+ }
            }
            /// One line naming the architecture.
            pub fn describe(&self) -> String {
                match self { $(DetectorConfig::$C(c) => <$M>::describe(c),)+ }
            }
            /// The `bench models` variant name this config is timed as.
            pub fn variant_name(&self) -> String {
                match self { $(DetectorConfig::$C(c) => <$M>::variant_name(c),)+ }
            }
            /// The one-class config of the `bench models` variant this config is timed as.
            pub fn variant_config(&self) -> Self {
                match self { $(DetectorConfig::$C(c) => DetectorConfig::$C(<$M>::variant_config(c)),)+ }
            }
            /// The one-class config of a `bench models` variant name, if a family knows
            /// the name (an error: a family's prefix with a bad option).
            pub fn parse_variant(name: &str) -> Option<Result<Self>> {
                None$(.or_else(|| <$M>::parse_variant(name).map(|r| r.map(DetectorConfig::$C))))+
            }
            /// Whether this config's family has the export `format`.
            pub fn exports(&self, format: ExportFormat) -> bool {
                match self { $(DetectorConfig::$C(_) => exporter::<$M>(format).is_some(),)+ }
            }
            /// The families that have the export `format` (their names, for messages).
            pub fn exporters(format: ExportFormat) -> Vec<&'static str> {
                let mut names = Vec::new();
                $(if exporter::<$M>(format).is_some() { names.push(<$M>::NAME); })+
                names
            }
            /// Every family's variant names, for help and error text.
            pub fn variant_help() -> String {
                [$(<$M>::VARIANT_HELP,)+].join(", or ")
            }
        }

        /// `--smoke`: the family's shrink of its `[model]` table.
        pub fn smoke_section(m: &mut ModelConfig) {
            match m { $(ModelConfig::$C(m) => <$M>::smoke(m),)+ }
        }

        impl Detector {
            /// Names of the loss terms, as logged in `metrics.jsonl` (`loss.<name>`).
            pub fn loss_names(&self) -> &'static [&'static str] {
                match self { $(Detector::$V(_) => <$M>::LOSS_NAMES,)+ }
            }
            /// Training loss of a batch. `images` are `[B, 3, H, W]` in `[0, 1]` (Mask R-CNN
            /// and Mask2Former normalise inside); `sample_seed` drives Mask R-CNN's anchor
            /// and RoI sampling and Mask2Former's point sampling, so a step does not depend
            /// on what ran before it.
            pub fn loss(&self, images: Tensor<4>, targets: &Targets, sample_seed: u64) -> StepLoss {
                match self { $(Detector::$V(m) => seeded_loss(m, images, targets, sample_seed),)+ }
            }
            /// [`Self::predict`] and the seconds of the network alone: YOLO's forward pass
            /// up to its output tensors (box decoding and NMS excluded); Mask R-CNN's
            /// `forward_infer` whole (its proposal, NMS and head stages interleave with the
            /// network); Mask2Former's `forward_infer` whole (network and top-k
            /// postprocess). Wall clock on the eager CPU backends; a lazy GPU backend would
            /// move time into the postprocess.
            pub fn predict_timed(&self, images: Tensor<4>, conf: f32) -> (Vec<Vec<Detection>>, f64) {
                match self { $(Detector::$V(m) => m.predict_timed(images, conf),)+ }
            }
            /// [`Self::predict`] with the NMS IoU and detection cap of `predict --iou
            /// --max-det`: YOLO's postprocess runs at them; Mask R-CNN's and Mask2Former's
            /// detections (their own NMS already applied) go through
            /// [`crate::model::detection::nms_detections`] at them.
            pub fn predict_nms(&self, images: Tensor<4>, conf: f32, iou: f32, max_det: usize) -> Vec<Vec<Detection>> {
                match self { $(Detector::$V(m) => m.predict_nms(images, conf, iou, max_det),)+ }
            }
            pub fn summary(&self, input: usize) -> ModelSummary {
                match self { $(Detector::$V(m) => m.summary_at(input),)+ }
            }
            /// Every tensor of `source` (a model of the same family) loaded into this one;
            /// with another class count the class-dependent ones keep their initialisation.
            pub fn apply_same_family(self, source: &Detector, origin: &str) -> Result<(Detector, Applied)> {
                match (self, source) {
                    $((Detector::$V(m), Detector::$V(s)) => {
                        let (m, a) = weights::apply(m, weights::collect(s), &<$M>::class_dependent, origin)?;
                        Ok((Detector::$V(m), a))
                    })+
                    #[allow(unreachable_patterns)]
                    _ => bail!("{origin}: weights of one family cannot start another"),
                }
            }
            /// This model (of family `config`) in the export `format`; `None` when the
            /// family has no such format.
            pub fn export(&self, config: &DetectorConfig, format: ExportFormat, r: &ExportRequest) -> Option<Result<String>> {
                match (self, config) {
                    $((Detector::$V(m), DetectorConfig::$C(c)) => exporter::<$M>(format).map(|f| f(m, c, r)),)+
                    #[allow(unreachable_patterns)]
                    _ => Some(Err(anyhow::anyhow!("{}: the weights are not of the model config's family", r.checkpoint.display()))),
                }
            }
            /// `model.init` from a file of another framework, as the family reads it.
            pub fn load_foreign(self, config: &DetectorConfig, path: &Path, format: Format, origin: &str) -> Result<ForeignInit<Detector>> {
                match (self, config) {
                    $((Detector::$V(m), DetectorConfig::$C(c)) => {
                        let f = m.load_foreign(c, path, format, origin)?;
                        Ok(ForeignInit { model: Detector::$V(f.model), applied: f.applied, what: f.what, fresh_why: f.fresh_why })
                    })+
                    #[allow(unreachable_patterns)]
                    _ => bail!("{origin}: the model config is not the model's family"),
                }
            }
        }
    };
}

crate::model::with_families!(families);

impl DetectorConfig {
    /// The model of run config `cfg` with `nc` classes.
    pub fn from_config(cfg: &Config, nc: usize) -> Result<Self> {
        if nc == 0 {
            bail!("the data has no categories to train on");
        }
        Ok(Self::of_section(
            &cfg.model,
            cfg.data.image_size as usize,
            nc,
        ))
    }

    /// Why a checkpoint's model cannot continue or replace this one, if it cannot.
    pub fn mismatch(&self, other: &DetectorConfig) -> Option<String> {
        if self.kind() != other.kind() {
            return Some(format!(
                "it holds a model.kind = \"{}\" model, the config asks for model.kind = \"{}\"",
                other.kind().name(),
                self.kind().name()
            ));
        }
        if self.num_classes() != other.num_classes() {
            return Some(format!(
                "it has {} classes, the data has {}",
                other.num_classes(),
                self.num_classes()
            ));
        }
        (self != other).then(|| format!("its model {other:?} differs from the config's {self:?}"))
    }
}

impl Detector {
    /// Detections per image with score ≥ `conf` (call on the eval-mode, plain-device model).
    /// Mask R-CNN applies its own score threshold (`roi.score_thresh`, 0.05) first.
    pub fn predict(&self, images: Tensor<4>, conf: f32) -> Vec<Vec<Detection>> {
        self.predict_timed(images, conf).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config;
    use crate::model::mask2former::Mask2FormerConfig;
    use crate::model::maskrcnn::MaskRcnnConfig;

    fn load(name: &str, ov: &[&str]) -> Config {
        let ov: Vec<String> = ov.iter().map(|s| s.to_string()).collect();
        config::load(name, &ov).unwrap()
    }

    #[test]
    fn config_keys_reach_the_model_config() {
        let c = DetectorConfig::from_config(&load("maskrcnn_r101_syn1000", &[]), 1).unwrap();
        let DetectorConfig::Maskrcnn(m) = &c else {
            panic!("{c:?}")
        };
        assert_eq!(
            m,
            &MaskRcnnConfig::new(101, 1).with_input_size(640),
            "compact preset, 640 px"
        );
        let c = DetectorConfig::from_config(
            &load(
                "maskrcnn_r50_syn750",
                &[
                    "model.preset=\"paper\"",
                    "model.roi_batch=64",
                    "model.anchor_sizes=[16.0, 32.0, 64.0, 128.0, 256.0]",
                    "model.mask_class_agnostic=true",
                    "model.rpn_post_nms_topk_test=77",
                ],
            ),
            2,
        )
        .unwrap();
        let DetectorConfig::Maskrcnn(m) = &c else {
            panic!("{c:?}")
        };
        assert_eq!((m.depth, m.num_classes, m.fpn_channels), (50, 2, 256));
        assert_eq!(m.roi.batch_per_image, 64);
        assert_eq!(m.roi.fc_dim, 1024, "paper preset kept where not overridden");
        assert_eq!(m.anchors.sizes, [16.0, 32.0, 64.0, 128.0, 256.0]);
        assert!(m.mask.class_agnostic);
        assert_eq!(m.rpn.post_nms_topk_test, 77);
        let y = DetectorConfig::from_config(&load("quickstart", &[]), 1).unwrap();
        assert_eq!(y.kind(), ModelKind::Yolo);
        assert_eq!(y.input_size(), 256);
    }

    #[test]
    fn mask2former_keys_reach_the_model_config() {
        let c = DetectorConfig::from_config(&load("mask2former_syn500", &[]), 1).unwrap();
        let DetectorConfig::Mask2former(m) = &c else {
            panic!("{c:?}")
        };
        let mut want = Mask2FormerConfig::new(50, 1);
        want.input_size = 640;
        assert_eq!(m, &want, "compact preset, 25 queries, 640 px");
        let c = DetectorConfig::from_config(
            &load(
                "mask2former_syn750",
                &[
                    "model.preset=\"paper\"",
                    "model.queries=30",
                    "model.points=999",
                    "model.depth=101",
                ],
            ),
            2,
        )
        .unwrap();
        let DetectorConfig::Mask2former(m) = &c else {
            panic!("{c:?}")
        };
        assert_eq!((m.depth, m.num_classes, m.queries), (101, 2, 30));
        assert_eq!(
            (m.hidden_dim, m.dec_layers, m.criterion.points),
            (256, 9, 999)
        );
        let y = DetectorConfig::from_config(&load("quickstart", &[]), 1).unwrap();
        let e = c.mismatch(&y).unwrap();
        assert!(e.contains("asks for model.kind = \"mask2former\""), "{e}");
        let bad = config::load(
            "mask2former_syn250",
            &["model.hidden_dim=100".into(), "model.heads=8".into()],
        );
        let e = format!("{:#}", bad.unwrap_err());
        assert!(
            e.contains("model.hidden_dim = 100 must be even and a multiple of model.heads = 8"),
            "{e}"
        );
    }

    #[test]
    fn mismatches_name_the_kind_and_the_class_count() {
        let m = DetectorConfig::from_config(&load("maskrcnn_r50_syn250", &[]), 1).unwrap();
        let y = DetectorConfig::from_config(&load("quickstart", &[]), 1).unwrap();
        let m3 = DetectorConfig::from_config(&load("maskrcnn_r50_syn250", &[]), 3).unwrap();
        assert_eq!(m.mismatch(&m.clone()), None);
        let e = m.mismatch(&y).unwrap();
        assert!(
            e.contains("holds a model.kind = \"yolo\" model")
                && e.contains("asks for model.kind = \"maskrcnn\""),
            "{e}"
        );
        let e = m.mismatch(&m3).unwrap();
        assert!(e.contains("it has 3 classes, the data has 1"), "{e}");
    }
}
