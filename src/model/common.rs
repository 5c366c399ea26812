//! Building blocks shared by the model families: Conv-BN-SiLU, Bottleneck, C3k, C3k2, SPPF,
//! the C2PSA attention block and the mask-prototype head (Proto).
//!
//! They follow ultralytics 8.3 `nn/modules/conv.py` and `block.py` layer for layer (same
//! channel splits, same BN eps 1e-3 / momentum 0.03), so parameter counts match the
//! reference and published YOLO11 numbers can be compared. No heads and no losses live here.
//!
//! Every block also reports its multiply-accumulate count for a given input size
//! (`macs`), computed from its own weight shapes, so the GFLOPs printed at start cannot drift
//! from the model that is actually built.

use burn::module::{Module, ModuleVisitor, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::{silu, softmax};
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor};

/// BatchNorm epsilon used by ultralytics (`nn/modules/conv.py`, `Conv.bn`), not PyTorch's 1e-5.
pub const BN_EPS: f64 = 1e-3;
/// BatchNorm momentum used by ultralytics (`utils/torch_utils.py::initialize_weights`), not 0.1.
pub const BN_MOMENTUM: f64 = 0.03;

/// Number of trainable scalars of a module: every float parameter except BatchNorm running
/// statistics (which Burn's `num_params` counts too, PyTorch's `parameters()` does not).
pub fn trainable_params<M: Module>(module: &M) -> usize {
    struct Count {
        path: Vec<String>,
        n: usize,
    }
    impl ModuleVisitor for Count {
        fn enter_module(&mut self, name: &str, _container: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let running = self.path.last().is_some_and(|s| s.starts_with("running_"));
            if !running {
                self.n += param.lazy_shape().num_elements();
            }
        }
    }
    let mut c = Count {
        path: Vec::new(),
        n: 0,
    };
    module.visit(&mut c);
    c.n
}

/// Output size of a convolution or pooling with "same"-style padding `k / 2`.
pub fn conv_out(size: usize, kernel: usize, stride: usize) -> usize {
    (size + 2 * (kernel / 2) - kernel) / stride + 1
}

/// Nearest-neighbour ×2 upsampling (the only interpolation whose backward runs on both flex
/// and ndarray, see `shared/notes/burn-0.22.md`).
///
/// # Shapes
/// - `x`: `[B, C, H, W]` → `[B, C, 2H, 2W]`
pub fn upsample2x(x: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([2 * h, 2 * w]),
    )
}

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

/// MACs of a plain [`Conv2d`] with padding `k/2` for an `[h, w]` input, and its output size.
pub fn conv_macs(conv: &Conv2d, hw: [usize; 2]) -> (u64, [usize; 2]) {
    let [co, ci_g, kh, kw] = conv.weight.dims();
    let oh = conv_out(hw[0], kh, conv.stride[0]);
    let ow = conv_out(hw[1], kw, conv.stride[1]);
    ((co * ci_g * kh * kw * oh * ow) as u64, [oh, ow])
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
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.cv1.forward(x);
        let mut parts = y.chunk(2, 1);
        let mut last = parts[1].clone();
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

/// Multi-head self-attention over all positions of a feature map, with a depthwise 3×3
/// positional encoding on the values: ultralytics' `Attention` (attn_ratio 0.5).
#[derive(Module, Debug)]
pub struct Attention {
    pub qkv: ConvBn,
    pub proj: ConvBn,
    pub pe: ConvBn,
    pub num_heads: usize,
    pub head_dim: usize,
    pub key_dim: usize,
}

impl Attention {
    pub fn new(dim: usize, num_heads: usize, device: &Device) -> Self {
        assert!(
            num_heads > 0 && dim.is_multiple_of(num_heads),
            "Attention: dim {dim} must be a positive multiple of num_heads {num_heads}"
        );
        let head_dim = dim / num_heads;
        let key_dim = head_dim / 2;
        assert!(
            key_dim > 0,
            "Attention: head_dim {head_dim} too small for a key"
        );
        let h = dim + 2 * key_dim * num_heads;
        Self {
            qkv: ConvBn::new(dim, h, 1, 1, 1, false, device),
            proj: ConvBn::new(dim, dim, 1, 1, 1, false, device),
            pe: ConvBn::new(dim, dim, 3, 1, dim, false, device),
            num_heads,
            head_dim,
            key_dim,
        }
    }

    /// # Shapes
    /// - `x`: `[B, C, H, W]` → `[B, C, H, W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [b, c, h, w] = x.dims();
        let n = h * w;
        let (nh, kd, hd) = (self.num_heads, self.key_dim, self.head_dim);
        // [B, nh, 2kd + hd, N]
        let qkv = self.qkv.forward(x).reshape([b, nh, 2 * kd + hd, n]);
        let q = qkv.clone().narrow(2, 0, kd);
        let k = qkv.clone().narrow(2, kd, kd);
        let v = qkv.narrow(2, 2 * kd, hd);
        let scale = (kd as f64).powf(-0.5);
        // [B, nh, N, N]
        let attn = softmax(q.swap_dims(2, 3).matmul(k).mul_scalar(scale), 3);
        // [B, nh, hd, N]
        let out = v.clone().matmul(attn.swap_dims(2, 3));
        let out = out.reshape([b, c, h, w]) + self.pe.forward(v.reshape([b, c, h, w]));
        self.proj.forward(out)
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        let n = (hw[0] * hw[1]) as u64;
        let heads = self.num_heads as u64;
        let attn = heads * n * n * (self.key_dim + self.head_dim) as u64;
        self.qkv.macs(hw).0 + self.proj.macs(hw).0 + self.pe.macs(hw).0 + attn
    }

    pub fn fuse(self) -> Self {
        Self {
            qkv: self.qkv.fuse(),
            proj: self.proj.fuse(),
            pe: self.pe.fuse(),
            ..self
        }
    }
}

