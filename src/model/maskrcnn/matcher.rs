//! IoU-threshold matcher (detectron2 `modeling/matcher.py`): assigns every predicted box
//! (anchor or proposal) its best ground-truth box and a label from IoU thresholds, with
//! optional "low-quality" matches so that every GT keeps at least its best prediction.
//!
//! Plain Rust over host vectors, no gradients. The pairwise IoU matrix is `G × N`
//! row-major (GT rows, prediction columns), like detectron2's `match_quality_matrix`.

use crate::model::detection::box_iou;

/// Label of an ignored prediction (between the thresholds of the RPN matcher).
pub const IGNORE: i8 = -1;
/// Label of a background prediction.
pub const NEGATIVE: i8 = 0;
/// Label of a foreground prediction.
pub const POSITIVE: i8 = 1;

/// Pairwise IoU of `gt` (rows) and `boxes` (columns), all xyxy: `G × N` row-major.
pub fn pairwise_iou(gt: &[[f32; 4]], boxes: &[[f32; 4]]) -> Vec<f32> {
    let mut m = Vec::with_capacity(gt.len() * boxes.len());
    for g in gt {
        m.extend(boxes.iter().map(|b| box_iou(*g, *b)));
    }
    m
}

/// Matcher with thresholds `t_1 < … < t_k` and `k + 1` labels: IoU in `[t_i, t_{i+1})` gets
/// `labels[i]` (with `t_0 = −∞`, `t_{k+1} = +∞`).
#[derive(Debug, Clone, PartialEq)]
pub struct Matcher {
    pub thresholds: Vec<f32>,
    pub labels: Vec<i8>,
    pub allow_low_quality_matches: bool,
}

/// Result of [`Matcher::match_boxes`], one entry per prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct Matches {
    /// Index of the best GT (0 when there is no GT).
    pub gt: Vec<usize>,
    /// [`NEGATIVE`], [`IGNORE`] or [`POSITIVE`].
    pub labels: Vec<i8>,
}

impl Matcher {
    /// Panics naming the values unless thresholds increase and `labels.len() ==
    /// thresholds.len() + 1` with every label in {-1, 0, 1}.
    pub fn new(thresholds: Vec<f32>, labels: Vec<i8>, allow_low_quality_matches: bool) -> Self {
        assert!(
            !thresholds.is_empty() && thresholds.windows(2).all(|w| w[0] <= w[1]),
            "Matcher: thresholds must be non-empty and non-decreasing, got {thresholds:?}"
        );
        assert!(
            labels.len() == thresholds.len() + 1
                && labels.iter().all(|l| [IGNORE, NEGATIVE, POSITIVE].contains(l)),
            "Matcher: need thresholds.len() + 1 labels in {{-1, 0, 1}}, got thresholds {thresholds:?} labels {labels:?}"
        );
        Self {
            thresholds,
            labels,
            allow_low_quality_matches,
        }
    }

    /// RPN matcher: background below `bg`, ignored in `[bg, fg)`, foreground from `fg`,
    /// low-quality matches on (detectron2 `MODEL.RPN.IOU_THRESHOLDS` [0.3, 0.7]).
    pub fn rpn(bg: f32, fg: f32) -> Self {
        Self::new(vec![bg, fg], vec![NEGATIVE, IGNORE, POSITIVE], true)
    }

    /// RoI-head matcher: foreground from `fg` (detectron2 0.5), no low-quality matches.
    pub fn roi(fg: f32) -> Self {
        Self::new(vec![fg], vec![NEGATIVE, POSITIVE], false)
    }

