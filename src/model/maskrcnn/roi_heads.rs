//! Box branch of the RoI heads (detectron2 `roi_heads/roi_heads.py` `StandardROIHeads`,
//! `box_head.py` `FastRCNNConvFCHead`, `fast_rcnn.py` `FastRCNNOutputLayers`):
//!
//! - training targets: proposals plus the GT boxes, matched at IoU 0.5 (no low-quality
//!   matches), `batch_per_image` sampled with 25 % foreground, background class = `nc`
//!   ([`label_and_sample`]);
//! - the head: flatten → `num_fc` × (FC + ReLU) → class logits (`nc + 1`) and box deltas
//!   (`4·nc` class-specific, or 4 class-agnostic) ([`BoxHead`]);
//! - losses: softmax CE over the sampled RoIs, smooth-L1 / L1 of the foreground deltas of
//!   the GT class summed and divided by the number of sampled RoIs ([`box_loss`]);
//! - inference: softmax scores, per-class decoding, score threshold, class-wise NMS,
//!   top-k per image ([`box_inference`]).

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::{relu, softmax};
use burn::tensor::{Device, Tensor};
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::box_coder::{clip_box, BoxCoder};
use super::losses::{cross_entropy, one_hot, smooth_l1};
use super::matcher::{pairwise_iou, Matcher};
use super::roi_align::index_tensor;
use super::rpn::Proposal;
use super::sampler::subsample_labels;
use crate::annotations::targets::ImageTargets;
use crate::model::detection::nms;
use crate::util::tensor::{host, to_host};

/// RoI-head hyper-parameters (detectron2 `MODEL.ROI_HEADS.*`, `MODEL.ROI_BOX_HEAD.*`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoiHeadsConfig {
    /// IoU from which a proposal is foreground.
    pub fg_iou: f32,
    pub batch_per_image: usize,
    pub positive_fraction: f32,
    /// RoIAlign output side of the box branch (7).
    pub pool_size: usize,
    /// RoIAlign samples per bin side (2).
    pub sampling_ratio: usize,
    pub fc_dim: usize,
    pub num_fc: usize,
    pub class_agnostic_box: bool,
    /// Smooth-L1 β of the box loss (0 = L1, detectron2's default; torchvision uses 1/9).
    pub smooth_l1_beta: f32,
    /// Inference: minimum class score, class-wise NMS IoU, detections per image.
    pub score_thresh: f32,
    pub nms_iou: f32,
    pub max_det: usize,
}

impl RoiHeadsConfig {
    /// detectron2 R50-FPN: 512 RoIs per image, two 1024-wide FCs.
    pub fn paper() -> Self {
        Self {
            fg_iou: 0.5,
            batch_per_image: 512,
            positive_fraction: 0.25,
            pool_size: 7,
            sampling_ratio: 2,
            fc_dim: 1024,
            num_fc: 2,
            class_agnostic_box: false,
            smooth_l1_beta: 0.0,
            score_thresh: 0.05,
            nms_iou: 0.5,
            max_det: 100,
        }
    }

    /// Scene-sized: 128 RoIs per image, 256-wide FCs.
    pub fn compact() -> Self {
        Self {
            batch_per_image: 128,
            fc_dim: 256,
            ..Self::paper()
        }
    }

    pub fn validate(&self) {
        assert!(
            self.batch_per_image > 0 && self.pool_size > 0 && self.sampling_ratio > 0 && self.fc_dim > 0 && self.max_det > 0,
            "RoiHeadsConfig: batch_per_image, pool_size, sampling_ratio, fc_dim and max_det must be > 0, got {self:?}"
        );
        assert!(
            (0.0..=1.0).contains(&self.fg_iou)
                && (0.0..=1.0).contains(&self.positive_fraction)
                && (0.0..=1.0).contains(&self.nms_iou),
            "RoiHeadsConfig: fg_iou, positive_fraction and nms_iou must be in [0, 1], got {} {} {}",
            self.fg_iou,
            self.positive_fraction,
            self.nms_iou
        );
    }
}

/// Box head and predictor.
#[derive(Module, Debug)]
pub struct BoxHead {
    pub fcs: Vec<Linear>,
    pub cls_score: Linear,
    pub bbox_pred: Linear,
    pub num_classes: usize,
    pub class_agnostic: bool,
}

impl BoxHead {
    /// `in_features = C · pool²` of the pooled features.
    pub fn new(
        in_features: usize,
        cfg: &RoiHeadsConfig,
        num_classes: usize,
        device: &Device,
    ) -> Self {
        let mut fcs = Vec::new();
        let mut d = in_features;
        for _ in 0..cfg.num_fc {
            // c2_xavier_fill ≈ Kaiming-uniform with gain 1 (detectron2 `weight_init.py`).
            fcs.push(
                LinearConfig::new(d, cfg.fc_dim)
                    .with_initializer(Initializer::KaimingUniform {
                        gain: 1.0,
                        fan_out_only: false,
                    })
                    .init(device),
            );
            d = cfg.fc_dim;
        }
        let nb = if cfg.class_agnostic_box {
            1
        } else {
            num_classes
        };
        Self {
            fcs,
            cls_score: LinearConfig::new(d, num_classes + 1)
                .with_initializer(Initializer::Normal {
                    mean: 0.0,
                    std: 0.01,
                })
                .init(device),
            bbox_pred: LinearConfig::new(d, 4 * nb)
                .with_initializer(Initializer::Normal {
                    mean: 0.0,
                    std: 0.001,
                })
                .init(device),
            num_classes,
            class_agnostic: cfg.class_agnostic_box,
        }
    }

