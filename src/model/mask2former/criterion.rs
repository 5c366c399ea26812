//! Mask2Former's set criterion (reference `criterion.py`, `SetCriterion`): at every
//! decoder layer (the final prediction and each auxiliary one) the queries are matched to
//! the ground truth ([`super::matcher`]), then
//!
//! - class: cross-entropy over `C + 1` classes, unmatched queries labelled no-object, the
//!   no-object class weighted `no_object_weight` (0.1) — PyTorch's weighted mean;
//! - mask: BCE and dice of the matched masks on K points picked by importance sampling
//!   ([`super::point_sample::importance_points`]: oversample 3, ratio 0.75), each summed
//!   over masks and divided by the number of ground-truth masks in the batch (at least 1).
//!
//! The layer losses are weighted (2, 5, 5 in the paper) and summed. Points and matching are
//! host work on detached copies; only the sampled logits carry gradients.

use burn::tensor::activation::sigmoid;
use burn::tensor::{Int, Tensor, TensorData};
use rand::Rng;

use super::matcher::{cost_matrix, match_queries, CostWeights};
use super::point_sample::{importance_points, sample_host, sample_mask, uniform_points, PointTaps};
use crate::annotations::targets::ImageTargets;
use crate::model::loss::{bce_with_logits, log_softmax_stable};
use crate::util::tensor::{host, to_host};

/// Loss options (the paper's values in [`CriterionConfig::paper`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CriterionConfig {
    pub class_weight: f32,
    pub mask_weight: f32,
    pub dice_weight: f32,
    pub no_object_weight: f32,
    /// K: points per mask for matching and for the mask losses (paper 12544 = 112²).
    pub points: usize,
    pub oversample: usize,
    pub importance_ratio: f32,
}

impl CriterionConfig {
    pub fn paper() -> Self {
        Self {
            class_weight: 2.0,
            mask_weight: 5.0,
            dice_weight: 5.0,
            no_object_weight: 0.1,
            points: 12544,
            oversample: 3,
            importance_ratio: 0.75,
        }
    }

    fn cost_weights(&self) -> CostWeights {
        CostWeights {
            class: self.class_weight as f64,
            mask: self.mask_weight as f64,
            dice: self.dice_weight as f64,
        }
    }
}

/// One layer's predictions.
#[derive(Debug, Clone)]
pub struct LayerOutput {
    /// `[B, Q, C + 1]`, last = no-object.
    pub class_logits: Tensor<3>,
    /// `[B, Q, h, w]` at stride 4 of the input.
    pub mask_logits: Tensor<4>,
}

/// The three weighted terms (summed over layers) and their total, each `[1]`.
#[derive(Debug, Clone)]
pub struct Mask2FormerLosses {
    pub class: Tensor<1>,
    pub mask: Tensor<1>,
    pub dice: Tensor<1>,
    pub total: Tensor<1>,
    /// Matched queries of the last layer.
    pub matched: usize,
}

