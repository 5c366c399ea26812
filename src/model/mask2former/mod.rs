//! Compact Mask2Former (Cheng et al. 2022, "Masked-attention Mask Transformer for
//! Universal Image Segmentation") for instance segmentation, in Burn.
//!
//! - Backbone: the Mask R-CNN family's ResNet ([`crate::model::maskrcnn::resnet`], same
//!   module paths, so torchvision ImageNet weights load the same way).
//! - [`pixel_decoder`]: MaskFormer's FPN-style decoder in place of the paper's MSDeformAttn
//!   encoder (see there why); stride-4 per-pixel embedding + strides 32/16/8 for the decoder.
//! - [`transformer_decoder`] with [`masked_attention`]: Q learnable queries, L layers round
//!   robin over the 3 scales, predictions before and after every layer.
//! - Training: [`matcher`] (Hungarian on class + mask BCE + dice costs on uniform points,
//!   [`crate::util::hungarian`]), [`criterion`] (class CE with no-object weight, BCE and
//!   dice on importance-sampled [`point_sample`] points, every layer).
//! - [`postprocess`]: class × mask score, top k, masks decoded at the original size by the
//!   shared [`crate::model::instance_mask`] path.
//!
//! [`Mask2FormerConfig::new`] is the compact preset (CPU- and scene-sized: 128-wide, 6
//! layers, 25 queries, 3136 points); [`Mask2FormerConfig::paper`] the paper's R50 sizes
//! (256-wide, 9 layers, 100 queries, 12544 points, 8 heads, FFN 2048).

pub mod config;
pub mod criterion;
pub mod family;
pub mod masked_attention;
pub mod matcher;
pub mod pixel_decoder;
pub mod point_sample;
pub mod postprocess;
pub mod transformer_decoder;

#[cfg(test)]
pub(crate) mod fixture;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::annotations::targets::ImageTargets;
use crate::model::detection::Detection;
use crate::model::maskrcnn::resnet::{self, ResNet};
use crate::model::maskrcnn::{check_batch, check_input, check_scale, normalize};
use crate::model::summary::ModelSummary;
use crate::util::tensor::to_host;
pub use config::{Mask2FormerModelConfig, Mask2FormerPreset};
use criterion::{set_criterion, LayerOutput};
pub use criterion::{CriterionConfig, Mask2FormerLosses};
use pixel_decoder::PixelDecoder;
use transformer_decoder::{DecoderSizes, TransformerDecoder};

/// Model options; [`Mask2FormerConfig::init`] validates and panics naming the bad value
/// (the `[model]` table is range-checked before, with errors naming the key).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mask2FormerConfig {
    /// ResNet depth: 18, 34, 50 or 101.
    pub depth: usize,
    pub width_mult: f64,
    pub num_classes: usize,
    /// Nominal square input size (px, multiple of 32) for the printed GFLOPs.
    pub input_size: usize,
    /// Pixel-decoder width.
    pub conv_dim: usize,
    /// Per-pixel embedding width.
    pub mask_dim: usize,
    pub hidden_dim: usize,
    pub heads: usize,
    pub ffn_dim: usize,
    /// Transformer decoder layers L (paper 9).
    pub dec_layers: usize,
    /// Queries Q (paper 100).
    pub queries: usize,
    /// Detections per image at inference (paper 100).
    pub top_k: usize,
    pub criterion: CriterionConfig,
}

impl Mask2FormerConfig {
    /// The model of a validated `[model]` table at `input_size` px with `num_classes`.
    pub fn from_config(m: &Mask2FormerModelConfig, input_size: usize, num_classes: usize) -> Self {
        let mut c = match m.preset {
            Mask2FormerPreset::Compact => Self::new(m.depth, num_classes),
            Mask2FormerPreset::Paper => Self::paper(m.depth, num_classes),
        };
        c.width_mult = m.width_mult;
        c.input_size = input_size;
        c.conv_dim = m.conv_dim.unwrap_or(c.conv_dim);
        c.mask_dim = m.mask_dim.unwrap_or(c.mask_dim);
        c.hidden_dim = m.hidden_dim.unwrap_or(c.hidden_dim);
        c.heads = m.heads.unwrap_or(c.heads);
        c.ffn_dim = m.ffn_dim.unwrap_or(c.ffn_dim);
        c.dec_layers = m.dec_layers.unwrap_or(c.dec_layers);
        c.queries = m.queries.unwrap_or(c.queries);
        c.top_k = m.top_k.unwrap_or(c.top_k);
        c.criterion.points = m.points.unwrap_or(c.criterion.points);
        c
    }

    /// Compact preset (module docs).
    pub fn new(depth: usize, num_classes: usize) -> Self {
        Self {
            depth,
            width_mult: 1.0,
            num_classes,
            input_size: 512,
            conv_dim: 128,
            mask_dim: 128,
            hidden_dim: 128,
            heads: 4,
            ffn_dim: 512,
            dec_layers: 6,
            queries: 25,
            top_k: 50,
            criterion: CriterionConfig {
                points: 3136,
                ..CriterionConfig::paper()
            },
        }
    }

