//! The COCO evaluator, reproducing pycocotools 2.0.11's `COCOeval` bit for bit.
//!
//! One concept: pycocotools' `COCOeval` (`loadRes`, `evaluateImg`, `accumulate`,
//! `summarize`), kept in one file as `cocoeval.py` keeps it in one class, so that the two
//! read side by side.
//!
//! Every epoch's metrics, every bench row and every claim against the paper go through
//! this file, so it follows `cocoeval.py` step by step rather than re-deriving mAP:
//! `loadRes` (box area for results that carry a box, ids from 1), `evaluateImg` (stable
//! score sort, ignored GTs last, greedy matching with the `1 − 1e−10` cap, crowd reuse,
//! unmatched detections outside the area range ignored), `accumulate` (stable merge of
//! per-image top-k, 101-point interpolation, −1 for categories without GT) and
//! `summarize` (numpy's pairwise-summed mean over the entries > −1). Its quirks are kept
//! on purpose, e.g. a GT whose id is 0 never counts as matched, exactly as in pycocotools.

use std::collections::HashMap;

use anyhow::{bail, Context, Result};

use crate::annotations::coco::{CocoDataset, Detection, Segmentation};
use crate::annotations::rle::{bbox_iou, rle_iou, Rle};

/// Which geometry IoU is computed on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IouType {
    Bbox,
    Segm,
}

impl std::str::FromStr for IouType {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "bbox" => Ok(IouType::Bbox),
            "segm" => Ok(IouType::Segm),
            _ => bail!("unknown IoU type {s:?}: use bbox or segm"),
        }
    }
}

/// Names of the 12 stats, in pycocotools order.
pub const STAT_NAMES: [&str; 12] = [
    "AP", "AP50", "AP75", "APs", "APm", "APl", "AR1", "AR10", "AR100", "ARs", "ARm", "ARl",
];

const AREA_RANGES: [[f64; 2]; 4] = [[0.0, 1e10], [0.0, 1024.0], [1024.0, 9216.0], [9216.0, 1e10]];
const AREA_LABELS: [&str; 4] = ["all", "small", "medium", "large"];
const MAX_DETS: [usize; 3] = [1, 10, 100];

/// `np.linspace(start, stop, num)` with numpy's exact float operations.
fn linspace(start: f64, stop: f64, num: usize) -> Vec<f64> {
    let step = (stop - start) / (num - 1) as f64;
    let mut y: Vec<f64> = (0..num).map(|i| i as f64 * step + start).collect();
    y[num - 1] = stop;
    y
}

