//! YOLO11 building blocks: Conv-BN-SiLU, Bottleneck, C3k, C3k2, SPPF and the
//! mask-prototype head (Proto); the C2PSA attention block is in [`super::attention`].
//!
//! They follow ultralytics 8.3 `nn/modules/conv.py` and `block.py` layer for layer (same
//! channel splits, same BN eps 1e-3 / momentum 0.03), so parameter counts match the
//! reference and published YOLO11 numbers can be compared. No heads and no losses live here.
//!
//! Every block also reports its multiply-accumulate count for a given input size
//! (`macs`), computed from its own weight shapes, so the GFLOPs printed at start cannot drift
//! from the model that is actually built.

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor};

use crate::model::fused_conv::conv_silu;
use crate::model::layers::conv_macs;
#[cfg(test)]
use crate::model::layers::trainable_params;

/// BatchNorm epsilon used by ultralytics (`nn/modules/conv.py`, `Conv.bn`), not PyTorch's 1e-5.
pub const BN_EPS: f64 = 1e-3;
/// BatchNorm momentum used by ultralytics (`utils/torch_utils.py::initialize_weights`), not 0.1.
pub const BN_MOMENTUM: f64 = 0.03;

/// Convolution (no bias) + BatchNorm + optional SiLU: ultralytics' `Conv` (and `DWConv` when
/// `groups > 1`).
#[derive(Module, Debug)]
pub struct ConvBn {
    pub conv: Conv2d,
    pub bn: BatchNorm,
    /// SiLU after BN (`act=True`); false for the linear convs inside attention.
    pub act: bool,
    /// BN folded into the conv (inference only, see [`ConvBn::fuse`]): `bn` is skipped.
    pub fused: bool,
}

impl ConvBn {
    /// `k×k` conv with padding `k/2`, stride `s`, `groups` groups, BN and SiLU if `act`.
    ///
    /// Panics (in Burn's conv checks) when `c_in` or `c_out` is not divisible by `groups`.
    pub fn new(
        c_in: usize,
        c_out: usize,
        k: usize,
        s: usize,
        groups: usize,
        act: bool,
        device: &Device,
    ) -> Self {
        assert!(
            c_in > 0 && c_out > 0 && k > 0 && s > 0,
            "ConvBn needs positive sizes, got c_in {c_in}, c_out {c_out}, k {k}, s {s}"
        );
        let p = k / 2;
        let conv = Conv2dConfig::new([c_in, c_out], [k, k])
            .with_stride([s, s])
            .with_groups(groups)
            .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
            .with_bias(false)
            .init(device);
        let bn = BatchNormConfig::new(c_out)
            .with_epsilon(BN_EPS)
            .with_momentum(BN_MOMENTUM)
            .init(device);
        Self {
            conv,
            bn,
            act,
            fused: false,
        }
    }

    /// Folds the BatchNorm (running statistics) into the conv's weight and bias, so that
    /// inference skips one elementwise pass per conv. For eval-mode (`valid()`) models only:
    /// the result no longer normalises by batch statistics.
    pub fn fuse(mut self) -> Self {
        if self.fused {
            return self;
        }
        let co = self.out_channels();
        let bn = &self.bn;
        let scale = bn.gamma.val() / bn.running_var.value().add_scalar(bn.epsilon).sqrt();
        let bias = bn.beta.val() - bn.running_mean.value() * scale.clone();
        let weight = self.conv.weight.val() * scale.reshape([co, 1, 1, 1]);
        self.conv.weight = Param::from_tensor(weight);
        self.conv.bias = Some(Param::from_tensor(bias));
        self.fused = true;
        self
    }

