//! Compact Mask R-CNN (He et al. 2017) in Burn: ResNet-FPN backbone, RPN, box and mask
//! RoI heads, following detectron2's R-CNN meta-architecture (`modeling/meta_arch/rcnn.py`).
//!
//! - Pieces with no parameters: [`box_coder`], [`matcher`], [`sampler`], [`anchors`],
//!   [`pooler`] (FPN level assignment), [`roi_align`]; [`losses`] holds loss primitives.
//! - Trainable modules: [`resnet`], [`fpn`], [`rpn`] (head + proposals + loss),
//!   [`roi_heads`] (box head + targets + loss + inference), [`mask_head`] (logits; loss,
//!   targets and pasting beside it).
//! - Weights out: [`torchvision`] (state dict names, both ways), [`onnx`] (three graphs).
//!
//! [`MaskRcnnConfig`] builds the model; "compact" defaults ([`MaskRcnnConfig::new`]) are
//! sized for CPU and the carcass scene (≤ 12 instances, one class, top view): 128-wide FPN,
//! 200 / 100 proposals, 128 sampled RoIs, 256-wide FCs, 128-wide mask convs, 512 px input.
//! [`MaskRcnnConfig::paper`] gives the detectron2 R-FPN sizes. Targets and detections are
//! the YOLO model's types ([`ImageTargets`], [`Detection`]) so one loop serves both.

pub mod anchors;
pub mod box_coder;
pub mod config;
pub mod export;
pub mod family;
pub mod fpn;
pub mod losses;
pub mod mask_head;
pub mod matcher;
pub mod onnx;
pub mod pooler;
pub mod resnet;
pub mod roi_align;
pub mod roi_heads;
pub mod rpn;
pub mod sampler;
pub mod torchvision;

use burn::module::Module;
use burn::tensor::activation::sigmoid;
use burn::tensor::{Device, Tensor};
use rand::Rng;
use serde::{Deserialize, Serialize};

pub use crate::annotations::targets::ImageTargets;
pub use crate::model::detection::Detection;
use crate::model::instance_mask::MaskSource;
pub use crate::model::summary::ModelSummary;
use crate::util::tensor::{host, to_host};
use anchors::AnchorConfig;
pub use config::{MaskRcnnModelConfig, MaskRcnnPreset};
use fpn::Fpn;
use mask_head::{mask_loss, mask_targets, MaskHead, MaskHeadConfig};
use pooler::pool_levels;
use resnet::ResNet;
use roi_heads::{box_inference, box_loss, label_and_sample, BoxHead, RoiHeadsConfig};
use rpn::{find_proposals, rpn_loss, RpnConfig, RpnHead};

/// Strides of P2…P6.
pub const STRIDES: [usize; 5] = [4, 8, 16, 32, 64];
/// ImageNet statistics applied inside the model to `[0, 1]` RGB input (detectron2's
/// `pixel_mean` / `pixel_std`, rescaled), so the trainer feeds both models the same images.
pub const PIXEL_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
pub const PIXEL_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// `[0, 1]` images as the ResNet takes them, `(x − PIXEL_MEAN) / PIXEL_STD` per channel
/// (Mask R-CNN's and Mask2Former's backbone input).
pub fn normalize(images: Tensor<4>) -> Tensor<4> {
    let device = images.device();
    let mean: Tensor<4> = host(PIXEL_MEAN.to_vec(), [1, 3, 1, 1], &device);
    let std: Tensor<4> = host(PIXEL_STD.to_vec(), [1, 3, 1, 1], &device);
    (images - mean) / std
}

/// `[H, W]` of a batch for a ResNet-FPN model (`model` names it in the panic): `[B, 3, H,
/// W]` with B ≥ 1 and H, W multiples of 32 and at least 64.
pub fn check_input(images: &Tensor<4>, model: &str) -> [usize; 2] {
    let [b, c, h, w] = images.dims();
    assert!(
        b > 0 && c == 3 && h >= 64 && w >= 64 && h % 32 == 0 && w % 32 == 0,
        "{model} expects [B, 3, H, W] with H, W multiples of 32 and ≥ 64, got [{b}, {c}, {h}, {w}]"
    );
    [h, w]
}

