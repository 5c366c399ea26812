//! The tiny Mask R-CNN of the model-level tests: ResNet-18 at quarter width, anchors for
//! 64 px, a few dozen proposals and RoIs. The tests differ only in the head widths.

use chicktrain::model::maskrcnn::anchors::AnchorConfig;
use chicktrain::model::maskrcnn::mask_head::MaskHeadConfig;
use chicktrain::model::maskrcnn::roi_heads::RoiHeadsConfig;
use chicktrain::model::maskrcnn::rpn::RpnConfig;
use chicktrain::model::maskrcnn::MaskRcnnConfig;

/// The widths that differ between the tests' tiny models.
#[derive(Clone, Copy, Debug)]
pub struct TinyWidths {
    /// FPN channels.
    pub fpn: usize,
    /// Box head fully connected width.
    pub fc: usize,
    /// Mask head conv channels.
    pub mask_conv: usize,
    /// Mask head conv layers.
    pub mask_convs: usize,
}

/// One class, `input_size` px, heads as wide as `w`.
pub fn tiny_maskrcnn(input_size: usize, w: TinyWidths) -> MaskRcnnConfig {
    MaskRcnnConfig::new(18, 1)
        .with_width_mult(0.25)
        .with_input_size(input_size)
        .with_fpn_channels(w.fpn)
        .with_anchors(AnchorConfig {
            sizes: vec![12.0, 24.0, 48.0, 96.0, 192.0],
            ratios: vec![0.5, 1.0, 2.0],
        })
        .with_rpn(RpnConfig {
            batch_per_image: 64,
            pre_nms_topk_train: 200,
            post_nms_topk_train: 50,
            pre_nms_topk_test: 200,
            post_nms_topk_test: 50,
            ..RpnConfig::compact()
        })
        .with_roi(RoiHeadsConfig {
            batch_per_image: 32,
            fc_dim: w.fc,
            ..RoiHeadsConfig::compact()
        })
        .with_mask(MaskHeadConfig {
            conv_dim: w.mask_conv,
            num_conv: w.mask_convs,
            ..MaskHeadConfig::compact()
        })
}
