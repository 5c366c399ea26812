//! `[model]` with `kind = "maskrcnn"`: the Mask R-CNN family's table and its range checks.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::model::section::{self, ModelSection};

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
    #[serde(default = "crate::model::section::default_one")]
    pub width_mult: f64,
    /// ResNet depth: 18, 34, 50 or 101.
    #[serde(default = "crate::model::section::default_depth")]
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

impl ModelSection for MaskRcnnModelConfig {
    /// `crop` is `data.crop` (a Mask R-CNN needs 64).
    fn validate(&self, crop: u32) -> Result<()> {
        let m = self;
        section::check_resnet(m.depth, crop, "maskrcnn")?;
        if let Some(a) = &m.anchor_sizes {
            if a.len() != 5 || a.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                bail!("model.anchor_sizes = {a:?} must be 5 positive sizes in pixels (P2…P6)");
            }
        }
        section::check_ranges(&[
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
        ])
    }
    fn freeze_limit(&self) -> (usize, &'static str) {
        (5, section::RESNET_STAGES)
    }
}