/// The checks every ResNet-FPN model config makes (`config` names it in the panic): a
/// finite, positive `width_mult` and an `input_size` that is a multiple of 32 and ≥ 64.
pub fn check_scale(config: &str, width_mult: f64, input_size: usize) {
    assert!(
        width_mult.is_finite() && width_mult > 0.0,
        "{config}: width_mult must be finite and > 0, got {width_mult}"
    );
    assert!(
        input_size >= 64 && input_size % 32 == 0,
        "{config}: input_size must be a multiple of 32 and ≥ 64, got {input_size}"
    );
}

/// One targets entry per image of a batch of `b` (`caller` names it in the panic).
pub fn check_batch(targets: &[ImageTargets], b: usize, caller: &str) {
    assert_eq!(
        targets.len(),
        b,
        "{caller}: {} targets for a batch of {b}",
        targets.len()
    );
}

/// Model options. [`MaskRcnnConfig::new`] gives the compact preset, [`MaskRcnnConfig::paper`]
/// the detectron2 sizes; [`MaskRcnnConfig::init`] validates and panics naming the bad value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaskRcnnConfig {
    /// ResNet depth: 18, 34 (basic blocks), 50, 101, 152 (bottlenecks).
    pub depth: usize,
    pub width_mult: f64,
    pub num_classes: usize,
    /// Nominal square input size (px, multiple of 32), used for the printed GFLOPs; the
    /// forward passes accept any multiple of 32.
    pub input_size: usize,
    pub fpn_channels: usize,
    pub anchors: AnchorConfig,
    pub rpn: RpnConfig,
    pub roi: RoiHeadsConfig,
    pub mask: MaskHeadConfig,
}

impl MaskRcnnConfig {
    /// The model of a validated `[model]` table: its preset at `input_size` px with
    /// `num_classes`, then each size the table sets.
    pub fn from_config(m: &MaskRcnnModelConfig, input_size: usize, num_classes: usize) -> Self {
        let mut c = match m.preset {
            MaskRcnnPreset::Compact => MaskRcnnConfig::new(m.depth, num_classes),
            MaskRcnnPreset::Paper => MaskRcnnConfig::paper(m.depth, num_classes),
        }
        .with_width_mult(m.width_mult)
        .with_input_size(input_size);
        if let Some(f) = m.fpn_channels {
            c.fpn_channels = f;
        }
        if let Some(s) = &m.anchor_sizes {
            c.anchors = AnchorConfig {
                sizes: s.clone(),
                ..c.anchors
            };
        }
        let r = &mut c.rpn;
        r.batch_per_image = m.rpn_batch.unwrap_or(r.batch_per_image);
        r.pre_nms_topk_train = m.rpn_pre_nms_topk_train.unwrap_or(r.pre_nms_topk_train);
        r.post_nms_topk_train = m.rpn_post_nms_topk_train.unwrap_or(r.post_nms_topk_train);
        r.pre_nms_topk_test = m.rpn_pre_nms_topk_test.unwrap_or(r.pre_nms_topk_test);
        r.post_nms_topk_test = m.rpn_post_nms_topk_test.unwrap_or(r.post_nms_topk_test);
        c.roi.batch_per_image = m.roi_batch.unwrap_or(c.roi.batch_per_image);
        c.roi.fc_dim = m.box_fc_dim.unwrap_or(c.roi.fc_dim);
        c.mask.conv_dim = m.mask_conv_dim.unwrap_or(c.mask.conv_dim);
        c.mask.class_agnostic = m.mask_class_agnostic.unwrap_or(c.mask.class_agnostic);
        c
    }

    /// Compact preset (see the module docs).
    pub fn new(depth: usize, num_classes: usize) -> Self {
        Self {
            depth,
            width_mult: 1.0,
            num_classes,
            input_size: 512,
            fpn_channels: 128,
            anchors: AnchorConfig::compact(),
            rpn: RpnConfig::compact(),
            roi: RoiHeadsConfig::compact(),
            mask: MaskHeadConfig::compact(),
        }
    }

    /// detectron2 / torchvision R-FPN sizes (256-wide FPN, 1000 proposals, 512 RoIs,
    /// 1024-wide FCs, 256-wide mask convs, anchors 32…512; 800 px nominal input).
    pub fn paper(depth: usize, num_classes: usize) -> Self {
        Self {
            input_size: 800,
            fpn_channels: 256,
            anchors: AnchorConfig::paper(),
            rpn: RpnConfig::paper(),
            roi: RoiHeadsConfig::paper(),
            mask: MaskHeadConfig::paper(),
            ..Self::new(depth, num_classes)
        }
    }