/// numpy's pairwise summation (`pairwise_sum_DOUBLE`), which `np.mean` uses.
fn pairwise_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        let mut res = 0.0;
        for &v in a {
            res += v;
        }
        res
    } else if n <= 128 {
        let mut r = [0.0f64; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - (n % 8) {
            for j in 0..8 {
                r[j] += a[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            res += a[i];
            i += 1;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise_sum(&a[..n2]) + pairwise_sum(&a[n2..])
    }
}

struct Inst {
    id: u64,
    area: f64,
    crowd: bool,
    score: f64,
    bbox: [f64; 4],
    rle: Option<Rle>,
    rle_box: [f64; 4],
}

/// Per image × category × area range: what `evaluateImg` returns.
struct ImgEval {
    /// Scores of the kept detections, sorted (stable) high to low.
    scores: Vec<f64>,
    /// `[t][d]`: matched to a GT whose id is non-zero (pycocotools' `dtm != 0`).
    dt_matched: Vec<Vec<bool>>,
    /// `[t][d]`
    dt_ignore: Vec<Vec<bool>>,
    gt_ignore: Vec<bool>,
}

/// Everything `COCOeval` computes, kept for reports and plots.
#[derive(Clone, Debug)]
pub struct CocoEvalResult {
    pub iou_type: IouType,
    pub stats: [f64; 12],
    pub iou_thrs: Vec<f64>,
    pub rec_thrs: Vec<f64>,
    pub cat_ids: Vec<u64>,
    /// `[T][R][K][A][M]`, flattened in C order; −1 where a category has no GT.
    pub precision: Vec<f64>,
    /// `[T][K][A][M]`, flattened in C order.
    pub recall: Vec<f64>,
    /// pycocotools' `eval['scores']`: the score of the detection at which each recall
    /// threshold is read, `[T][R][K][A][M]` like `precision` (0 past the last one).
    pub scores: Vec<f64>,
    /// Per category (index of `cat_ids`), at IoU 0.5, all areas, 100 detections: every
    /// ranked detection's score with the recall and raw precision after it (the points the
    /// interpolated `precision` is read from; the confidence curves of a run are drawn
    /// from them). None where pycocotools skips the category (no evaluated image or GT).
    pub ranked: Vec<Option<RankedPr>>,
}

/// Score, recall and raw (not interpolated) precision after each ranked detection of a
/// category: what `accumulate` computes before the 101-point interpolation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RankedPr {
    pub scores: Vec<f64>,
    pub recall: Vec<f64>,
    pub precision: Vec<f64>,
    /// Unignored ground-truth instances of the category.
    pub num_gt: usize,
}

/// The detections as `loadRes` turns them into annotations.
struct DtAnn<'a> {
    det: &'a Detection,
    id: u64,
    area: f64,
    bbox: [f64; 4],
    /// The mask, when `loadRes` already decoded it for the area (results without boxes).
    rle: Option<Rle>,
}

fn load_res<'a>(sizes: &HashMap<u64, (u32, u32)>, dets: &'a [Detection]) -> Result<Vec<DtAnn<'a>>> {
    let box_branch = dets.first().is_some_and(|d| d.bbox.is_some());
    let mut out = Vec::with_capacity(dets.len());
    for (i, d) in dets.iter().enumerate() {
        let Some(&(h, w)) = sizes.get(&d.image_id) else {
            bail!(
                "detection {i} is for image_id {}, which is not in the ground truth",
                d.image_id
            );
        };
        let (area, bbox, rle) = if box_branch {
            let bb = d.bbox.with_context(|| {
                format!("detection {i} has no bbox, but the first detection has one")
            })?;
            (bb[2] * bb[3], bb, None)
        } else {
            let seg = d
                .segmentation
                .as_ref()
                .with_context(|| format!("detection {i} has neither bbox nor segmentation"))?;
            let rle = seg
                .to_rle(h, w)
                .with_context(|| format!("detection {i} (image {})", d.image_id))?;
            (
                rle.area() as f64,
                d.bbox.unwrap_or_else(|| rle.bbox()),
                Some(rle),
            )
        };
        out.push(DtAnn {
            det: d,
            id: i as u64 + 1,
            area,
            bbox,
            rle,
        });
    }
    Ok(out)
}

/// Evaluates `dets` against `gt` exactly as pycocotools' `COCOeval` (+ `loadRes`) would.
pub fn evaluate(gt: &CocoDataset, dets: &[Detection], iou_type: IouType) -> Result<CocoEvalResult> {
    let iou_thrs = linspace(0.5, 0.95, 10);
    let rec_thrs = linspace(0.0, 1.0, 101);
    let index = EvalIndex::new(gt);
    let segm = iou_type == IouType::Segm;
    let gts = gather_gts(gt, &index, segm)?;
    let mut dts = gather_dts(dets, &index, segm)?;
    let max_det = *MAX_DETS.last().unwrap_or(&100);
    let ious = compute_ious(&gts, &mut dts, max_det);
    let evals = evaluate_imgs(&index, &gts, &dts, &ious, max_det, &iou_thrs);
    let (ni, nk) = (index.img_ids.len(), index.cat_ids.len());
    let acc = accumulate(&evals, ni, nk, &iou_thrs, &rec_thrs);
    let mut result = CocoEvalResult {
        iou_type,
        stats: [0.0; 12],
        iou_thrs,
        rec_thrs,
        cat_ids: index.cat_ids,
        precision: acc.precision,
        recall: acc.recall,
        scores: acc.scores,
        ranked: acc.ranked,
    };
    result.stats = STAT_ROWS.map(|(ap, thr, area, md)| result.summarize(ap, thr, area, md));
    Ok(result)
}