    /// The paper's sizes (R50 instance segmentation on COCO, 1024 px nominal input).
    pub fn paper(depth: usize, num_classes: usize) -> Self {
        Self {
            input_size: 1024,
            conv_dim: 256,
            mask_dim: 256,
            hidden_dim: 256,
            heads: 8,
            ffn_dim: 2048,
            dec_layers: 9,
            queries: 100,
            top_k: 100,
            criterion: CriterionConfig::paper(),
            ..Self::new(depth, num_classes)
        }
    }

    /// Panics with the offending value if the config cannot build a model.
    pub fn validate(&self) {
        resnet::depth_layout(self.depth);
        let pos = |name: &str, v: usize| {
            assert!(v > 0, "Mask2FormerConfig: {name} must be > 0, got {v}");
        };
        pos("num_classes", self.num_classes);
        pos("conv_dim", self.conv_dim);
        pos("mask_dim", self.mask_dim);
        pos("queries", self.queries);
        pos("dec_layers", self.dec_layers);
        pos("top_k", self.top_k);
        pos("points", self.criterion.points);
        assert!(
            self.heads > 0 && self.hidden_dim % self.heads == 0 && self.hidden_dim % 2 == 0,
            "Mask2FormerConfig: hidden_dim {} must be even and a multiple of heads {}",
            self.hidden_dim,
            self.heads
        );
        check_scale("Mask2FormerConfig", self.width_mult, self.input_size);
    }

    pub fn init(&self, device: &Device) -> Mask2Former {
        self.validate();
        let backbone = ResNet::new(self.depth, self.width_mult, device);
        let pixel_decoder =
            PixelDecoder::new(&backbone.out_channels, self.conv_dim, self.mask_dim, device);
        let transformer_decoder = TransformerDecoder::new(
            DecoderSizes {
                in_channels: self.conv_dim,
                hidden: self.hidden_dim,
                heads: self.heads,
                ffn: self.ffn_dim,
                layers: self.dec_layers,
                queries: self.queries,
                mask_dim: self.mask_dim,
                num_classes: self.num_classes,
            },
            device,
        );
        Mask2Former {
            backbone,
            pixel_decoder,
            transformer_decoder,
            config: self.clone(),
        }
    }
}

/// Whether the tensor at module path `path` is sized by the class count (the classifier),
/// re-initialised when weights come from a model with another class count.
pub fn class_dependent(path: &str) -> bool {
    path.starts_with("transformer_decoder.class_embed.")
}

#[derive(Module, Debug)]
pub struct Mask2Former {
    pub backbone: ResNet,
    pub pixel_decoder: PixelDecoder,
    pub transformer_decoder: TransformerDecoder,
    #[module(skip)]
    pub config: Mask2FormerConfig,
}

impl Mask2Former {
    /// The L + 1 predictions of a batch of `[0, 1]` images.
    pub fn forward(&self, images: Tensor<4>) -> Vec<LayerOutput> {
        let c = self.backbone.forward(normalize(images));
        let (mask_features, multi) = self.pixel_decoder.forward(c);
        self.transformer_decoder.forward(&multi, &mask_features)
    }

    /// Training forward: the set-criterion losses of all layers. `rng` draws the points.
    ///
    /// # Shapes
    /// - `images`: `[B, 3, H, W]` in `[0, 1]`; `targets`: `B` entries, masks `H·W` bytes
    pub fn forward_train<R: Rng>(
        &self,
        images: Tensor<4>,
        targets: &[ImageTargets],
        rng: &mut R,
    ) -> Mask2FormerLosses {
        let [h, w] = check_input(&images, "Mask2Former");
        check_batch(targets, images.dims()[0], "Mask2Former::forward_train");
        for (i, t) in targets.iter().enumerate() {
            assert!(
                t.classes.len() == t.masks.len()
                    && t.masks.iter().all(|m| m.len() == h * w)
                    && t.classes.iter().all(|&c| c < self.config.num_classes),
                "Mask2Former::forward_train: image {i}: {} classes (each < {}), {} masks of {h}×{w} bytes",
                t.classes.len(),
                self.config.num_classes,
                t.masks.len()
            );
        }
        let layers = self.forward(images);
        set_criterion(&layers, targets, [h, w], &self.config.criterion, rng)
    }

