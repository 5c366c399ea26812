//! Region Proposal Network (Ren et al. 2015; detectron2 `proposal_generator/rpn.py`):
//! a shared 3×3 conv + ReLU and two 1×1 convs per level (objectness per anchor, 4 deltas per
//! anchor), proposal selection (per-level top-N by objectness, decode, clip, drop empty
//! boxes, NMS per level, post-NMS top-N per image) and the RPN loss (anchor matching at
//! 0.3 / 0.7 with low-quality matches, balanced sampling, BCE on sampled anchors and
//! smooth-L1 / L1 on positive deltas, both normalised by `images × batch_per_image`).
//!
//! Proposal selection and matching run on host copies (NMS in plain Rust: burn-vision's
//! does not run on ndarray); the loss gathers the sampled rows of the network output.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::box_coder::{clip_box, BoxCoder};
use super::losses::{bce_with_logits, smooth_l1};
use super::matcher::{pairwise_iou, Matcher, NEGATIVE, POSITIVE};
use super::roi_align::index_tensor;
use super::sampler::subsample_labels;
use crate::annotations::targets::ImageTargets;
use crate::model::detection::nms;
use crate::model::layers::conv_macs;
use crate::util::tensor::{host, to_host};

/// RPN hyper-parameters (detectron2 `MODEL.RPN.*`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RpnConfig {
    /// IoU below which an anchor is background.
    pub bg_iou: f32,
    /// IoU from which an anchor is foreground.
    pub fg_iou: f32,
    /// Anchors sampled per image for the loss.
    pub batch_per_image: usize,
    pub positive_fraction: f32,
    /// Top-N per level before NMS, training / inference.
    pub pre_nms_topk_train: usize,
    pub pre_nms_topk_test: usize,
    /// Proposals kept per image after NMS, training / inference.
    pub post_nms_topk_train: usize,
    pub post_nms_topk_test: usize,
    pub nms_iou: f32,
    /// Smooth-L1 β of the delta loss (0 = L1, detectron2's default).
    pub smooth_l1_beta: f32,
}

impl RpnConfig {
    /// detectron2 R50-FPN: 256 anchors per image, 2000 / 1000 per level pre-NMS,
    /// 1000 / 1000 post-NMS, NMS 0.7.
    pub fn paper() -> Self {
        Self {
            bg_iou: 0.3,
            fg_iou: 0.7,
            batch_per_image: 256,
            positive_fraction: 0.5,
            pre_nms_topk_train: 2000,
            pre_nms_topk_test: 1000,
            post_nms_topk_train: 1000,
            post_nms_topk_test: 1000,
            nms_iou: 0.7,
            smooth_l1_beta: 0.0,
        }
    }

    /// Scene-sized: ≤ 12 carcasses per image need far fewer proposals.
    pub fn compact() -> Self {
        Self {
            batch_per_image: 128,
            pre_nms_topk_train: 500,
            pre_nms_topk_test: 300,
            post_nms_topk_train: 200,
            post_nms_topk_test: 100,
            ..Self::paper()
        }
    }

    /// Panics naming the values if the config is inconsistent.
    pub fn validate(&self) {
        assert!(
            0.0 <= self.bg_iou && self.bg_iou <= self.fg_iou && self.fg_iou <= 1.0,
            "RpnConfig: need 0 ≤ bg_iou ≤ fg_iou ≤ 1, got bg_iou {} fg_iou {}",
            self.bg_iou,
            self.fg_iou
        );
        assert!(
            self.batch_per_image > 0
                && self.pre_nms_topk_train > 0
                && self.pre_nms_topk_test > 0
                && self.post_nms_topk_train > 0
                && self.post_nms_topk_test > 0,
            "RpnConfig: batch_per_image and the top-N sizes must be > 0, got {self:?}"
        );
        assert!(
            (0.0..=1.0).contains(&self.positive_fraction) && (0.0..=1.0).contains(&self.nms_iou),
            "RpnConfig: positive_fraction and nms_iou must be in [0, 1], got {} and {}",
            self.positive_fraction,
            self.nms_iou
        );
    }
}

/// Shared RPN head over all levels.
#[derive(Module, Debug)]
pub struct RpnHead {
    pub conv: Conv2d,
    pub objectness: Conv2d,
    pub deltas: Conv2d,
    pub num_anchors: usize,
}

/// Raw RPN output, levels concatenated, anchors ordered as [`super::anchors`] documents.
#[derive(Debug, Clone)]
pub struct RpnOutput {
    /// `[B, A_total]` objectness logits.
    pub logits: Tensor<2>,
    /// `[B, A_total, 4]` anchor deltas.
    pub deltas: Tensor<3>,
    /// `(stride, height, width)` of each level.
    pub levels: Vec<(usize, usize, usize)>,
}