    pub fn with_width_mult(mut self, w: f64) -> Self {
        self.width_mult = w;
        self
    }
    pub fn with_input_size(mut self, s: usize) -> Self {
        self.input_size = s;
        self
    }
    pub fn with_fpn_channels(mut self, c: usize) -> Self {
        self.fpn_channels = c;
        self
    }
    pub fn with_anchors(mut self, a: AnchorConfig) -> Self {
        self.anchors = a;
        self
    }
    pub fn with_rpn(mut self, r: RpnConfig) -> Self {
        self.rpn = r;
        self
    }
    pub fn with_roi(mut self, r: RoiHeadsConfig) -> Self {
        self.roi = r;
        self
    }
    pub fn with_mask(mut self, m: MaskHeadConfig) -> Self {
        self.mask = m;
        self
    }

    /// Panics with the offending value if the config cannot build a model.
    pub fn validate(&self) {
        resnet::depth_layout(self.depth);
        assert!(
            self.num_classes > 0,
            "MaskRcnnConfig: num_classes must be > 0, got {}",
            self.num_classes
        );
        check_scale("MaskRcnnConfig", self.width_mult, self.input_size);
        assert!(
            self.fpn_channels > 0,
            "MaskRcnnConfig: fpn_channels must be > 0, got {}",
            self.fpn_channels
        );
        self.anchors.validate(STRIDES.len());
        self.rpn.validate();
        self.roi.validate();
        self.mask.validate();
    }

    pub fn init(&self, device: &Device) -> MaskRcnn {
        self.validate();
        let backbone = ResNet::new(self.depth, self.width_mult, device);
        let fpn = Fpn::new(&backbone.out_channels, self.fpn_channels, device);
        let c = fpn.channels;
        MaskRcnn {
            rpn: RpnHead::new(c, self.anchors.per_location(), device),
            box_head: BoxHead::new(
                c * self.roi.pool_size * self.roi.pool_size,
                &self.roi,
                self.num_classes,
                device,
            ),
            mask_head: MaskHead::new(c, &self.mask, self.num_classes, device),
            backbone,
            fpn,
            config: self.clone(),
        }
    }
}

/// Whether the tensor at module path `path` is sized by the class count (the box
/// predictor's logits and deltas, the mask logits): those are re-initialised when weights
/// come from a model with another class count (`model.init`).
pub fn class_dependent(path: &str) -> bool {
    path.starts_with("box_head.cls_score.")
        || path.starts_with("box_head.bbox_pred.")
        || path.starts_with("mask_head.predictor.")
}

/// Named training losses (each `[1]`) and their sum.
#[derive(Debug, Clone)]
pub struct MaskRcnnLosses {
    pub rpn_cls: Tensor<1>,
    pub rpn_box: Tensor<1>,
    pub roi_cls: Tensor<1>,
    pub roi_box: Tensor<1>,
    pub mask: Tensor<1>,
    pub total: Tensor<1>,
    /// Foreground RoIs in the batch (mask-loss instances).
    pub num_fg: usize,
}

impl MaskRcnnLosses {
    /// The terms' names as logged (`metrics.jsonl`, `results.csv`): the RoI head's
    /// classification and box terms are `cls` and `box`.
    pub const NAMES: [&'static str; 5] = ["rpn_cls", "rpn_box", "cls", "box", "mask"];

    /// Host values in [`Self::NAMES`] order, then the total (syncs the device).
    pub fn values(&self) -> [f32; 6] {
        let v = |t: &Tensor<1>| to_host(t.clone())[0];
        [
            v(&self.rpn_cls),
            v(&self.rpn_box),
            v(&self.roi_cls),
            v(&self.roi_box),
            v(&self.mask),
            v(&self.total),
        ]
    }
}

#[derive(Module, Debug)]
pub struct MaskRcnn {
    pub backbone: ResNet,
    pub fpn: Fpn,
    pub rpn: RpnHead,
    pub box_head: BoxHead,
    pub mask_head: MaskHead,
    #[module(skip)]
    pub config: MaskRcnnConfig,
}

impl MaskRcnn {
    /// P2…P6 of normalised images.
    ///
    /// # Shapes
    /// - `images`: `[B, 3, H, W]` in `[0, 1]` → 5 × `[B, fpn_channels, H/s, W/s]`, s = 4…64
    pub fn features(&self, images: Tensor<4>) -> Vec<Tensor<4>> {
        self.fpn.forward(self.backbone.forward(normalize(images)))
    }

