//! Task-aligned assigner (TAL, Feng et al. 2021, as in ultralytics 8.4.190 `utils/tal.py`).
//!
//! Decides, per image, which anchors are positives for which ground-truth box and with what
//! soft class target. It works on detached host vectors (predicted probabilities and boxes
//! come in as plain `f32` slices), so it has no tensors, no parameters and no gradients, and
//! runs identically whatever the device. Box counts per image are small, so an O(G·A) pass
//! is cheaper than launching tensor ops.
//!
//! The algorithm, step by step (names follow ultralytics):
//! 1. candidates: anchor centres strictly inside the GT box, where GT sides shorter than
//!    `stride_val` (the second stride, 16) are widened to it about the centre;
//! 2. align metric `s^α · CIoU^β` (CIoU clamped ≥ 0, `s` = predicted probability of the
//!    GT's class) for candidates, 0 elsewhere;
//! 3. the `topk` anchors by metric per GT (ties broken by lower anchor index), kept if they
//!    are candidates;
//! 4. an anchor claimed by several GTs goes to the GT with the highest CIoU;
//! 5. soft target = one-hot class · max over GTs of `metric · maxIoU_g / maxMetric_g`.
//!
//! GT boxes whose coordinates sum to ≤ 0 are treated as padding (as ultralytics' `mask_gt`).

/// TAL hyper-parameters (ultralytics `v8DetectionLoss`: topk 10, alpha 0.5, beta 6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssignerConfig {
    pub topk: usize,
    pub alpha: f32,
    pub beta: f32,
    pub eps: f32,
    /// Minimum GT side for candidate selection, pixels (the model's second stride).
    pub stride_val: f32,
}

impl AssignerConfig {
    /// ultralytics defaults for a model with these strides.
    pub fn for_strides(strides: &[usize]) -> Self {
        assert!(
            !strides.is_empty(),
            "AssignerConfig needs at least one stride"
        );
        let stride_val = if strides.len() > 1 {
            strides[1]
        } else {
            strides[0]
        } as f32;
        Self {
            topk: 10,
            alpha: 0.5,
            beta: 6.0,
            eps: 1e-9,
            stride_val,
        }
    }
}

/// Assignment of one image's anchors.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageAssignment {
    /// Anchor is a positive.
    pub fg: Vec<bool>,
    /// Index of the assigned GT (meaningful where `fg`).
    pub target_gt: Vec<usize>,
    /// Assigned GT box, xyxy pixels (meaningful where `fg`).
    pub target_boxes: Vec<[f32; 4]>,
    /// Soft class targets, `[A · nc]` row-major (zero rows for negatives).
    pub target_scores: Vec<f32>,
    pub num_classes: usize,
}

impl ImageAssignment {
    /// The no-GT result: everything background.
    pub fn empty(num_anchors: usize, num_classes: usize) -> Self {
        Self {
            fg: vec![false; num_anchors],
            target_gt: vec![0; num_anchors],
            target_boxes: vec![[0.0; 4]; num_anchors],
            target_scores: vec![0.0; num_anchors * num_classes],
            num_classes,
        }
    }

    pub fn num_fg(&self) -> usize {
        self.fg.iter().filter(|&&f| f).count()
    }

    /// Σ soft targets of the anchor (the box-loss weight).
    pub fn weight(&self, anchor: usize) -> f32 {
        let nc = self.num_classes;
        self.target_scores[anchor * nc..(anchor + 1) * nc]
            .iter()
            .sum()
    }
}

/// Complete IoU of two xyxy boxes, ultralytics `bbox_iou(CIoU=True, eps=1e-7)` in f32.
pub fn ciou(b1: [f32; 4], b2: [f32; 4]) -> f32 {
    let eps = 1e-7f32;
    let (w1, h1) = (b1[2] - b1[0], b1[3] - b1[1] + eps);
    let (w2, h2) = (b2[2] - b2[0], b2[3] - b2[1] + eps);
    let iw = (b1[2].min(b2[2]) - b1[0].max(b2[0])).max(0.0);
    let ih = (b1[3].min(b2[3]) - b1[1].max(b2[1])).max(0.0);
    let inter = iw * ih;
    let union = w1 * h1 + w2 * h2 - inter + eps;
    let iou = inter / union;
    let cw = b1[2].max(b2[2]) - b1[0].min(b2[0]);
    let ch = b1[3].max(b2[3]) - b1[1].min(b2[1]);
    let c2 = cw * cw + ch * ch + eps;
    let dx = b2[0] + b2[2] - b1[0] - b1[2];
    let dy = b2[1] + b2[3] - b1[1] - b1[3];
    let rho2 = (dx * dx + dy * dy) / 4.0;
    let da = (w2 / h2).atan() - (w1 / h1).atan();
    let v = (4.0 / (std::f32::consts::PI * std::f32::consts::PI)) * da * da;
    let alpha = v / (1.0 - iou + v + eps);
    iou - (rho2 / c2 + v * alpha)
}