    /// Inference: per image at most `top_k` detections. Call on `model.valid()`.
    pub fn forward_infer(&self, images: Tensor<4>) -> Vec<Vec<Detection>> {
        let [ih, iw] = check_input(&images, "Mask2Former");
        let out = self.forward(images).pop().expect("at least one prediction");
        let [b, q, c1] = out.class_logits.dims();
        let [_, _, h, w] = out.mask_logits.dims();
        let cls = to_host(out.class_logits);
        let masks = to_host(out.mask_logits);
        (0..b)
            .map(|i| {
                postprocess::instance_inference(
                    &cls[i * q * c1..(i + 1) * q * c1],
                    &masks[i * q * h * w..(i + 1) * q * h * w],
                    q,
                    [h, w],
                    [ih, iw],
                    self.config.top_k,
                )
            })
            .collect()
    }

    pub fn num_classes(&self) -> usize {
        self.config.num_classes
    }

    /// Trainable parameters and GFLOPs (2 × MACs of convs and matrix products) at a square
    /// `input`.
    pub fn summary(&self, input: usize) -> ModelSummary {
        let sizes: Vec<[usize; 2]> = [4, 8, 16, 32]
            .iter()
            .map(|&s| [input.div_ceil(s), input.div_ceil(s)])
            .collect();
        let mem = [sizes[3], sizes[2], sizes[1]];
        let macs = self.backbone.macs([input, input])
            + self.pixel_decoder.macs(&sizes)
            + self
                .transformer_decoder
                .macs(&mem, sizes[0], self.config.mask_dim);
        ModelSummary {
            params: crate::model::layers::trainable_params(self),
            gflops: 2.0 * macs as f64 / 1e9,
            input,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn tiny(nc: usize) -> Mask2FormerConfig {
        Mask2FormerConfig {
            width_mult: 0.25,
            input_size: 64,
            conv_dim: 16,
            mask_dim: 16,
            hidden_dim: 16,
            heads: 2,
            ffn_dim: 32,
            dec_layers: 3,
            queries: 6,
            top_k: 10,
            criterion: CriterionConfig {
                points: 64,
                ..CriterionConfig::paper()
            },
            ..Mask2FormerConfig::new(18, nc)
        }
    }

    fn square(h: usize, w: usize, x0: usize, y0: usize, s: usize) -> Vec<u8> {
        let mut m = vec![0u8; h * w];
        for y in y0..y0 + s {
            for x in x0..x0 + s {
                m[y * w + x] = 1;
            }
        }
        m
    }

    #[test]
    fn losses_finite_for_0_1_and_200_instances_and_backprop() {
        let d = Device::flex().autodiff();
        let model = tiny(2).init(&d);
        let imgs: Tensor<4> = Tensor::ones([2, 3, 64, 64], &d) * 0.5;
        let empty = ImageTargets::default();
        let one = ImageTargets {
            boxes: vec![[8.0, 8.0, 24.0, 24.0]],
            classes: vec![1],
            masks: vec![square(64, 64, 8, 8, 16)],
        };
        let many = ImageTargets {
            boxes: vec![[0.0, 0.0, 4.0, 4.0]; 200],
            classes: (0..200).map(|i| i % 2).collect(),
            masks: (0..200)
                .map(|i| square(64, 64, (i % 15) * 4, (i / 15) * 4, 4))
                .collect(),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for t in [
            [empty.clone(), empty.clone()],
            [empty, one],
            [many.clone(), many],
        ] {
            let l = model.forward_train(imgs.clone(), &t, &mut rng);
            let v = l.values();
            assert!(v.iter().all(|x| x.is_finite()), "{v:?}");
            let g = l.total.backward();
            let w = model.transformer_decoder.class_embed.weight.val().grad(&g);
            assert!(w.is_some_and(|g| to_host(g).iter().all(|x| x.is_finite())));
        }
    }

    #[test]
    fn same_seed_same_loss_and_inference_shapes() {
        let d = Device::flex().autodiff();
        d.seed(5);
        let model = tiny(1).init(&d);
        let imgs: Tensor<4> = Tensor::ones([1, 3, 64, 64], &d) * 0.3;
        let t = vec![ImageTargets {
            boxes: vec![[8.0, 8.0, 40.0, 40.0]],
            classes: vec![0],
            masks: vec![square(64, 64, 8, 8, 32)],
        }];
        let a = model
            .forward_train(imgs.clone(), &t, &mut ChaCha8Rng::seed_from_u64(9))
            .values();
        let b = model
            .forward_train(imgs.clone(), &t, &mut ChaCha8Rng::seed_from_u64(9))
            .values();
        assert_eq!(a, b);
        let plain = Tensor::<4>::from_data(imgs.into_data(), &Device::flex());
        let dets = model.valid().forward_infer(plain);
        assert_eq!(dets.len(), 1);
        assert!(dets[0].len() <= 6);
        assert!(model.summary(64).params > 0);
    }

    #[test]
    #[should_panic(expected = "hidden_dim 10 must be even and a multiple of heads 4")]
    fn rejects_uneven_heads() {
        Mask2FormerConfig {
            hidden_dim: 10,
            heads: 4,
            ..tiny(1)
        }
        .init(&Device::flex());
    }
}