    /// Training forward: all losses of a batch. `rng` drives anchor and RoI sampling.
    ///
    /// # Shapes
    /// - `images`: `[B, 3, H, W]` in `[0, 1]`, H, W multiples of 32
    /// - `targets`: `B` entries; boxes xyxy px, classes `< num_classes`, masks `H·W` bytes
    pub fn forward_train<R: Rng>(
        &self,
        images: Tensor<4>,
        targets: &[ImageTargets],
        rng: &mut R,
    ) -> MaskRcnnLosses {
        let [h, w] = check_input(&images, "MaskRcnn");
        check_batch(targets, images.dims()[0], "MaskRcnn::forward_train");
        for (i, t) in targets.iter().enumerate() {
            assert!(
                t.classes.len() == t.boxes.len() && t.masks.len() == t.boxes.len(),
                "MaskRcnn::forward_train: image {i} has {} boxes, {} classes, {} masks",
                t.boxes.len(),
                t.classes.len(),
                t.masks.len()
            );
        }
        let cfg = &self.config;
        let nc = cfg.num_classes;
        let device = images.device();
        let feats = self.features(images);
        let rpn_out = self.rpn.forward(&feats, &STRIDES);
        let anchors = cfg.anchors.generate(&rpn_out.levels);
        let (rpn_cls, rpn_box) = rpn_loss(&rpn_out, &anchors, targets, &cfg.rpn, rng);
        let proposals = find_proposals(
            &rpn_out,
            &anchors,
            [h, w],
            cfg.rpn.pre_nms_topk_train,
            cfg.rpn.post_nms_topk_train,
            cfg.rpn.nms_iou,
        );
        let sampled = label_and_sample(&proposals, targets, &cfg.roi, nc, rng);
        let pooled = pool_levels(
            &feats[..4],
            2,
            &sampled.rois,
            cfg.roi.pool_size,
            cfg.roi.sampling_ratio,
        );
        let (cls, deltas) = self.box_head.forward(pooled);
        let (roi_cls, roi_box) = box_loss(cls, deltas, &sampled, targets, &cfg.roi, nc);

        let fg = sampled.foreground(nc);
        let mask = if fg.is_empty() {
            Tensor::zeros([1], &device)
        } else {
            let rois: Vec<(usize, [f32; 4])> = fg.iter().map(|&k| sampled.rois[k]).collect();
            let classes: Vec<usize> = fg.iter().map(|&k| sampled.classes[k]).collect();
            let m = cfg.mask.mask_size();
            let items: Vec<(&[u8], [f32; 4])> = fg
                .iter()
                .map(|&k| {
                    let (img, r) = sampled.rois[k];
                    let gm = &targets[img].masks[sampled.gt[k]];
                    assert_eq!(
                        gm.len(),
                        h * w,
                        "MaskRcnn: mask of image {img} has {} bytes for {h}×{w}",
                        gm.len()
                    );
                    (gm.as_slice(), r)
                })
                .collect();
            let tgt = mask_targets(&items, [h, w], m);
            let pooled = pool_levels(
                &feats[..4],
                2,
                &rois,
                cfg.mask.pool_size,
                cfg.mask.sampling_ratio,
            );
            mask_loss(self.mask_head.forward(pooled), &classes, tgt)
        };
        let total =
            rpn_cls.clone() + rpn_box.clone() + roi_cls.clone() + roi_box.clone() + mask.clone();
        MaskRcnnLosses {
            rpn_cls,
            rpn_box,
            roi_cls,
            roi_box,
            mask,
            total,
            num_fg: fg.len(),
        }
    }