    /// # Shapes
    /// - `x`: `[N, C, P, P]` → class logits `[N, nc + 1]`, deltas `[N, 4·nc]` (or `[N, 4]`)
    pub fn forward(&self, x: Tensor<4>) -> (Tensor<2>, Tensor<2>) {
        let x: Tensor<2> = x.flatten(1, 3);
        let x = self.fcs.iter().fold(x, |x, fc| relu(fc.forward(x)));
        (self.cls_score.forward(x.clone()), self.bbox_pred.forward(x))
    }

    pub fn macs(&self, num_rois: usize) -> u64 {
        let lin = |l: &Linear| {
            let [i, o] = l.weight.dims();
            (i * o) as u64
        };
        let per: u64 =
            self.fcs.iter().map(lin).sum::<u64>() + lin(&self.cls_score) + lin(&self.bbox_pred);
        per * num_rois as u64
    }
}

/// Sampled RoIs of a batch (all images, image-major) with their training targets.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SampledRois {
    /// `(image, xyxy)`.
    pub rois: Vec<(usize, [f32; 4])>,
    /// Class in `0..nc`, or `nc` for background.
    pub classes: Vec<usize>,
    /// Matched GT index in its image (meaningful for foreground only).
    pub gt: Vec<usize>,
}

impl SampledRois {
    pub fn foreground(&self, num_classes: usize) -> Vec<usize> {
        (0..self.classes.len())
            .filter(|&i| self.classes[i] < num_classes)
            .collect()
    }
}

/// Adds the GT boxes to each image's proposals, matches and samples them (see module docs).
pub fn label_and_sample<R: Rng>(
    proposals: &[Vec<Proposal>],
    targets: &[ImageTargets],
    cfg: &RoiHeadsConfig,
    num_classes: usize,
    rng: &mut R,
) -> SampledRois {
    let matcher = Matcher::roi(cfg.fg_iou);
    let mut out = SampledRois::default();
    for (i, (props, t)) in proposals.iter().zip(targets).enumerate() {
        let mut boxes: Vec<[f32; 4]> = props.iter().map(|p| p.0).collect();
        boxes.extend(t.boxes.iter().copied());
        let (g, n) = (t.boxes.len(), boxes.len());
        let m = matcher.match_boxes(&pairwise_iou(&t.boxes, &boxes), g, n);
        let s = subsample_labels(&m.labels, cfg.batch_per_image, cfg.positive_fraction, rng);
        for &k in &s.positive {
            let c = t.classes[m.gt[k]];
            assert!(
                c < num_classes,
                "label_and_sample: class {c} in image {i} is not < {num_classes}"
            );
            out.rois.push((i, boxes[k]));
            out.classes.push(c);
            out.gt.push(m.gt[k]);
        }
        for &k in &s.negative {
            out.rois.push((i, boxes[k]));
            out.classes.push(num_classes);
            out.gt.push(0);
        }
    }
    out
}

/// Box-branch losses `(classification [1], box regression [1])`.
///
/// # Shapes
/// - `cls`: `[N, nc + 1]`, `deltas`: `[N, 4·nc]` or `[N, 4]`, `N = sampled.rois.len()`
pub fn box_loss(
    cls: Tensor<2>,
    deltas: Tensor<2>,
    sampled: &SampledRois,
    targets: &[ImageTargets],
    cfg: &RoiHeadsConfig,
    num_classes: usize,
) -> (Tensor<1>, Tensor<1>) {
    let device = cls.device();
    let n = sampled.rois.len();
    if n == 0 {
        return (Tensor::zeros([1], &device), Tensor::zeros([1], &device));
    }
    let ce = cross_entropy(cls, &sampled.classes);
    let fg = sampled.foreground(num_classes);
    if fg.is_empty() {
        return (ce, Tensor::zeros([1], &device));
    }
    let coder = BoxCoder::roi();
    let mut tgt = Vec::with_capacity(fg.len() * 4);
    for &k in &fg {
        let (img, r) = sampled.rois[k];
        tgt.extend(coder.encode(r, targets[img].boxes[sampled.gt[k]]));
    }
    let f = fg.len();
    let d = deltas.select(0, index_tensor(&fg, &device));
    let d = if cfg.class_agnostic_box {
        d
    } else {
        let cls_fg: Vec<usize> = fg.iter().map(|&k| sampled.classes[k]).collect();
        let oh: Tensor<3> = one_hot(&cls_fg, num_classes, &device).reshape([f, num_classes, 1]);
        (d.reshape([f, num_classes, 4]) * oh)
            .sum_dim(1)
            .reshape([f, 4])
    };
    let reg = smooth_l1(d, host(tgt, [f, 4], &device), cfg.smooth_l1_beta)
        .sum()
        .reshape([1])
        / n as f64;
    (ce, reg)
}

