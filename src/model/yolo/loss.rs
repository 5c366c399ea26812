//! YOLO-seg training losses, following ultralytics 8.4.190 `v8SegmentationLoss`:
//! BCE-with-logits classification against TAL soft targets, CIoU + DFL box losses on the
//! positives, and the prototype mask loss (per positive: BCE of `coef · proto` against its
//! GT mask, cropped to the GT box, mean over pixels divided by the normalised box area,
//! averaged over all positives). Gains box 7.5, cls 0.5, dfl 1.5, seg 7.5 by default.
//!
//! Numerics (the known NaN sources of the reference): the target-score sum is clamped to ≥ 1;
//! with no positives the box, DFL and mask terms are exact zeros (no `inf · 0`); BCE and
//! log-softmax are written in their overflow-free forms; the normalised box area of the
//! mask loss is clamped to at least one prototype pixel; CIoU carries the reference's eps.
//!
//! Ground truth comes as [`Targets`] (per image: boxes xyxy px, classes, instance masks
//! at input resolution). The assigner runs on host copies of the detached predictions.

use burn::tensor::{Device, FloatDType, Int, Tensor, TensorData};

use super::assigner::{assign_image, AssignerConfig, ImageAssignment};
use super::head::REG_MAX;
use super::YoloOutput;
use crate::annotations::targets::{ImageTargets, Targets};
use crate::util::tensor::{host, scalar, to_host};

/// Loss gains (ultralytics hyp `box`, `cls`, `dfl`; the mask loss uses the `box` gain there).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossWeights {
    pub bbox: f64,
    pub cls: f64,
    pub dfl: f64,
    pub seg: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            bbox: 7.5,
            cls: 0.5,
            dfl: 1.5,
            seg: 7.5,
        }
    }
}

/// Named loss terms, each already multiplied by its gain (as ultralytics logs them), and
/// `total = (box + cls + dfl + seg) · batch_size`, the quantity ultralytics back-propagates.
#[derive(Debug, Clone)]
pub struct LossTerms {
    pub bbox: Tensor<1>,
    pub cls: Tensor<1>,
    pub dfl: Tensor<1>,
    pub seg: Tensor<1>,
    pub total: Tensor<1>,
    /// Number of positive anchors in the batch.
    pub num_fg: usize,
}

