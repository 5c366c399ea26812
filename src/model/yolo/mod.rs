//! YOLO11-seg-style one-stage instance segmentation model in Burn.
//!
//! - [`scale`]: n/s presets and the channel rule; [`backbone`], [`neck`], [`head`]: the network.
//! - [`assigner`]: task-aligned assigner (plain Rust over host vectors, no gradients).
//! - [`loss`]: BCE class, CIoU + DFL box and prototype mask losses ([`loss::yolo_loss`]).
//! - [`postprocess`]: decoding, class-wise NMS and mask assembly for inference.
//! - [`ultralytics`]: ultralytics `state_dict` names ↔ ours, weights in (`.pt`, safetensors)
//!   and out.
//! - [`onnx`]: ONNX export in ultralytics' output layout.
//!
//! This module defines the model config ([`YoloSegConfig`]), the model ([`YoloSeg`]) and its
//! output ([`YoloOutput`]). It reads no training config.

pub mod assigner;
pub mod attention;
pub mod backbone;
pub mod blocks;
pub mod config;
pub mod export;
pub mod family;
pub mod head;
pub mod loss;
pub mod neck;
pub mod onnx;
mod onnx_metadata;
pub mod postprocess;
pub mod scale;
pub mod ultralytics;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

pub use crate::model::summary::ModelSummary;
use backbone::Backbone;
use head::{SegmentHead, REG_MAX};
pub use neck::HeadLevels;
use neck::Neck;
pub use scale::Scale;
use scale::Scaler;

pub use config::{YoloModelConfig, YoloScale};

/// Scene-sized options of a YOLO-seg model. Build with [`YoloSegConfig::new`] and the
/// `with_*` setters; [`YoloSegConfig::init`] validates and panics naming the bad value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct YoloSegConfig {
    pub scale: Scale,
    pub num_classes: usize,
    /// Square training / inference input size in pixels (a multiple of 32).
    pub input_size: usize,
    pub levels: HeadLevels,
    /// C2PSA attention after SPPF (YOLO11 default on).
    pub c2psa: bool,
    /// Multiplies the scale's width factor (1.0 = the preset).
    pub width_mult: f64,
    /// Number of mask prototypes / coefficients (YOLO: 32).
    pub num_masks: usize,
}

impl YoloSegConfig {
    /// The model of a validated `[model]` table at `input_size` px with `num_classes`.
    pub fn from_config(m: &YoloModelConfig, input_size: usize, num_classes: usize) -> Self {
        let scale = match m.scale {
            YoloScale::N => Scale::N,
            YoloScale::S => Scale::S,
        };
        let levels = if m.levels == [4, 5] {
            HeadLevels::P4P5
        } else {
            HeadLevels::P3P5
        };
        YoloSegConfig::new(scale, num_classes)
            .with_input_size(input_size)
            .with_levels(levels)
            .with_c2psa(m.c2psa)
            .with_width_mult(m.width_mult)
            .with_num_masks(m.prototypes)
    }

    /// The YOLO11-seg preset: 640 px, heads on P3–P5, C2PSA on, 32 prototypes.
    pub fn new(scale: Scale, num_classes: usize) -> Self {
        Self {
            scale,
            num_classes,
            input_size: 640,
            levels: HeadLevels::P3P5,
            c2psa: true,
            width_mult: 1.0,
            num_masks: 32,
        }
    }
    pub fn with_input_size(mut self, s: usize) -> Self {
        self.input_size = s;
        self
    }
    pub fn with_levels(mut self, l: HeadLevels) -> Self {
        self.levels = l;
        self
    }
    pub fn with_c2psa(mut self, on: bool) -> Self {
        self.c2psa = on;
        self
    }
    pub fn with_width_mult(mut self, w: f64) -> Self {
        self.width_mult = w;
        self
    }
    pub fn with_num_masks(mut self, n: usize) -> Self {
        self.num_masks = n;
        self
    }