/// Assigns one image.
///
/// - `pd_scores`: `[A · nc]` predicted probabilities (sigmoid of the class logits);
/// - `pd_boxes`: `[A]` predicted boxes, xyxy pixels;
/// - `anchors`: `[A]` anchor centres in pixels;
/// - `gt_boxes`, `gt_labels`: the image's GT, xyxy pixels and class indices (< nc).
#[allow(clippy::too_many_arguments)]
pub fn assign_image(
    cfg: &AssignerConfig,
    pd_scores: &[f32],
    pd_boxes: &[[f32; 4]],
    anchors: &[[f32; 2]],
    gt_boxes: &[[f32; 4]],
    gt_labels: &[usize],
    num_classes: usize,
) -> ImageAssignment {
    let na = anchors.len();
    let ng = gt_boxes.len();
    assert!(
        pd_boxes.len() == na && pd_scores.len() == na * num_classes,
        "assign_image: {} boxes and {} scores for {na} anchors × {num_classes} classes",
        pd_boxes.len(),
        pd_scores.len()
    );
    assert_eq!(ng, gt_labels.len(), "assign_image: boxes vs labels");
    if let Some(&l) = gt_labels.iter().find(|&&l| l >= num_classes) {
        panic!("assign_image: GT label {l} out of range for {num_classes} classes");
    }
    if ng == 0 {
        return ImageAssignment::empty(na, num_classes);
    }
    let valid: Vec<bool> = gt_boxes
        .iter()
        .map(|b| b.iter().sum::<f32>() > 0.0)
        .collect();
    let in_gts = candidates(cfg, anchors, gt_boxes, &valid);
    let (overlaps, metric) = align_metric(
        cfg,
        pd_scores,
        pd_boxes,
        gt_boxes,
        gt_labels,
        num_classes,
        &in_gts,
    );
    let mut mask_pos = select_topk(cfg, &metric, &in_gts, &valid, na);
    resolve_multi_claims(&mut mask_pos, &overlaps, ng, na);
    let mut out = ImageAssignment::empty(na, num_classes);
    fill_targets(&mut out, &mask_pos, gt_boxes, ng);
    fill_soft_scores(&mut out, cfg, &mask_pos, &metric, &overlaps, gt_labels, ng);
    out
}

/// Step 1, `[G · A]`: anchor centres strictly (by `eps`) inside each valid GT box, with
/// GT sides shorter than `stride_val` widened to it about the centre (ultralytics 8.4).
fn candidates(
    cfg: &AssignerConfig,
    anchors: &[[f32; 2]],
    gt_boxes: &[[f32; 4]],
    valid: &[bool],
) -> Vec<bool> {
    let (na, ng) = (anchors.len(), gt_boxes.len());
    let mut in_gts = vec![false; ng * na];
    for g in 0..ng {
        if !valid[g] {
            continue;
        }
        let b = gt_boxes[g];
        let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
        let (mut w, mut h) = (b[2] - b[0], b[3] - b[1]);
        if w < cfg.stride_val {
            w = cfg.stride_val;
        }
        if h < cfg.stride_val {
            h = cfg.stride_val;
        }
        let (x1, y1, x2, y2) = (cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0);
        for (a, p) in anchors.iter().enumerate() {
            in_gts[g * na + a] = p[0] - x1 > cfg.eps
                && p[1] - y1 > cfg.eps
                && x2 - p[0] > cfg.eps
                && y2 - p[1] > cfg.eps;
        }
    }
    in_gts
}

