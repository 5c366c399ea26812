//! YOLO11 Segment head = Detect (decoupled box / class branches per level, DFL box
//! distributions with `reg_max` bins) + Proto (mask prototypes at twice the finest level's
//! resolution) + a mask-coefficient branch per level. ultralytics `nn/modules/head.py`.
//!
//! The head returns raw logits only; decoding lives in `postprocess.rs` and losses in
//! `loss.rs`.

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::{Device, Tensor};

use crate::model::layers::conv_macs;
use crate::model::yolo::blocks::{ConvBn, Proto};

/// Bins of the distribution focal loss box representation (ultralytics `reg_max`).
pub const REG_MAX: usize = 16;

/// Box branch: Conv 3×3, Conv 3×3, 1×1 to `4 · REG_MAX`.
#[derive(Module, Debug)]
pub struct BoxBranch {
    pub c1: ConvBn,
    pub c2: ConvBn,
    pub out: Conv2d,
}

/// Class branch (YOLO11, non-legacy): DWConv 3×3 + Conv 1×1, twice, then 1×1 to `nc`.
#[derive(Module, Debug)]
pub struct ClsBranch {
    pub dw1: ConvBn,
    pub pw1: ConvBn,
    pub dw2: ConvBn,
    pub pw2: ConvBn,
    pub out: Conv2d,
}

/// Mask-coefficient branch: Conv 3×3, Conv 3×3, 1×1 to `nm`.
#[derive(Module, Debug)]
pub struct CoefBranch {
    pub c1: ConvBn,
    pub c2: ConvBn,
    pub out: Conv2d,
}

fn conv1x1(c_in: usize, c_out: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([c_in, c_out], [1, 1]).init(device)
}

fn set_bias(conv: &mut Conv2d, value: f64, device: &Device) {
    let n = conv.weight.dims()[0];
    conv.bias = Some(Param::from_tensor(Tensor::full([n], value, device)));
}

/// Raw per-level outputs concatenated over all anchors (levels finest first, row-major cells).
#[derive(Debug, Clone)]
pub struct HeadOutput {
    /// `[B, 4 · REG_MAX, A]` box distribution logits (l, t, r, b blocks of REG_MAX).
    pub box_dist: Tensor<3>,
    /// `[B, nc, A]` class logits.
    pub cls_logits: Tensor<3>,
    /// `[B, nm, A]` mask coefficients.
    pub mask_coef: Tensor<3>,
    /// `[B, nm, Hp, Wp]` mask prototypes (Hp = 2 · finest level's height).
    pub proto: Tensor<4>,
}

#[derive(Module, Debug)]
pub struct SegmentHead {
    pub boxes: Vec<BoxBranch>,
    pub cls: Vec<ClsBranch>,
    pub coef: Vec<CoefBranch>,
    pub proto: Proto,
    pub num_classes: usize,
    pub num_masks: usize,
}

impl SegmentHead {
    /// `ch`: input channels per level (finest first); `strides`: the levels' strides (for the
    /// class-bias prior); `proto_hidden`: Proto width (`npr`).
    pub fn new(
        ch: &[usize],
        strides: &[usize],
        num_classes: usize,
        num_masks: usize,
        proto_hidden: usize,
        device: &Device,
    ) -> Self {
        assert!(
            !ch.is_empty() && ch.len() == strides.len(),
            "SegmentHead: {} channel entries for {} strides",
            ch.len(),
            strides.len()
        );
        assert!(
            num_classes > 0 && num_masks > 0,
            "SegmentHead: num_classes {num_classes} and num_masks {num_masks} must be > 0"
        );
        let c2 = (ch[0] / 4).max(16).max(4 * REG_MAX);
        let c3 = ch[0].max(num_classes.min(100));
        let c4 = (ch[0] / 4).max(num_masks);
        let mut boxes = Vec::new();
        let mut cls = Vec::new();
        let mut coef = Vec::new();
        for (&x, &s) in ch.iter().zip(strides) {
            let mut b = BoxBranch {
                c1: ConvBn::silu(x, c2, 3, 1, device),
                c2: ConvBn::silu(c2, c2, 3, 1, device),
                out: conv1x1(c2, 4 * REG_MAX, device),
            };
            // ultralytics Detect.bias_init (8.4): box 2.0, class log(5 / nc / (640 / s)²).
            set_bias(&mut b.out, 2.0, device);
            let mut c = ClsBranch {
                dw1: ConvBn::new(x, x, 3, 1, x, true, device),
                pw1: ConvBn::silu(x, c3, 1, 1, device),
                dw2: ConvBn::new(c3, c3, 3, 1, c3, true, device),
                pw2: ConvBn::silu(c3, c3, 1, 1, device),
                out: conv1x1(c3, num_classes, device),
            };
            let prior = (5.0 / num_classes as f64 / (640.0 / s as f64).powi(2)).ln();
            set_bias(&mut c.out, prior, device);
            boxes.push(b);
            cls.push(c);
            coef.push(CoefBranch {
                c1: ConvBn::silu(x, c4, 3, 1, device),
                c2: ConvBn::silu(c4, c4, 3, 1, device),
                out: conv1x1(c4, num_masks, device),
            });
        }
        Self {
            boxes,
            cls,
            coef,
            proto: Proto::new(ch[0], proto_hidden, num_masks, device),
            num_classes,
            num_masks,
        }
    }

