//! `[model]` with `kind = "mask2former"`: the Mask2Former family's table and its range
//! checks.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::model::section::{self, ModelSection};

/// Size preset of a Mask2Former: `compact` (CPU- and scene-sized: 128-wide, 6 decoder
/// layers, 25 queries, 3136 points) or `paper` (the paper's R50 sizes: 256-wide, 9 layers,
/// 100 queries, 12544 points). Single `model.*` keys override either.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mask2FormerPreset {
    #[default]
    Compact,
    Paper,
}

/// `[model]` with `kind = "mask2former"`: ResNet depth and preset, and optional overrides
/// of the preset's sizes (unset keys keep the preset's value).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mask2FormerModelConfig {
    #[serde(default = "crate::model::section::default_one")]
    pub width_mult: f64,
    /// ResNet depth: 18, 34, 50 or 101.
    #[serde(default = "crate::model::section::default_depth")]
    pub depth: usize,
    #[serde(default)]
    pub preset: Mask2FormerPreset,
    /// Object queries Q (paper 100; a top-view pile needs fewer).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub queries: Option<usize>,
    /// Transformer decoder layers L (paper 9), round robin over strides 32/16/8.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dec_layers: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hidden_dim: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heads: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ffn_dim: Option<usize>,
    /// Pixel-decoder width and per-pixel embedding width.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conv_dim: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_dim: Option<usize>,
    /// K: sampled points per mask for matching and the mask losses (paper 12544).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<usize>,
    /// Detections per image at inference (paper 100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top_k: Option<usize>,
    /// Weights to start from (`model.init = "PATH"`): a chicktrain checkpoint, or a
    /// torchvision ResNet / Mask R-CNN state dict for the backbone. Ignored by `--resume`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<String>,
}

impl ModelSection for Mask2FormerModelConfig {
    /// `crop` is `data.crop` (the ResNet needs 64).
    fn validate(&self, crop: u32) -> Result<()> {
        let m = self;
        section::check_resnet(m.depth, crop, "mask2former")?;
        section::check_ranges(&[
            ("queries", m.queries, 1000),
            ("dec_layers", m.dec_layers, 32),
            ("hidden_dim", m.hidden_dim, 2048),
            ("heads", m.heads, 64),
            ("ffn_dim", m.ffn_dim, 16384),
            ("conv_dim", m.conv_dim, 2048),
            ("mask_dim", m.mask_dim, 2048),
            ("points", m.points, 1 << 20),
            ("top_k", m.top_k, 10_000),
        ])?;
        let (h, heads) = match m.preset {
            Mask2FormerPreset::Compact => (128, 4),
            Mask2FormerPreset::Paper => (256, 8),
        };
        let (h, heads) = (m.hidden_dim.unwrap_or(h), m.heads.unwrap_or(heads));
        if h % heads != 0 || h % 2 != 0 {
            bail!("model.hidden_dim = {h} must be even and a multiple of model.heads = {heads}");
        }
        Ok(())
    }
    fn freeze_limit(&self) -> (usize, &'static str) {
        (5, section::RESNET_STAGES)
    }
}
