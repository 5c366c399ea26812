//! Feature Pyramid Network (Lin et al. 2017; detectron2 `modeling/backbone/fpn.py`): 1×1
//! lateral convs on C2–C5, nearest ×2 top-down sums, 3×3 output convs, and P6 as a
//! stride-2 subsample of P5 (`LastLevelMaxPool`, a 1×1 max-pool with stride 2) for the RPN.
//! No normalisation, as in the reference.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::PaddingConfig2d;
use burn::tensor::{Device, Tensor};

use crate::model::layers::{conv_macs, upsample2x};

#[derive(Module, Debug)]
pub struct Fpn {
    pub lateral: Vec<Conv2d>,
    pub output: Vec<Conv2d>,
    pub channels: usize,
}

impl Fpn {
    /// `in_channels`: C2…C5 channels (the backbone's `out_channels`).
    pub fn new(in_channels: &[usize], channels: usize, device: &Device) -> Self {
        assert!(
            in_channels.len() == 4 && channels > 0,
            "Fpn: needs 4 input levels and > 0 channels, got {in_channels:?} → {channels}"
        );
        let lateral = in_channels
            .iter()
            .map(|&c| Conv2dConfig::new([c, channels], [1, 1]).init(device))
            .collect();
        let output = in_channels
            .iter()
            .map(|_| {
                Conv2dConfig::new([channels, channels], [3, 3])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .init(device)
            })
            .collect();
        Self {
            lateral,
            output,
            channels,
        }
    }

    /// # Shapes
    /// - `c`: C2…C5, `[B, c_i, H/2^i, W/2^i]` → P2…P6 `[B, channels, H/2^i, W/2^i]`, i = 2..=6
    pub fn forward(&self, c: Vec<Tensor<4>>) -> Vec<Tensor<4>> {
        let n = c.len();
        let mut outs = vec![None; n];
        let mut prev = self.lateral[n - 1].forward(c[n - 1].clone());
        outs[n - 1] = Some(self.output[n - 1].forward(prev.clone()));
        for i in (0..n - 1).rev() {
            prev = self.lateral[i].forward(c[i].clone()) + upsample2x(prev);
            outs[i] = Some(self.output[i].forward(prev.clone()));
        }
        let mut outs: Vec<Tensor<4>> = outs.into_iter().map(|o| o.unwrap()).collect();
        let p5 = outs[n - 1].clone();
        let [_, _, h, w] = p5.dims();
        // 1×1 max-pool with stride 2 = every other pixel (ceil for odd sizes, like PyTorch).
        let p6 = subsample2(p5, [h, w]);
        outs.push(p6);
        outs
    }

    pub fn macs(&self, in_sizes: &[[usize; 2]]) -> u64 {
        let mut t = 0;
        for (i, &hw) in in_sizes.iter().enumerate() {
            t += conv_macs(&self.lateral[i], hw).0 + conv_macs(&self.output[i], hw).0;
        }
        t
    }
}

/// Every other row and column: `[B, C, H, W]` → `[B, C, ⌈H/2⌉, ⌈W/2⌉]`.
fn subsample2(x: Tensor<4>, [h, w]: [usize; 2]) -> Tensor<4> {
    let [b, c, _, _] = x.dims();
    let (oh, ow) = (h.div_ceil(2), w.div_ceil(2));
    if h % 2 == 0 && w % 2 == 0 {
        // Pairs of rows/columns, keep the first of each.
        return x
            .reshape([b, c, oh, 2, ow, 2])
            .narrow(3, 0, 1)
            .narrow(5, 0, 1)
            .reshape([b, c, oh, ow]);
    }
    let rows: Vec<Tensor<4>> = (0..oh).map(|i| x.clone().narrow(2, 2 * i, 1)).collect();
    let x = Tensor::cat(rows, 2);
    let cols: Vec<Tensor<4>> = (0..ow).map(|j| x.clone().narrow(3, 2 * j, 1)).collect();
    Tensor::cat(cols, 3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_shapes() {
        let d = Device::flex();
        let fpn = Fpn::new(&[8, 16, 32, 64], 24, &d);
        let c = vec![
            Tensor::zeros([2, 8, 16, 24], &d),
            Tensor::zeros([2, 16, 8, 12], &d),
            Tensor::zeros([2, 32, 4, 6], &d),
            Tensor::zeros([2, 64, 2, 3], &d),
        ];
        let p: Vec<[usize; 4]> = fpn.forward(c).iter().map(|t| t.dims()).collect();
        assert_eq!(
            p,
            vec![
                [2, 24, 16, 24],
                [2, 24, 8, 12],
                [2, 24, 4, 6],
                [2, 24, 2, 3],
                [2, 24, 1, 2]
            ]
        );
    }

    #[test]
    fn subsample_picks_even_pixels() {
        let d = Device::flex();
        let x: Tensor<4> = Tensor::arange(0..16, &d).float().reshape([1, 1, 4, 4]);
        let v = subsample2(x, [4, 4])
            .into_data_as::<f32>()
            .try_into_vec::<f32>()
            .unwrap();
        assert_eq!(v, vec![0.0, 2.0, 8.0, 10.0]);
        let x: Tensor<4> = Tensor::arange(0..6, &d).float().reshape([1, 1, 2, 3]);
        let v = subsample2(x, [2, 3])
            .into_data_as::<f32>()
            .try_into_vec::<f32>()
            .unwrap();
        assert_eq!(v, vec![0.0, 2.0]);
    }
}
