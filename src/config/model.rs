//! `[model]`: one typed table per model family, picked by `kind`.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// The model family of a config or checkpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    Yolo,
    Maskrcnn,
    Mask2former,
}

/// `[model]`: one table per family, picked by `kind` (default `"yolo"`). Each family's
/// table rejects unknown keys, so a key of the other family (`depth` under
/// `kind = "yolo"`) is a parse error naming the key and its line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum ModelConfig {
    Yolo(YoloModelConfig),
    Maskrcnn(MaskRcnnModelConfig),
    Mask2former(Mask2FormerModelConfig),
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig::Yolo(YoloModelConfig::default())
    }
}

impl ModelConfig {
    pub fn kind(&self) -> ModelKind {
        match self {
            ModelConfig::Yolo(_) => ModelKind::Yolo,
            ModelConfig::Maskrcnn(_) => ModelKind::Maskrcnn,
            ModelConfig::Mask2former(_) => ModelKind::Mask2former,
        }
    }

    /// `model.init` of either family.
    pub fn init(&self) -> Option<&str> {
        match self {
            ModelConfig::Yolo(m) => m.init.as_deref(),
            ModelConfig::Maskrcnn(m) => m.init.as_deref(),
            ModelConfig::Mask2former(m) => m.init.as_deref(),
        }
    }

    /// Channel-width multiplier of either family.
    pub fn width_mult(&self) -> f64 {
        match self {
            ModelConfig::Yolo(m) => m.width_mult,
            ModelConfig::Maskrcnn(m) => m.width_mult,
            ModelConfig::Mask2former(m) => m.width_mult,
        }
    }
}

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
    #[serde(default = "default_one")]
    pub width_mult: f64,
    #[serde(default)]
    pub scale: YoloScale,
    /// Head levels: `[3, 4, 5]` (P3–P5, ultralytics) or `[4, 5]` (scene-sized).
    #[serde(default = "default_levels")]
    pub levels: Vec<u32>,
    #[serde(default = "default_true")]
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

impl Default for YoloModelConfig {
    fn default() -> Self {
        toml::from_str("").expect("yolo model defaults")
    }
}

fn default_levels() -> Vec<u32> {
    vec![3, 4, 5]
}
fn default_prototypes() -> usize {
    32
}
fn default_depth() -> usize {
    50
}

/// Size preset of a Mask R-CNN: `compact` (CPU- and scene-sized) or `paper` (detectron2's
/// R-FPN sizes). Single `model.*` keys override either.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaskRcnnPreset {
    #[default]
    Compact,
    Paper,
}

/// `[model]` with `kind = "maskrcnn"`: depth and preset, and optional overrides of the
/// preset's sizes (unset keys keep the preset's value).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaskRcnnModelConfig {
    #[serde(default = "default_one")]
    pub width_mult: f64,
    /// ResNet depth: 18, 34, 50 or 101.
    #[serde(default = "default_depth")]
    pub depth: usize,
    #[serde(default)]
    pub preset: MaskRcnnPreset,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fpn_channels: Option<usize>,
    /// Anchor sizes in input pixels, one per level P2…P6.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchor_sizes: Option<Vec<f32>>,
    /// Anchors sampled per image for the RPN loss.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_batch: Option<usize>,
    /// RPN proposals per level before NMS and per image after NMS, in training.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_pre_nms_topk_train: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_post_nms_topk_train: Option<usize>,
    /// The same at inference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_pre_nms_topk_test: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_post_nms_topk_test: Option<usize>,
    /// RoIs sampled per image for the box and mask losses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roi_batch: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub box_fc_dim: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_conv_dim: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_class_agnostic: Option<bool>,
    /// Weights to start from (`model.init = "PATH"`): a chicktrain checkpoint of either
    /// family, a torchvision state dict (Mask R-CNN) or an ultralytics checkpoint (YOLO);
    /// the format is read from the file's first bytes. Ignored by `--resume`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<String>,
}

impl Default for MaskRcnnModelConfig {
    fn default() -> Self {
        toml::from_str("").expect("maskrcnn model defaults")
    }
}

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
    #[serde(default = "default_one")]
    pub width_mult: f64,
    /// ResNet depth: 18, 34, 50 or 101.
    #[serde(default = "default_depth")]
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

