//! ResNet backbone (He et al. 2016; torchvision `resnet.py`, "v1.5": the stride sits on the
//! 3×3 conv of a bottleneck) with selectable depth and a width multiplier.
//!
//! Depths 18/34 use basic blocks (two 3×3 convs), 50/101 bottlenecks (1×1, 3×3, 1×1 with
//! 4× expansion). BatchNorm uses PyTorch's defaults (eps 1e-5, momentum 0.1) and is trained
//! unless `train.freeze` freezes its stage (`model::freeze`). Module paths follow
//! torchvision's layout (`stem` = `conv1`/`bn1`, `stages.i.blocks.j.convs.k` =
//! `layer{i+1}.{j}.conv{k+1}`), so ImageNet weights map one to one (`super::torchvision`).
//! Outputs C2–C5 (strides 4–32) for the FPN; no classifier.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use crate::model::layers::conv_macs;

/// Blocks per stage for a supported depth, and whether they are bottlenecks.
pub fn depth_layout(depth: usize) -> ([usize; 4], bool) {
    match depth {
        18 => ([2, 2, 2, 2], false),
        34 => ([3, 4, 6, 3], false),
        50 => ([3, 4, 6, 3], true),
        101 => ([3, 4, 23, 3], true),
        152 => ([3, 8, 36, 3], true),
        d => panic!("ResNet: depth must be one of 18, 34, 50, 101, 152, got {d}"),
    }
}

/// `c · width_mult` rounded to a multiple of 8 (at least 8).
pub fn scaled(c: usize, width_mult: f64) -> usize {
    (((c as f64 * width_mult) / 8.0).round() as usize).max(1) * 8
}

/// Conv (no bias) + BatchNorm, ReLU if `act`.
#[derive(Module, Debug)]
pub struct ConvBnRelu {
    pub conv: Conv2d,
    pub bn: BatchNorm,
    pub act: bool,
}

impl ConvBnRelu {
    pub fn new(c_in: usize, c_out: usize, k: usize, s: usize, act: bool, device: &Device) -> Self {
        let p = k / 2;
        Self {
            conv: Conv2dConfig::new([c_in, c_out], [k, k])
                .with_stride([s, s])
                .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                .with_bias(false)
                .init(device),
            bn: BatchNormConfig::new(c_out).init(device),
            act,
        }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H/s, W/s]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.bn.forward(self.conv.forward(x));
        if self.act {
            relu(y)
        } else {
            y
        }
    }
}

/// Residual block: `convs` (2 for basic, 3 for bottleneck; the last without ReLU), identity
/// or 1×1 projection shortcut, ReLU after the sum.
#[derive(Module, Debug)]
pub struct ResBlock {
    pub convs: Vec<ConvBnRelu>,
    pub down: Option<ConvBnRelu>,
}

impl ResBlock {
    fn new(
        c_in: usize,
        mid: usize,
        c_out: usize,
        stride: usize,
        bottleneck: bool,
        d: &Device,
    ) -> Self {
        let convs = if bottleneck {
            vec![
                ConvBnRelu::new(c_in, mid, 1, 1, true, d),
                ConvBnRelu::new(mid, mid, 3, stride, true, d),
                ConvBnRelu::new(mid, c_out, 1, 1, false, d),
            ]
        } else {
            vec![
                ConvBnRelu::new(c_in, c_out, 3, stride, true, d),
                ConvBnRelu::new(c_out, c_out, 3, 1, false, d),
            ]
        };
        let down = (stride != 1 || c_in != c_out)
            .then(|| ConvBnRelu::new(c_in, c_out, 1, stride, false, d));
        Self { convs, down }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H/stride, W/stride]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let id = match &self.down {
            Some(d) => d.forward(x.clone()),
            None => x.clone(),
        };
        let y = self.convs.iter().fold(x, |y, c| c.forward(y));
        relu(y + id)
    }

    fn macs(&self, hw: [usize; 2]) -> (u64, [usize; 2]) {
        let mut total = 0;
        let mut cur = hw;
        for c in &self.convs {
            let (m, o) = conv_macs(&c.conv, cur);
            total += m;
            cur = o;
        }
        if let Some(d) = &self.down {
            total += conv_macs(&d.conv, hw).0;
        }
        (total, cur)
    }
}