    /// Inference: per image, at most `roi.max_det` detections, each with its RoI's mask
    /// probabilities (decoded by the caller at the size it needs).
    /// Call on `model.valid()` (no autodiff graph).
    ///
    /// # Shapes
    /// - `images`: `[B, 3, H, W]` in `[0, 1]` → `B` lists; `mask` holds `M × M` probabilities
    pub fn forward_infer(&self, images: Tensor<4>) -> Vec<Vec<Detection>> {
        check_input(&images, "MaskRcnn");
        infer(self, &self.config, images).expect("chicktrain's own modules do not fail")
    }

    pub fn num_classes(&self) -> usize {
        self.config.num_classes
    }

    /// Trainable parameters (BN running statistics excluded) and GFLOPs (2 × MACs of convs,
    /// deconvs and FCs) at a square `input`, with `rpn.post_nms_topk_test` RoIs through the
    /// box head and `roi.max_det` through the mask head (detectron2's inference-time count).
    pub fn summary(&self, input: usize) -> ModelSummary {
        let hw = [input, input];
        let sizes: Vec<[usize; 2]> = STRIDES
            .iter()
            .map(|&s| [input.div_ceil(s), input.div_ceil(s)])
            .collect();
        let cfg = &self.config;
        let macs = self.backbone.macs(hw)
            + self.fpn.macs(&sizes[..4])
            + self.rpn.macs(&sizes)
            + self.box_head.macs(cfg.rpn.post_nms_topk_test)
            + self.mask_head.macs(cfg.roi.max_det, cfg.mask.pool_size);
        ModelSummary {
            params: crate::model::layers::trainable_params(self),
            gflops: 2.0 * macs as f64 / 1e9,
            input,
        }
    }
}

/// The network pieces of inference, apart from the data-dependent steps between them, so
/// that one postprocess ([`infer`]) serves chicktrain's modules and the exported ONNX
/// graphs run by tract (`predict --onnx`, [`onnx::OnnxMaskRcnn`]).
pub trait InferenceNet {
    /// P2…P6 of `[0, 1]` images and the RPN head's raw maps per level
    /// ([`RpnHead::forward_levels`]).
    #[allow(clippy::type_complexity)]
    fn features_and_rpn(
        &self,
        images: Tensor<4>,
    ) -> anyhow::Result<(Vec<Tensor<4>>, Vec<(Tensor<4>, Tensor<4>)>)>;
    /// Pooled `[N, C, P, P]` → class logits `[N, nc + 1]`, deltas `[N, 4·nc]`.
    fn box_head(&self, pooled: Tensor<4>) -> anyhow::Result<(Tensor<2>, Tensor<2>)>;
    /// Pooled `[N, C, P, P]` → mask logits `[N, K, 2P, 2P]`.
    fn mask_head(&self, pooled: Tensor<4>) -> anyhow::Result<Tensor<4>>;
}

impl InferenceNet for MaskRcnn {
    fn features_and_rpn(
        &self,
        images: Tensor<4>,
    ) -> anyhow::Result<(Vec<Tensor<4>>, Vec<(Tensor<4>, Tensor<4>)>)> {
        let feats = self.features(images);
        let maps = self.rpn.forward_levels(&feats);
        Ok((feats, maps))
    }
    fn box_head(&self, pooled: Tensor<4>) -> anyhow::Result<(Tensor<2>, Tensor<2>)> {
        Ok(self.box_head.forward(pooled))
    }
    fn mask_head(&self, pooled: Tensor<4>) -> anyhow::Result<Tensor<4>> {
        Ok(self.mask_head.forward(pooled))
    }
}

/// Inference of `net` (a model of `cfg`): per image, at most `roi.max_det` detections,
/// each with its RoI's mask probabilities. See [`MaskRcnn::forward_infer`].
pub fn infer<N: InferenceNet + ?Sized>(
    net: &N,
    cfg: &MaskRcnnConfig,
    images: Tensor<4>,
) -> anyhow::Result<Vec<Vec<Detection>>> {
    let [b, _, h, w] = images.dims();
    let (feats, maps) = net.features_and_rpn(images)?;
    let rpn_out = rpn::RpnOutput::from_levels(maps, &STRIDES, cfg.anchors.per_location());
    let anchors = cfg.anchors.generate(&rpn_out.levels);
    let proposals = find_proposals(
        &rpn_out,
        &anchors,
        [h, w],
        cfg.rpn.pre_nms_topk_test,
        cfg.rpn.post_nms_topk_test,
        cfg.rpn.nms_iou,
    );
    let rois: Vec<(usize, [f32; 4])> = proposals
        .iter()
        .enumerate()
        .flat_map(|(i, p)| p.iter().map(move |q| (i, q.0)))
        .collect();
    if rois.is_empty() {
        return Ok(vec![Vec::new(); b]);
    }
    let pooled = pool_levels(
        &feats[..4],
        2,
        &rois,
        cfg.roi.pool_size,
        cfg.roi.sampling_ratio,
    );
    let (cls, deltas) = net.box_head(pooled)?;
    let dets = box_inference(cls, deltas, &rois, b, [h, w], &cfg.roi);
    let det_rois: Vec<(usize, [f32; 4])> = dets
        .iter()
        .enumerate()
        .flat_map(|(i, d)| d.iter().map(move |x| (i, x.0)))
        .collect();
    if det_rois.is_empty() {
        return Ok(vec![Vec::new(); b]);
    }
    let pooled = pool_levels(
        &feats[..4],
        2,
        &det_rois,
        cfg.mask.pool_size,
        cfg.mask.sampling_ratio,
    );
    let logits = net.mask_head(pooled)?;
    let [n, k, m, _] = logits.dims();
    let probs = to_host(sigmoid(logits));
    let flat: Vec<([f32; 4], f32, usize, usize)> = dets
        .iter()
        .enumerate()
        .flat_map(|(i, d)| d.iter().map(move |x| (x.0, x.1, x.2, i)))
        .collect();
    debug_assert_eq!(flat.len(), n);
    let thr = cfg.mask.threshold;
    let built: Vec<(usize, Detection)> = flat
        .iter()
        .enumerate()
        .map(|(r, &(bx, score, class, img))| {
            let ch = if k == 1 { 0 } else { class };
            let p = &probs[(r * k + ch) * m * m..(r * k + ch + 1) * m * m];
            (
                img,
                Detection {
                    bbox: [bx[0], bx[1], bx[2] - bx[0], bx[3] - bx[1]],
                    score,
                    class,
                    mask: MaskSource::RoiProbs {
                        probs: p.to_vec(),
                        size: m,
                        threshold: thr,
                    },
                },
            )
        })
        .collect();
    let mut out = vec![Vec::new(); b];
    for (img, d) in built {
        out[img].push(d);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_sizes_match_torchvision() {
        // torchvision 0.29 `maskrcnn_resnet50_fpn(weights=None, weights_backbone=None,
        // num_classes=2)`: 43,975,515 parameters; `MaskRCNN(resnet_fpn_backbone("resnet101",
        // trainable_layers=5, norm_layer=BatchNorm2d), num_classes=2)`: 62,967,643.
        // torchvision also regresses boxes and predicts a mask for the background class:
        // 1024·4 + 4 and 256 + 1 more parameters than our class-specific heads for nc = 1.
        let d = Device::flex();
        let extra = 1024 * 4 + 4 + 256 + 1;
        let r50 = MaskRcnnConfig::paper(50, 1).init(&d).summary(800).params;
        assert_eq!(r50, 43_975_515 - extra);
        let r101 = MaskRcnnConfig::paper(101, 1).init(&d).summary(800).params;
        assert_eq!(r101, 62_967_643 - extra);
    }

    #[test]
    fn compact_is_smaller_and_depths_order() {
        let d = Device::flex();
        let s18 = MaskRcnnConfig::new(18, 1)
            .with_width_mult(0.5)
            .init(&d)
            .summary(512);
        let s50 = MaskRcnnConfig::new(50, 1).init(&d).summary(512);
        let s101 = MaskRcnnConfig::new(101, 1).init(&d).summary(512);
        let p50 = MaskRcnnConfig::paper(50, 1).init(&d).summary(512);
        assert!(
            s18.params < s50.params && s50.params < s101.params,
            "{s18} {s50} {s101}"
        );
        assert!(
            s50.gflops < s101.gflops && s50.gflops < p50.gflops,
            "{s50} {s101} {p50}"
        );
    }

    #[test]
    #[should_panic(expected = "input_size must be a multiple of 32 and ≥ 64, got 100")]
    fn rejects_input_size() {
        MaskRcnnConfig::new(18, 1)
            .with_input_size(100)
            .init(&Device::flex());
    }
}
