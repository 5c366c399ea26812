//! Multi-head attention with Mask2Former's masked attention (Cheng et al. 2022, §3.2.1):
//! each query attends only to the memory pixels inside the mask its previous prediction
//! gives (`sigmoid > 0.5`, i.e. logit > 0), resized to the memory's scale. A query whose
//! mask is empty at that scale would have nothing to attend to: as the reference
//! (`mask2former_transformer_decoder.py`, `attn_mask[attn_mask.sum(-1) == L] = False`), it
//! attends everywhere instead.
//!
//! The mask is built on the host from the detached mask logits (no gradient flows through
//! it, as in the reference) and applied as an additive bias (0 or −1e30, PyTorch turns a
//! boolean mask into −inf), which both CPU backends broadcast. Projections are PyTorch's
//! `nn.MultiheadAttention` (q, k, v, out with biases), in Burn's `[in, out]` layout.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor, TensorData};

/// What a blocked key adds to the attention logit. Finite, so no `inf − inf` can appear.
pub const BLOCKED: f32 = -1e30;

#[derive(Module, Debug)]
pub struct MaskedAttention {
    pub q: Linear,
    pub k: Linear,
    pub v: Linear,
    pub out: Linear,
    pub heads: usize,
}

impl MaskedAttention {
    /// Panics naming the sizes unless `dim` splits into `heads` equal heads.
    pub fn new(dim: usize, heads: usize, device: &Device) -> Self {
        assert!(
            heads > 0 && dim > 0 && dim % heads == 0,
            "MaskedAttention: dim {dim} must be a positive multiple of heads {heads}"
        );
        let lin = || LinearConfig::new(dim, dim).init(device);
        Self {
            q: lin(),
            k: lin(),
            v: lin(),
            out: lin(),
            heads,
        }
    }

    /// Attention of `query` over `key`/`value`, with an optional additive `bias`
    /// ([`attention_bias`]: 0 where allowed, [`BLOCKED`] where not).
    ///
    /// # Shapes
    /// - `query`: `[B, Sq, C]`, `key`, `value`: `[B, Sk, C]`
    /// - `bias`: `[B, 1, Sq, Sk]` (same for every head)
    /// - output: `[B, Sq, C]`
    pub fn forward(
        &self,
        query: Tensor<3>,
        key: Tensor<3>,
        value: Tensor<3>,
        bias: Option<Tensor<4>>,
    ) -> Tensor<3> {
        let [b, sq, c] = query.dims();
        let sk = key.dims()[1];
        let h = self.heads;
        let d = c / h;
        let split = |x: Tensor<3>, s: usize| x.reshape([b, s, h, d]).swap_dims(1, 2);
        let q = split(self.q.forward(query), sq) * (1.0 / (d as f64).sqrt());
        let k = split(self.k.forward(key), sk);
        let v = split(self.v.forward(value), sk);
        let mut logits = q.matmul(k.swap_dims(2, 3)); // [B, h, Sq, Sk]
        if let Some(bias) = bias {
            logits = logits + bias;
        }
        let attn = softmax(logits, 3);
        let o = attn.matmul(v).swap_dims(1, 2).reshape([b, sq, c]);
        self.out.forward(o)
    }
}

/// PyTorch's bilinear resize (`F.interpolate(..., align_corners=False)`, no antialias) of
/// one row-major `h × w` map to `oh × ow`.
pub fn resize_bilinear(x: &[f32], h: usize, w: usize, oh: usize, ow: usize) -> Vec<f32> {
    let src = |dst: usize, n_in: usize, n_out: usize| {
        let scale = n_in as f32 / n_out as f32;
        let s = ((dst as f32 + 0.5) * scale - 0.5).max(0.0);
        let i0 = (s.floor() as usize).min(n_in - 1);
        let i1 = (i0 + 1).min(n_in - 1);
        (i0, i1, s - i0 as f32)
    };
    let rows: Vec<_> = (0..oh).map(|y| src(y, h, oh)).collect();
    let cols: Vec<_> = (0..ow).map(|x| src(x, w, ow)).collect();
    let mut out = Vec::with_capacity(oh * ow);
    for &(y0, y1, fy) in &rows {
        for &(x0, x1, fx) in &cols {
            let top = x[y0 * w + x0] * (1.0 - fx) + x[y0 * w + x1] * fx;
            let bot = x[y1 * w + x0] * (1.0 - fx) + x[y1 * w + x1] * fx;
            out.push(top * (1.0 - fy) + bot * fy);
        }
    }
    out
}

/// Additive attention bias of masked attention from host mask logits: a query may attend
/// to memory pixel `p` iff its mask, resized to the memory's `[mh, mw]`, has logit `≥ 0`
/// there (`sigmoid ≥ 0.5`; the reference blocks `sigmoid < 0.5`); a query blocked
/// everywhere is unblocked everywhere. A NaN logit blocks (the comparison is false).
///
/// # Shapes
/// - `logits`: `[B, Q, h, w]` row-major → `[B, 1, Q, mh·mw]`
pub fn attention_bias(
    logits: &[f32],
    [b, q, h, w]: [usize; 4],
    [mh, mw]: [usize; 2],
    device: &Device,
) -> Tensor<4> {
    let n = mh * mw;
    let mut bias = vec![0.0f32; b * q * n];
    for (r, row) in bias.chunks_mut(n).enumerate() {
        let m = resize_bilinear(&logits[r * h * w..(r + 1) * h * w], h, w, mh, mw);
        let mut any = false;
        for (o, &v) in row.iter_mut().zip(&m) {
            if v >= 0.0 {
                any = true;
            } else {
                *o = BLOCKED;
            }
        }
        if !any {
            row.fill(0.0);
        }
    }
    Tensor::from_data(TensorData::new(bias, [b, 1, q, n]), device)
}

