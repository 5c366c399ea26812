//! Instance-segmentation models.
//!
//! - [`yolo`]: the YOLO11-seg-style one-stage model (its blocks, task-aligned assigner,
//!   losses and postprocess).
//! - [`maskrcnn`]: the two-stage Mask R-CNN (ResNet-FPN, RPN, RoIAlign, box and mask heads).
//! - [`mask2former`]: the set-prediction Mask2Former (Mask R-CNN's ResNet, FPN pixel decoder,
//!   masked-attention transformer decoder, Hungarian matching, point-sampled losses).
//! - Shared by both: [`detection`] (what a model predicts, box IoU, NMS),
//!   [`instance_mask`] (a detection's mask, decoded at the input or the original size), [`layers`]
//!   (parameter and MAC counts, upsampling), [`loss`] (overflow-free primitives) and
//!   [`summary`] (model size).
//! - [`weights`]: weights from files (chicktrain checkpoints, PyTorch, safetensors) as
//!   named snapshots, and the one loader that applies them with shape checks; `freeze`
//!   (the first N stages of either family).
//! - [`onnx`]: the ONNX graph writer, the tract engine that runs exported files, and the
//!   reference file written beside an export.
//! - [`family`]: the interface every family implements (`model/<family>/family.rs`), so
//!   that the rest of the crate reaches a family in one place (`infer::detector`);
//!   [`section`]: what the run config needs of a family's `[model]` table
//!   (`model/<family>/config.rs`).
//! - The families themselves are registered below: a `pub mod` line and a line of
//!   [`with_families!`] each, from which [`ModelKind`] and [`ModelConfig`] (the `[model]`
//!   table picked by `kind`) are built here and the trained-model enums in
//!   `infer::detector`.
//!
//! Models read their ground truth as [`crate::annotations::targets::Targets`] and import
//! nothing of the config, the renderer, the loader or the trainer (only the foundation):
//! every model is built from its own typed config, and the run config (`config::Config`)
//! holds this layer's [`ModelConfig`] as its `[model]` table, the way detectron2's projects
//! add their keys to the config (`add_pointrend_config`).

pub mod detection;
pub mod family;
pub mod freeze;
pub mod fused_conv;
pub mod instance_mask;
pub mod layers;
pub mod loss;
pub mod onnx;
pub mod section;
pub mod summary;
pub mod weights;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use section::ModelSection;

// The families: a `pub mod` line here (a module declared inside a macro would be invisible
// to rustfmt) and a line in `with_families!` each.
pub mod mask2former;
pub mod maskrcnn;
pub mod yolo;

/// The registration list, one line per family:
/// `module: ConfigVariant(Table) = "kind", DetectorVariant(Model);` — the `[model]`
/// table `module::Table` and its variant of [`ModelConfig`] and [`ModelKind`] (and of
/// `infer::detector::DetectorConfig`), the `model.kind` string, and the model type
/// `module::Model` (its `impl Family`) with its variant of `infer::detector::Detector`,
/// which names its Burn record in checkpoints. `with_families!(m)` calls macro `m` with
/// the list: `declare_families!` below, and `infer::detector`'s `families!`.
macro_rules! with_families {
    ($then:ident) => {
        $then! {
            yolo: Yolo(YoloModelConfig) = "yolo", Yolo(YoloSeg);
            maskrcnn: Maskrcnn(MaskRcnnModelConfig) = "maskrcnn", MaskRcnn(MaskRcnn);
            mask2former: Mask2former(Mask2FormerModelConfig) = "mask2former", Mask2Former(Mask2Former);
        }
    };
}
pub(crate) use with_families;

/// [`ModelKind`], [`ModelConfig`] and every table's `Default` (the table of an empty
/// TOML: all keys at their serde defaults) from the list.
macro_rules! declare_families {
    ($($m:ident: $C:ident($T:ident) = $name:literal, $V:ident($M:ident);)+) => {
        /// The model family of a config or checkpoint.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
        #[serde(rename_all = "lowercase")]
        pub enum ModelKind {
            $($C,)+
        }

        /// `[model]`: one table per family, picked by `kind` (default `"yolo"`). Each
        /// family's table rejects unknown keys, so a key of the other family (`depth` under
        /// `kind = "yolo"`) is a parse error naming the key and its line.
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        #[serde(tag = "kind", rename_all = "lowercase")]
        pub enum ModelConfig {
            $($C($m::$T),)+
        }

        $(impl Default for $m::$T {
            fn default() -> Self {
                toml::from_str("").expect(concat!($name, " model defaults"))
            }
        })+

        impl ModelKind {
            /// The `model.kind` string.
            pub fn name(self) -> &'static str {
                match self { $(ModelKind::$C => $name,)+ }
            }
        }

        impl ModelConfig {
            pub fn kind(&self) -> ModelKind {
                match self { $(ModelConfig::$C(_) => ModelKind::$C,)+ }
            }
            /// The family's table.
            pub fn section(&self) -> &dyn ModelSection {
                match self { $(ModelConfig::$C(m) => m,)+ }
            }
            /// `model.init` of any family.
            pub fn init(&self) -> Option<&str> {
                match self { $(ModelConfig::$C(m) => m.init.as_deref(),)+ }
            }
            /// Channel-width multiplier of any family.
            pub fn width_mult(&self) -> f64 {
                match self { $(ModelConfig::$C(m) => m.width_mult,)+ }
            }
        }
    };
}

with_families!(declare_families);

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig::Yolo(yolo::YoloModelConfig::default())
    }
}

impl ModelConfig {
    /// Range checks of the family's keys; `crop` is `data.crop` (a Mask R-CNN needs 64).
    pub fn validate(&self, crop: u32) -> Result<()> {
        let wm = self.width_mult();
        if !(wm.is_finite() && wm > 0.0 && wm <= 4.0) {
            bail!("model.width_mult = {wm} must be in (0, 4]");
        }
        if self.init().is_some_and(|p| p.trim().is_empty()) {
            bail!("model.init is empty: give the path of a weights file, or leave the key out");
        }
        self.section().validate(crop)
    }

    /// `train.freeze = n` against the family's stages.
    pub fn validate_freeze(&self, n: usize) -> Result<()> {
        let (max, stages) = self.section().freeze_limit();
        if n > max {
            bail!(
                "train.freeze = {n} must be at most {max} for model.kind = \"{}\" ({stages})",
                self.kind().name()
            );
        }
        Ok(())
    }
}
