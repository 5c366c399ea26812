//! The curves ultralytics users look at first, from the crate's own COCO evaluator:
//! `BoxPR_curve.png` / `MaskPR_curve.png` (precision against recall at IoU 0.5: the
//! 101-point interpolated precision pycocotools averages into AP50) and
//! `BoxF1_curve.png` / `MaskF1_curve.png` (F1 against confidence at IoU 0.5).
//!
//! The confidence curves follow ultralytics' `ap_per_class` (`ultralytics/utils/metrics.py`):
//! recall and precision after each ranked detection, read at 1000 confidences in [0, 1]
//! by linear interpolation over the descending scores (`np.interp(-px, -conf, …)`,
//! recall 0 and precision 1 above the highest score), F1 = 2PR / (P + R). The ranked
//! points are the evaluator's own ([`RankedPr`]), so they agree with the AP it reports
//! (crowd and ignored detections handled as pycocotools does); each plot has one curve
//! per class and their mean, "all classes", drawn thick as ultralytics draws it.

use std::path::Path;

use anyhow::Result;

use super::coco_eval::{CocoEvalResult, RankedPr};
use super::plots::{write_png, Mark, Panel, Series, PALETTE};

/// Confidences the F1 curve is read at (ultralytics: `np.linspace(0, 1, 1000)`).
pub const CONF_POINTS: usize = 1000;

/// Precision at each of the 101 recall thresholds at IoU 0.5, all areas, 100 detections,
/// for category index `k` (pycocotools' `eval['precision'][0, :, k, 0, 2]`); None where
/// the category has no ground truth (−1 there).
pub fn pr_at_50(res: &CocoEvalResult, k: usize) -> Option<Vec<(f64, f64)>> {
    let (nr, nk, na, nm) = (res.rec_thrs.len(), res.cat_ids.len(), 4, 3);
    let at = |r: usize| res.precision[((r * nk + k) * na) * nm + nm - 1];
    if at(0) < 0.0 {
        return None;
    }
    Some((0..nr).map(|r| (res.rec_thrs[r], at(r))).collect())
}

/// `np.interp(x, xp, fp, left, right)` for ascending `xp` (ties: the last of equal `xp`
/// values at or below `x`, as numpy's search lands).
fn interp(x: f64, xp: &[f64], fp: &[f64], left: f64) -> f64 {
    let n = xp.len();
    if n == 0 || x < xp[0] {
        return left;
    }
    let j = xp.partition_point(|&v| v <= x) - 1;
    if j + 1 >= n {
        return fp[n - 1];
    }
    let (x0, x1) = (xp[j], xp[j + 1]);
    if x == x0 {
        return fp[j];
    }
    fp[j] + (fp[j + 1] - fp[j]) * (x - x0) / (x1 - x0)
}

/// Precision, recall and F1 of one category at each of [`CONF_POINTS`] confidences.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfCurve {
    pub conf: Vec<f64>,
    pub precision: Vec<f64>,
    pub recall: Vec<f64>,
    pub f1: Vec<f64>,
}

/// The confidence curves of one category from its ranked detections.
pub fn conf_curve(r: &RankedPr) -> ConfCurve {
    let conf: Vec<f64> = (0..CONF_POINTS)
        .map(|i| i as f64 / (CONF_POINTS - 1) as f64)
        .collect();
    let neg: Vec<f64> = r.scores.iter().map(|s| -s).collect();
    let recall: Vec<f64> = conf
        .iter()
        .map(|c| interp(-c, &neg, &r.recall, 0.0))
        .collect();
    let precision: Vec<f64> = conf
        .iter()
        .map(|c| interp(-c, &neg, &r.precision, 1.0))
        .collect();
    let f1 = precision
        .iter()
        .zip(&recall)
        .map(|(p, r)| 2.0 * p * r / (p + r + 1e-16))
        .collect();
    ConfCurve {
        conf,
        precision,
        recall,
        f1,
    }
}

/// Pointwise mean of curves sampled at the same abscissae.
fn mean_curve(curves: &[Vec<(f64, f64)>]) -> Vec<(f64, f64)> {
    let Some(first) = curves.first() else {
        return Vec::new();
    };
    (0..first.len())
        .map(|i| {
            let y = curves.iter().map(|c| c[i].1).sum::<f64>() / curves.len() as f64;
            (first[i].0, y)
        })
        .collect()
}