/// One detection before masks: xyxy, score, class.
pub type BoxDetection = ([f32; 4], f32, usize);

/// Per-image detections from the box branch (see module docs).
///
/// # Shapes
/// - `cls`: `[N, nc + 1]`, `deltas`: `[N, 4·nc]` or `[N, 4]`, rows of `rois`
pub fn box_inference(
    cls: Tensor<2>,
    deltas: Tensor<2>,
    rois: &[(usize, [f32; 4])],
    num_images: usize,
    image: [usize; 2],
    cfg: &RoiHeadsConfig,
) -> Vec<Vec<BoxDetection>> {
    let [n, k1] = cls.dims();
    let nc = k1 - 1;
    let nd = deltas.dims()[1] / 4;
    let probs = to_host(softmax(cls, 1));
    let deltas = to_host(deltas);
    let coder = BoxCoder::roi();
    let mut per_image: Vec<Vec<BoxDetection>> = vec![Vec::new(); num_images];
    for r in 0..n {
        let (img, roi) = rois[r];
        for c in 0..nc {
            let s = probs[r * k1 + c];
            if !(s > cfg.score_thresh) {
                continue;
            }
            let j = if nd == 1 { 0 } else { c };
            let g = (r * nd + j) * 4;
            let d = [deltas[g], deltas[g + 1], deltas[g + 2], deltas[g + 3]];
            let b = clip_box(coder.decode(d, roi), image);
            if b[2] > b[0] && b[3] > b[1] && b.iter().all(|v| v.is_finite()) {
                per_image[img].push((b, s, c));
            }
        }
    }
    per_image
        .into_iter()
        .map(|c| {
            nms(&c, cfg.nms_iou, cfg.max_det)
                .into_iter()
                .map(|k| c[k])
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn target(boxes: Vec<[f32; 4]>) -> ImageTargets {
        let n = boxes.len();
        ImageTargets {
            boxes,
            classes: vec![0; n],
            masks: vec![Vec::new(); n],
        }
    }

    #[test]
    fn gt_boxes_are_always_sampled_positive() {
        let cfg = RoiHeadsConfig::compact();
        let t = vec![target(vec![[10.0, 10.0, 40.0, 50.0]]), target(vec![])];
        let props = vec![
            vec![
                ([60.0, 60.0, 90.0, 90.0], 1.0),
                ([12.0, 10.0, 40.0, 52.0], 0.5),
            ],
            vec![([0.0, 0.0, 9.0, 9.0], 0.1)],
        ];
        let s = label_and_sample(&props, &t, &cfg, 1, &mut ChaCha8Rng::seed_from_u64(0));
        // Image 0: the GT itself and the 0.9-IoU proposal are foreground, one background.
        assert_eq!(s.rois.len(), 4);
        assert_eq!(s.foreground(1).len(), 2);
        assert!(s.rois.iter().any(|r| r.1 == [10.0, 10.0, 40.0, 50.0]));
        // Image 1 has no GT: background only.
        let img1: Vec<usize> = (0..4).filter(|&i| s.rois[i].0 == 1).collect();
        assert_eq!(img1.len(), 1);
        assert_eq!(s.classes[img1[0]], 1);
    }

    #[test]
    fn perfect_prediction_has_small_loss_and_exact_boxes() {
        let d = Device::flex();
        let cfg = RoiHeadsConfig {
            class_agnostic_box: false,
            ..RoiHeadsConfig::compact()
        };
        let t = vec![target(vec![[10.0, 10.0, 40.0, 50.0]])];
        let sampled = SampledRois {
            rois: vec![(0, [12.0, 8.0, 44.0, 50.0]), (0, [70.0, 70.0, 90.0, 90.0])],
            classes: vec![0, 1],
            gt: vec![0, 0],
        };
        let tg = BoxCoder::roi().encode([12.0, 8.0, 44.0, 50.0], [10.0, 10.0, 40.0, 50.0]);
        let cls = host(vec![20.0, -20.0, -20.0, 20.0], [2, 2], &d);
        let deltas = host(
            vec![tg[0], tg[1], tg[2], tg[3], 0.0, 0.0, 0.0, 0.0],
            [2, 4],
            &d,
        );
        let (ce, reg) = box_loss(cls.clone(), deltas.clone(), &sampled, &t, &cfg, 1);
        assert!(to_host(ce)[0] < 1e-6 && to_host(reg)[0] < 1e-5);
        let dets = box_inference(cls, deltas, &sampled.rois, 1, [100, 100], &cfg);
        assert_eq!(dets[0].len(), 1);
        let (b, s, c) = dets[0][0];
        assert!(c == 0 && s > 0.99);
        assert!(
            b.iter()
                .zip([10.0, 10.0, 40.0, 50.0])
                .all(|(x, y)| (x - y).abs() < 1e-3),
            "{b:?}"
        );
    }
}
