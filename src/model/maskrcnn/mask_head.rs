//! Mask branch (detectron2 `roi_heads/mask_head.py`, `MaskRCNNConvUpsampleHead`): `num_conv`
//! 3×3 convs + ReLU on 14×14 RoI features, a 2×2 stride-2 deconv + ReLU, and a 1×1
//! predictor giving 28×28 logits per class (or one class-agnostic map). The head returns
//! logits only; [`mask_loss`] (per-pixel BCE against GT masks RoIAligned onto the proposal,
//! binarised at 0.5, on the GT class's map) and [`mask_targets`] are free functions beside
//! it; pasting the probabilities into the image is
//! [`crate::model::instance_mask::paste_roi_mask`], at whatever size the caller decodes.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::losses::{bce_with_logits, one_hot};
use super::roi_align::roi_align_mask;
use crate::model::layers::conv_macs;
use crate::util::tensor::host;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaskHeadConfig {
    pub num_conv: usize,
    pub conv_dim: usize,
    /// RoIAlign output side (14); masks are twice that (28).
    pub pool_size: usize,
    pub sampling_ratio: usize,
    pub class_agnostic: bool,
    /// Inference threshold on pasted mask probabilities.
    pub threshold: f32,
}

impl MaskHeadConfig {
    /// detectron2: 4 × 256-wide convs, 14 → 28, class-specific.
    pub fn paper() -> Self {
        Self {
            num_conv: 4,
            conv_dim: 256,
            pool_size: 14,
            sampling_ratio: 2,
            class_agnostic: false,
            threshold: 0.5,
        }
    }

    /// Scene-sized: 128-wide convs.
    pub fn compact() -> Self {
        Self {
            conv_dim: 128,
            ..Self::paper()
        }
    }

    pub fn validate(&self) {
        assert!(
            self.conv_dim > 0 && self.pool_size > 0 && self.sampling_ratio > 0,
            "MaskHeadConfig: conv_dim, pool_size and sampling_ratio must be > 0, got {self:?}"
        );
        assert!(
            self.threshold > 0.0 && self.threshold < 1.0,
            "MaskHeadConfig: threshold must be in (0, 1), got {}",
            self.threshold
        );
    }

    pub fn mask_size(&self) -> usize {
        2 * self.pool_size
    }
}

#[derive(Module, Debug)]
pub struct MaskHead {
    pub convs: Vec<Conv2d>,
    pub deconv: ConvTranspose2d,
    pub predictor: Conv2d,
}

impl MaskHead {
    /// `channels`: the FPN's output channels.
    pub fn new(channels: usize, cfg: &MaskHeadConfig, num_classes: usize, device: &Device) -> Self {
        // c2_msra_fill: Kaiming-normal (fan_out) with zero bias.
        let msra = Initializer::KaimingNormal {
            gain: 2f64.sqrt(),
            fan_out_only: true,
        };
        let mut convs = Vec::new();
        let mut c = channels;
        for _ in 0..cfg.num_conv {
            convs.push(
                Conv2dConfig::new([c, cfg.conv_dim], [3, 3])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .with_initializer(msra.clone())
                    .init(device),
            );
            c = cfg.conv_dim;
        }
        let k = if cfg.class_agnostic { 1 } else { num_classes };
        Self {
            convs,
            deconv: ConvTranspose2dConfig::new([c, cfg.conv_dim], [2, 2])
                .with_stride([2, 2])
                // The same MSRA fill written out: Burn's transposed conv cannot take a
                // fan-based initializer (fan_out of a `[c, c', 2, 2]` deconv is `4c`).
                .with_initializer(Initializer::Normal {
                    mean: 0.0,
                    std: (2.0 / (4 * c) as f64).sqrt(),
                })
                .init(device),
            predictor: Conv2dConfig::new([cfg.conv_dim, k], [1, 1])
                .with_initializer(Initializer::Normal {
                    mean: 0.0,
                    std: 0.001,
                })
                .init(device),
        }
    }