impl Mask2FormerLosses {
    pub const NAMES: [&'static str; 3] = ["cls", "mask", "dice"];

    /// Host values in [`Self::NAMES`] order, then the total (syncs the device).
    pub fn values(&self) -> [f32; 4] {
        let v = |t: &Tensor<1>| to_host(t.clone())[0];
        [v(&self.class), v(&self.mask), v(&self.dice), v(&self.total)]
    }
}

/// Mean BCE over the K points of each mask, summed over masks, over `num_masks`.
///
/// # Shapes
/// - `logits`, `labels`: `[N, K]` → `[1]`
pub fn sigmoid_ce_loss(logits: Tensor<2>, labels: Tensor<2>, num_masks: f32) -> Tensor<1> {
    bce_with_logits(logits, labels).mean_dim(1).sum() / num_masks
}

/// `1 − (2·|p∩y| + 1) / (|p| + |y| + 1)` of each mask on its points (p = sigmoid),
/// summed over masks, over `num_masks`.
///
/// # Shapes
/// - `logits`, `labels`: `[N, K]` → `[1]`
pub fn dice_loss(logits: Tensor<2>, labels: Tensor<2>, num_masks: f32) -> Tensor<1> {
    let p = sigmoid(logits);
    let num = (p.clone() * labels.clone()).sum_dim(1) * 2.0 + 1.0;
    let den = p.sum_dim(1) + labels.sum_dim(1) + 1.0;
    (num / den).neg().add_scalar(1.0).sum() / num_masks
}

/// Weighted cross-entropy of the class logits (PyTorch's `cross_entropy(weight=…)`:
/// `Σ w_i·nll_i / Σ w_i`); the no-object class (index `C`) has weight `no_object_weight`.
///
/// # Shapes
/// - `logits`: `[B, Q, C + 1]`, `targets`: `B·Q` class indices `≤ C` → `[1]`
pub fn class_loss(logits: Tensor<3>, targets: &[usize], no_object_weight: f32) -> Tensor<1> {
    let [b, q, c1] = logits.dims();
    assert_eq!(
        targets.len(),
        b * q,
        "class_loss: {} targets for {b}×{q} queries",
        targets.len()
    );
    let mut w = vec![0.0f32; b * q * c1];
    let mut total = 0.0f32;
    for (i, &t) in targets.iter().enumerate() {
        let wt = if t + 1 == c1 { no_object_weight } else { 1.0 };
        w[i * c1 + t] = wt;
        total += wt;
    }
    let device = logits.device();
    let w: Tensor<2> = host(w, [b * q, c1], &device);
    let logp = log_softmax_stable(logits.reshape([b * q, c1]), 1);
    (logp * w).sum().neg() / total.max(f32::MIN_POSITIVE)
}

/// Losses of all layers for a batch at input size `[H, W]` (target masks are `H·W` bytes).
/// `rng` draws the matching and loss points.
pub fn set_criterion<R: Rng>(
    layers: &[LayerOutput],
    targets: &[ImageTargets],
    [ih, iw]: [usize; 2],
    cfg: &CriterionConfig,
    rng: &mut R,
) -> Mask2FormerLosses {
    let device = layers[0].class_logits.device();
    let num_masks = targets.iter().map(|t| t.masks.len()).sum::<usize>().max(1) as f32;
    let zero = || Tensor::<1>::zeros([1], &device);
    let (mut lc, mut lm, mut ld) = (zero(), zero(), zero());
    let mut matched = 0;
    for layer in layers {
        let [b, q, c1] = layer.class_logits.dims();
        let [_, _, h, w] = layer.mask_logits.dims();
        let cls_h = to_host(layer.class_logits.clone().detach());
        let mask_h = to_host(layer.mask_logits.clone().detach());
        let hw = h * w;
        let mut cls_t = vec![c1 - 1; b * q];
        // (row in [B·Q], image, target)
        let mut pairs: Vec<(usize, usize, usize)> = Vec::new();
        for (bi, t) in targets.iter().enumerate() {
            let nt = t.masks.len();
            if nt == 0 {
                continue;
            }
            let pts = uniform_points(cfg.points, rng);
            let tgt: Vec<f32> = t
                .masks
                .iter()
                .flat_map(|m| sample_mask(m, ih, iw, &pts))
                .collect();
            let pred: Vec<f32> = (0..q)
                .flat_map(|qi| {
                    let m = &mask_h[(bi * q + qi) * hw..(bi * q + qi + 1) * hw];
                    pts.iter().map(move |&p| sample_host(m, h, w, p))
                })
                .collect();
            let cost = cost_matrix(
                &cls_h[bi * q * c1..(bi + 1) * q * c1],
                &pred,
                &t.classes,
                &tgt,
                cfg.points,
                cfg.cost_weights(),
            );
            for (qi, ti) in match_queries(&cost, q, nt) {
                cls_t[bi * q + qi] = t.classes[ti];
                pairs.push((bi * q + qi, bi, ti));
            }
        }
        matched = pairs.len();
        lc = lc
            + class_loss(layer.class_logits.clone(), &cls_t, cfg.no_object_weight)
                * cfg.class_weight;
        if pairs.is_empty() {
            continue;
        }
        let pts: Vec<Vec<_>> = pairs
            .iter()
            .map(|&(r, _, _)| {
                importance_points(
                    &mask_h[r * hw..(r + 1) * hw],
                    h,
                    w,
                    cfg.points,
                    cfg.oversample,
                    cfg.importance_ratio,
                    rng,
                )
            })
            .collect();
        let labels: Vec<f32> = pairs
            .iter()
            .zip(&pts)
            .flat_map(|(&(_, bi, ti), p)| sample_mask(&targets[bi].masks[ti], ih, iw, p))
            .collect();
        let n = pairs.len();
        let rows: Tensor<1, Int> = Tensor::from_data(
            TensorData::new(pairs.iter().map(|p| p.0 as i64).collect::<Vec<_>>(), [n]),
            &device,
        );
        let src = layer
            .mask_logits
            .clone()
            .reshape([b * q, hw])
            .select(0, rows);
        let logits = PointTaps::new(&pts, h, w).sample(src);
        let labels: Tensor<2> = host(labels, [n, cfg.points], &device);
        lm = lm + sigmoid_ce_loss(logits.clone(), labels.clone(), num_masks) * cfg.mask_weight;
        ld = ld + dice_loss(logits, labels, num_masks) * cfg.dice_weight;
    }
    let total = lc.clone() + lm.clone() + ld.clone();
    Mask2FormerLosses {
        class: lc,
        mask: lm,
        dice: ld,
        total,
        matched,
    }
}

#[cfg(test)]
mod tests {
    use super::super::fixture::{points_losses, vecf};
    use super::*;
    use burn::tensor::Device;