/// The `summarize()` rows behind the 12 stats: (AP or AR, IoU threshold, area, maxDets).
const STAT_ROWS: [(bool, Option<f64>, &str, usize); 12] = [
    (true, None, "all", 100),
    (true, Some(0.5), "all", 100),
    (true, Some(0.75), "all", 100),
    (true, None, "small", 100),
    (true, None, "medium", 100),
    (true, None, "large", 100),
    (false, None, "all", 1),
    (false, None, "all", 10),
    (false, None, "all", 100),
    (false, None, "small", 100),
    (false, None, "medium", 100),
    (false, None, "large", 100),
];

/// pycocotools' `params.imgIds` / `params.catIds` (sorted, unique) and the lookups from
/// ids to their positions, so every image × category cell has one flat index `i * nk + k`.
struct EvalIndex {
    img_ids: Vec<u64>,
    cat_ids: Vec<u64>,
    img_index: HashMap<u64, usize>,
    cat_index: HashMap<u64, usize>,
    /// `(height, width)` per image id, for decoding masks.
    sizes: HashMap<u64, (u32, u32)>,
}

impl EvalIndex {
    /// From the GT's images and categories (duplicate ids collapse, as in pycocotools).
    fn new(gt: &CocoDataset) -> Self {
        let mut img_ids: Vec<u64> = gt.images.iter().map(|im| im.id).collect();
        img_ids.sort_unstable();
        img_ids.dedup();
        let mut cat_ids: Vec<u64> = gt.categories.iter().map(|c| c.id).collect();
        cat_ids.sort_unstable();
        cat_ids.dedup();
        let img_index: HashMap<u64, usize> =
            img_ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        let cat_index: HashMap<u64, usize> =
            cat_ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        let sizes: HashMap<u64, (u32, u32)> = gt
            .images
            .iter()
            .map(|im| (im.id, (im.height, im.width)))
            .collect();
        EvalIndex {
            img_ids,
            cat_ids,
            img_index,
            cat_index,
            sizes,
        }
    }

    /// Number of image × category cells.
    fn cells(&self) -> usize {
        self.img_ids.len() * self.cat_ids.len()
    }
}

/// `_prepare` for the ground truth: every GT annotation in its image × category cell,
/// in file order, with its mask decoded when IoU is on masks.
fn gather_gts(gt: &CocoDataset, index: &EvalIndex, segm: bool) -> Result<Vec<Vec<Inst>>> {
    let nk = index.cat_ids.len();
    let mut gts: Vec<Vec<Inst>> = (0..index.cells()).map(|_| Vec::new()).collect();
    for a in &gt.annotations {
        let (Some(&i), Some(&k)) = (
            index.img_index.get(&a.image_id),
            index.cat_index.get(&a.category_id),
        ) else {
            bail!(
                "GT annotation {} refers to an unknown image or category",
                a.id
            );
        };
        let rle = if segm {
            let (h, w) = index.sizes[&a.image_id];
            Some(
                a.segmentation
                    .to_rle(h, w)
                    .with_context(|| format!("GT annotation {}", a.id))?,
            )
        } else {
            None
        };
        let rle_box = rle.as_ref().map_or([0.0; 4], |r| r.bbox());
        gts[i * nk + k].push(Inst {
            id: a.id,
            area: a.area,
            crowd: a.iscrowd != 0,
            score: 0.0,
            bbox: a.bbox,
            rle,
            rle_box,
        });
    }
    Ok(gts)
}

/// `loadRes` + `_prepare` for the detections: each one in its image × category cell, in
/// file order; detections of categories the GT lacks are dropped, as pycocotools does.
fn gather_dts(dets: &[Detection], index: &EvalIndex, segm: bool) -> Result<Vec<Vec<Inst>>> {
    let nk = index.cat_ids.len();
    let mut dts: Vec<Vec<Inst>> = (0..index.cells()).map(|_| Vec::new()).collect();
    for mut d in load_res(&index.sizes, dets)? {
        let Some(&k) = index.cat_index.get(&d.det.category_id) else {
            continue; // pycocotools only evaluates the GT's categories
        };
        let i = index.img_index[&d.det.image_id];
        let rle = if segm {
            let size = index.sizes[&d.det.image_id];
            Some(detection_mask(&mut d, size)?)
        } else {
            None
        };
        let rle_box = rle.as_ref().map_or([0.0; 4], |r| r.bbox());
        dts[i * nk + k].push(Inst {
            id: d.id,
            area: d.area,
            crowd: false,
            score: d.det.score,
            bbox: d.bbox,
            rle,
            rle_box,
        });
    }
    Ok(dts)
}

