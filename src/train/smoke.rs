//! `--smoke`: any config shrunk to about a minute that still goes through every stage.

use crate::config::{Config, ModelConfig};

/// 64 px images (no crop), at most 9 real and 4 synthetic images, 2 epochs (of at
/// most 3 steps when `train.steps_per_epoch` is set), batch 4.
/// A Mask R-CNN keeps its depth (so the R101 code paths run) but gets quarter widths,
/// anchors sized for 64 px and a few dozen proposals and RoIs. A Mask2Former keeps its
/// depth, gets quarter widths, a 32-wide 3-layer decoder, ≤ 10 queries and 256 points.
pub fn smoke_config(cfg: &mut Config) {
    cfg.name = format!("{}_smoke", cfg.name);
    let d = &mut cfg.data;
    d.image_size = 64;
    d.crop = 64;
    d.real.count = d.real.count.min(9);
    d.real.limit = Some(d.real.limit.unwrap_or(9).min(9));
    d.synthetic = d.synthetic.min(4);
    let t = &mut cfg.train;
    t.epochs = t.epochs.min(2);
    t.steps_per_epoch = t.steps_per_epoch.map(|n| n.min(3));
    t.batch = t.batch.min(4);
    t.warmup_epochs = t.warmup_epochs.min(1.0);
    t.warmup_iters = t.warmup_iters.min(2);
    t.milestones.retain(|&m| m < t.epochs);
    if let ModelConfig::Maskrcnn(m) = &mut cfg.model {
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
    if let ModelConfig::Mask2former(m) = &mut cfg.model {
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
}
