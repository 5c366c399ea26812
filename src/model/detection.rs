//! What every model family predicts ([`Detection`]) and the box arithmetic both
//! postprocesses share: IoU of two boxes and greedy NMS.

use crate::annotations::mask::CroppedMask;

pub use super::instance_mask::MaskSource;

/// Offset that separates classes in the coordinate space of class-wise NMS (ultralytics'
/// `max_wh`).
pub const MAX_WH: f32 = 7680.0;
/// At most this many boxes enter NMS per image (ultralytics' `max_nms`).
pub const MAX_NMS: usize = 30_000;

/// One detected instance.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// `[x, y, width, height]` in input pixels (COCO order).
    pub bbox: [f32; 4],
    pub score: f32,
    pub class: usize,
    /// What the mask decodes from; [`Detection::mask_in`] decodes it at any image size.
    pub mask: MaskSource,
}

impl Detection {
    /// The box as xyxy input pixels.
    pub fn xyxy(&self) -> [f32; 4] {
        let b = self.bbox;
        [b[0], b[1], b[0] + b[2], b[1] + b[3]]
    }

    /// The mask in an image of `(width, height)` pixels whose xyxy box is `bx` (the
    /// original image and the box mapped to it, or the input and [`Self::xyxy`]).
    pub fn mask_in(&self, image: (u32, u32), bx: [f32; 4]) -> CroppedMask {
        self.mask.decode(image, bx)
    }

    /// Row-major `h × w` mask at a `[h, w]` network input, 1 inside the instance.
    pub fn input_mask(&self, [h, w]: [usize; 2]) -> Vec<u8> {
        self.mask_in((w as u32, h as u32), self.xyxy()).full().data
    }
}

/// IoU of two xyxy boxes (no +1, no eps: zero-area pairs give 0).
pub fn box_iou(a: [f32; 4], b: [f32; 4]) -> f32 {
    let iw = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let ih = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Greedy class-wise NMS. `cands` are `(xyxy, score, class)`; returns kept indices in
/// descending score order (ties: lower index first), at most `max_det`. Candidates with a
/// NaN score or a non-finite coordinate (a diverged model's output) are never kept: they
/// would rank first under `total_cmp` and reach results.json as `null`.
pub fn nms(cands: &[([f32; 4], f32, usize)], iou: f32, max_det: usize) -> Vec<usize> {
    if max_det == 0 {
        return Vec::new();
    }
    let mut order: Vec<usize> = (0..cands.len())
        .filter(|&i| !cands[i].1.is_nan() && cands[i].0.iter().all(|v| v.is_finite()))
        .collect();
    order.sort_by(|&i, &j| cands[j].1.total_cmp(&cands[i].1).then(i.cmp(&j)));
    order.truncate(MAX_NMS);
    let shifted: Vec<[f32; 4]> = cands
        .iter()
        .map(|(b, _, c)| {
            let o = *c as f32 * MAX_WH;
            [b[0] + o, b[1] + o, b[2] + o, b[3] + o]
        })
        .collect();
    let mut keep = Vec::new();
    let mut suppressed = vec![false; cands.len()];
    for (rank, &i) in order.iter().enumerate() {
        if suppressed[i] {
            continue;
        }
        keep.push(i);
        if keep.len() == max_det {
            break;
        }
        for &j in &order[rank + 1..] {
            if !suppressed[j] && box_iou(shifted[i], shifted[j]) > iou {
                suppressed[j] = true;
            }
        }
    }
    keep
}

/// [`nms`] over finished detections (class-wise, at `iou`, at most `max_det`), highest
/// score first: `predict --iou --max-det` for the families whose own postprocess does not
/// take them (Mask R-CNN and Mask2Former run their own NMS first, at their config's IoU).
pub fn nms_detections(dets: Vec<Detection>, iou: f32, max_det: usize) -> Vec<Detection> {
    let cands: Vec<_> = dets.iter().map(|d| (d.xyxy(), d.score, d.class)).collect();
    let keep = nms(&cands, iou, max_det);
    let mut slots: Vec<Option<Detection>> = dets.into_iter().map(Some).collect();
    keep.into_iter().filter_map(|i| slots[i].take()).collect()
}