impl LossTerms {
    /// The terms' names as logged (`metrics.jsonl`, `results.csv`), ultralytics' order.
    pub const NAMES: [&'static str; 4] = ["box", "cls", "dfl", "seg"];

    /// Host values in [`Self::NAMES`] order, then the total (syncs the device).
    pub fn values(&self) -> [f32; 5] {
        [
            scalar(&self.bbox),
            scalar(&self.cls),
            scalar(&self.dfl),
            scalar(&self.seg),
            scalar(&self.total),
        ]
    }
}

fn host_index(v: Vec<usize>, device: &Device) -> Tensor<1, Int> {
    let n = v.len();
    let v: Vec<i64> = v.into_iter().map(|i| i as i64).collect();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

pub use crate::model::loss::{bce_with_logits, log_softmax_stable};

/// DFL expectation: distances `[.., 4]` from bin logits `[.., 4, REG_MAX]` (last dim bins).
fn dfl_expectation<const D: usize, const D1: usize>(logits: Tensor<D>) -> Tensor<D1> {
    let device = logits.device();
    let p = log_softmax_stable(logits, D - 1).exp();
    let bins: Vec<f32> = (0..REG_MAX).map(|i| i as f32).collect();
    let mut shape = [1usize; D];
    shape[D - 1] = REG_MAX;
    let proj = host(bins, shape, &device);
    (p * proj).sum_dim(D - 1).squeeze_dim(D - 1)
}

/// Complete IoU of paired boxes (ultralytics `bbox_iou(xywh=False, CIoU=True)`), with the
/// aspect-ratio trade-off `alpha` detached as in the reference. Computed in f32 whatever
/// the boxes' type (returned in theirs): in bf16, `1 + eps` rounds to 1, so a box that
/// matches its target exactly (iou 1, v 0) made `alpha` 0 / 0 = NaN (a full bf16
/// quickstart run stopped on it at epoch 14). A no-op on f32 boxes.
///
/// # Shapes
/// - `b1`, `b2`: `[N, 4]` xyxy → `[N]`
pub fn ciou_tensor(b1: Tensor<2>, b2: Tensor<2>) -> Tensor<1> {
    let dtype = FloatDType::from(b1.dtype());
    let (b1, b2) = (b1.cast(FloatDType::F32), b2.cast(FloatDType::F32));
    let eps = 1e-7;
    let col = |t: &Tensor<2>, i: usize| t.clone().narrow(1, i, 1).squeeze_dim::<1>(1);
    let (a_x1, a_y1, a_x2, a_y2) = (col(&b1, 0), col(&b1, 1), col(&b1, 2), col(&b1, 3));
    let (b_x1, b_y1, b_x2, b_y2) = (col(&b2, 0), col(&b2, 1), col(&b2, 2), col(&b2, 3));
    let w1 = a_x2.clone() - a_x1.clone();
    let h1 = a_y2.clone() - a_y1.clone() + eps;
    let w2 = b_x2.clone() - b_x1.clone();
    let h2 = b_y2.clone() - b_y1.clone() + eps;
    let iw =
        (a_x2.clone().min_pair(b_x2.clone()) - a_x1.clone().max_pair(b_x1.clone())).clamp_min(0.0);
    let ih =
        (a_y2.clone().min_pair(b_y2.clone()) - a_y1.clone().max_pair(b_y1.clone())).clamp_min(0.0);
    let inter = iw * ih;
    let union = w1.clone() * h1.clone() + w2.clone() * h2.clone() - inter.clone() + eps;
    let iou = inter / union;
    let cw = a_x2.clone().max_pair(b_x2.clone()) - a_x1.clone().min_pair(b_x1.clone());
    let ch = a_y2.clone().max_pair(b_y2.clone()) - a_y1.clone().min_pair(b_y1.clone());
    let c2 = cw.powi_scalar(2) + ch.powi_scalar(2) + eps;
    let dx = b_x1 + b_x2 - a_x1 - a_x2;
    let dy = b_y1 + b_y2 - a_y1 - a_y2;
    let rho2 = (dx.powi_scalar(2) + dy.powi_scalar(2)) / 4.0;
    let v = ((w2 / h2).atan() - (w1 / h1).atan())
        .powi_scalar(2)
        .mul_scalar(4.0 / (std::f64::consts::PI * std::f64::consts::PI));
    let alpha = (v.clone() / (iou.clone().neg() + v.clone() + (1.0 + eps))).detach();
    (iou - (rho2 / c2 + v * alpha)).cast(dtype)
}

/// Builds the per-instance "overlap" index map at prototype resolution: value `k + 1` where
/// instance `k` owns the pixel, 0 for background. Instances are painted largest first, so
/// pixels shared by several instances go to the smaller one (ultralytics
/// `polygons2masks_overlap`). Pixel `(i, j)` samples the input mask at the centre of its
/// `ds × ds` block.
pub fn overlap_index_map(t: &ImageTargets, input: [usize; 2], proto: [usize; 2]) -> Vec<u16> {
    let [h, w] = input;
    let [ph, pw] = proto;
    for (k, m) in t.masks.iter().enumerate() {
        assert_eq!(
            m.len(),
            h * w,
            "mask {k} has {} bytes, expected {h}×{w} (the input size)",
            m.len()
        );
    }
    let areas: Vec<usize> = t
        .masks
        .iter()
        .map(|m| m.iter().filter(|&&v| v != 0).count())
        .collect();
    let mut order: Vec<usize> = (0..t.masks.len()).collect();
    order.sort_by(|&a, &b| areas[b].cmp(&areas[a]).then(a.cmp(&b)));
    let mut out = vec![0u16; ph * pw];
    for &k in &order {
        let m = &t.masks[k];
        for i in 0..ph {
            let y = ((2 * i + 1) * h / (2 * ph)).min(h - 1);
            for j in 0..pw {
                let x = ((2 * j + 1) * w / (2 * pw)).min(w - 1);
                if m[y * w + x] != 0 {
                    out[i * pw + j] = (k + 1) as u16;
                }
            }
        }
    }
    out
}

/// One positive anchor, host side.
#[derive(Debug, Clone, Copy)]
struct Positive {
    image: usize,
    anchor: usize,
    gt: usize,
    weight: f32,
}

/// Full YOLO-seg loss of a batch; see the module docs.
///
/// `targets.images.len()` must equal the batch size; class indices must be `< nc`.
pub fn yolo_loss(out: &YoloOutput, targets: &Targets, weights: &LossWeights) -> LossTerms {
    let device = out.cls_logits.device();
    let [b, _, na] = out.cls_logits.dims();
    let [_, nm, ph, pw] = out.proto.dims();
    check_batch(out, targets);
    let points = out.grid.points();
    let strides = out.grid.strides();
    let assignments = assign_batch(out, targets, &points, &strides);
    let tss: f32 = assignments
        .iter()
        .flat_map(|a| a.target_scores.iter())
        .sum::<f32>()
        .max(1.0);
    let cls = classification_loss(out, &assignments, tss);
    let positives = collect_positives(&assignments, na);
    let num_fg = positives.len();
    let zero = || Tensor::<1>::zeros([1], &device);
    let (bbox, dfl, seg) = if num_fg == 0 {
        (zero(), zero(), zero())
    } else {
        let (bbox, dfl) = box_losses(out, &assignments, &positives, &points, &strides, tss);
        let seg = mask_loss(out, targets, &assignments, &positives, [nm, ph, pw]);
        (bbox, dfl, seg)
    };
    let bbox = bbox.mul_scalar(weights.bbox);
    let cls = cls.reshape([1]).mul_scalar(weights.cls);
    let dfl = dfl.mul_scalar(weights.dfl);
    let seg = seg.mul_scalar(weights.seg);
    let total = (bbox.clone() + cls.clone() + dfl.clone() + seg.clone()).mul_scalar(b as f64);
    LossTerms {
        bbox,
        cls,
        dfl,
        seg,
        total,
        num_fg,
    }
}

/// Panics with a message when the targets do not fit the batch: one target image per
/// batch image, anchors matching the grid, as many boxes as classes and masks.
fn check_batch(out: &YoloOutput, targets: &Targets) {
    let [b, _, na] = out.cls_logits.dims();
    assert_eq!(
        targets.images.len(),
        b,
        "yolo_loss: {} target images for a batch of {b}",
        targets.images.len()
    );
    assert_eq!(na, out.grid.num_anchors(), "yolo_loss: anchors vs grid");
    for (i, t) in targets.images.iter().enumerate() {
        assert!(
            t.boxes.len() == t.classes.len() && t.boxes.len() == t.masks.len(),
            "yolo_loss: image {i} has {} boxes, {} classes and {} masks",
            t.boxes.len(),
            t.classes.len(),
            t.masks.len()
        );
    }
}

/// Runs the TAL assigner per image on host copies of the detached predictions:
/// probabilities `[B, nc, A]` and DFL-decoded boxes (xyxy pixels).
fn assign_batch(
    out: &YoloOutput,
    targets: &Targets,
    points: &[[f32; 2]],
    strides: &[f32],
) -> Vec<ImageAssignment> {
    let [b, nc, na] = out.cls_logits.dims();
    let level_strides: Vec<usize> = out.grid.levels.iter().map(|l| l.0).collect();
    let acfg = AssignerConfig::for_strides(&level_strides);
    let probs = to_host(burn::tensor::activation::sigmoid(
        out.cls_logits.clone().detach(),
    ));
    let dist = out
        .box_dist
        .clone()
        .detach()
        .reshape([b, 4, REG_MAX, na])
        .swap_dims(2, 3);
    let dist = to_host(dfl_expectation::<4, 3>(dist)); // [B, 4, A]
    let anchors_px: Vec<[f32; 2]> = points
        .iter()
        .zip(strides)
        .map(|(p, &s)| [p[0] * s, p[1] * s])
        .collect();
    let mut assignments = Vec::with_capacity(b);
    for (i, t) in targets.images.iter().enumerate() {
        let mut sc = vec![0f32; na * nc];
        for c in 0..nc {
            for a in 0..na {
                sc[a * nc + c] = probs[(i * nc + c) * na + a];
            }
        }
        let d = |k: usize, a: usize| dist[(i * 4 + k) * na + a];
        let boxes: Vec<[f32; 4]> = (0..na)
            .map(|a| {
                let (p, s) = (points[a], strides[a]);
                [
                    (p[0] - d(0, a)) * s,
                    (p[1] - d(1, a)) * s,
                    (p[0] + d(2, a)) * s,
                    (p[1] + d(3, a)) * s,
                ]
            })
            .collect();
        assignments.push(assign_image(
            &acfg,
            &sc,
            &boxes,
            &anchors_px,
            &t.boxes,
            &t.classes,
            nc,
        ));
    }
    assignments
}

/// Classification (un-gained): BCE over every anchor and class against the soft
/// targets, summed and divided by the target-score sum `tss`.
fn classification_loss(out: &YoloOutput, assignments: &[ImageAssignment], tss: f32) -> Tensor<1> {
    let device = out.cls_logits.device();
    let [b, nc, na] = out.cls_logits.dims();
    let mut tgt = vec![0f32; b * nc * na];
    for (i, asg) in assignments.iter().enumerate() {
        for a in 0..na {
            for c in 0..nc {
                tgt[(i * nc + c) * na + a] = asg.target_scores[a * nc + c];
            }
        }
    }
    let tgt = host(tgt, [b, nc, na], &device);
    bce_with_logits(out.cls_logits.clone(), tgt)
        .sum()
        .div_scalar(tss)
}

/// The batch's positive anchors, image by image and anchor by anchor, with their GT
/// and box-loss weight.
fn collect_positives(assignments: &[ImageAssignment], na: usize) -> Vec<Positive> {
    assignments
        .iter()
        .enumerate()
        .flat_map(|(i, asg)| {
            (0..na).filter(move |&a| asg.fg[a]).map(move |a| Positive {
                image: i,
                anchor: a,
                gt: asg.target_gt[a],
                weight: asg.weight(a),
            })
        })
        .collect()
}

/// CIoU and DFL losses over the positives (un-gained), each `[1]`.
fn box_losses(
    out: &YoloOutput,
    assignments: &[ImageAssignment],
    positives: &[Positive],
    points: &[[f32; 2]],
    strides: &[f32],
    tss: f32,
) -> (Tensor<1>, Tensor<1>) {
    let device = out.box_dist.device();
    let [b, _, na] = out.box_dist.dims();
    let p = positives.len();
    // [B, 4·R, A] → [B, A, 4·R] → [B·A, 4, R], then the positives' rows.
    let rows = out
        .box_dist
        .clone()
        .swap_dims(1, 2)
        .reshape([b * na, 4, REG_MAX]);
    let idx = host_index(
        positives.iter().map(|q| q.image * na + q.anchor).collect(),
        &device,
    );
    let logits = rows.select(0, idx); // [P, 4, R]
    let dist: Tensor<2> = dfl_expectation::<3, 2>(logits.clone()); // [P, 4] grid units

    let mut anc = Vec::with_capacity(p * 4);
    let mut tbox = Vec::with_capacity(p * 4);
    let mut wts = Vec::with_capacity(p);
    let mut dfl_w = vec![0f32; p * 4 * REG_MAX];
    for (k, q) in positives.iter().enumerate() {
        let (pt, s) = (points[q.anchor], strides[q.anchor]);
        anc.extend_from_slice(&[pt[0], pt[1], pt[0], pt[1]]);
        let t = assignments[q.image].target_boxes[q.anchor];
        let t = [t[0] / s, t[1] / s, t[2] / s, t[3] / s];
        tbox.extend_from_slice(&t);
        wts.push(q.weight);
        // bbox2dist clamped to [0, reg_max − 1 − 0.01], then the two neighbouring bins.
        let ltrb = [pt[0] - t[0], pt[1] - t[1], t[2] - pt[0], t[3] - pt[1]];
        for (side, &d) in ltrb.iter().enumerate() {
            let d = d.clamp(0.0, REG_MAX as f32 - 1.0 - 0.01);
            let tl = d.floor() as usize;
            let wl = (tl + 1) as f32 - d;
            let base = (k * 4 + side) * REG_MAX;
            dfl_w[base + tl] = wl;
            dfl_w[base + tl + 1] = 1.0 - wl;
        }
    }
    let anc = host(anc, [p, 4], &device);
    let sign = host(vec![-1.0, -1.0, 1.0, 1.0], [1, 4], &device);
    let pred = anc + dist * sign;
    let target = host(tbox, [p, 4], &device);
    let w = host(wts, [p], &device);
    let iou = ciou_tensor(pred, target);
    let loss_iou = ((iou.neg() + 1.0) * w.clone()).sum().div_scalar(tss);

    let logp = log_softmax_stable(logits, 2);
    let dfl_w = host(dfl_w, [p, 4, REG_MAX], &device);
    let per = (logp * dfl_w).sum_dim(2).neg().mean_dim(1).reshape([p]); // [P]
    let loss_dfl = (per * w).sum().div_scalar(tss);
    (loss_iou.reshape([1]), loss_dfl.reshape([1]))
}

/// Prototype mask loss (un-gained), `[1]`.
///
/// Positives assigned to the same GT share its crop window and its GT mask, so they are
/// evaluated together and only inside that window (everything outside is cropped to zero
/// weight anyway): `Σ_groups Σ_window bce(coef · proto, gt) / (Hp·Wp) / area / #positives`.
fn mask_loss(
    out: &YoloOutput,
    targets: &Targets,
    assignments: &[ImageAssignment],
    positives: &[Positive],
    [nm, ph, pw]: [usize; 3],
) -> Tensor<1> {
    let device = out.proto.device();
    let [b, _, na] = out.mask_coef.dims();
    let [ih, iw] = out.grid.input;
    let coef_rows = out.mask_coef.clone().swap_dims(1, 2).reshape([b * na, nm]);
    let num_fg = positives.len() as f32;
    let mut total = Tensor::<1>::zeros([1], &device);
    for (i, t) in targets.images.iter().enumerate() {
        let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
        for q in positives.iter().filter(|q| q.image == i) {
            groups.entry(q.gt).or_default().push(q.anchor);
        }
        if groups.is_empty() {
            continue;
        }
        let index_map = overlap_index_map(t, [ih, iw], [ph, pw]);
        let proto_i = out.proto.clone().narrow(0, i, 1).reshape([nm, ph, pw]);
        for (gt, anchors) in groups {
            let box_px = assignments[i].target_boxes[anchors[0]];
            let Some(win) = CropWindow::new(box_px, [ih, iw], [ph, pw]) else {
                continue;
            };
            let (h, w) = (win.rows.1 - win.rows.0, win.cols.1 - win.cols.0);
            let label = (gt + 1) as u16;
            let mut gt_row = Vec::with_capacity(h * w);
            for r in win.rows.0..win.rows.1 {
                for c in win.cols.0..win.cols.1 {
                    gt_row.push(f32::from(index_map[r * pw + c] == label));
                }
            }
            let gt_row = host(gt_row, [1, h * w], &device);
            let proto = proto_i
                .clone()
                .narrow(1, win.rows.0, h)
                .narrow(2, win.cols.0, w)
                .reshape([nm, h * w]);
            let idx = host_index(anchors.iter().map(|&a| i * na + a).collect(), &device);
            let coef = coef_rows.clone().select(0, idx); // [k, nm]
            let pred = coef.matmul(proto); // [k, h·w]
            let weight = 1.0 / (ph * pw) as f32 / win.area / num_fg;
            total = total + bce_with_logits(pred, gt_row).sum().mul_scalar(weight);
        }
    }
    total
}

/// The prototype pixels inside a GT box (ultralytics `crop_mask`: column `c` is inside iff
/// `x1 ≤ c < x2` with the box scaled to prototype pixels), and the box's normalised area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropWindow {
    /// Half-open row range.
    pub rows: (usize, usize),
    /// Half-open column range.
    pub cols: (usize, usize),
    /// `w · h` of the box as a fraction of the image, clamped to one prototype pixel so that
    /// boxes thinner than a prototype pixel cannot blow the weight up.
    pub area: f32,
}

impl CropWindow {
    /// `None` when no prototype pixel lies inside the box.
    pub fn new(box_px: [f32; 4], [ih, iw]: [usize; 2], [ph, pw]: [usize; 2]) -> Option<Self> {
        let nb = [
            box_px[0] / iw as f32,
            box_px[1] / ih as f32,
            box_px[2] / iw as f32,
            box_px[3] / ih as f32,
        ];
        let range = |lo: f32, hi: f32, n: usize| {
            let a = (lo.max(0.0).ceil() as usize).min(n);
            let b = (hi.max(0.0).ceil() as usize).min(n);
            (a, b.max(a))
        };
        let cols = range(nb[0] * pw as f32, nb[2] * pw as f32, pw);
        let rows = range(nb[1] * ph as f32, nb[3] * ph as f32, ph);
        if cols.0 == cols.1 || rows.0 == rows.1 {
            return None;
        }
        let area = ((nb[2] - nb[0]) * (nb[3] - nb[1])).max(1.0 / (ph * pw) as f32);
        Some(Self { rows, cols, area })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ciou_of_matching_bf16_boxes_is_finite() {
        // A prediction equal to its target: iou 1, v 0, the alpha denominator 0 in bf16.
        let dev = Device::flex();
        let b = Tensor::<2>::from_data(
            TensorData::new(vec![2.0f32, 4.0, 10.0, 8.0, 1.0, 1.0, 5.0, 3.0], [2, 4]),
            &dev,
        )
        .cast(FloatDType::BF16);
        let c = ciou_tensor(b.clone(), b);
        assert_eq!(FloatDType::from(c.dtype()), FloatDType::BF16);
        let v = to_host(c);
        assert!(v.iter().all(|x| (x - 1.0).abs() < 1e-2), "{v:?}");
    }

    #[test]
    fn overlap_pixels_go_to_the_smaller_instance() {
        // 8×8 input, proto 4×4: a big square and a small one inside it.
        let (h, w) = (8, 8);
        let big: Vec<u8> = (0..64).map(|p| u8::from(p % 8 < 6 && p / 8 < 6)).collect();
        let small: Vec<u8> = (0..64).map(|p| u8::from(p % 8 < 2 && p / 8 < 2)).collect();
        let t = ImageTargets {
            boxes: vec![[0.0, 0.0, 6.0, 6.0], [0.0, 0.0, 2.0, 2.0]],
            classes: vec![0, 0],
            masks: vec![big, small],
        };
        let m = overlap_index_map(&t, [h, w], [4, 4]);
        assert_eq!(m[0], 2, "shared pixel belongs to the small instance");
        assert_eq!(m[1], 1);
        assert_eq!(m[15], 0);
    }

    #[test]
    fn crop_window_follows_crop_mask() {
        // 64 px input, 16 px prototypes: box 4.8..20 px → 1.2..5 proto px → columns 2..5.
        let w = CropWindow::new([4.8, 0.0, 20.0, 64.0], [64, 64], [16, 16]).unwrap();
        assert_eq!(w.cols, (2, 5));
        assert_eq!(w.rows, (0, 16));
        // Thinner than a prototype pixel with no pixel inside: no window.
        assert_eq!(
            CropWindow::new([4.1, 0.0, 4.2, 64.0], [64, 64], [16, 16]),
            None
        );
        // Zero-area boxes: none; out-of-image boxes: none.
        assert_eq!(
            CropWindow::new([8.0, 8.0, 8.0, 8.0], [64, 64], [16, 16]),
            None
        );
        assert_eq!(
            CropWindow::new([-9.0, -9.0, -1.0, -1.0], [64, 64], [16, 16]),
            None
        );
    }

    #[test]
    #[should_panic(expected = "image 0 has 1 boxes, 1 classes and 0 masks")]
    fn loss_rejects_missing_masks() {
        let d = Device::flex();
        let grid = super::super::AnchorGrid::new([32, 32], &[8, 16, 32]);
        let na = grid.num_anchors();
        let out = YoloOutput {
            box_dist: Tensor::zeros([1, 64, na], &d),
            cls_logits: Tensor::zeros([1, 1, na], &d),
            mask_coef: Tensor::zeros([1, 2, na], &d),
            proto: Tensor::zeros([1, 2, 8, 8], &d),
            grid,
        };
        let t = Targets {
            images: vec![ImageTargets {
                boxes: vec![[0.0, 0.0, 8.0, 8.0]],
                classes: vec![0],
                masks: vec![],
            }],
        };
        yolo_loss(&out, &t, &LossWeights::default());
    }

    #[test]
    fn bce_is_finite_at_extremes() {
        let d = Device::flex();
        let x = Tensor::<1>::from_floats([1e4, -1e4, 0.0, 30.0], &d);
        let y = Tensor::<1>::from_floats([0.0, 1.0, 0.5, 1.0], &d);
        let v = to_host(bce_with_logits(x, y));
        assert!(
            (v[0] - 1e4).abs() < 1.0 && (v[1] - 1e4).abs() < 1.0,
            "{v:?}"
        );
        assert!((v[2] - std::f32::consts::LN_2).abs() < 1e-6);
        assert!(v[3] >= 0.0 && v[3] < 1e-12);
    }
}