#[cfg(test)]
mod tests {
    use super::super::fixture::vecf;
    use super::*;
    use crate::util::tensor::{host, to_host};
    use burn::module::Param;
    use serde_json::Value;

    fn linear(w: Vec<f32>, b: Vec<f32>, dim: usize, d: &Device) -> Linear {
        // PyTorch's weight is [out, in]; Burn's [in, out].
        let w: Tensor<2> = host(w, [dim, dim], d).transpose();
        Linear {
            weight: Param::from_tensor(w),
            bias: Some(Param::from_tensor(host(b, [dim], d))),
        }
    }

    /// `masked_attention.json` (made by `tests/fixtures/mask2former/make_masked_attention.py`):
    /// `nn.MultiheadAttention` with random weights over a query set and a memory, with the
    /// mask Mask2Former builds from random mask logits (bilinear resize, `sigmoid < 0.5`,
    /// all-blocked rows reset), incl. one all-blocked query.
    #[test]
    fn equals_pytorch_multihead_attention_with_mask() {
        let f: Value = serde_json::from_str(include_str!(
            "../../../tests/fixtures/mask2former/masked_attention.json"
        ))
        .unwrap();
        let d = Device::flex();
        let u = |k: &str| f[k].as_u64().unwrap() as usize;
        let (b, q, s, c, heads, h, w, mh, mw) = (
            u("batch"),
            u("queries"),
            u("memory"),
            u("dim"),
            u("heads"),
            u("mask_h"),
            u("mask_w"),
            u("mem_h"),
            u("mem_w"),
        );
        assert_eq!(s, mh * mw);
        let win = vecf(&f["in_proj_weight"]);
        let bin = vecf(&f["in_proj_bias"]);
        let part = |v: &[f32], i: usize, n: usize| v[i * n..(i + 1) * n].to_vec();
        let att = MaskedAttention {
            q: linear(part(&win, 0, c * c), part(&bin, 0, c), c, &d),
            k: linear(part(&win, 1, c * c), part(&bin, 1, c), c, &d),
            v: linear(part(&win, 2, c * c), part(&bin, 2, c), c, &d),
            out: linear(
                vecf(&f["out_proj_weight"]),
                vecf(&f["out_proj_bias"]),
                c,
                &d,
            ),
            heads,
        };
        let logits = vecf(&f["mask_logits"]);
        let bias = attention_bias(&logits, [b, q, h, w], [mh, mw], &d);
        // The boolean mask itself equals the reference's.
        let want_mask = vecf(&f["blocked"]);
        let got_mask: Vec<f32> = to_host(bias.clone())
            .iter()
            .map(|&v| if v < 0.0 { 1.0 } else { 0.0 })
            .collect();
        assert_eq!(got_mask, want_mask);
        assert!(
            want_mask.chunks(s).any(|r| r.iter().all(|&v| v == 0.0)),
            "fixture has an unblocked (fallback) row"
        );
        let query = host(vecf(&f["query"]), [b, q, c], &d);
        let memory = host(vecf(&f["memory_feat"]), [b, s, c], &d);
        let key = memory.clone() + host(vecf(&f["pos"]), [b, s, c], &d);
        let got = to_host(att.forward(query, key, memory, Some(bias)));
        let want = vecf(&f["output"]);
        assert_eq!(got.len(), want.len());
        let err = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(err < 1e-4, "max |Burn − PyTorch| = {err}");
    }

    #[test]
    fn all_blocked_rows_fall_back_and_extremes_stay_finite() {
        let d = Device::flex();
        // Query 0: all logits negative (blocked everywhere → unblocked); query 1: +1e4 on
        // the left half, −1e4 on the right.
        let mut logits = vec![-5.0f32; 16];
        logits.extend((0..16).map(|i| if i % 4 < 2 { 1e4 } else { -1e4 }));
        let bias = to_host(attention_bias(&logits, [1, 2, 4, 4], [2, 2], &d));
        assert_eq!(&bias[..4], &[0.0; 4]);
        assert_eq!(&bias[4..], &[0.0, BLOCKED, 0.0, BLOCKED]);
        let att = MaskedAttention::new(8, 2, &d);
        let x = host(vec![1e4; 2 * 8], [1, 2, 8], &d);
        let m = host(vec![-1e4; 4 * 8], [1, 4, 8], &d);
        let bias = attention_bias(&logits, [1, 2, 4, 4], [2, 2], &d);
        let out = to_host(att.forward(x, m.clone(), m, Some(bias)));
        assert!(out.iter().all(|v| v.is_finite()), "{out:?}");
    }

    #[test]
    #[should_panic(expected = "dim 10 must be a positive multiple of heads 4")]
    fn rejects_uneven_heads() {
        MaskedAttention::new(10, 4, &Device::flex());
    }
}