    /// Matches `n` predictions against `g` GT boxes given the `g × n` IoU matrix.
    ///
    /// With no GT every prediction is labelled `labels[0]` (background), the explicit
    /// empty path of detectron2. Low-quality matches: each GT whose best IoU is positive
    /// turns every prediction reaching that IoU positive (detectron2 also does this for a
    /// best IoU of 0, which would mark unrelated boxes; we skip those GTs).
    pub fn match_boxes(&self, iou: &[f32], g: usize, n: usize) -> Matches {
        assert_eq!(
            iou.len(),
            g * n,
            "Matcher: IoU matrix has {} values, expected {g} × {n}",
            iou.len()
        );
        if g == 0 {
            return Matches {
                gt: vec![0; n],
                labels: vec![self.labels[0]; n],
            };
        }
        let mut gt = vec![0usize; n];
        let mut best = vec![f32::NEG_INFINITY; n];
        for j in 0..g {
            for i in 0..n {
                let v = iou[j * n + i];
                if v > best[i] {
                    best[i] = v;
                    gt[i] = j;
                }
            }
        }
        let mut labels: Vec<i8> = best
            .iter()
            .map(|&v| {
                let k = self.thresholds.iter().filter(|&&t| v >= t).count();
                self.labels[k]
            })
            .collect();
        if self.allow_low_quality_matches {
            for j in 0..g {
                let row = &iou[j * n..(j + 1) * n];
                let top = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                if top <= 0.0 {
                    continue;
                }
                for (i, &v) in row.iter().enumerate() {
                    if v == top {
                        labels[i] = POSITIVE;
                    }
                }
            }
        }
        Matches { gt, labels }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_matrix_like_detectron2() {
        // detectron2 tests/modeling/test_matcher.py style: 3 GT × 4 predictions.
        #[rustfmt::skip]
        let iou = [
            0.10, 0.75, 0.20, 0.00,
            0.35, 0.10, 0.25, 0.00,
            0.05, 0.20, 0.28, 0.00,
        ];
        let m = Matcher::new(vec![0.3, 0.7], vec![NEGATIVE, IGNORE, POSITIVE], false)
            .match_boxes(&iou, 3, 4);
        assert_eq!(m.gt, vec![1, 0, 2, 0]);
        assert_eq!(m.labels, vec![IGNORE, POSITIVE, NEGATIVE, NEGATIVE]);
        // Low quality: GT 1's best (0.35 at pred 0) and GT 2's best (0.28 at pred 2) become
        // positive; pred 3 (IoU 0 with everything) stays background.
        let m = Matcher::rpn(0.3, 0.7).match_boxes(&iou, 3, 4);
        assert_eq!(m.labels, vec![POSITIVE, POSITIVE, POSITIVE, NEGATIVE]);
        assert_eq!(m.gt, vec![1, 0, 2, 0]);
    }

    #[test]
    fn roi_threshold_is_inclusive() {
        let m = Matcher::roi(0.5).match_boxes(&[0.5, 0.4999], 1, 2);
        assert_eq!(m.labels, vec![POSITIVE, NEGATIVE]);
    }

    #[test]
    fn empty_gt_is_all_background() {
        let m = Matcher::rpn(0.3, 0.7).match_boxes(&[], 0, 3);
        assert_eq!(m.labels, vec![NEGATIVE; 3]);
        assert_eq!(m.gt, vec![0; 3]);
    }

    #[test]
    fn iou_matrix() {
        let m = pairwise_iou(
            &[[0.0, 0.0, 10.0, 10.0]],
            &[
                [0.0, 0.0, 10.0, 10.0],
                [5.0, 0.0, 15.0, 10.0],
                [20.0, 20.0, 30.0, 30.0],
            ],
        );
        assert_eq!(m.len(), 3);
        assert!((m[0] - 1.0).abs() < 1e-6 && (m[1] - 1.0 / 3.0).abs() < 1e-6 && m[2] == 0.0);
    }

    #[test]
    #[should_panic(
        expected = "need thresholds.len() + 1 labels in {-1, 0, 1}, got thresholds [0.5] labels [0]"
    )]
    fn rejects_label_count() {
        Matcher::new(vec![0.5], vec![0], false);
    }
}
