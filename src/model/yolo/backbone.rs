//! YOLO11 backbone: strided Conv-BN-SiLU stem and stages with C3k2 blocks, SPPF and
//! (optionally) C2PSA attention at stride 32. Layers 0–10 of `yolo11-seg.yaml`.
//!
//! Returns the P3 (stride 8), P4 (16) and P5 (32) feature maps the neck consumes.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use super::scale::Scaler;
use crate::model::yolo::attention::C2psa;
use crate::model::yolo::blocks::{C3k2, ConvBn, Sppf};

/// Backbone of YOLO11, layer names follow the yaml's indices.
#[derive(Module, Debug)]
pub struct Backbone {
    pub l0: ConvBn,
    pub l1: ConvBn,
    pub l2: C3k2,
    pub l3: ConvBn,
    pub l4: C3k2,
    pub l5: ConvBn,
    pub l6: C3k2,
    pub l7: ConvBn,
    pub l8: C3k2,
    pub sppf: Sppf,
    pub psa: Option<C2psa>,
}

/// Output channels of the three feature maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BackboneChannels {
    pub p3: usize,
    pub p4: usize,
    pub p5: usize,
}

impl Backbone {
    pub fn new(sc: &Scaler, c2psa: bool, device: &Device) -> Self {
        let (c64, c128, c256, c512, c1024) =
            (sc.ch(64), sc.ch(128), sc.ch(256), sc.ch(512), sc.ch(1024));
        let n2 = sc.n(2);
        Self {
            l0: ConvBn::silu(3, c64, 3, 2, device),
            l1: ConvBn::silu(c64, c128, 3, 2, device),
            l2: C3k2::new(c128, c256, n2, false, 0.25, device),
            l3: ConvBn::silu(c256, c256, 3, 2, device),
            l4: C3k2::new(c256, c512, n2, false, 0.25, device),
            l5: ConvBn::silu(c512, c512, 3, 2, device),
            l6: C3k2::new(c512, c512, n2, true, 0.5, device),
            l7: ConvBn::silu(c512, c1024, 3, 2, device),
            l8: C3k2::new(c1024, c1024, n2, true, 0.5, device),
            sppf: Sppf::new(c1024, c1024, 5, device),
            psa: c2psa.then(|| C2psa::new(c1024, n2, device)),
        }
    }

    pub fn channels(&self) -> BackboneChannels {
        BackboneChannels {
            p3: self.l4.out_channels(),
            p4: self.l6.out_channels(),
            p5: self.sppf.cv2.out_channels(),
        }
    }

    /// # Shapes
    /// - `x`: `[B, 3, H, W]` (H, W multiples of 32)
    /// - returns `(p3 [B, c3, H/8, W/8], p4 [B, c4, H/16, W/16], p5 [B, c5, H/32, W/32])`
    pub fn forward(&self, x: Tensor<4>) -> (Tensor<4>, Tensor<4>, Tensor<4>) {
        let x = self.l1.forward(self.l0.forward(x));
        let x = self.l3.forward(self.l2.forward(x));
        let p3 = self.l4.forward(x);
        let p4 = self.l6.forward(self.l5.forward(p3.clone()));
        let mut p5 = self
            .sppf
            .forward(self.l8.forward(self.l7.forward(p4.clone())));
        if let Some(psa) = &self.psa {
            p5 = psa.forward(p5);
        }
        (p3, p4, p5)
    }

    /// MACs for an `[h, w]` input.
    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        let (m0, hw) = self.l0.macs(hw);
        let (m1, hw) = self.l1.macs(hw);
        let m2 = self.l2.macs(hw);
        let (m3, hw) = self.l3.macs(hw);
        let m4 = self.l4.macs(hw);
        let (m5, hw) = self.l5.macs(hw);
        let m6 = self.l6.macs(hw);
        let (m7, hw) = self.l7.macs(hw);
        let m8 = self.l8.macs(hw) + self.sppf.macs(hw);
        let m10 = self.psa.as_ref().map_or(0, |p| p.macs(hw));
        m0 + m1 + m2 + m3 + m4 + m5 + m6 + m7 + m8 + m10
    }

    /// Folds every BatchNorm into its conv (inference only; see `ConvBn::fuse`).
    pub fn fuse(self) -> Self {
        Self {
            l0: self.l0.fuse(),
            l1: self.l1.fuse(),
            l2: self.l2.fuse(),
            l3: self.l3.fuse(),
            l4: self.l4.fuse(),
            l5: self.l5.fuse(),
            l6: self.l6.fuse(),
            l7: self.l7.fuse(),
            l8: self.l8.fuse(),
            sppf: self.sppf.fuse(),
            psa: self.psa.map(C2psa::fuse),
        }
    }
}