    /// Plain `Conv(c_in, c_out, k, s)` with SiLU.
    pub fn silu(c_in: usize, c_out: usize, k: usize, s: usize, device: &Device) -> Self {
        Self::new(c_in, c_out, k, s, 1, true, device)
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H', W']`, `H' = (H + 2(k/2) − k)/s + 1`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        // Folded and activated: one flex convolution with a SiLU epilogue (inference only).
        let x = if self.fused && self.act {
            match conv_silu(&self.conv, x) {
                Ok(y) => return y,
                Err(x) => x,
            }
        } else {
            x
        };
        let y = self.conv.forward(x);
        let y = if self.fused { y } else { self.bn.forward(y) };
        if self.act {
            silu(y)
        } else {
            y
        }
    }

    pub fn out_channels(&self) -> usize {
        self.conv.weight.dims()[0]
    }

    /// MACs and output size for an `[h, w]` input.
    pub fn macs(&self, hw: [usize; 2]) -> (u64, [usize; 2]) {
        conv_macs(&self.conv, hw)
    }
}

/// Residual block of two convs: ultralytics' `Bottleneck(c1, c2, shortcut, g, k, e)`.
#[derive(Module, Debug)]
pub struct Bottleneck {
    pub cv1: ConvBn,
    pub cv2: ConvBn,
    pub add: bool,
}

impl Bottleneck {
    /// Hidden width `int(c_out · e)`; residual when `shortcut` and `c_in == c_out`.
    pub fn new(
        c_in: usize,
        c_out: usize,
        shortcut: bool,
        k: [usize; 2],
        e: f64,
        device: &Device,
    ) -> Self {
        let hidden = ((c_out as f64) * e) as usize;
        Self {
            cv1: ConvBn::silu(c_in, hidden, k[0], 1, device),
            cv2: ConvBn::silu(hidden, c_out, k[1], 1, device),
            add: shortcut && c_in == c_out,
        }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H, W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.cv2.forward(self.cv1.forward(x.clone()));
        if self.add {
            x + y
        } else {
            y
        }
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        self.cv1.macs(hw).0 + self.cv2.macs(hw).0
    }

    pub fn fuse(self) -> Self {
        Self {
            cv1: self.cv1.fuse(),
            cv2: self.cv2.fuse(),
            ..self
        }
    }
}

/// CSP block with two parallel 1×1 paths and `n` 3×3 bottlenecks: ultralytics' `C3k`
/// (= `C3` with `k×k` bottlenecks, e 0.5 outside and 1.0 inside).
#[derive(Module, Debug)]
pub struct C3k {
    pub cv1: ConvBn,
    pub cv2: ConvBn,
    pub cv3: ConvBn,
    pub m: Vec<Bottleneck>,
}

impl C3k {
    pub fn new(c_in: usize, c_out: usize, n: usize, shortcut: bool, device: &Device) -> Self {
        let hidden = c_out / 2;
        Self {
            cv1: ConvBn::silu(c_in, hidden, 1, 1, device),
            cv2: ConvBn::silu(c_in, hidden, 1, 1, device),
            cv3: ConvBn::silu(2 * hidden, c_out, 1, 1, device),
            m: (0..n)
                .map(|_| Bottleneck::new(hidden, hidden, shortcut, [3, 3], 1.0, device))
                .collect(),
        }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H, W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut a = self.cv1.forward(x.clone());
        for b in &self.m {
            a = b.forward(a);
        }
        let b = self.cv2.forward(x);
        self.cv3.forward(Tensor::cat(vec![a, b], 1))
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        self.cv1.macs(hw).0
            + self.cv2.macs(hw).0
            + self.cv3.macs(hw).0
            + self.m.iter().map(|b| b.macs(hw)).sum::<u64>()
    }

    pub fn fuse(self) -> Self {
        Self {
            cv1: self.cv1.fuse(),
            cv2: self.cv2.fuse(),
            cv3: self.cv3.fuse(),
            m: self.m.into_iter().map(Bottleneck::fuse).collect(),
        }
    }
}

/// The inner block of a [`C3k2`]: a Bottleneck (`c3k = false`) or a two-bottleneck C3k.
#[derive(Module, Debug)]
#[allow(clippy::large_enum_variant)] // a handful per model; boxing buys nothing
pub enum C3k2Inner {
    Bottleneck(Bottleneck),
    C3k(C3k),
}