impl RpnOutput {
    /// Levels' raw maps ([`RpnHead::forward_levels`], or an ONNX runtime's outputs)
    /// flattened and concatenated; `a` anchors per location.
    pub fn from_levels(maps: Vec<(Tensor<4>, Tensor<4>)>, strides: &[usize], a: usize) -> Self {
        let mut logits = Vec::new();
        let mut deltas = Vec::new();
        let mut levels = Vec::new();
        for ((o, d), &s) in maps.into_iter().zip(strides) {
            let [b, _, h, w] = o.dims();
            // [B, A, H, W] → [B, H, W, A] → [B, HWA]
            logits.push(o.permute([0, 2, 3, 1]).reshape([b, h * w * a]));
            // [B, 4A, H, W] → [B, A, 4, H, W] → [B, H, W, A, 4] → [B, HWA, 4]
            let d: Tensor<5> = d.reshape([b, a, 4, h, w]);
            deltas.push(d.permute([0, 3, 4, 1, 2]).reshape([b, h * w * a, 4]));
            levels.push((s, h, w));
        }
        RpnOutput {
            logits: Tensor::cat(logits, 1),
            deltas: Tensor::cat(deltas, 1),
            levels,
        }
    }
}

impl RpnHead {
    /// `channels`: the FPN's output channels; `num_anchors` per location.
    pub fn new(channels: usize, num_anchors: usize, device: &Device) -> Self {
        let small = Initializer::Normal {
            mean: 0.0,
            std: 0.01,
        };
        Self {
            conv: Conv2dConfig::new([channels, channels], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .with_initializer(small.clone())
                .init(device),
            objectness: Conv2dConfig::new([channels, num_anchors], [1, 1])
                .with_initializer(small.clone())
                .init(device),
            deltas: Conv2dConfig::new([channels, 4 * num_anchors], [1, 1])
                .with_initializer(small)
                .init(device),
            num_anchors,
        }
        .zero_biases()
    }

    fn zero_biases(mut self) -> Self {
        for c in [&mut self.conv, &mut self.objectness, &mut self.deltas] {
            if let Some(b) = c.bias.take() {
                c.bias = Some(b.map(|t| t.zeros_like()));
            }
        }
        self
    }

    /// # Shapes
    /// - `feats[l]`: `[B, C, H_l, W_l]` with stride `strides[l]`
    /// - returns logits `[B, Σ H_l W_l A]`, deltas `[B, Σ H_l W_l A, 4]`
    pub fn forward(&self, feats: &[Tensor<4>], strides: &[usize]) -> RpnOutput {
        RpnOutput::from_levels(self.forward_levels(feats), strides, self.num_anchors)
    }

    /// The head's raw maps per level, in torchvision's `RPNHead` layout (what the ONNX
    /// export outputs).
    ///
    /// # Shapes
    /// - `feats[l]`: `[B, C, H_l, W_l]` → objectness `[B, A, H_l, W_l]`, deltas `[B, 4A, H_l, W_l]`
    pub fn forward_levels(&self, feats: &[Tensor<4>]) -> Vec<(Tensor<4>, Tensor<4>)> {
        feats
            .iter()
            .map(|f| {
                let t = relu(self.conv.forward(f.clone()));
                (self.objectness.forward(t.clone()), self.deltas.forward(t))
            })
            .collect()
    }

    pub fn macs(&self, sizes: &[[usize; 2]]) -> u64 {
        sizes
            .iter()
            .map(|&hw| {
                conv_macs(&self.conv, hw).0
                    + conv_macs(&self.objectness, hw).0
                    + conv_macs(&self.deltas, hw).0
            })
            .sum()
    }
}

/// One proposal: xyxy box (input px) and its objectness logit.
pub type Proposal = ([f32; 4], f32);

/// Proposals of every image (host), sorted by objectness, at most `post_nms_topk`.
///
/// `anchors[l]` are the level's anchors; `image` is `[height, width]` for clipping.
pub fn find_proposals(
    out: &RpnOutput,
    anchors: &[Vec<[f32; 4]>],
    image: [usize; 2],
    pre_nms_topk: usize,
    post_nms_topk: usize,
    nms_iou: f32,
) -> Vec<Vec<Proposal>> {
    let [b, total] = out.logits.dims();
    let logits = to_host(out.logits.clone().detach());
    let deltas = to_host(out.deltas.clone().detach());
    let coder = BoxCoder::rpn();
    (0..b)
        .map(|i| {
            let mut cands: Vec<([f32; 4], f32, usize)> = Vec::new();
            let mut off = 0;
            for (l, anc) in anchors.iter().enumerate() {
                let n = anc.len();
                let lg = &logits[i * total + off..i * total + off + n];
                let mut idx: Vec<usize> = (0..n).filter(|&k| lg[k].is_finite()).collect();
                let k = pre_nms_topk.min(idx.len());
                if k < idx.len() {
                    idx.select_nth_unstable_by(k, |&x, &y| lg[y].total_cmp(&lg[x]));
                    idx.truncate(k);
                }
                for a in idx {
                    let g = (i * total + off + a) * 4;
                    let d = [deltas[g], deltas[g + 1], deltas[g + 2], deltas[g + 3]];
                    let bx = clip_box(coder.decode(d, anc[a]), image);
                    if bx[2] > bx[0] && bx[3] > bx[1] && bx.iter().all(|v| v.is_finite()) {
                        cands.push((bx, lg[a], l));
                    }
                }
                off += n;
            }
            // Levels as NMS classes: boxes compete only within their level (detectron2
            // `batched_nms(..., level_ids)`), then the best `post_nms_topk` overall.
            nms(&cands, nms_iou, post_nms_topk)
                .into_iter()
                .map(|k| (cands[k].0, cands[k].1))
                .collect()
        })
        .collect()
}

/// RPN objectness and box losses of a batch.
///
/// # Shapes
/// - returns `(objectness [1], deltas [1])`
pub fn rpn_loss<R: Rng>(
    out: &RpnOutput,
    anchors: &[Vec<[f32; 4]>],
    targets: &[ImageTargets],
    cfg: &RpnConfig,
    rng: &mut R,
) -> (Tensor<1>, Tensor<1>) {
    let device = out.logits.device();
    let [b, total] = out.logits.dims();
    let flat_anchors: Vec<[f32; 4]> = anchors.iter().flatten().copied().collect();
    assert_eq!(
        flat_anchors.len(),
        total,
        "rpn_loss: {} anchors for {total} outputs",
        flat_anchors.len()
    );
    let matcher = Matcher::rpn(cfg.bg_iou, cfg.fg_iou);
    let coder = BoxCoder::rpn();
    let (mut cls_idx, mut cls_lab, mut pos_idx, mut pos_tgt) = (vec![], vec![], vec![], vec![]);
    for (i, t) in targets.iter().enumerate() {
        let g = t.boxes.len();
        let iou = pairwise_iou(&t.boxes, &flat_anchors);
        let m = matcher.match_boxes(&iou, g, total);
        let s = subsample_labels(&m.labels, cfg.batch_per_image, cfg.positive_fraction, rng);
        for &a in &s.positive {
            cls_idx.push(i * total + a);
            cls_lab.push(1.0f32);
            pos_idx.push(i * total + a);
            pos_tgt.extend(coder.encode(flat_anchors[a], t.boxes[m.gt[a]]));
        }
        for &a in &s.negative {
            debug_assert_eq!(m.labels[a], NEGATIVE);
            cls_idx.push(i * total + a);
            cls_lab.push(0.0);
        }
        debug_assert!(s.positive.iter().all(|&a| m.labels[a] == POSITIVE));
    }
    let norm = (b * cfg.batch_per_image) as f64;
    let n = cls_idx.len();
    let cls = if n == 0 {
        Tensor::zeros([1], &device)
    } else {
        let x = out
            .logits
            .clone()
            .reshape([b * total])
            .select(0, index_tensor(&cls_idx, &device));
        bce_with_logits(x, host(cls_lab, [n], &device))
            .sum()
            .reshape([1])
            / norm
    };
    let np = pos_idx.len();
    let reg = if np == 0 {
        Tensor::zeros([1], &device)
    } else {
        let x = out
            .deltas
            .clone()
            .reshape([b * total, 4])
            .select(0, index_tensor(&pos_idx, &device));
        smooth_l1(x, host(pos_tgt, [np, 4], &device), cfg.smooth_l1_beta)
            .sum()
            .reshape([1])
            / norm
    };
    (cls, reg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Param;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Head whose output is its biases only: objectness `a`, delta `(a, k)` = `10a + k`.
    fn bias_only_head(d: &Device) -> RpnHead {
        let mut h = RpnHead::new(4, 3, d);
        h.objectness.weight = Param::from_tensor(h.objectness.weight.val().zeros_like());
        h.deltas.weight = Param::from_tensor(h.deltas.weight.val().zeros_like());
        h.objectness.bias = Some(Param::from_tensor(host(vec![0.0, 1.0, 2.0], [3], d)));
        let db: Vec<f32> = (0..3)
            .flat_map(|a| (0..4).map(move |k| (10 * a + k) as f32))
            .collect();
        h.deltas.bias = Some(Param::from_tensor(host(db, [12], d)));
        h
    }

    #[test]
    fn output_layout_matches_anchor_order() {
        let d = Device::flex();
        let h = bias_only_head(&d);
        let feats = vec![
            Tensor::ones([2, 4, 2, 3], &d),
            Tensor::ones([2, 4, 1, 2], &d),
        ];
        let out = h.forward(&feats, &[4, 8]);
        assert_eq!(out.logits.dims(), [2, (6 + 2) * 3]);
        assert_eq!(out.deltas.dims(), [2, (6 + 2) * 3, 4]);
        assert_eq!(out.levels, vec![(4, 2, 3), (8, 1, 2)]);
        let lg = to_host(out.logits);
        let dl = to_host(out.deltas);
        // Row r belongs to cell anchor r % 3 at every location of every level.
        for r in 0..24 {
            assert_eq!(lg[24 + r], (r % 3) as f32);
            for k in 0..4 {
                assert_eq!(dl[(24 + r) * 4 + k], (10 * (r % 3) + k) as f32);
            }
        }
    }

    #[test]
    fn proposals_are_top_n_per_level_and_nms_within_level() {
        let d = Device::flex();
        // Level 0: three anchors, two overlapping heavily; level 1: one anchor equal to the
        // first (different level, so NMS keeps both).
        let anchors = vec![
            vec![
                [0.0, 0.0, 20.0, 20.0],
                [1.0, 1.0, 21.0, 21.0],
                [40.0, 40.0, 60.0, 60.0],
            ],
            vec![[0.0, 0.0, 20.0, 20.0]],
        ];
        let out = RpnOutput {
            logits: host(vec![3.0, 2.0, 1.0, 0.5], [1, 4], &d),
            deltas: Tensor::zeros([1, 4, 4], &d),
            levels: vec![(4, 1, 3), (8, 1, 1)],
        };
        let p = find_proposals(&out, &anchors, [64, 64], 10, 10, 0.7);
        let boxes: Vec<[f32; 4]> = p[0].iter().map(|x| x.0).collect();
        assert_eq!(
            boxes,
            vec![
                [0.0, 0.0, 20.0, 20.0],
                [40.0, 40.0, 60.0, 60.0],
                [0.0, 0.0, 20.0, 20.0]
            ]
        );
        // Pre-NMS top-1 per level keeps one proposal from each level.
        let p = find_proposals(&out, &anchors, [64, 64], 1, 10, 0.7);
        assert_eq!(p[0].len(), 2);
        // Post-NMS top-N caps the total, best first; boxes are clipped to the image.
        let p = find_proposals(&out, &anchors, [50, 50], 10, 2, 0.7);
        assert_eq!(p[0].iter().map(|x| x.1).collect::<Vec<_>>(), vec![3.0, 1.0]);
        assert_eq!(p[0][1].0, [40.0, 40.0, 50.0, 50.0]);
    }

    #[test]
    fn loss_hand_values() {
        let d = Device::flex();
        // Four anchors, GT equal to anchor 0: one positive, three negatives sampled (batch 8).
        let anchors = vec![vec![
            [0.0, 0.0, 10.0, 10.0],
            [30.0, 30.0, 40.0, 40.0],
            [50.0, 0.0, 60.0, 10.0],
            [0.0, 50.0, 10.0, 60.0],
        ]];
        let out = RpnOutput {
            logits: Tensor::zeros([1, 4], &d),
            deltas: host(vec![0.5; 16], [1, 4, 4], &d),
            levels: vec![(4, 1, 4)],
        };
        let t = vec![ImageTargets {
            boxes: vec![[0.0, 0.0, 10.0, 10.0]],
            classes: vec![0],
            masks: vec![vec![]],
        }];
        let cfg = RpnConfig {
            batch_per_image: 8,
            ..RpnConfig::compact()
        };
        let (cls, reg) = rpn_loss(&out, &anchors, &t, &cfg, &mut ChaCha8Rng::seed_from_u64(0));
        // BCE at logit 0 is ln 2 for each of the 4 sampled anchors, / (1 image × 8).
        assert!((to_host(cls)[0] - 4.0 * 2f32.ln() / 8.0).abs() < 1e-6);
        // Target deltas are 0: L1 = 4 × 0.5 on the positive, / 8.
        assert!((to_host(reg)[0] - 2.0 / 8.0).abs() < 1e-6);
        // No GT: every sampled anchor is negative, no box loss.
        let empty = vec![ImageTargets::default()];
        let (cls, reg) = rpn_loss(
            &out,
            &anchors,
            &empty,
            &cfg,
            &mut ChaCha8Rng::seed_from_u64(0),
        );
        assert!((to_host(cls)[0] - 4.0 * 2f32.ln() / 8.0).abs() < 1e-6);
        assert_eq!(to_host(reg)[0], 0.0);
    }
}
