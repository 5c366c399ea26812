//! `[model]`: one typed table per model family, picked by `kind`; each family's table is
//! a file of its own here (`yolo`, `maskrcnn`, `mask2former`) implementing
//! [`ModelSection`] (`section`), and registered in the [`sections!`] list below. The rest of a
//! family (how the table builds a model) is `model::family::Family`, a layer up.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

pub mod mask2former;
pub mod maskrcnn;
mod section;
pub mod yolo;

pub use mask2former::{Mask2FormerModelConfig, Mask2FormerPreset};
pub use maskrcnn::{MaskRcnnModelConfig, MaskRcnnPreset};
pub use section::ModelSection;
pub use yolo::{YoloModelConfig, YoloScale};

/// The registration list: `Variant(Table) = "kind";` per family. It defines
/// [`ModelKind`] and [`ModelConfig`] (whose variants are `infer::detector`'s
/// `DetectorConfig` variants too).
macro_rules! sections {
    ($($C:ident($T:ty) = $name:literal;)+) => {
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
            $($C($T),)+
        }

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
        }
    };
}

sections! {
    Yolo(YoloModelConfig) = "yolo";
    Maskrcnn(MaskRcnnModelConfig) = "maskrcnn";
    Mask2former(Mask2FormerModelConfig) = "mask2former";
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig::Yolo(YoloModelConfig::default())
    }
}

impl ModelConfig {
    /// `model.init` of any family.
    pub fn init(&self) -> Option<&str> {
        self.section().init()
    }

    /// Channel-width multiplier of any family.
    pub fn width_mult(&self) -> f64 {
        self.section().width_mult()
    }

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