impl C3k2Inner {
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        match self {
            C3k2Inner::Bottleneck(b) => b.forward(x),
            C3k2Inner::C3k(c) => c.forward(x),
        }
    }

    fn macs(&self, hw: [usize; 2]) -> u64 {
        match self {
            C3k2Inner::Bottleneck(b) => b.macs(hw),
            C3k2Inner::C3k(c) => c.macs(hw),
        }
    }

    fn fuse(self) -> Self {
        match self {
            C3k2Inner::Bottleneck(b) => C3k2Inner::Bottleneck(b.fuse()),
            C3k2Inner::C3k(c) => C3k2Inner::C3k(c.fuse()),
        }
    }
}

/// YOLO11's C3k2: a C2f-style split (1×1 to 2c, keep both halves, chain `n` inner blocks on
/// the second half, concatenate all, 1×1 to `c_out`) with Bottleneck or C3k inner blocks.
#[derive(Module, Debug)]
pub struct C3k2 {
    pub cv1: ConvBn,
    pub cv2: ConvBn,
    pub m: Vec<C3k2Inner>,
    /// Width of each split half, `int(c_out · e)`.
    pub c: usize,
}

impl C3k2 {
    /// ultralytics `C3k2(c1, c2, n, c3k, e, g=1, shortcut=True)`.
    pub fn new(c_in: usize, c_out: usize, n: usize, c3k: bool, e: f64, device: &Device) -> Self {
        let c = ((c_out as f64) * e) as usize;
        assert!(
            c > 0 && n > 0,
            "C3k2({c_in} → {c_out}, n {n}, e {e}) has an empty hidden width {c} or no blocks"
        );
        let m = (0..n)
            .map(|_| {
                if c3k {
                    C3k2Inner::C3k(C3k::new(c, c, 2, true, device))
                } else {
                    C3k2Inner::Bottleneck(Bottleneck::new(c, c, true, [3, 3], 0.5, device))
                }
            })
            .collect();
        Self {
            cv1: ConvBn::silu(c_in, 2 * c, 1, 1, device),
            cv2: ConvBn::silu((2 + n) * c, c_out, 1, 1, device),
            m,
            c,
        }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H, W]`
    ///
    /// ultralytics splits `y` with `chunk(2, 1)` and concatenates both halves first; they
    /// are adjacent there, so `y` enters the concatenation whole and only the second half
    /// is sliced out for the inner blocks. Same values, one slice instead of two: Burn's
    /// gradient of a slice is a zero tensor of the input's shape with the slice's gradient
    /// written in, so each slice costs a fill of `y`'s size and a copy in the backward.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.cv1.forward(x);
        let mut last = y.clone().narrow(1, self.c, self.c);
        let mut parts = vec![y];
        for block in &self.m {
            last = block.forward(last);
            parts.push(last.clone());
        }
        self.cv2.forward(Tensor::cat(parts, 1))
    }

    pub fn out_channels(&self) -> usize {
        self.cv2.out_channels()
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        self.cv1.macs(hw).0 + self.cv2.macs(hw).0 + self.m.iter().map(|b| b.macs(hw)).sum::<u64>()
    }

    pub fn fuse(self) -> Self {
        Self {
            cv1: self.cv1.fuse(),
            cv2: self.cv2.fuse(),
            m: self.m.into_iter().map(C3k2Inner::fuse).collect(),
            c: self.c,
        }
    }
}

/// Spatial pyramid pooling, fast: 1×1 to c_in/2, three chained 5×5 stride-1 max pools,
/// concatenate the four maps, 1×1 to `c_out`.
#[derive(Module, Debug)]
pub struct Sppf {
    pub cv1: ConvBn,
    pub cv2: ConvBn,
    pub pool: MaxPool2d,
}

impl Sppf {
    pub fn new(c_in: usize, c_out: usize, k: usize, device: &Device) -> Self {
        let hidden = c_in / 2;
        let p = k / 2;
        Self {
            cv1: ConvBn::silu(c_in, hidden, 1, 1, device),
            cv2: ConvBn::silu(4 * hidden, c_out, 1, 1, device),
            pool: MaxPool2dConfig::new([k, k])
                .with_strides([1, 1])
                .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                .init(),
        }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, c_out, H, W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let a = self.cv1.forward(x);
        let [.., h, w] = a.dims();
        if h == 1 && w == 1 {
            // A padded max pool of a 1×1 map is the identity. Spelled out because
            // burn-ndarray 0.22's SIMD max pool indexes out of bounds on 1×1 maps with
            // ≥ 32 channels (a 32 px input on `--device ndarray` panicked).
            return self
                .cv2
                .forward(Tensor::cat(vec![a.clone(), a.clone(), a.clone(), a], 1));
        }
        let b = self.pool.forward(a.clone());
        let c = self.pool.forward(b.clone());
        let d = self.pool.forward(c.clone());
        self.cv2.forward(Tensor::cat(vec![a, b, c, d], 1))
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        self.cv1.macs(hw).0 + self.cv2.macs(hw).0
    }

    pub fn fuse(self) -> Self {
        Self {
            cv1: self.cv1.fuse(),
            cv2: self.cv2.fuse(),
            pool: self.pool,
        }
    }
}

/// Mask prototypes: 3×3 conv, 2× transposed conv, 3×3 conv, 1×1 conv to `n_masks` maps at
/// twice the input resolution (1/4 of the image when fed P3): ultralytics' `Proto`.
#[derive(Module, Debug)]
pub struct Proto {
    pub cv1: ConvBn,
    pub upsample: ConvTranspose2d,
    pub cv2: ConvBn,
    pub cv3: ConvBn,
}

impl Proto {
    pub fn new(c_in: usize, hidden: usize, n_masks: usize, device: &Device) -> Self {
        Self {
            cv1: ConvBn::silu(c_in, hidden, 3, 1, device),
            upsample: ConvTranspose2dConfig::new([hidden, hidden], [2, 2])
                .with_stride([2, 2])
                .with_bias(true)
                .init(device),
            cv2: ConvBn::silu(hidden, hidden, 3, 1, device),
            cv3: ConvBn::silu(hidden, n_masks, 1, 1, device),
        }
    }

    /// # Shapes
    /// - `x`: `[B, c_in, H, W]` → `[B, n_masks, 2H, 2W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = self.cv1.forward(x);
        let x = self.upsample.forward(x);
        self.cv3.forward(self.cv2.forward(x))
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        let [ci, co, kh, kw] = self.upsample.weight.dims();
        let up = (ci * co * kh * kw * hw[0] * hw[1]) as u64;
        let hw2 = [hw[0] * 2, hw[1] * 2];
        self.cv1.macs(hw).0 + up + self.cv2.macs(hw2).0 + self.cv3.macs(hw2).0
    }