    /// Panics with the offending value if the config cannot build a model.
    pub fn validate(&self) {
        assert!(
            self.num_classes > 0,
            "YoloSegConfig: num_classes must be > 0, got {}",
            self.num_classes
        );
        assert!(
            self.input_size >= 32 && self.input_size.is_multiple_of(32),
            "YoloSegConfig: input_size must be a positive multiple of 32 (the largest stride), got {}",
            self.input_size
        );
        assert!(
            self.num_masks > 0,
            "YoloSegConfig: num_masks must be > 0, got {}",
            self.num_masks
        );
        assert!(
            self.width_mult.is_finite() && self.width_mult > 0.0,
            "YoloSegConfig: width_mult must be finite and > 0, got {}",
            self.width_mult
        );
    }

    /// Parameter count and GFLOPs at `input_size` (builds the model once on flex).
    pub fn summary(&self) -> ModelSummary {
        self.init(&Device::flex()).summary(self.input_size)
    }

    pub fn init(&self, device: &Device) -> YoloSeg {
        self.validate();
        let sc = Scaler::new(self.scale, self.width_mult);
        let backbone = Backbone::new(&sc, self.c2psa, device);
        let neck = Neck::new(&sc, backbone.channels(), self.levels, device);
        let ch = neck.out_channels();
        let head = SegmentHead::new(
            &ch,
            self.levels.strides(),
            self.num_classes,
            self.num_masks,
            sc.ch(256),
            device,
        );
        YoloSeg {
            backbone,
            neck,
            head,
            strides: self.levels.strides().to_vec(),
        }
    }
}

/// Anchor layout of one forward pass: levels finest first, cells row-major inside a level.
#[derive(Debug, Clone, PartialEq)]
pub struct AnchorGrid {
    /// Input image `[height, width]` in pixels.
    pub input: [usize; 2],
    /// `(stride, height, width)` per level.
    pub levels: Vec<(usize, usize, usize)>,
}

impl AnchorGrid {
    pub fn new(input: [usize; 2], strides: &[usize]) -> Self {
        Self {
            input,
            levels: strides
                .iter()
                .map(|&s| (s, input[0] / s, input[1] / s))
                .collect(),
        }
    }

    pub fn num_anchors(&self) -> usize {
        self.levels.iter().map(|&(_, h, w)| h * w).sum()
    }

    /// Anchor centres in grid units of their own level, `(x + 0.5, y + 0.5)`
    /// (ultralytics `make_anchors(..., 0.5)`).
    pub fn points(&self) -> Vec<[f32; 2]> {
        let mut v = Vec::with_capacity(self.num_anchors());
        for &(_, h, w) in &self.levels {
            for y in 0..h {
                for x in 0..w {
                    v.push([x as f32 + 0.5, y as f32 + 0.5]);
                }
            }
        }
        v
    }

    /// Stride of each anchor.
    pub fn strides(&self) -> Vec<f32> {
        let mut v = Vec::with_capacity(self.num_anchors());
        for &(s, h, w) in &self.levels {
            v.extend(std::iter::repeat_n(s as f32, h * w));
        }
        v
    }
}

/// Raw model output plus its anchor layout; see [`head::HeadOutput`] for the tensors.
#[derive(Debug, Clone)]
pub struct YoloOutput {
    /// `[B, 4 · REG_MAX, A]`
    pub box_dist: Tensor<3>,
    /// `[B, nc, A]`
    pub cls_logits: Tensor<3>,
    /// `[B, nm, A]`
    pub mask_coef: Tensor<3>,
    /// `[B, nm, Hp, Wp]`
    pub proto: Tensor<4>,
    pub grid: AnchorGrid,
}

/// Whether the tensor at module path `path` is sized by the class count: the class
/// branch of the head (ultralytics' `cv3`, whose hidden width is `max(c, min(nc, 100))`
/// too). Those are re-initialised when weights come from a model with another class count
/// (`model.init`), as ultralytics does.
pub fn class_dependent(path: &str) -> bool {
    path.starts_with("head.cls.")
}