/// A detection's mask for segm IoU: the one `loadRes` already decoded, else its
/// segmentation, else (box-only results) its box as a polygon, as `loadRes` makes it.
fn detection_mask(d: &mut DtAnn, (h, w): (u32, u32)) -> Result<Rle> {
    if let Some(rle) = d.rle.take() {
        return Ok(rle);
    }
    let rle = match &d.det.segmentation {
        Some(seg) => seg.to_rle(h, w),
        None => {
            // loadRes gives box-only results the box as a polygon
            let b = d.bbox;
            let (x1, x2, y1, y2) = (b[0], b[0] + b[2], b[1], b[1] + b[3]);
            Segmentation::Polygons(vec![vec![x1, y1, x1, y2, x2, y2, x2, y1]]).to_rle(h, w)
        }
    };
    rle.with_context(|| format!("detection {} (image {})", d.id - 1, d.det.image_id))
}

/// `computeIoU` per cell: detections sorted by score (stable), cut to the top `max_det`,
/// and the IoU of every kept detection with every GT, row-major `[d][g]`.
fn compute_ious(gts: &[Vec<Inst>], dts: &mut [Vec<Inst>], max_det: usize) -> Vec<Vec<f64>> {
    let mut ious: Vec<Vec<f64>> = Vec::with_capacity(gts.len());
    for (g, d) in gts.iter().zip(dts.iter_mut()) {
        d.sort_by(|a, b| desc_score(a.score, b.score));
        d.truncate(max_det);
        let mut m = Vec::with_capacity(d.len() * g.len());
        for di in d.iter() {
            for gi in g.iter() {
                m.push(match (&di.rle, &gi.rle) {
                    (Some(dr), Some(gr)) => rle_iou(dr, &di.rle_box, gr, &gi.rle_box, gi.crowd),
                    _ => bbox_iou(&di.bbox, &gi.bbox, gi.crowd),
                });
            }
        }
        ious.push(m);
    }
    ious
}

/// `evaluateImg` for every category × area range × image, in pycocotools' order, so
/// entry `(k * na + a) * ni + i` is what `accumulate` reads for that triple.
fn evaluate_imgs(
    index: &EvalIndex,
    gts: &[Vec<Inst>],
    dts: &[Vec<Inst>],
    ious: &[Vec<f64>],
    max_det: usize,
    iou_thrs: &[f64],
) -> Vec<Option<ImgEval>> {
    let (ni, nk) = (index.img_ids.len(), index.cat_ids.len());
    let mut evals: Vec<Option<ImgEval>> = Vec::with_capacity(nk * AREA_RANGES.len() * ni);
    for k in 0..nk {
        for rng in AREA_RANGES {
            for i in 0..ni {
                let cell = i * nk + k;
                evals.push(evaluate_img(
                    &gts[cell],
                    &dts[cell],
                    &ious[cell],
                    rng,
                    max_det,
                    iou_thrs,
                ));
            }
        }
    }
    evals
}

/// What `accumulate` returns (see the fields of [`CocoEvalResult`]).
struct Accumulated {
    precision: Vec<f64>,
    recall: Vec<f64>,
    scores: Vec<f64>,
    ranked: Vec<Option<RankedPr>>,
}