/// Step 2, `[G · A]` each: overlaps (CIoU clamped ≥ 0) and the align metric
/// `s^α · CIoU^β` for candidates, 0 elsewhere.
fn align_metric(
    cfg: &AssignerConfig,
    pd_scores: &[f32],
    pd_boxes: &[[f32; 4]],
    gt_boxes: &[[f32; 4]],
    gt_labels: &[usize],
    num_classes: usize,
    in_gts: &[bool],
) -> (Vec<f32>, Vec<f32>) {
    let (na, ng) = (pd_boxes.len(), gt_boxes.len());
    let mut overlaps = vec![0f32; ng * na];
    let mut metric = vec![0f32; ng * na];
    for g in 0..ng {
        for a in 0..na {
            if in_gts[g * na + a] {
                let iou = ciou(gt_boxes[g], pd_boxes[a]).max(0.0);
                let s = pd_scores[a * num_classes + gt_labels[g]];
                overlaps[g * na + a] = iou;
                metric[g * na + a] = s.powf(cfg.alpha) * iou.powf(cfg.beta);
            }
        }
    }
    (overlaps, metric)
}

/// Step 3, `mask_pos [G · A]`: the `topk` anchors by metric per valid GT (ties broken by
/// lower anchor index), kept if they are candidates.
fn select_topk(
    cfg: &AssignerConfig,
    metric: &[f32],
    in_gts: &[bool],
    valid: &[bool],
    na: usize,
) -> Vec<bool> {
    let ng = valid.len();
    let k = cfg.topk.min(na);
    let mut mask_pos = vec![false; ng * na];
    let mut order: Vec<usize> = (0..na).collect();
    for g in 0..ng {
        if !valid[g] {
            continue;
        }
        let row = &metric[g * na..(g + 1) * na];
        // A total order (metric descending, then index), so the selected set is unique.
        if k > 0 && k < na {
            order.select_nth_unstable_by(k - 1, |&i, &j| row[j].total_cmp(&row[i]).then(i.cmp(&j)));
        }
        for &a in &order[..k] {
            mask_pos[g * na + a] = in_gts[g * na + a];
        }
    }
    mask_pos
}

/// Step 4: an anchor claimed by several GTs keeps only the highest-overlap GT (the
/// first on ties).
fn resolve_multi_claims(mask_pos: &mut [bool], overlaps: &[f32], ng: usize, na: usize) {
    for a in 0..na {
        let claims = (0..ng).filter(|&g| mask_pos[g * na + a]).count();
        if claims > 1 {
            let best = argmax_first((0..ng).map(|g| overlaps[g * na + a]));
            for g in 0..ng {
                mask_pos[g * na + a] = g == best;
            }
        }
    }
}

/// Foreground flags, assigned GT and target box per anchor; negatives get GT 0's box
/// (ultralytics' argmax over an all-zero column).
fn fill_targets(out: &mut ImageAssignment, mask_pos: &[bool], gt_boxes: &[[f32; 4]], ng: usize) {
    let na = out.fg.len();
    for a in 0..na {
        if let Some(g) = (0..ng).find(|&g| mask_pos[g * na + a]) {
            out.fg[a] = true;
            out.target_gt[a] = g;
            out.target_boxes[a] = gt_boxes[g];
        } else {
            // ultralytics: argmax over an all-zero column is GT 0.
            out.target_boxes[a] = gt_boxes[0];
        }
    }
}

/// Step 5: each positive's soft score on its GT's class, the max over its GTs of
/// `metric · maxIoU_g / (maxMetric_g + eps)` (maxima over each GT's positives).
fn fill_soft_scores(
    out: &mut ImageAssignment,
    cfg: &AssignerConfig,
    mask_pos: &[bool],
    metric: &[f32],
    overlaps: &[f32],
    gt_labels: &[usize],
    ng: usize,
) {
    let (na, num_classes) = (out.fg.len(), out.num_classes);
    let mut pos_metric = vec![0f32; ng];
    let mut pos_overlap = vec![0f32; ng];
    for g in 0..ng {
        for a in 0..na {
            if mask_pos[g * na + a] {
                pos_metric[g] = pos_metric[g].max(metric[g * na + a]);
                pos_overlap[g] = pos_overlap[g].max(overlaps[g * na + a]);
            }
        }
    }
    for a in 0..na {
        if !out.fg[a] {
            continue;
        }
        let mut norm = 0f32;
        for g in 0..ng {
            if mask_pos[g * na + a] {
                norm = norm.max(metric[g * na + a] * pos_overlap[g] / (pos_metric[g] + cfg.eps));
            }
        }
        out.target_scores[a * num_classes + gt_labels[out.target_gt[a]]] = norm;
    }
}

