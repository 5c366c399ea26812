//! YOLO11's attention: multi-head self-attention over a feature map ([`Attention`]), the
//! PSA block around it and the C2PSA stage after SPPF, layer for layer as ultralytics 8.3
//! `nn/modules/block.py`, with their multiply-accumulate counts.

use burn::module::Module;
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor};

use super::blocks::ConvBn;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn c2psa_keeps_shape() {
        let d = Device::flex();
        let x = Tensor::<4>::ones([2, 16, 8, 8], &d);
        assert_eq!(C2psa::new(16, 1, &d).forward(x).dims(), [2, 16, 8, 8]);
    }

    #[test]
    #[should_panic(expected = "dim 48 must be a positive multiple of num_heads 5")]
    fn attention_rejects_bad_heads() {
        Attention::new(48, 5, &Device::flex());
    }
}