/// `accumulate`: precision and scores `[T][R][K][A][M]` and recall `[T][K][A][M]` (C
/// order), −1 where a category × area range × maxDets has no evaluated image or no
/// unignored GT; and the ranked points of each category at IoU 0.5, all areas, 100.
fn accumulate(
    evals: &[Option<ImgEval>],
    ni: usize,
    nk: usize,
    iou_thrs: &[f64],
    rec_thrs: &[f64],
) -> Accumulated {
    let (nt, nr, na, nm) = (
        iou_thrs.len(),
        rec_thrs.len(),
        AREA_RANGES.len(),
        MAX_DETS.len(),
    );
    let mut precision = vec![-1.0; nt * nr * nk * na * nm];
    let mut recall = vec![-1.0; nt * nk * na * nm];
    let mut scores = vec![-1.0; nt * nr * nk * na * nm];
    let mut ranked_pr = vec![None; nk];
    for k in 0..nk {
        for a in 0..na {
            for (m, &md) in MAX_DETS.iter().enumerate() {
                let es: Vec<&ImgEval> = (0..ni)
                    .filter_map(|i| evals[k * na * ni + a * ni + i].as_ref())
                    .collect();
                let Some(ranked) = RankedDets::new(&es, md) else {
                    continue;
                };
                let ss = ranked.sorted_scores();
                for t in 0..nt {
                    let (rc, pr) = ranked.pr_curve(t);
                    recall[((t * nk + k) * na + a) * nm + m] = rc.last().copied().unwrap_or(0.0);
                    if t == 0 && a == 0 && m == nm - 1 {
                        ranked_pr[k] = Some(RankedPr {
                            scores: ss.clone(),
                            recall: rc.clone(),
                            precision: pr.clone(),
                            num_gt: ranked.npig,
                        });
                    }
                    for (r, (q, j)) in interpolate_precision(&rc, pr, rec_thrs).enumerate() {
                        let at = (((t * nr + r) * nk + k) * na + a) * nm + m;
                        precision[at] = q;
                        scores[at] = j.map_or(0.0, |j| ss[j]);
                    }
                }
            }
        }
    }
    Accumulated {
        precision,
        recall,
        scores,
        ranked: ranked_pr,
    }
}

/// One category × area range × maxDets in `accumulate`: every image's top-`md`
/// detections merged into one stable score ranking, with the count of unignored GTs.
struct RankedDets<'a> {
    es: &'a [&'a ImgEval],
    /// `(eval index, detection index)` of each gathered detection.
    owner: Vec<(usize, usize)>,
    /// Positions into `owner`, high score first (stable).
    order: Vec<usize>,
    /// pycocotools' `npig`: GTs that are not ignored.
    npig: usize,
}

impl<'a> RankedDets<'a> {
    /// `None` where pycocotools `continue`s: no evaluated image, or no unignored GT.
    fn new(es: &'a [&'a ImgEval], md: usize) -> Option<Self> {
        if es.is_empty() {
            return None;
        }
        let mut scores = Vec::new();
        let mut owner = Vec::new();
        for (e_i, e) in es.iter().enumerate() {
            for d in 0..e.scores.len().min(md) {
                scores.push(e.scores[d]);
                owner.push((e_i, d));
            }
        }
        let mut order: Vec<usize> = (0..scores.len()).collect();
        order.sort_by(|&x, &y| desc_score(scores[x], scores[y]));
        let npig = es
            .iter()
            .map(|e| e.gt_ignore.iter().filter(|&&g| !g).count())
            .sum::<usize>();
        if npig == 0 {
            return None;
        }
        Some(RankedDets {
            es,
            owner,
            order,
            npig,
        })
    }

    /// The scores of the ranked detections, high first (pycocotools' `dtScoresSorted`).
    fn sorted_scores(&self) -> Vec<f64> {
        self.order
            .iter()
            .map(|&o| {
                let (e_i, d) = self.owner[o];
                self.es[e_i].scores[d]
            })
            .collect()
    }

    /// Recall and raw precision after each ranked detection at IoU threshold `t`
    /// (cumulative TP/FP over the unignored detections, `np.spacing(1)` in the divisor).
    fn pr_curve(&self, t: usize) -> (Vec<f64>, Vec<f64>) {
        let eps = f64::EPSILON; // np.spacing(1)
        let nd = self.order.len();
        let mut rc = vec![0.0; nd];
        let mut pr = vec![0.0; nd];
        let (mut tp, mut fp) = (0.0f64, 0.0f64);
        for (j, &o) in self.order.iter().enumerate() {
            let (e_i, d) = self.owner[o];
            let e = self.es[e_i];
            if !e.dt_ignore[t][d] {
                if e.dt_matched[t][d] {
                    tp += 1.0;
                } else {
                    fp += 1.0;
                }
            }
            rc[j] = tp / self.npig as f64;
            pr[j] = tp / (fp + tp + eps);
        }
        (rc, pr)
    }
}

