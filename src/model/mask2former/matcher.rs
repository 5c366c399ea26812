//! Mask2Former's bipartite matcher (reference `matcher.py`, `HungarianMatcher`): per image
//! a cost `w_class·(−p(class)) + w_mask·BCE + w_dice·dice` between every query and every
//! ground-truth instance, with BCE and dice computed on the same K uniform points for all
//! pairs, then the minimum-cost one-to-one assignment ([`crate::util::hungarian`]).
//!
//! Runs on host copies of the detached predictions, in f64 (no gradient, as the
//! reference's `torch.no_grad()`).

use crate::util::hungarian::linear_sum_assignment;

/// Weights of the three matching costs (the paper: class 2, mask 5, dice 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CostWeights {
    pub class: f64,
    pub mask: f64,
    pub dice: f64,
}

/// Softplus `log(1 + e^x)` without overflow.
fn softplus(x: f64) -> f64 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

/// The `Q × T` cost matrix, row-major.
///
/// - `class_logits`: `Q × (C+1)` (last = no-object); `pred_points`: `Q × K` mask logits
/// - `target_classes`: `T` classes `< C`; `target_points`: `T × K` labels in `[0, 1]`
///
/// A NaN prediction (a diverged model) would make the assignment undefined: its costs
/// become `1e30`, the matching stays defined and the NaN loss reaches the trainer's
/// divergence guard instead of a panic here.
pub fn cost_matrix(
    class_logits: &[f32],
    pred_points: &[f32],
    target_classes: &[usize],
    target_points: &[f32],
    points: usize,
    w: CostWeights,
) -> Vec<f64> {
    let t = target_classes.len();
    let k = points;
    let q = if k == 0 { 0 } else { pred_points.len() / k };
    let c1 = if q == 0 { 0 } else { class_logits.len() / q };
    let mut cost = vec![0.0f64; q * t];
    let tsum: Vec<f64> = (0..t)
        .map(|j| {
            target_points[j * k..(j + 1) * k]
                .iter()
                .map(|&v| v as f64)
                .sum()
        })
        .collect();
    for i in 0..q {
        let row = &class_logits[i * c1..(i + 1) * c1];
        let m = row.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b as f64));
        let z: f64 = row.iter().map(|&v| (v as f64 - m).exp()).sum();
        let x = &pred_points[i * k..(i + 1) * k];
        let pos: Vec<f64> = x.iter().map(|&v| softplus(-(v as f64))).collect();
        let neg: Vec<f64> = x.iter().map(|&v| softplus(v as f64)).collect();
        let sig: Vec<f64> = x
            .iter()
            .map(|&v| 1.0 / (1.0 + (-(v as f64)).exp()))
            .collect();
        let ssum: f64 = sig.iter().sum();
        for j in 0..t {
            let p = ((row[target_classes[j]] as f64) - m).exp() / z;
            let y = &target_points[j * k..(j + 1) * k];
            let (mut ce, mut inter) = (0.0, 0.0);
            for kk in 0..k {
                let yk = y[kk] as f64;
                ce += pos[kk] * yk + neg[kk] * (1.0 - yk);
                inter += sig[kk] * yk;
            }
            let dice = 1.0 - (2.0 * inter + 1.0) / (ssum + tsum[j] + 1.0);
            let c = w.class * -p + w.mask * ce / k.max(1) as f64 + w.dice * dice;
            cost[i * t + j] = if c.is_finite() { c } else { 1e30 };
        }
    }
    cost
}

/// `(query, target)` pairs of the minimum-cost matching (`min(Q, T)` pairs).
pub fn match_queries(cost: &[f64], queries: usize, targets: usize) -> Vec<(usize, usize)> {
    // Every entry is finite (see `cost_matrix`), so the solver cannot fail.
    linear_sum_assignment(cost, queries, targets)
        .unwrap_or_else(|e| unreachable!("finite {queries}×{targets} cost matrix rejected: {e}"))
}

#[cfg(test)]
mod tests {
    use super::super::fixture::{points_losses, vecf};
    use super::*;

    #[test]
    fn costs_and_assignment_equal_the_reference() {
        let f = points_losses();
        let m = &f["matcher"];
        let u = |k: &str| m[k].as_u64().unwrap() as usize;
        let (q, t, k) = (u("queries"), u("targets"), u("points"));
        let tc: Vec<usize> = m["target_classes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let w = CostWeights {
            class: 2.0,
            mask: 5.0,
            dice: 5.0,
        };
        let c = cost_matrix(
            &vecf(&m["class_logits"]),
            &vecf(&m["pred_points"]),
            &tc,
            &vecf(&m["target_points"]),
            k,
            w,
        );
        let want: Vec<f64> = m["cost"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for (i, (a, b)) in c.iter().zip(&want).enumerate() {
            assert!(
                (a - b).abs() < 1e-4 * b.abs().max(1.0),
                "cost {i}: {a} vs {b}"
            );
        }
        let pairs = match_queries(&c, q, t);
        let rows: Vec<usize> = pairs.iter().map(|p| p.0).collect();
        let cols: Vec<usize> = pairs.iter().map(|p| p.1).collect();
        let r: Vec<usize> = m["rows"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let cc: Vec<usize> = m["cols"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        assert_eq!((rows, cols), (r, cc));
    }

    #[test]
    fn empty_targets_and_nan_predictions() {
        let w = CostWeights {
            class: 2.0,
            mask: 5.0,
            dice: 5.0,
        };
        let c = cost_matrix(&[0.0; 6], &[0.0; 8], &[], &[], 4, w);
        assert!(c.is_empty());
        assert!(match_queries(&c, 2, 0).is_empty());
        let c = cost_matrix(&[f32::NAN; 6], &[f32::NAN; 8], &[0], &[1.0; 4], 4, w);
        assert_eq!(c, vec![1e30, 1e30]);
        assert_eq!(match_queries(&c, 2, 1).len(), 1);
    }
}