/// The precision-recall panel of one IoU type (`kind`: "Box" or "Mask").
pub fn pr_panel(res: &CocoEvalResult, names: &[String], kind: &str) -> Panel {
    let mut panel = Panel::new(
        format!("{kind} precision-recall (IoU 0.5)"),
        "recall",
        "precision",
    )
    .y_range(0.0, 1.0);
    let mut all = Vec::new();
    for k in 0..res.cat_ids.len() {
        let Some(pts) = pr_at_50(res, k) else {
            continue;
        };
        let ap = pts.iter().map(|p| p.1).sum::<f64>() / pts.len() as f64;
        let name = names
            .get(k)
            .cloned()
            .unwrap_or_else(|| res.cat_ids[k].to_string());
        panel = panel.push(
            Series::new(
                format!("{name} {ap:.3}"),
                pts.clone(),
                PALETTE[(1 + k) % 10],
            )
            .mark(Mark::Front),
        );
        all.push(pts);
    }
    let mean = mean_curve(&all);
    let map = mean.iter().map(|p| p.1).sum::<f64>() / mean.len().max(1) as f64;
    panel.push(
        Series::new(format!("all classes {map:.3} mAP@0.5"), mean, PALETTE[0]).mark(Mark::Curve),
    )
}

/// The F1-confidence panel of one IoU type.
pub fn f1_panel(res: &CocoEvalResult, names: &[String], kind: &str) -> Panel {
    let mut panel = Panel::new(
        format!("{kind} F1-confidence (IoU 0.5)"),
        "confidence",
        "F1",
    )
    .y_range(0.0, 1.0);
    let mut all = Vec::new();
    for (k, r) in res.ranked.iter().enumerate() {
        let Some(r) = r else { continue };
        let c = conf_curve(r);
        let pts: Vec<(f64, f64)> = c.conf.iter().copied().zip(c.f1.iter().copied()).collect();
        let name = names
            .get(k)
            .cloned()
            .unwrap_or_else(|| res.cat_ids[k].to_string());
        panel = panel.push(Series::new(name, pts.clone(), PALETTE[(1 + k) % 10]).mark(Mark::Front));
        all.push(pts);
    }
    let mean = mean_curve(&all);
    let best = mean
        .iter()
        .copied()
        .fold((0.0, 0.0), |b, p| if p.1 > b.1 { p } else { b });
    panel.push(
        Series::new(
            format!("all classes {:.2} at {:.3}", best.1, best.0),
            mean,
            PALETTE[0],
        )
        .mark(Mark::Curve),
    )
}

/// Writes `<dir>/{Box,Mask}PR_curve.png` and `<dir>/{Box,Mask}F1_curve.png` from the
/// bbox and segm evaluations of one split (`names`: class names, index = category index).
pub fn write_curves(
    dir: &Path,
    bbox: &CocoEvalResult,
    segm: &CocoEvalResult,
    names: &[String],
) -> Result<()> {
    for (res, kind) in [(bbox, "Box"), (segm, "Mask")] {
        write_png(
            &dir.join(format!("{kind}PR_curve.png")),
            &[pr_panel(res, names, kind)],
            1,
            640,
            480,
        )?;
        write_png(
            &dir.join(format!("{kind}F1_curve.png")),
            &[f1_panel(res, names, kind)],
            1,
            640,
            480,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interp_matches_numpy_on_ties_and_edges() {
        let xp = [-0.9, -0.5, -0.5, -0.1];
        let fp = [0.25, 0.5, 0.75, 1.0];
        assert_eq!(interp(-1.0, &xp, &fp, 0.0), 0.0, "left of the first point");
        assert_eq!(
            interp(0.0, &xp, &fp, 0.0),
            1.0,
            "right of the last: the last value"
        );
        assert_eq!(
            interp(-0.5, &xp, &fp, 0.0),
            0.75,
            "tie: the last equal point"
        );
        assert!((interp(-0.7, &xp, &fp, 0.0) - 0.375).abs() < 1e-12);
        assert!((interp(-0.3, &xp, &fp, 0.0) - 0.875).abs() < 1e-12);
    }

    #[test]
    fn f1_is_zero_above_the_top_score_and_peaks_between() {
        let r = RankedPr {
            scores: vec![0.9, 0.6, 0.3],
            recall: vec![0.5, 1.0, 1.0],
            precision: vec![1.0, 1.0, 2.0 / 3.0],
            num_gt: 2,
        };
        let c = conf_curve(&r);
        assert_eq!(c.conf.len(), CONF_POINTS);
        assert_eq!(c.recall[CONF_POINTS - 1], 0.0);
        assert_eq!(c.precision[CONF_POINTS - 1], 1.0);
        assert_eq!(c.f1[CONF_POINTS - 1], 0.0);
        let i = c.conf.iter().position(|&v| v >= 0.6).unwrap();
        assert!((c.f1[i] - 1.0).abs() < 1e-2, "{}", c.f1[i]);
        assert!(
            (c.f1[0] - 0.8).abs() < 1e-12,
            "below every score: P 2/3, R 1"
        );
    }
}