/// Attention + 2-layer 1×1 FFN, both residual: ultralytics' `PSABlock`.
#[derive(Module, Debug)]
pub struct PsaBlock {
    pub attn: Attention,
    pub ffn1: ConvBn,
    pub ffn2: ConvBn,
}

impl PsaBlock {
    pub fn new(c: usize, num_heads: usize, device: &Device) -> Self {
        Self {
            attn: Attention::new(c, num_heads, device),
            ffn1: ConvBn::silu(c, 2 * c, 1, 1, device),
            ffn2: ConvBn::new(2 * c, c, 1, 1, 1, false, device),
        }
    }

    /// # Shapes
    /// - `x`: `[B, C, H, W]` → `[B, C, H, W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = x.clone() + self.attn.forward(x);
        x.clone() + self.ffn2.forward(self.ffn1.forward(x))
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        self.attn.macs(hw) + self.ffn1.macs(hw).0 + self.ffn2.macs(hw).0
    }

    pub fn fuse(self) -> Self {
        Self {
            attn: self.attn.fuse(),
            ffn1: self.ffn1.fuse(),
            ffn2: self.ffn2.fuse(),
        }
    }
}

/// YOLO11's C2PSA: split in half, `n` PSA blocks on one half, concatenate, 1×1 back.
#[derive(Module, Debug)]
pub struct C2psa {
    pub cv1: ConvBn,
    pub cv2: ConvBn,
    pub m: Vec<PsaBlock>,
    pub c: usize,
}

impl C2psa {
    /// `num_heads = max(c/64, 1)` with `c = channels/2` (ultralytics uses `c // 64`, which is 0
    /// and crashes below 128 channels; we keep one head there so narrow models still build).
    pub fn new(channels: usize, n: usize, device: &Device) -> Self {
        let c = channels / 2;
        assert!(c > 0 && n > 0, "C2PSA({channels}, n {n}) is empty");
        let heads = (c / 64).max(1);
        Self {
            cv1: ConvBn::silu(channels, 2 * c, 1, 1, device),
            cv2: ConvBn::silu(2 * c, channels, 1, 1, device),
            m: (0..n).map(|_| PsaBlock::new(c, heads, device)).collect(),
            c,
        }
    }

    /// # Shapes
    /// - `x`: `[B, C, H, W]` → `[B, C, H, W]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.cv1.forward(x);
        let a = y.clone().narrow(1, 0, self.c);
        let mut b = y.narrow(1, self.c, self.c);
        for block in &self.m {
            b = block.forward(b);
        }
        self.cv2.forward(Tensor::cat(vec![a, b], 1))
    }

    pub fn macs(&self, hw: [usize; 2]) -> u64 {
        self.cv1.macs(hw).0 + self.cv2.macs(hw).0 + self.m.iter().map(|b| b.macs(hw)).sum::<u64>()
    }

    pub fn fuse(self) -> Self {
        Self {
            cv1: self.cv1.fuse(),
            cv2: self.cv2.fuse(),
            m: self.m.into_iter().map(PsaBlock::fuse).collect(),
            c: self.c,
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
        assert_eq!(
            C2psa::new(16, 1, &d).forward(x.clone()).dims(),
            [2, 16, 8, 8]
        );
        assert_eq!(Proto::new(16, 8, 4, &d).forward(x).dims(), [2, 4, 16, 16]);
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

    #[test]
    #[should_panic(expected = "dim 48 must be a positive multiple of num_heads 5")]
    fn attention_rejects_bad_heads() {
        Attention::new(48, 5, &dev());
    }
}