/// Index of the first maximum (torch's `max(dim).indices` on CPU).
fn argmax_first(values: impl Iterator<Item = f32>) -> usize {
    let mut best = (0, f32::NEG_INFINITY);
    for (i, v) in values.enumerate() {
        if v > best.1 {
            best = (i, v);
        }
    }
    best.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, stride: f32) -> Vec<[f32; 2]> {
        let mut v = Vec::new();
        for y in 0..n {
            for x in 0..n {
                v.push([(x as f32 + 0.5) * stride, (y as f32 + 0.5) * stride]);
            }
        }
        v
    }

    #[test]
    fn ciou_of_identical_boxes_is_one() {
        let b = [1.0, 2.0, 5.0, 9.0];
        assert!((ciou(b, b) - 1.0).abs() < 1e-6);
        // Zero-width and zero-area boxes stay finite.
        assert!(ciou([3.0, 3.0, 3.0, 8.0], b).is_finite());
        assert!(ciou([3.0, 3.0, 3.0, 3.0], [3.0, 3.0, 3.0, 3.0]).is_finite());
    }

    #[test]
    fn zero_gt_is_all_background() {
        let anchors = grid(4, 8.0);
        let a = assign_image(
            &AssignerConfig::for_strides(&[8, 16]),
            &[0.5; 16],
            &vec![[0.0, 0.0, 8.0, 8.0]; 16],
            &anchors,
            &[],
            &[],
            1,
        );
        assert_eq!(a.num_fg(), 0);
        assert!(a.target_scores.iter().all(|&s| s == 0.0));
    }

    #[test]
    fn perfect_prediction_gets_unit_target_and_topk_limit() {
        // 8×8 grid of stride 8; a GT covering 4×4 cells; predicted boxes all equal to the GT.
        let anchors = grid(8, 8.0);
        let gt = [8.0, 8.0, 40.0, 40.0];
        let na = anchors.len();
        let mut scores = vec![0.1f32; na];
        // Make the in-box anchors distinct so the top-k set is unambiguous.
        for (a, s) in scores.iter_mut().enumerate() {
            *s += a as f32 * 1e-3;
        }
        let a = assign_image(
            &AssignerConfig::for_strides(&[8, 16]),
            &scores,
            &vec![gt; na],
            &anchors,
            &[gt],
            &[0],
            1,
        );
        assert_eq!(a.num_fg(), 10, "16 candidates, top 10 kept");
        let max = a.target_scores.iter().cloned().fold(0.0f32, f32::max);
        assert!(
            (max - 1.0).abs() < 1e-5,
            "best anchor's target is maxIoU = 1, got {max}"
        );
        for (p, &fg) in anchors.iter().zip(&a.fg) {
            if fg {
                assert!(p[0] > 8.0 && p[0] < 40.0 && p[1] > 8.0 && p[1] < 40.0);
            }
        }
    }

    #[test]
    fn tiny_box_is_widened_to_stride_val() {
        // A 2×2 px box between anchor centres gets candidates once widened to 16 px.
        let anchors = grid(8, 8.0);
        let gt = [19.0, 19.0, 21.0, 21.0];
        let a = assign_image(
            &AssignerConfig::for_strides(&[8, 16, 32]),
            &vec![0.5; 64],
            &vec![[12.0, 12.0, 28.0, 28.0]; 64],
            &anchors,
            &[gt],
            &[0],
            1,
        );
        assert!(a.num_fg() > 0);
        assert!(a.target_scores.iter().all(|s| s.is_finite()));
    }

    #[test]
    #[should_panic(expected = "GT label 3 out of range for 2 classes")]
    fn rejects_bad_label() {
        let anchors = grid(2, 8.0);
        assign_image(
            &AssignerConfig::for_strides(&[8]),
            &[0.5; 8],
            &[[0.0; 4]; 4],
            &anchors,
            &[[0.0, 0.0, 4.0, 4.0]],
            &[3],
            2,
        );
    }
}