#[derive(Module, Debug)]
pub struct YoloSeg {
    pub backbone: Backbone,
    pub neck: Neck,
    pub head: SegmentHead,
    pub strides: Vec<usize>,
}

impl YoloSeg {
    /// # Shapes
    /// - `images`: `[B, 3, H, W]`, normalised to [0, 1], H and W multiples of 32
    /// - returns [`YoloOutput`]
    pub fn forward(&self, images: Tensor<4>) -> YoloOutput {
        let [_, c, h, w] = images.dims();
        assert!(
            c == 3 && h % 32 == 0 && w % 32 == 0 && h > 0 && w > 0,
            "YoloSeg::forward expects [B, 3, H, W] with H, W multiples of 32, got [_, {c}, {h}, {w}]"
        );
        let (p3, p4, p5) = self.backbone.forward(images);
        let feats = self.neck.forward(p3, p4, p5);
        let out = self.head.forward(feats);
        YoloOutput {
            box_dist: out.box_dist,
            cls_logits: out.cls_logits,
            mask_coef: out.mask_coef,
            proto: out.proto,
            grid: AnchorGrid::new([h, w], &self.strides),
        }
    }

    /// Inference copy with every BatchNorm folded into its conv (about one elementwise pass
    /// less per conv). Takes an eval-mode model (`model.valid()`); the result must not be
    /// trained.
    pub fn fuse(self) -> Self {
        Self {
            backbone: self.backbone.fuse(),
            neck: self.neck.fuse(),
            head: self.head.fuse(),
            strides: self.strides,
        }
    }

    pub fn num_classes(&self) -> usize {
        self.head.num_classes
    }

    /// Parameter count (trainable tensors: conv weights and biases, BN γ and β; running
    /// statistics excluded, like `sum(p.numel() for p in model.parameters())`) and GFLOPs at
    /// a square `input` size, counted from the built layers' weight shapes.
    pub fn summary(&self, input: usize) -> ModelSummary {
        let hw = [input, input];
        let sizes: Vec<[usize; 2]> = self
            .strides
            .iter()
            .map(|&s| [input / s, input / s])
            .collect();
        let macs = self.backbone.macs(hw) + self.neck.macs(hw) + self.head.macs(&sizes);
        ModelSummary {
            params: crate::model::layers::trainable_params(self),
            gflops: 2.0 * macs as f64 / 1e9,
            input,
        }
    }
}