    pub fn fuse(self) -> Self {
        Self {
            cv1: self.cv1.fuse(),
            upsample: self.upsample,
            cv2: self.cv2.fuse(),
            cv3: self.cv3.fuse(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dev() -> Device {
        Device::flex()
    }

    #[test]
    fn blocks_keep_shapes() {
        let d = dev();
        let x = Tensor::<4>::random(
            [2, 16, 8, 8],
            burn::tensor::Distribution::Normal(0.0, 1.0),
            &d,
        );
        assert_eq!(
            ConvBn::silu(16, 32, 3, 2, &d).forward(x.clone()).dims(),
            [2, 32, 4, 4]
        );
        assert_eq!(
            C3k2::new(16, 24, 1, false, 0.25, &d)
                .forward(x.clone())
                .dims(),
            [2, 24, 8, 8]
        );
        assert_eq!(
            C3k2::new(16, 32, 1, true, 0.5, &d)
                .forward(x.clone())
                .dims(),
            [2, 32, 8, 8]
        );
        assert_eq!(
            Sppf::new(16, 16, 5, &d).forward(x.clone()).dims(),
            [2, 16, 8, 8]
        );
        assert_eq!(Proto::new(16, 8, 4, &d).forward(x).dims(), [2, 4, 16, 16]);
    }

    /// C3k2 as ultralytics writes it (`y.chunk(2, 1)`, both halves into the concatenation):
    /// the reference for the single-slice [`C3k2::forward`].
    fn c3k2_chunked(m: &C3k2, x: Tensor<4>) -> Tensor<4> {
        let mut parts = m.cv1.forward(x).chunk(2, 1);
        let mut last = parts[1].clone();
        for block in &m.m {
            last = block.forward(last);
            parts.push(last.clone());
        }
        m.cv2.forward(Tensor::cat(parts, 1))
    }

    /// The single-slice split gives the chunked reference's output and gradients (input,
    /// `cv1`'s and the first inner block's weights), for Bottleneck and C3k inner blocks
    /// and one and two of them: a wrong half, order or width changes all three.
    #[test]
    fn c3k2_split_matches_the_chunked_reference() {
        use burn::tensor::Distribution;
        let ad = Device::flex().autodiff();
        ad.seed(37);
        for (c_in, c_out, n, c3k, e) in [(8, 12, 1, false, 0.25), (6, 16, 2, true, 0.5)] {
            let m = C3k2::new(c_in, c_out, n, c3k, e, &ad);
            let x = Tensor::<4>::random([2, c_in, 6, 10], Distribution::Normal(0.0, 1.0), &ad);
            let r = Tensor::<4>::random([2, c_out, 6, 10], Distribution::Normal(0.0, 1.0), &ad);
            let run = |f: &dyn Fn(Tensor<4>) -> Tensor<4>| {
                let xg = x.clone().detach().require_grad();
                let out = f(xg.clone());
                let g = (out.clone() * r.clone()).sum().backward();
                let first = match &m.m[0] {
                    C3k2Inner::Bottleneck(b) => b.cv1.conv.weight.val(),
                    C3k2Inner::C3k(k) => k.cv1.conv.weight.val(),
                };
                [
                    out,
                    xg.grad(&g).unwrap(),
                    m.cv1.conv.weight.val().grad(&g).unwrap(),
                    first.grad(&g).unwrap(),
                ]
                .map(crate::util::tensor::to_host)
            };
            let new = run(&|x| m.forward(x));
            let old = run(&|x| c3k2_chunked(&m, x));
            for (what, (a, b)) in ["output", "x grad", "cv1 grad", "inner grad"]
                .iter()
                .zip(new.iter().zip(&old))
            {
                let scale = b.iter().fold(0f32, |s, v| s.max(v.abs()));
                assert!(scale > 0.0, "{what}: all zero");
                let err = a.iter().zip(b).fold(0f32, |s, (u, v)| s.max((u - v).abs()));
                assert!(
                    err <= 1e-6 * scale,
                    "{what}: max error {err}, scale {scale}"
                );
            }
        }
    }

    /// Training step (forward + backward) of YOLO11n-seg's eight C3k2 blocks at batch 8 /
    /// 224 px, the chunked reference and the single-slice split interleaved (old, new, …),
    /// median of 15 each. `RAYON_NUM_THREADS=1 cargo test --release --lib c3k2_split_bench
    /// -- --ignored --nocapture`; output in `bench/results/convs/c3k2_split_bench.md`.
    #[test]
    #[ignore = "timing, run by hand"]
    fn c3k2_split_bench() {
        use burn::tensor::Distribution;
        use std::time::Instant;
        let ad = Device::flex().autodiff();
        // (name, c_in, c_out, c3k, e, side at 224 px): backbone l2 l4 l6 l8, neck
        // td_p4 td_p3 bu_p4 bu_p5 (`Backbone::new`, `Neck::new` at scale n).
        let blocks = [
            ("l2", 32, 64, false, 0.25, 56),
            ("l4", 64, 128, false, 0.25, 28),
            ("l6", 128, 128, true, 0.5, 14),
            ("l8", 256, 256, true, 0.5, 7),
            ("td_p4", 384, 128, false, 0.5, 14),
            ("td_p3", 256, 64, false, 0.5, 28),
            ("bu_p4", 192, 128, false, 0.5, 14),
            ("bu_p5", 384, 256, true, 0.5, 7),
        ];
        println!("| block | in | chunked ms | single slice ms | chunked ÷ single |");
        println!("|---|---|---|---|---|");
        let (mut total_old, mut total_new) = (0.0, 0.0);
        for (name, c_in, c_out, c3k, e, hw) in blocks {
            let m = C3k2::new(c_in, c_out, 1, c3k, e, &ad);
            let x = Tensor::<4>::random([8, c_in, hw, hw], Distribution::Normal(0.0, 1.0), &ad);
            let step = |f: &dyn Fn(Tensor<4>) -> Tensor<4>| {
                let t = Instant::now();
                let g = f(x.clone().require_grad()).sum().backward();
                drop(g);
                t.elapsed().as_secs_f64() * 1e3
            };
            let (mut old, mut new) = (Vec::new(), Vec::new());
            for i in 0..17 {
                let (o, n) = (step(&|x| c3k2_chunked(&m, x)), step(&|x| m.forward(x)));
                if i >= 2 {
                    old.push(o);
                    new.push(n);
                }
            }
            let median = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let (o, n) = (median(&mut old), median(&mut new));
            (total_old, total_new) = (total_old + o, total_new + n);
            println!(
                "| {name} | 8×{c_in}×{hw}×{hw} | {o:.2} | {n:.2} | {:.3} |",
                o / n
            );
        }
        println!(
            "| all eight | | {total_old:.2} | {total_new:.2} | {:.3} |",
            total_old / total_new
        );
    }

    #[test]
    fn conv_param_and_mac_count() {
        let d = dev();
        // 3×3 conv 16→32 stride 2: 16·32·9 weights + 2·32 BN.
        let c = ConvBn::silu(16, 32, 3, 2, &d);
        assert_eq!(trainable_params(&c), 16 * 32 * 9 + 64);
        // Burn's own count includes the two running statistics.
        assert_eq!(c.num_params(), 16 * 32 * 9 + 64 + 64);
        assert_eq!(c.macs([64, 64]), ((16 * 32 * 9 * 32 * 32) as u64, [32, 32]));
    }

    /// flex's f32 sigmoid (vendor/burn-flex patches 1 and 4: a vectorised kernel split over
    /// the rayon pool for large tensors) must not change a bit with the thread count, and
    /// stays within 3 ulp (at most 1e-6 relative) of the exact sigmoid. Every element of
    /// SiLU's sigmoid on a four-thread pool against a one-thread pool and against f64, on
    /// the in-place path (a tensor nobody else holds), the allocating path (SiLU's
    /// `x * sigmoid(x)` keeps `x`) and a transposed view.
    #[test]
    fn sigmoid_split_over_threads_is_bit_exact() {
        use burn::tensor::activation::sigmoid;
        use burn::tensor::{Distribution, TensorData};
        let d = dev();
        // 2·8·48·56 = 43008 elements: above the split threshold, not a multiple of the chunk.
        let x = Tensor::<4>::random([2, 8, 48, 56], Distribution::Normal(0.0, 6.0), &d);
        let host: Vec<f32> = x.to_data().try_to_vec::<f32>().unwrap();
        let fresh = || Tensor::<4>::from_data(TensorData::new(host.clone(), [2, 8, 48, 56]), &d);
        let bits = |t: Tensor<4>| -> Vec<u32> {
            let v: Vec<f32> = t.into_data().try_to_vec::<f32>().unwrap();
            v.iter().map(|x| x.to_bits()).collect()
        };
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let in_place = bits(sigmoid(fresh()));
                let kept = fresh();
                let allocating = bits(sigmoid(kept.clone()));
                drop(kept);
                let transposed = bits(sigmoid(fresh().swap_dims(1, 3)).swap_dims(1, 3));
                [in_place, allocating, transposed]
            })
        };
        let (one, four) = (on(1), on(4));
        for (what, (a, b)) in ["in place", "allocating", "transposed"]
            .iter()
            .zip(one.iter().zip(&four))
        {
            assert_eq!(a, b, "{what}: 1 vs 4 threads");
            assert_eq!(a, &one[0], "{what} vs in place");
        }
        for (&g, &v) in four[0].iter().zip(&host) {
            let exact = 1.0 / (1.0 + (-(v as f64)).exp());
            let got = f32::from_bits(g) as f64;
            assert!(
                (got - exact).abs() <= 1e-6 * exact,
                "sigmoid({v}) = {got}, exact {exact}"
            );
        }
    }
}
