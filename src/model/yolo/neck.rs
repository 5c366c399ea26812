//! YOLO11 PAN neck (layers 11–22 of `yolo11-seg.yaml`): top-down nearest ×2 upsampling with
//! concatenation and C3k2, then bottom-up strided convs with concatenation and C3k2.
//!
//! With heads on P3–P5 it returns three maps (strides 8, 16, 32). With heads on P4–P5 the
//! P3 top-down and bottom-up stages are skipped: the top-down P4 map feeds both its head and
//! the stride-2 conv to P5, which saves the stride-8 work for scenes of large objects.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use super::backbone::BackboneChannels;
use super::scale::Scaler;
use crate::model::layers::upsample2x;
use crate::model::yolo::blocks::{C3k2, ConvBn};

/// Which pyramid levels carry detection heads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum HeadLevels {
    /// Strides 8, 16, 32 (YOLO11 default).
    P3P5,
    /// Strides 16, 32 only.
    P4P5,
}

impl HeadLevels {
    pub fn strides(self) -> &'static [usize] {
        match self {
            HeadLevels::P3P5 => &[8, 16, 32],
            HeadLevels::P4P5 => &[16, 32],
        }
    }
}

/// P3 stages of the PAN, present only with [`HeadLevels::P3P5`].
#[derive(Module, Debug)]
pub struct NeckP3 {
    /// Layer 16: C3k2 on cat(up(P4'), P3).
    pub td_p3: C3k2,
    /// Layer 17: stride-2 conv from P3 out.
    pub down_p3: ConvBn,
    /// Layer 19: C3k2 on cat(down(P3 out), P4').
    pub bu_p4: C3k2,
}

#[derive(Module, Debug)]
pub struct Neck {
    /// Layer 13: C3k2 on cat(up(P5), P4) → P4'.
    pub td_p4: C3k2,
    pub p3: Option<NeckP3>,
    /// Layer 20: stride-2 conv from P4 out.
    pub down_p4: ConvBn,
    /// Layer 22: C3k2 on cat(down(P4 out), P5).
    pub bu_p5: C3k2,
}

impl Neck {
    pub fn new(sc: &Scaler, ch: BackboneChannels, levels: HeadLevels, device: &Device) -> Self {
        let n = sc.n(2);
        let (c256, c512, c1024) = (sc.ch(256), sc.ch(512), sc.ch(1024));
        let td_p4 = C3k2::new(ch.p5 + ch.p4, c512, n, false, 0.5, device);
        let p3 = match levels {
            HeadLevels::P3P5 => Some(NeckP3 {
                td_p3: C3k2::new(c512 + ch.p3, c256, n, false, 0.5, device),
                down_p3: ConvBn::silu(c256, c256, 3, 2, device),
                bu_p4: C3k2::new(c256 + c512, c512, n, false, 0.5, device),
            }),
            HeadLevels::P4P5 => None,
        };
        Self {
            td_p4,
            p3,
            down_p4: ConvBn::silu(c512, c512, 3, 2, device),
            bu_p5: C3k2::new(c512 + ch.p5, c1024, n, true, 0.5, device),
        }
    }

    /// Output channels per head level, finest first.
    pub fn out_channels(&self) -> Vec<usize> {
        let mut v = Vec::new();
        if let Some(p3) = &self.p3 {
            v.push(p3.td_p3.out_channels());
            v.push(p3.bu_p4.out_channels());
        } else {
            v.push(self.td_p4.out_channels());
        }
        v.push(self.bu_p5.out_channels());
        v
    }

    /// # Shapes
    /// - `p3 [B, c3, H/8, W/8]`, `p4 [B, c4, H/16, W/16]`, `p5 [B, c5, H/32, W/32]`
    /// - returns one map per head level, finest first (`[B, c_l, H/s_l, W/s_l]`)
    pub fn forward(&self, p3: Tensor<4>, p4: Tensor<4>, p5: Tensor<4>) -> Vec<Tensor<4>> {
        let p4_td = self
            .td_p4
            .forward(Tensor::cat(vec![upsample2x(p5.clone()), p4], 1));
        let (mut outs, p4_out) = match &self.p3 {
            Some(n3) => {
                let p3_out = n3
                    .td_p3
                    .forward(Tensor::cat(vec![upsample2x(p4_td.clone()), p3], 1));
                let p4_out = n3.bu_p4.forward(Tensor::cat(
                    vec![n3.down_p3.forward(p3_out.clone()), p4_td],
                    1,
                ));
                (vec![p3_out], p4_out)
            }
            None => (Vec::new(), p4_td),
        };
        let p5_out = self.bu_p5.forward(Tensor::cat(
            vec![self.down_p4.forward(p4_out.clone()), p5],
            1,
        ));
        outs.push(p4_out);
        outs.push(p5_out);
        outs
    }

    /// MACs for an input image of `[h, w]` (multiples of 32).
    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        let at = |s: usize| [hw[0] / s, hw[1] / s];
        let mut m = self.td_p4.macs(at(16));
        if let Some(n3) = &self.p3 {
            m += n3.td_p3.macs(at(8)) + n3.down_p3.macs(at(8)).0 + n3.bu_p4.macs(at(16));
        }
        m + self.down_p4.macs(at(16)).0 + self.bu_p5.macs(at(32))
    }

    /// Folds every BatchNorm into its conv (inference only; see `ConvBn::fuse`).
    pub fn fuse(self) -> Self {
        Self {
            td_p4: self.td_p4.fuse(),
            p3: self.p3.map(|n| NeckP3 {
                td_p3: n.td_p3.fuse(),
                down_p3: n.down_p3.fuse(),
                bu_p4: n.bu_p4.fuse(),
            }),
            down_p4: self.down_p4.fuse(),
            bu_p5: self.bu_p5.fuse(),
        }
    }
}