/// `REG_MAX` re-exported for callers decoding boxes.
pub const DFL_BINS: usize = REG_MAX;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yolo11n_seg_size_matches_ultralytics() {
        // ultralytics 8.4.190 `SegmentationModel('yolo11n-seg.yaml', nc=1)`: 2,842,803
        // parameters incl. 16 fixed DFL weights we do not store (see tests/fixtures/yolo).
        let m = YoloSegConfig::new(Scale::N, 1).init(&Device::flex());
        let s = m.summary(640);
        assert_eq!(s.params, 2_842_803 - 16, "{s}");
        // ultralytics' `get_flops` (thop) gives 9.79 GFLOPs for nc 1 and 9.96 for nc 80 at
        // 640; thop also counts BatchNorm, which we leave out (≈ 2 %).
        let g = s.gflops;
        assert!((g - 9.79).abs() / 9.79 < 0.03, "n nc1 GFLOPs {g}");
        let m80 = YoloSegConfig::new(Scale::N, 80).init(&Device::flex());
        let g = m80.summary(640).gflops;
        assert!((g - 9.96).abs() / 9.96 < 0.03, "n nc80 GFLOPs {g}");
    }

    #[test]
    fn yolo11s_seg_size_matches_ultralytics() {
        let m = YoloSegConfig::new(Scale::S, 1).init(&Device::flex());
        let s = m.summary(640);
        assert_eq!(s.params, 10_082_675 - 16, "{s}");
        // thop: 33.19 GFLOPs (nc 1, 640 px).
        assert!((s.gflops - 33.19).abs() / 33.19 < 0.03, "{s}");
    }

    #[test]
    fn scene_options_shrink_the_model() {
        let d = Device::flex();
        let full = YoloSegConfig::new(Scale::N, 1).init(&d).summary(320);
        let p45 = YoloSegConfig::new(Scale::N, 1)
            .with_levels(HeadLevels::P4P5)
            .with_c2psa(false)
            .init(&d)
            .summary(320);
        let narrow = YoloSegConfig::new(Scale::N, 1)
            .with_width_mult(0.5)
            .init(&d)
            .summary(320);
        assert!(p45.params < full.params && p45.gflops < full.gflops);
        assert!(narrow.params < full.params / 2, "{narrow} vs {full}");
    }

    #[test]
    fn forward_shapes() {
        let d = Device::flex();
        for levels in [HeadLevels::P3P5, HeadLevels::P4P5] {
            let m = YoloSegConfig::new(Scale::N, 2)
                .with_width_mult(0.5)
                .with_levels(levels)
                .with_num_masks(8)
                .init(&d);
            let out = m.forward(Tensor::zeros([2, 3, 64, 96], &d));
            let a = out.grid.num_anchors();
            let expect_a = match levels {
                HeadLevels::P3P5 => 8 * 12 + 4 * 6 + 2 * 3,
                HeadLevels::P4P5 => 4 * 6 + 2 * 3,
            };
            assert_eq!(a, expect_a);
            assert_eq!(out.box_dist.dims(), [2, 64, a]);
            assert_eq!(out.cls_logits.dims(), [2, 2, a]);
            assert_eq!(out.mask_coef.dims(), [2, 8, a]);
            let s0 = levels.strides()[0];
            assert_eq!(out.proto.dims(), [2, 8, 2 * 64 / s0, 2 * 96 / s0]);
        }
    }

    #[test]
    fn fused_model_matches_eval_model() {
        // Give the BatchNorms non-trivial running statistics with two train-mode passes.
        let ad = Device::flex().autodiff();
        ad.seed(1);
        let m = YoloSegConfig::new(Scale::N, 2)
            .with_width_mult(0.5)
            .with_num_masks(8)
            .init(&ad);
        let x = Tensor::<4>::random([2, 3, 64, 64], burn::tensor::Distribution::Default, &ad);
        for _ in 0..2 {
            let out = m.forward(x.clone());
            let _ = (out.cls_logits.sum() + out.proto.sum()).backward();
        }
        let eval = m.valid();
        let xe = Tensor::<4>::from_data(x.into_data(), &Device::flex());
        let a = eval.forward(xe.clone());
        let b = eval.clone().fuse().forward(xe);
        for (p, q) in [
            (a.cls_logits, b.cls_logits),
            (a.box_dist, b.box_dist),
            (a.mask_coef, b.mask_coef),
        ] {
            let (p, q) = (
                crate::util::tensor::to_host(p),
                crate::util::tensor::to_host(q),
            );
            for (u, v) in p.iter().zip(&q) {
                assert!((u - v).abs() <= 1e-3 * (1.0 + u.abs()), "{u} vs {v}");
            }
        }
        let (p, q) = (
            crate::util::tensor::to_host(a.proto),
            crate::util::tensor::to_host(b.proto),
        );
        assert!(p
            .iter()
            .zip(&q)
            .all(|(u, v)| (u - v).abs() <= 1e-3 * (1.0 + u.abs())));
        // Running stats really moved, so the test compares something.
        let rm = crate::util::tensor::to_host(eval.backbone.l0.bn.running_mean.value());
        assert!(rm.iter().any(|v| v.abs() > 1e-4));
    }

    #[test]
    #[should_panic(
        expected = "input_size must be a positive multiple of 32 (the largest stride), got 100"
    )]
    fn rejects_input_size() {
        YoloSegConfig::new(Scale::N, 1)
            .with_input_size(100)
            .init(&Device::flex());
    }
}