impl Default for Mask2FormerModelConfig {
    fn default() -> Self {
        toml::from_str("").expect("mask2former model defaults")
    }
}

fn default_true() -> bool {
    true
}
fn default_one() -> f64 {
    1.0
}

impl ModelConfig {
    /// Range checks of the family's keys; `crop` is `data.crop` (a Mask R-CNN needs 64).
    pub fn validate(&self, crop: u32) -> Result<()> {
        let m = self;
        let d_crop = crop;
        let wm = m.width_mult();
        if !(wm.is_finite() && wm > 0.0 && wm <= 4.0) {
            bail!("model.width_mult = {wm} must be in (0, 4]");
        }
        if self.init().is_some_and(|p| p.trim().is_empty()) {
            bail!("model.init is empty: give the path of a weights file, or leave the key out");
        }
        match m {
            ModelConfig::Yolo(m) => {
                if m.levels != [3, 4, 5] && m.levels != [4, 5] {
                    bail!("model.levels = {:?} must be [3, 4, 5] or [4, 5]", m.levels);
                }
                if !(1..=256).contains(&m.prototypes) {
                    bail!("model.prototypes = {} must be in 1..=256", m.prototypes);
                }
            }
            ModelConfig::Maskrcnn(m) => {
                if ![18, 34, 50, 101].contains(&m.depth) {
                    bail!("model.depth = {} must be 18, 34, 50 or 101", m.depth);
                }
                if d_crop < 64 {
                    bail!(
                        "data.crop = {} must be at least 64 for model.kind = \"maskrcnn\"",
                        d_crop
                    );
                }
                if let Some(a) = &m.anchor_sizes {
                    if a.len() != 5 || a.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                        bail!(
                            "model.anchor_sizes = {a:?} must be 5 positive sizes in pixels (P2…P6)"
                        );
                    }
                }
                for (k, v, max) in [
                    ("fpn_channels", m.fpn_channels, 1024),
                    ("rpn_batch", m.rpn_batch, 4096),
                    ("rpn_pre_nms_topk_train", m.rpn_pre_nms_topk_train, 100_000),
                    (
                        "rpn_post_nms_topk_train",
                        m.rpn_post_nms_topk_train,
                        100_000,
                    ),
                    ("rpn_pre_nms_topk_test", m.rpn_pre_nms_topk_test, 100_000),
                    ("rpn_post_nms_topk_test", m.rpn_post_nms_topk_test, 100_000),
                    ("roi_batch", m.roi_batch, 4096),
                    ("box_fc_dim", m.box_fc_dim, 8192),
                    ("mask_conv_dim", m.mask_conv_dim, 1024),
                ] {
                    if let Some(v) = v {
                        if !(1..=max).contains(&v) {
                            bail!("model.{k} = {v} must be in 1..={max}");
                        }
                    }
                }
            }
            ModelConfig::Mask2former(m) => {
                if ![18, 34, 50, 101].contains(&m.depth) {
                    bail!("model.depth = {} must be 18, 34, 50 or 101", m.depth);
                }
                if d_crop < 64 {
                    bail!(
                        "data.crop = {d_crop} must be at least 64 for model.kind = \"mask2former\""
                    );
                }
                for (k, v, max) in [
                    ("queries", m.queries, 1000),
                    ("dec_layers", m.dec_layers, 32),
                    ("hidden_dim", m.hidden_dim, 2048),
                    ("heads", m.heads, 64),
                    ("ffn_dim", m.ffn_dim, 16384),
                    ("conv_dim", m.conv_dim, 2048),
                    ("mask_dim", m.mask_dim, 2048),
                    ("points", m.points, 1 << 20),
                    ("top_k", m.top_k, 10_000),
                ] {
                    if let Some(v) = v {
                        if !(1..=max).contains(&v) {
                            bail!("model.{k} = {v} must be in 1..={max}");
                        }
                    }
                }
                let (h, heads) = match m.preset {
                    Mask2FormerPreset::Compact => (128, 4),
                    Mask2FormerPreset::Paper => (256, 8),
                };
                let (h, heads) = (m.hidden_dim.unwrap_or(h), m.heads.unwrap_or(heads));
                if h % heads != 0 || h % 2 != 0 {
                    bail!(
                        "model.hidden_dim = {h} must be even and a multiple of model.heads = {heads}"
                    );
                }
            }
        }
        Ok(())
    }
}
