//! Mask2Former's transformer decoder (reference `MultiScaleMaskedTransformerDecoder`):
//! Q learnable query features with learnable positional embeddings; L layers, layer `i`
//! attending to feature scale `i mod 3` (strides 32, 16, 8, round robin) through masked
//! cross-attention, then self-attention, then an FFN (post-norm, no dropout, as the
//! reference). The memory of each scale gets the sine positional encoding
//! ([`sine_encoding`]) on its keys and a learnable level embedding. A shared head
//! (LayerNorm, linear classifier, 3-layer MLP mask embedding dotted with the per-pixel
//! embedding) predicts classes and masks before the first layer and after every layer:
//! the L + 1 predictions all get losses (the first L are the auxiliary ones), and the
//! masks of each prediction restrict the next layer's attention.

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Distribution, Tensor};

use super::criterion::LayerOutput;
use super::masked_attention::{attention_bias, MaskedAttention};
use crate::util::tensor::{host, to_host};

/// DETR's normalised sine positional encoding (`PositionEmbeddingSine`, temperature 1e4,
/// scale 2π, `num_pos_feats = dim / 2`): `dim` channels, y first, then x.
///
/// # Shapes
/// - → `[h·w, dim]` row-major (pixel-major)
pub fn sine_encoding(h: usize, w: usize, dim: usize) -> Vec<f32> {
    let npf = dim / 2;
    let scale = 2.0 * std::f64::consts::PI;
    let eps = 1e-6;
    let dim_t: Vec<f64> = (0..npf)
        .map(|i| 10000f64.powf(2.0 * (i / 2) as f64 / npf as f64))
        .collect();
    let mut out = vec![0.0f32; h * w * dim];
    for y in 0..h {
        let ye = (y + 1) as f64 / (h as f64 + eps) * scale;
        for x in 0..w {
            let xe = (x + 1) as f64 / (w as f64 + eps) * scale;
            let o = &mut out[(y * w + x) * dim..(y * w + x + 1) * dim];
            // stack((sin of even, cos of odd), dim=4).flatten(3) interleaves sin, cos.
            for i in 0..npf {
                let (vy, vx) = (ye / dim_t[i], xe / dim_t[i]);
                let (sy, sx) = if i % 2 == 0 {
                    (vy.sin(), vx.sin())
                } else {
                    (vy.cos(), vx.cos())
                };
                o[i] = sy as f32;
                o[npf + i] = sx as f32;
            }
        }
    }
    out
}

/// Post-norm FFN: `norm(x + W2·relu(W1·x))`.
#[derive(Module, Debug)]
pub struct Ffn {
    pub linear1: Linear,
    pub linear2: Linear,
    pub norm: LayerNorm,
}

#[derive(Module, Debug)]
pub struct DecoderLayer {
    pub cross: MaskedAttention,
    pub cross_norm: LayerNorm,
    pub self_attn: MaskedAttention,
    pub self_norm: LayerNorm,
    pub ffn: Ffn,
}

/// Decoder sizes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecoderSizes {
    pub in_channels: usize,
    pub hidden: usize,
    pub heads: usize,
    pub ffn: usize,
    pub layers: usize,
    pub queries: usize,
    pub mask_dim: usize,
    pub num_classes: usize,
}

#[derive(Module, Debug)]
pub struct TransformerDecoder {
    /// 1×1 projections of the 3 scales to `hidden` (empty when the widths already agree).
    pub input_proj: Vec<Conv2d>,
    /// `[3, hidden]`.
    pub level_embed: Param<Tensor<2>>,
    /// `[Q, hidden]` each.
    pub query_feat: Param<Tensor<2>>,
    pub query_embed: Param<Tensor<2>>,
    pub layers: Vec<DecoderLayer>,
    pub decoder_norm: LayerNorm,
    pub class_embed: Linear,
    pub mask_embed: Vec<Linear>,
    pub hidden: usize,
}