/// The 101-point interpolated precision: `pr` made non-increasing from the right, then
/// read at the first detection whose recall reaches each threshold (0 past the end), with
/// the index of that detection (None past the end).
fn interpolate_precision<'a>(
    rc: &'a [f64],
    mut pr: Vec<f64>,
    rec_thrs: &'a [f64],
) -> impl Iterator<Item = (f64, Option<usize>)> + 'a {
    let nd = rc.len();
    for j in (1..nd).rev() {
        if pr[j] > pr[j - 1] {
            pr[j - 1] = pr[j];
        }
    }
    let mut j = 0;
    rec_thrs.iter().map(move |&thr| {
        while j < nd && rc[j] < thr {
            j += 1;
        }
        if j < nd {
            (pr[j], Some(j))
        } else {
            (0.0, None)
        }
    })
}

/// `np.argsort(-score, kind='mergesort')` as a comparator: high first, NaN last, stable.
fn desc_score(a: f64, b: f64) -> std::cmp::Ordering {
    let (na, nb) = (-a, -b);
    match (na.is_nan(), nb.is_nan()) {
        (true, true) => std::cmp::Ordering::Equal,
        (true, false) => std::cmp::Ordering::Greater,
        (false, true) => std::cmp::Ordering::Less,
        _ => na.partial_cmp(&nb).unwrap_or(std::cmp::Ordering::Equal),
    }
}

fn evaluate_img(
    gt: &[Inst],
    dt: &[Inst],
    ious: &[f64],
    rng: [f64; 2],
    max_det: usize,
    iou_thrs: &[f64],
) -> Option<ImgEval> {
    if gt.is_empty() && dt.is_empty() {
        return None;
    }
    let ng = gt.len();
    let flag: Vec<bool> = gt
        .iter()
        .map(|g| g.crowd || g.area < rng[0] || g.area > rng[1])
        .collect();
    // Ignored GTs last, stable.
    let mut gtind: Vec<usize> = (0..ng).collect();
    gtind.sort_by_key(|&g| flag[g]);
    let gt_ignore: Vec<bool> = gtind.iter().map(|&g| flag[g]).collect();
    let nd = dt.len().min(max_det);
    let nt = iou_thrs.len();
    let mut dt_matched = vec![vec![false; nd]; nt];
    let mut dt_ignore = vec![vec![false; nd]; nt];
    if !ious.is_empty() {
        for (t, &thr) in iou_thrs.iter().enumerate() {
            let mut gt_taken = vec![false; ng];
            for d in 0..nd {
                let mut iou = thr.min(1.0 - 1e-10);
                let mut m: Option<usize> = None;
                for (gs, &g) in gtind.iter().enumerate() {
                    if gt_taken[gs] && !gt[g].crowd {
                        continue;
                    }
                    if let Some(mm) = m {
                        if !gt_ignore[mm] && gt_ignore[gs] {
                            break;
                        }
                    }
                    let v = ious[d * ng + g];
                    if v < iou {
                        continue;
                    }
                    iou = v;
                    m = Some(gs);
                }
                let Some(mm) = m else { continue };
                dt_ignore[t][d] = gt_ignore[mm];
                dt_matched[t][d] = gt[gtind[mm]].id != 0;
                gt_taken[mm] = true;
            }
        }
    }
    for d in 0..nd {
        let out = dt[d].area < rng[0] || dt[d].area > rng[1];
        for t in 0..nt {
            dt_ignore[t][d] = dt_ignore[t][d] || (!dt_matched[t][d] && out);
        }
    }
    Some(ImgEval {
        scores: dt[..nd].iter().map(|d| d.score).collect(),
        dt_matched,
        dt_ignore,
        gt_ignore,
    })
}