    /// # Shapes
    /// - `x`: `[N, C, P, P]` → logits `[N, K, 2P, 2P]` (`K = nc`, or 1 class-agnostic)
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = self.convs.iter().fold(x, |x, c| relu(c.forward(x)));
        self.predictor.forward(relu(self.deconv.forward(x)))
    }

    pub fn macs(&self, num_rois: usize, pool: usize) -> u64 {
        let mut t: u64 = self
            .convs
            .iter()
            .map(|c| conv_macs(c, [pool, pool]).0)
            .sum();
        let [ci, co, k, _] = self.deconv.weight.dims();
        t += (ci * co * k * k * pool * pool) as u64;
        t += conv_macs(&self.predictor, [2 * pool, 2 * pool]).0;
        t * num_rois as u64
    }
}

/// Binary mask targets (`0.0` / `1.0`, `size × size` each, concatenated): GT mask `m`
/// RoIAligned onto its proposal `roi` and thresholded at 0.5 (detectron2
/// `BitMasks.crop_and_resize`).
pub fn mask_targets(items: &[(&[u8], [f32; 4])], image: [usize; 2], size: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(items.len() * size * size);
    for (m, roi) in items {
        out.extend(roi_align_mask(m, image, *roi, size).into_iter().map(|v| {
            if v >= 0.5 {
                1.0
            } else {
                0.0
            }
        }));
    }
    out
}

/// Mean per-pixel BCE of the GT class's logits against `targets`.
///
/// # Shapes
/// - `logits`: `[N, K, M, M]`; `classes.len() == N` (ignored when `K == 1`);
///   `targets.len() == N·M·M` → `[1]`
pub fn mask_loss(logits: Tensor<4>, classes: &[usize], targets: Vec<f32>) -> Tensor<1> {
    let device = logits.device();
    let [n, k, m, _] = logits.dims();
    assert_eq!(
        targets.len(),
        n * m * m,
        "mask_loss: {} target pixels for {n} masks of {m}×{m}",
        targets.len()
    );
    if n == 0 {
        return Tensor::zeros([1], &device);
    }
    let x: Tensor<3> = if k == 1 {
        logits.reshape([n, m, m])
    } else {
        let oh: Tensor<4> = one_hot(classes, k, &device).reshape([n, k, 1, 1]);
        (logits * oh).sum_dim(1).reshape([n, m, m])
    };
    bce_with_logits(x, host(targets, [n, m, m], &device))
        .mean()
        .reshape([1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::instance_mask::paste_roi_mask;
    use crate::util::tensor::{host, to_host};

    #[test]
    fn targets_then_paste_round_trip() {
        // A disc, cropped to its box at 28×28 and pasted back, is recovered.
        let (h, w) = (48, 48);
        let mut mask = vec![0u8; h * w];
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 + 0.5 - 24.0, y as f32 + 0.5 - 20.0);
                if dx * dx / 225.0 + dy * dy / 100.0 <= 1.0 {
                    mask[y * w + x] = 1;
                }
            }
        }
        let bx = [9.0, 10.0, 39.0, 30.0];
        let t = mask_targets(&[(&mask, bx)], [h, w], 28);
        let back = paste_roi_mask(&t, 28, bx, (w as u32, h as u32), 0.5)
            .full()
            .data;
        let inter = mask
            .iter()
            .zip(&back)
            .filter(|(a, b)| **a == 1 && **b == 1)
            .count();
        let union = mask
            .iter()
            .zip(&back)
            .filter(|(a, b)| **a == 1 || **b == 1)
            .count();
        assert!(
            inter as f32 / union as f32 > 0.93,
            "IoU {}",
            inter as f32 / union as f32
        );
    }

    #[test]
    fn loss_selects_the_class_map() {
        let d = Device::flex();
        // Two classes; class 1's map is saturated right, class 0's wrong.
        let mut v = vec![-30.0f32; 4];
        v.extend([30.0f32; 4]);
        let logits = host(v, [1, 2, 2, 2], &d);
        let l1 = to_host(mask_loss(logits.clone(), &[1], vec![1.0; 4]))[0];
        let l0 = to_host(mask_loss(logits, &[0], vec![1.0; 4]))[0];
        assert!(l1 < 1e-6 && (l0 - 30.0).abs() < 1e-3, "{l1} {l0}");
    }
}