    fn close(a: &[f32], b: &[f32], tol: f32) {
        assert_eq!(a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() <= tol * y.abs().max(1.0), "{i}: {x} vs {y}");
        }
    }

    #[test]
    fn point_sample_equals_grid_sample() {
        let f = points_losses();
        let d = Device::flex();
        let u = |k: &str| f[k].as_u64().unwrap() as usize;
        let (n, k, h, w) = (u("n"), u("k"), u("h"), u("w"));
        let c = vecf(&f["coords"]);
        let pts: Vec<Vec<[f32; 2]>> = (0..n)
            .map(|i| {
                (0..k)
                    .map(|j| [c[(i * k + j) * 2], c[(i * k + j) * 2 + 1]])
                    .collect()
            })
            .collect();
        let logits: Tensor<2> = host(vecf(&f["logits"]), [n, h * w], &d);
        let got = to_host(PointTaps::new(&pts, h, w).sample(logits));
        close(&got, &vecf(&f["sampled"]), 1e-5);
        let (mh, mw) = (u("mask_h"), u("mask_w"));
        let mask: Vec<u8> = vecf(&f["mask"]).iter().map(|&v| v as u8).collect();
        let got: Vec<f32> = (0..n)
            .flat_map(|i| sample_mask(&mask[i * mh * mw..(i + 1) * mh * mw], mh, mw, &pts[i]))
            .collect();
        close(&got, &vecf(&f["mask_sampled"]), 1e-5);
    }

    #[test]
    fn bce_dice_and_class_loss_equal_the_reference() {
        let f = points_losses();
        let d = Device::flex();
        let (n, k) = (
            f["n"].as_u64().unwrap() as usize,
            f["k"].as_u64().unwrap() as usize,
        );
        let x: Tensor<2> = host(vecf(&f["sampled"]), [n, k], &d);
        let y: Tensor<2> = host(vecf(&f["mask_sampled"]), [n, k], &d);
        let nm = f["num_masks"].as_f64().unwrap() as f32;
        let ce = to_host(sigmoid_ce_loss(x.clone(), y.clone(), nm))[0];
        let dice = to_host(dice_loss(x, y, nm))[0];
        close(&[ce], &[f["sigmoid_ce"].as_f64().unwrap() as f32], 1e-5);
        close(&[dice], &[f["dice"].as_f64().unwrap() as f32], 1e-5);
        let cl = &f["class_loss"];
        let t: Vec<usize> = cl["targets"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let logits: Tensor<3> = host(vecf(&cl["logits"]), [2, 3, 3], &d);
        let got = to_host(class_loss(logits, &t, 0.1))[0];
        close(&[got], &[cl["ce"].as_f64().unwrap() as f32], 1e-5);
    }

    #[test]
    fn losses_at_extreme_logits_are_finite() {
        let d = Device::flex();
        let x: Tensor<2> = host(vec![1e4, -1e4, 1e4, -1e4], [2, 2], &d);
        let y: Tensor<2> = host(vec![0.0, 1.0, 1.0, 0.0], [2, 2], &d);
        let ce = to_host(sigmoid_ce_loss(x.clone(), y.clone(), 1.0))[0];
        let dice = to_host(dice_loss(x, y, 1.0))[0];
        // Row 0 wrong by 1e4 at both points, row 1 right: mean BCE 1e4 + 0.
        assert!((ce - 1e4).abs() < 1.0, "{ce}");
        assert!(dice.is_finite() && dice > 0.0, "{dice}");
        let l: Tensor<3> = host(vec![1e4, -1e4, 0.0, -1e4, 1e4, 0.0], [1, 2, 3], &d);
        let c = to_host(class_loss(l, &[1, 2], 0.1))[0];
        assert!(c.is_finite() && c > 0.0, "{c}");
    }
}