impl CocoEvalResult {
    fn summarize(&self, ap: bool, iou_thr: Option<f64>, area: &str, max_dets: usize) -> f64 {
        let (nt, nr, nk, na, nm) = (
            self.iou_thrs.len(),
            self.rec_thrs.len(),
            self.cat_ids.len(),
            AREA_LABELS.len(),
            MAX_DETS.len(),
        );
        let Some(a) = AREA_LABELS.iter().position(|&l| l == area) else {
            return -1.0;
        };
        let Some(m) = MAX_DETS.iter().position(|&d| d == max_dets) else {
            return -1.0;
        };
        let ts: Vec<usize> = match iou_thr {
            Some(thr) => (0..nt).filter(|&t| self.iou_thrs[t] == thr).collect(),
            None => (0..nt).collect(),
        };
        let mut vals = Vec::new();
        for &t in &ts {
            if ap {
                for r in 0..nr {
                    for k in 0..nk {
                        let v = self.precision[(((t * nr + r) * nk + k) * na + a) * nm + m];
                        if v > -1.0 {
                            vals.push(v);
                        }
                    }
                }
            } else {
                for k in 0..nk {
                    let v = self.recall[((t * nk + k) * na + a) * nm + m];
                    if v > -1.0 {
                        vals.push(v);
                    }
                }
            }
        }
        if vals.is_empty() {
            -1.0
        } else {
            pairwise_sum(&vals) / vals.len() as f64
        }
    }

    /// AP@[.5:.95] of one category (area all, 100 detections), −1 without GT.
    pub fn category_ap(&self, cat_id: u64) -> f64 {
        let Some(k) = self.cat_ids.iter().position(|&c| c == cat_id) else {
            return -1.0;
        };
        let (nt, nr, nk, na, nm) = (
            self.iou_thrs.len(),
            self.rec_thrs.len(),
            self.cat_ids.len(),
            4,
            3,
        );
        let vals: Vec<f64> = (0..nt)
            .flat_map(|t| (0..nr).map(move |r| (t, r)))
            .map(|(t, r)| self.precision[(((t * nr + r) * nk + k) * na) * nm + 2])
            .filter(|&v| v > -1.0)
            .collect();
        if vals.is_empty() {
            -1.0
        } else {
            pairwise_sum(&vals) / vals.len() as f64
        }
    }

    /// The 12 lines pycocotools' `summarize()` prints.
    pub fn summary(&self) -> String {
        let mut s = String::new();

        for (i, (ap, thr, area, md)) in STAT_ROWS.into_iter().enumerate() {
            let (title, kind) = if ap {
                ("Average Precision", "(AP)")
            } else {
                ("Average Recall", "(AR)")
            };
            let iou = match thr {
                Some(t) => format!("{t:0.2}"),
                None => format!(
                    "{:0.2}:{:0.2}",
                    self.iou_thrs[0],
                    self.iou_thrs[self.iou_thrs.len() - 1]
                ),
            };
            s.push_str(&format!(
                " {:<18} {} @[ IoU={:<9} | area={:>6} | maxDets={:>3} ] = {:0.3}\n",
                title, kind, iou, area, md, self.stats[i]
            ));
        }
        s
    }

    /// `{"iou_type", "stats": [12], "AP": .., ...}` for scripts.
    pub fn to_json(&self) -> serde_json::Value {
        let mut o = serde_json::Map::new();
        o.insert(
            "iou_type".into(),
            serde_json::to_value(self.iou_type).unwrap_or_default(),
        );
        o.insert("stats".into(), serde_json::json!(self.stats.to_vec()));
        for (name, v) in STAT_NAMES.iter().zip(self.stats) {
            o.insert((*name).into(), serde_json::json!(v));
        }
        serde_json::Value::Object(o)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_are_numpy_linspace() {
        let t = linspace(0.5, 0.95, 10);
        assert_eq!(t[5], 0.75);
        assert_eq!(t[1], 0.55);
        assert_eq!(linspace(0.0, 1.0, 101)[7], 0.07);
    }

    #[test]
    fn pairwise_sum_matches_numpy_blocks() {
        let v: Vec<f64> = (0..1000).map(|i| 1.0 / (i as f64 + 1.0)).collect();
        let naive: f64 = v.iter().sum();
        assert!((pairwise_sum(&v) - naive).abs() < 1e-12);
        assert_eq!(pairwise_sum(&v[..3]), v[0] + v[1] + v[2]);
    }
}