impl TransformerDecoder {
    pub fn new(s: DecoderSizes, d: &Device) -> Self {
        assert!(
            s.layers > 0 && s.queries > 0 && s.ffn > 0,
            "TransformerDecoder: layers {}, queries {} and ffn {} must be > 0",
            s.layers,
            s.queries,
            s.ffn
        );
        let h = s.hidden;
        let ln = || LayerNormConfig::new(h).init(d);
        let layers = (0..s.layers)
            .map(|_| DecoderLayer {
                cross: MaskedAttention::new(h, s.heads, d),
                cross_norm: ln(),
                self_attn: MaskedAttention::new(h, s.heads, d),
                self_norm: ln(),
                ffn: Ffn {
                    linear1: LinearConfig::new(h, s.ffn).init(d),
                    linear2: LinearConfig::new(s.ffn, h).init(d),
                    norm: ln(),
                },
            })
            .collect();
        let normal = |n: usize| {
            Param::from_tensor(Tensor::random([n, h], Distribution::Normal(0.0, 1.0), d))
        };
        Self {
            input_proj: if s.in_channels == h {
                Vec::new()
            } else {
                (0..3)
                    .map(|_| Conv2dConfig::new([s.in_channels, h], [1, 1]).init(d))
                    .collect()
            },
            level_embed: normal(3),
            query_feat: normal(s.queries),
            query_embed: normal(s.queries),
            layers,
            decoder_norm: ln(),
            class_embed: LinearConfig::new(h, s.num_classes + 1).init(d),
            mask_embed: vec![
                LinearConfig::new(h, h).init(d),
                LinearConfig::new(h, h).init(d),
                LinearConfig::new(h, s.mask_dim).init(d),
            ],
            hidden: h,
        }
    }

    /// Class and mask predictions of the current queries, and the host copy of the mask
    /// logits (for the next layer's attention mask).
    fn predict(&self, q: Tensor<3>, mask_features: &Tensor<4>) -> (LayerOutput, Vec<f32>) {
        let [b, md, mh, mw] = mask_features.dims();
        let nq = q.dims()[1];
        let x = self.decoder_norm.forward(q);
        let class_logits = self.class_embed.forward(x.clone());
        let mut e = x;
        for (i, l) in self.mask_embed.iter().enumerate() {
            e = l.forward(e);
            if i + 1 < self.mask_embed.len() {
                e = relu(e);
            }
        }
        let masks = e
            .matmul(mask_features.clone().reshape([b, md, mh * mw]))
            .reshape([b, nq, mh, mw]);
        let host_masks = to_host(masks.clone().detach());
        (
            LayerOutput {
                class_logits,
                mask_logits: masks,
            },
            host_masks,
        )
    }

    /// All L + 1 predictions, the last one final.
    ///
    /// # Shapes
    /// - `multi`: 3 × `[B, in_channels, h_i, w_i]` (strides 32, 16, 8)
    /// - `mask_features`: `[B, mask_dim, H/4, W/4]`
    pub fn forward(&self, multi: &[Tensor<4>], mask_features: &Tensor<4>) -> Vec<LayerOutput> {
        let device = mask_features.device();
        let [b, _, mh, mw] = mask_features.dims();
        let h = self.hidden;
        let level = self.level_embed.val();
        let mut mem = Vec::with_capacity(3);
        for (i, f) in multi.iter().enumerate() {
            let f = match self.input_proj.get(i) {
                Some(p) => p.forward(f.clone()),
                None => f.clone(),
            };
            let [_, _, fh, fw] = f.dims();
            let src = f.reshape([b, h, fh * fw]).swap_dims(1, 2)
                + level.clone().narrow(0, i, 1).reshape([1, 1, h]);
            let pos: Tensor<3> = host(sine_encoding(fh, fw, h), [1, fh * fw, h], &device);
            mem.push((src.clone() + pos, src, [fh, fw]));
        }
        let nq = self.query_feat.val().dims()[0];
        let qpos = self.query_embed.val().reshape([1, nq, h]);
        let mut q = self.query_feat.val().reshape([1, nq, h]).repeat_dim(0, b);
        let mut outs = Vec::with_capacity(self.layers.len() + 1);
        let (out, mut prev) = self.predict(q.clone(), mask_features);
        outs.push(out);
        for (i, layer) in self.layers.iter().enumerate() {
            let (key, value, size) = &mem[i % 3];
            let bias = attention_bias(&prev, [b, nq, mh, mw], *size, &device);
            let a = layer.cross.forward(
                q.clone() + qpos.clone(),
                key.clone(),
                value.clone(),
                Some(bias),
            );
            q = layer.cross_norm.forward(q + a);
            let qk = q.clone() + qpos.clone();
            let a = layer.self_attn.forward(qk.clone(), qk, q.clone(), None);
            q = layer.self_norm.forward(q + a);
            let f = layer
                .ffn
                .linear2
                .forward(relu(layer.ffn.linear1.forward(q.clone())));
            q = layer.ffn.norm.forward(q + f);
            let (out, m) = self.predict(q.clone(), mask_features);
            outs.push(out);
            prev = m;
        }
        outs
    }

