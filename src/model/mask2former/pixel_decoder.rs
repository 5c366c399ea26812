//! Pixel decoder: backbone features C2–C5 → the stride-4 per-pixel embedding the masks are
//! dot products with, and the stride 32/16/8 features the transformer decoder attends to.
//!
//! This is MaskFormer's FPN-style `BasePixelDecoder` (Cheng et al. 2021), not the paper's
//! 6-layer multi-scale deformable-attention encoder (MSDeformAttn): a 1×1 lateral conv +
//! GroupNorm per level, nearest ×2 top-down sums, a 3×3 conv + GroupNorm + ReLU after each,
//! and a 3×3 conv to `mask_dim` on the stride-4 level. The paper's pixel-decoder ablation
//! ranks MSDeformAttn above FPN on COCO; the FPN needs no custom kernel (deformable
//! sampling has no Burn op on either CPU backend) and trains at CPU speed, which is why
//! this model uses it. Its 3 coarse outputs play the role of MSDeformAttn's.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{GroupNorm, GroupNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use crate::model::layers::{conv_macs, upsample2x};

/// GroupNorm groups for `c` channels: 32 as detectron2, or the largest power of two that
/// divides `c`.
pub fn groups(c: usize) -> usize {
    [32, 16, 8, 4, 2, 1]
        .into_iter()
        .find(|g| c % g == 0)
        .unwrap_or(1)
}

/// Conv (no bias) + GroupNorm, ReLU if `act`.
#[derive(Module, Debug)]
pub struct ConvGn {
    pub conv: Conv2d,
    pub norm: GroupNorm,
    pub act: bool,
}

impl ConvGn {
    fn new(ci: usize, co: usize, k: usize, act: bool, d: &Device) -> Self {
        let p = k / 2;
        Self {
            conv: Conv2dConfig::new([ci, co], [k, k])
                .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                .with_bias(false)
                .init(d),
            norm: GroupNormConfig::new(groups(co), co).init(d),
            act,
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.norm.forward(self.conv.forward(x));
        if self.act {
            relu(y)
        } else {
            y
        }
    }
}

#[derive(Module, Debug)]
pub struct PixelDecoder {
    /// Laterals of C2…C4 (C5 enters its output conv directly, as in MaskFormer).
    pub lateral: Vec<ConvGn>,
    /// Output convs of C2…C5.
    pub output: Vec<ConvGn>,
    pub mask_features: Conv2d,
    pub channels: usize,
    pub mask_dim: usize,
}

impl PixelDecoder {
    /// `in_channels`: C2…C5 of the backbone.
    pub fn new(in_channels: &[usize], channels: usize, mask_dim: usize, d: &Device) -> Self {
        assert!(
            in_channels.len() == 4 && channels > 0 && mask_dim > 0,
            "PixelDecoder: needs 4 input levels and > 0 channels, got {in_channels:?} → {channels}, {mask_dim}"
        );
        let lateral = in_channels[..3]
            .iter()
            .map(|&c| ConvGn::new(c, channels, 1, false, d))
            .collect();
        let output = (0..4)
            .map(|i| {
                let ci = if i == 3 { in_channels[3] } else { channels };
                ConvGn::new(ci, channels, 3, true, d)
            })
            .collect();
        Self {
            lateral,
            output,
            mask_features: Conv2dConfig::new([channels, mask_dim], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(d),
            channels,
            mask_dim,
        }
    }

    /// # Shapes
    /// - `c`: C2…C5 `[B, c_i, H/2^i, W/2^i]`, i = 2..=5
    /// - → (`[B, mask_dim, H/4, W/4]`, `[P5, P4, P3]` each `[B, channels, H/s, W/s]`, s =
    ///   32, 16, 8: the order the transformer decoder visits them)
    pub fn forward(&self, c: Vec<Tensor<4>>) -> (Tensor<4>, Vec<Tensor<4>>) {
        let mut y = self.output[3].forward(c[3].clone());
        let mut multi = vec![y.clone()];
        for i in (0..3).rev() {
            let cur = self.lateral[i].forward(c[i].clone()) + upsample2x(y);
            y = self.output[i].forward(cur);
            if multi.len() < 3 {
                multi.push(y.clone());
            }
        }
        (self.mask_features.forward(y), multi)
    }

    /// MACs at C2…C5 sizes.
    pub fn macs(&self, sizes: &[[usize; 2]]) -> u64 {
        let mut t = conv_macs(&self.mask_features, sizes[0]).0;
        for (i, &hw) in sizes.iter().enumerate() {
            t += conv_macs(&self.output[i].conv, hw).0;
            if i < 3 {
                t += conv_macs(&self.lateral[i].conv, hw).0;
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_and_group_counts() {
        let d = Device::flex();
        assert_eq!((groups(256), groups(48), groups(6)), (32, 16, 2));
        let p = PixelDecoder::new(&[8, 16, 32, 64], 16, 12, &d);
        let c = vec![
            Tensor::zeros([2, 8, 16, 24], &d),
            Tensor::zeros([2, 16, 8, 12], &d),
            Tensor::zeros([2, 32, 4, 6], &d),
            Tensor::zeros([2, 64, 2, 3], &d),
        ];
        let (m, multi) = p.forward(c);
        assert_eq!(m.dims(), [2, 12, 16, 24]);
        let dims: Vec<[usize; 4]> = multi.iter().map(|t| t.dims()).collect();
        assert_eq!(dims, vec![[2, 16, 2, 3], [2, 16, 4, 6], [2, 16, 8, 12]]);
    }
}