#[derive(Module, Debug)]
pub struct ResStage {
    pub blocks: Vec<ResBlock>,
}

/// ResNet trunk: stem (7×7/2 conv, 3×3/2 max-pool) and four stages.
#[derive(Module, Debug)]
pub struct ResNet {
    pub stem: ConvBnRelu,
    pub pool: MaxPool2d,
    pub stages: Vec<ResStage>,
    /// Output channels of C2…C5.
    pub out_channels: Vec<usize>,
}

impl ResNet {
    /// Panics naming the value on an unsupported depth or a non-positive width.
    pub fn new(depth: usize, width_mult: f64, device: &Device) -> Self {
        assert!(
            width_mult.is_finite() && width_mult > 0.0,
            "ResNet: width_mult must be finite and > 0, got {width_mult}"
        );
        let (blocks, bottleneck) = depth_layout(depth);
        let expansion = if bottleneck { 4 } else { 1 };
        let stem_c = scaled(64, width_mult);
        let mut c_in = stem_c;
        let mut stages = Vec::new();
        let mut out_channels = Vec::new();
        for (i, &n) in blocks.iter().enumerate() {
            let mid = scaled(64 << i, width_mult);
            let c_out = mid * expansion;
            let stride = if i == 0 { 1 } else { 2 };
            let blocks = (0..n)
                .map(|j| {
                    let b = ResBlock::new(
                        c_in,
                        mid,
                        c_out,
                        if j == 0 { stride } else { 1 },
                        bottleneck,
                        device,
                    );
                    c_in = c_out;
                    b
                })
                .collect();
            stages.push(ResStage { blocks });
            out_channels.push(c_out);
        }
        Self {
            stem: ConvBnRelu::new(3, stem_c, 7, 2, true, device),
            pool: MaxPool2dConfig::new([3, 3])
                .with_strides([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(),
            stages,
            out_channels,
        }
    }

    /// # Shapes
    /// - `x`: `[B, 3, H, W]` (H, W multiples of 32) → C2…C5 `[B, c_i, H/2^(i), W/2^(i)]`,
    ///   `i = 2..=5`
    pub fn forward(&self, x: Tensor<4>) -> Vec<Tensor<4>> {
        let mut x = self.pool.forward(self.stem.forward(x));
        let mut outs = Vec::with_capacity(4);
        for s in &self.stages {
            x = s.blocks.iter().fold(x, |y, b| b.forward(y));
            outs.push(x.clone());
        }
        outs
    }

    /// Multiply-accumulates at an `[h, w]` input (max-pool excluded).
    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        let (mut total, cur) = conv_macs(&self.stem.conv, hw);
        let mut cur = [cur[0].div_ceil(2), cur[1].div_ceil(2)];
        for s in &self.stages {
            for b in &s.blocks {
                let (m, o) = b.macs(cur);
                total += m;
                cur = o;
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::layers::trainable_params;

    #[test]
    fn params_match_torchvision() {
        // torchvision resnet18 / resnet50 without the fc layer (512·1000+1000, 2048·1000+1000):
        // 11,689,512 − 513,000 and 25,557,032 − 2,049,000.
        let d = Device::flex();
        assert_eq!(
            trainable_params(&ResNet::new(18, 1.0, &d)),
            11_689_512 - 513_000
        );
        assert_eq!(
            trainable_params(&ResNet::new(50, 1.0, &d)),
            25_557_032 - 2_049_000
        );
    }

    #[test]
    fn output_shapes() {
        let d = Device::flex();
        let net = ResNet::new(18, 0.25, &d);
        let outs = net.forward(Tensor::zeros([1, 3, 64, 96], &d));
        let dims: Vec<[usize; 4]> = outs.iter().map(|t| t.dims()).collect();
        assert_eq!(
            dims,
            vec![
                [1, 16, 16, 24],
                [1, 32, 8, 12],
                [1, 64, 4, 6],
                [1, 128, 2, 3]
            ]
        );
        assert_eq!(net.out_channels, vec![16, 32, 64, 128]);
    }

    #[test]
    #[should_panic(expected = "depth must be one of 18, 34, 50, 101, 152, got 42")]
    fn rejects_depth() {
        ResNet::new(42, 1.0, &Device::flex());
    }
}