    /// MACs of the decoder at the memory sizes (`[h, w]` of the 3 scales) and mask size.
    pub fn macs(&self, sizes: &[[usize; 2]], mask_hw: [usize; 2], mask_dim: usize) -> u64 {
        let h = self.hidden as u64;
        let q = self.query_feat.val().dims()[0] as u64;
        let hw = (mask_hw[0] * mask_hw[1]) as u64;
        let mut t = 0;
        for (i, s) in sizes.iter().enumerate() {
            let n = (s[0] * s[1]) as u64;
            if i < self.input_proj.len() {
                let ci = self.input_proj[i].weight.val().dims()[1] as u64;
                t += n * ci * h;
            }
        }
        let ffn = self
            .layers
            .first()
            .map_or(0, |l| l.ffn.linear1.weight.val().dims()[1]) as u64;
        for i in 0..self.layers.len() {
            let n = (sizes[i % 3][0] * sizes[i % 3][1]) as u64;
            // cross: q, out on Q; k, v on n; logits and weighted sum Q·n·h.
            t += 2 * q * h * h + 2 * n * h * h + 2 * q * n * h;
            t += 4 * q * h * h + 2 * q * q * h; // self-attention
            t += 2 * q * h * ffn;
        }
        let heads = (self.layers.len() + 1) as u64;
        let c1 = self.class_embed.weight.val().dims()[1] as u64;
        t += heads
            * (q * h * c1 + 2 * q * h * h + q * h * mask_dim as u64 + q * mask_dim as u64 * hw);
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sine_encoding_matches_detr_at_known_values() {
        // h = w = 1: embed = 2π / (1 + 1e-6); channel 0 = sin(2π), channel 1 = cos(2π / 1e4^0),
        // channel 2 = sin(2π / 1e4^(2/4)).
        let e = sine_encoding(1, 1, 8);
        let v = 2.0 * std::f64::consts::PI / (1.0 + 1e-6);
        assert!((e[0] as f64 - v.sin()).abs() < 1e-6);
        assert!((e[1] as f64 - (v / 10000f64.powf(0.0)).cos()).abs() < 1e-6);
        assert!((e[2] as f64 - (v / 10000f64.powf(0.5)).sin()).abs() < 1e-6);
        assert_eq!(&e[..4], &e[4..], "x and y halves agree on a 1×1 map");
    }

    #[test]
    fn predictions_per_layer_and_shapes() {
        let d = Device::flex();
        let s = DecoderSizes {
            in_channels: 12,
            hidden: 16,
            heads: 2,
            ffn: 32,
            layers: 4,
            queries: 5,
            mask_dim: 8,
            num_classes: 2,
        };
        let dec = TransformerDecoder::new(s, &d);
        let multi = vec![
            Tensor::random([2, 12, 2, 2], Distribution::Normal(0.0, 1.0), &d),
            Tensor::random([2, 12, 4, 4], Distribution::Normal(0.0, 1.0), &d),
            Tensor::random([2, 12, 8, 8], Distribution::Normal(0.0, 1.0), &d),
        ];
        let mf = Tensor::random([2, 8, 16, 16], Distribution::Normal(0.0, 1.0), &d);
        let outs = dec.forward(&multi, &mf);
        assert_eq!(outs.len(), 5, "before the first layer and after each of 4");
        for o in &outs {
            assert_eq!(o.class_logits.dims(), [2, 5, 3]);
            assert_eq!(o.mask_logits.dims(), [2, 5, 16, 16]);
            assert!(to_host(o.mask_logits.clone()).iter().all(|v| v.is_finite()));
        }
    }
}