    /// # Shapes
    /// - `feats[l]`: `[B, ch[l], H_l, W_l]`, finest first
    /// - returns [`HeadOutput`] with `A = Σ H_l·W_l`
    pub fn forward(&self, feats: Vec<Tensor<4>>) -> HeadOutput {
        let proto = self.proto.forward(feats[0].clone());
        let mut bd = Vec::new();
        let mut cl = Vec::new();
        let mut co = Vec::new();
        for (l, x) in feats.into_iter().enumerate() {
            let [b, _, h, w] = x.dims();
            let bb = &self.boxes[l];
            let d = bb.out.forward(bb.c2.forward(bb.c1.forward(x.clone())));
            bd.push(d.reshape([b, 4 * REG_MAX, h * w]));
            let cb = &self.cls[l];
            let y = cb.pw1.forward(cb.dw1.forward(x.clone()));
            let y = cb.out.forward(cb.pw2.forward(cb.dw2.forward(y)));
            cl.push(y.reshape([b, self.num_classes, h * w]));
            let mb = &self.coef[l];
            let m = mb.out.forward(mb.c2.forward(mb.c1.forward(x)));
            co.push(m.reshape([b, self.num_masks, h * w]));
        }
        HeadOutput {
            box_dist: Tensor::cat(bd, 2),
            cls_logits: Tensor::cat(cl, 2),
            mask_coef: Tensor::cat(co, 2),
            proto,
        }
    }

    /// Folds every BatchNorm into its conv (inference only; see `ConvBn::fuse`).
    pub fn fuse(self) -> Self {
        Self {
            boxes: self
                .boxes
                .into_iter()
                .map(|b| BoxBranch {
                    c1: b.c1.fuse(),
                    c2: b.c2.fuse(),
                    out: b.out,
                })
                .collect(),
            cls: self
                .cls
                .into_iter()
                .map(|c| ClsBranch {
                    dw1: c.dw1.fuse(),
                    pw1: c.pw1.fuse(),
                    dw2: c.dw2.fuse(),
                    pw2: c.pw2.fuse(),
                    out: c.out,
                })
                .collect(),
            coef: self
                .coef
                .into_iter()
                .map(|k| CoefBranch {
                    c1: k.c1.fuse(),
                    c2: k.c2.fuse(),
                    out: k.out,
                })
                .collect(),
            proto: self.proto.fuse(),
            ..self
        }
    }

    /// MACs for level sizes `sizes[l] = [h, w]`.
    pub fn macs(&self, sizes: &[[usize; 2]]) -> u64 {
        let mut m = self.proto.macs(sizes[0]);
        for (l, &hw) in sizes.iter().enumerate() {
            let b = &self.boxes[l];
            m += b.c1.macs(hw).0 + b.c2.macs(hw).0 + conv_macs(&b.out, hw).0;
            let c = &self.cls[l];
            m += c.dw1.macs(hw).0 + c.pw1.macs(hw).0 + c.dw2.macs(hw).0 + c.pw2.macs(hw).0;
            m += conv_macs(&c.out, hw).0;
            let k = &self.coef[l];
            m += k.c1.macs(hw).0 + k.c2.macs(hw).0 + conv_macs(&k.out, hw).0;
        }
        m
    }
}
