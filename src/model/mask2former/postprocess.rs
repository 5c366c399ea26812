//! Mask2Former's instance inference (reference `MaskFormer.instance_inference`): every
//! (query, class) pair is a candidate scored `p(class) · mask score`, where the mask score
//! is the mean sigmoid inside the binarised mask (logit > 0); the top k candidates become
//! detections — no NMS, the set prediction is already one mask per object.
//!
//! The mask score is computed on the stride-4 logits (the reference computes it after
//! upsampling to the image, which changes it only at the edges). Each detection keeps its
//! mask logits as a one-channel [`Prototypes`] map at stride 4, so eval and predict decode
//! it at the original image size through the shared path (bilinear upsampling, threshold
//! at logit 0, letterbox padding removed: `instance_mask::prototype_mask`); its box is the
//! box of the mask decoded at the input size.

use std::sync::Arc;

use crate::model::detection::Detection;
use crate::model::instance_mask::{MaskSource, Prototypes};

/// Detections of one image from its final class logits (`Q × (C+1)`) and mask logits
/// (`Q × h × w`, stride 4 of an `[H, W]` input), the `top_k` best; candidates whose mask
/// is empty (score 0) or whose score is not finite are dropped.
pub fn instance_inference(
    class_logits: &[f32],
    mask_logits: &[f32],
    queries: usize,
    [h, w]: [usize; 2],
    [ih, iw]: [usize; 2],
    top_k: usize,
) -> Vec<Detection> {
    if queries == 0 {
        return Vec::new();
    }
    let c1 = class_logits.len() / queries;
    let nc = c1 - 1;
    let hw = h * w;
    let mut cands: Vec<(f32, usize)> = Vec::with_capacity(queries * nc);
    for q in 0..queries {
        let row = &class_logits[q * c1..(q + 1) * c1];
        let m = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let z: f32 = row.iter().map(|&v| (v - m).exp()).sum();
        for c in 0..nc {
            let p = (row[c] - m).exp() / z;
            if p.is_finite() {
                cands.push((p, q * nc + c));
            }
        }
    }
    cands.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    cands.truncate(top_k);
    let mut out = Vec::with_capacity(cands.len());
    for (p, idx) in cands {
        let (q, class) = (idx / nc, idx % nc);
        let m = &mask_logits[q * hw..(q + 1) * hw];
        let (mut s, mut n) = (0.0f64, 0usize);
        for &v in m {
            if v > 0.0 {
                s += 1.0 / (1.0 + (-v as f64).exp());
                n += 1;
            }
        }
        let score = p * (s / (n as f64 + 1e-6)) as f32;
        if n == 0 || !score.is_finite() || score <= 0.0 {
            continue;
        }
        let mask = MaskSource::Prototypes {
            coef: vec![1.0],
            protos: Arc::new(Prototypes {
                data: m.to_vec(),
                channels: 1,
                height: h,
                width: w,
                stride: ih / h.max(1),
            }),
        };
        let full = mask.decode((iw as u32, ih as u32), [0.0, 0.0, iw as f32, ih as f32]);
        let Some(bbox) = window_box(&full) else {
            continue;
        };
        out.push(Detection {
            bbox,
            score,
            class,
            mask,
        });
    }
    out
}

/// `[x, y, w, h]` of the set pixels of a decoded mask (pixel edges), `None` if empty.
fn window_box(m: &crate::annotations::mask::CroppedMask) -> Option<[f32; 4]> {
    let (ww, wh) = (m.window.width as usize, m.window.height as usize);
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for y in 0..wh {
        for x in 0..ww {
            if m.window.data[y * ww + x] != 0 {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    (x0 != usize::MAX).then(|| {
        let (ox, oy) = (m.x0 as f32, m.y0 as f32);
        [
            ox + x0 as f32,
            oy + y0 as f32,
            (x1 - x0) as f32,
            (y1 - y0) as f32,
        ]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_are_class_times_mask_and_boxes_follow_masks() {
        // 2 queries, 1 class; 4×4 masks at stride 4 of a 16×16 input.
        let cls = vec![2.0, 0.0, -1e4, 1e4];
        let mut m = vec![-10.0f32; 32];
        for y in 1..3 {
            for x in 1..3 {
                m[y * 4 + x] = 10.0;
            }
        }
        let d = instance_inference(&cls, &m, 2, [4, 4], [16, 16], 10);
        assert_eq!(d.len(), 1, "query 1's mask is empty");
        let p = 2f32.exp() / (2f32.exp() + 1.0);
        let ms = 1.0 / (1.0 + (-10f32).exp());
        assert!((d[0].score - p * ms).abs() < 1e-5, "{}", d[0].score);
        let b = d[0].bbox;
        assert!(
            b[0] >= 2.0 && b[0] <= 6.0 && b[2] >= 6.0 && b[2] <= 10.0,
            "{b:?}"
        );
        let mask = d[0].input_mask([16, 16]);
        assert_eq!(mask[8 * 16 + 8], 1);
        assert_eq!(mask[0], 0);
    }

    #[test]
    fn nan_logits_give_no_detections() {
        let d = instance_inference(&[f32::NAN; 4], &[f32::NAN; 32], 2, [4, 4], [16, 16], 10);
        assert!(d.is_empty());
    }
}
