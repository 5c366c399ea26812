//! `[model]` with `kind = "yolo"`: the YOLO-seg family's table and its range checks.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::model::section::ModelSection;

/// YOLO11-seg size preset (ultralytics' `n` and `s`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum YoloScale {
    #[default]
    N,
    S,
}

/// `[model]` with `kind = "yolo"`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct YoloModelConfig {
    #[serde(default = "crate::model::section::default_one")]
    pub width_mult: f64,
    #[serde(default)]
    pub scale: YoloScale,
    /// Head levels: `[3, 4, 5]` (P3–P5, ultralytics) or `[4, 5]` (scene-sized).
    #[serde(default = "default_levels")]
    pub levels: Vec<u32>,
    #[serde(default = "crate::model::section::default_true")]
    pub c2psa: bool,
    /// Mask prototypes (ultralytics: 32).
    #[serde(default = "default_prototypes")]
    pub prototypes: usize,
    /// Weights to start from (`model.init = "PATH"`): a chicktrain checkpoint of either
    /// family, a torchvision state dict (Mask R-CNN) or an ultralytics checkpoint (YOLO);
    /// the format is read from the file's first bytes. Ignored by `--resume`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<String>,
}

fn default_levels() -> Vec<u32> {
    vec![3, 4, 5]
}
fn default_prototypes() -> usize {
    32
}

impl ModelSection for YoloModelConfig {
    fn validate(&self, _crop: u32) -> Result<()> {
        if self.levels != [3, 4, 5] && self.levels != [4, 5] {
            bail!(
                "model.levels = {:?} must be [3, 4, 5] or [4, 5]",
                self.levels
            );
        }
        if !(1..=256).contains(&self.prototypes) {
            bail!("model.prototypes = {} must be in 1..=256", self.prototypes);
        }
        Ok(())
    }
    fn freeze_limit(&self) -> (usize, &'static str) {
        (23, "ultralytics layer indices; 23 is the head")
    }
}
