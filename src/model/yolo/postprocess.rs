//! Inference postprocess: decode boxes and scores, class-wise NMS, and masks.
//!
//! Runs in plain Rust over host copies of the output (box counts are small, and
//! burn-vision's NMS does not run on ndarray). Masks follow the order that does not leak
//! pixels outside the box (ultralytics #24272): bilinearly upsample the mask logits
//! (`align_corners = false`) to the input size, threshold at 0, then crop to the box. Only
//! pixels inside each box are evaluated, since everything outside is cropped away.

use rayon::prelude::*;

use super::head::REG_MAX;
use super::YoloOutput;
use crate::model::detection::{nms, Detection};
use crate::util::tensor::to_host;

/// Decodes, filters (`score > conf`, best class per anchor), runs class-wise NMS at `iou`,
/// keeps `max_det` per image and builds their masks.
pub fn postprocess(out: &YoloOutput, conf: f32, iou: f32, max_det: usize) -> Vec<Vec<Detection>> {
    let [b, nc, na] = out.cls_logits.dims();
    let [_, nm, ph, pw] = out.proto.dims();
    let [ih, iw] = out.grid.input;
    let probs = to_host(burn::tensor::activation::sigmoid(out.cls_logits.clone()));
    let dist = to_host(burn::tensor::activation::softmax(
        out.box_dist.clone().reshape([b, 4, REG_MAX, na]),
        2,
    ));
    let coef = to_host(out.mask_coef.clone());
    let proto = to_host(out.proto.clone());
    let points = out.grid.points();
    let strides = out.grid.strides();

    (0..b)
        .map(|i| {
            let mut cands = Vec::new();
            let mut anchor_of = Vec::new();
            for a in 0..na {
                let (mut best, mut cls) = (f32::NEG_INFINITY, 0);
                for c in 0..nc {
                    let p = probs[(i * nc + c) * na + a];
                    if p > best {
                        best = p;
                        cls = c;
                    }
                }
                if best <= conf {
                    continue;
                }
                let mut d = [0f32; 4];
                for (k, dk) in d.iter_mut().enumerate() {
                    for r in 0..REG_MAX {
                        *dk += r as f32 * dist[((i * 4 + k) * REG_MAX + r) * na + a];
                    }
                }
                let (p, s) = (points[a], strides[a]);
                let bx = [
                    (p[0] - d[0]) * s,
                    (p[1] - d[1]) * s,
                    (p[0] + d[2]) * s,
                    (p[1] + d[3]) * s,
                ];
                cands.push((bx, best, cls));
                anchor_of.push(a);
            }
            let keep = nms(&cands, iou, max_det);
            let proto_i = &proto[i * nm * ph * pw..(i + 1) * nm * ph * pw];
            keep.par_iter()
                .map(|&k| {
                    let (bx, score, class) = cands[k];
                    let a = anchor_of[k];
                    let c: Vec<f32> = (0..nm).map(|m| coef[(i * nm + m) * na + a]).collect();
                    let mask = instance_mask(&c, proto_i, [ph, pw], [ih, iw], bx);
                    Detection {
                        bbox: [bx[0], bx[1], bx[2] - bx[0], bx[3] - bx[1]],
                        score,
                        class,
                        mask,
                    }
                })
                .collect()
        })
        .collect()
}

/// The same postprocess on ultralytics' ONNX layout (what an exported file outputs, see
/// [`super::onnx`]): `output0` `[B, 4 + nc + nm, A]` with xywh boxes in input pixels and
/// sigmoid scores, `proto` `[B, nm, ph, pw]`, both row-major; `input = [H, W]`.
pub fn postprocess_layout(
    output0: (&[f32], [usize; 3]),
    proto: (&[f32], [usize; 4]),
    num_classes: usize,
    input: [usize; 2],
    (conf, iou, max_det): (f32, f32, usize),
) -> Vec<Vec<Detection>> {
    let (y, [b, no, na]) = output0;
    let (proto, [_, nm, ph, pw]) = proto;
    let nc = num_classes;
    debug_assert_eq!(no, 4 + nc + nm);
    let at = |i: usize, ch: usize, a: usize| y[(i * no + ch) * na + a];
    (0..b)
        .map(|i| {
            let mut cands = Vec::new();
            let mut anchor_of = Vec::new();
            for a in 0..na {
                let (mut best, mut cls) = (f32::NEG_INFINITY, 0);
                for c in 0..nc {
                    let p = at(i, 4 + c, a);
                    if p > best {
                        best = p;
                        cls = c;
                    }
                }
                if best <= conf {
                    continue;
                }
                let (cx, cy, w, h) = (at(i, 0, a), at(i, 1, a), at(i, 2, a), at(i, 3, a));
                let bx = [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0];
                cands.push((bx, best, cls));
                anchor_of.push(a);
            }
            let keep = nms(&cands, iou, max_det);
            let proto_i = &proto[i * nm * ph * pw..(i + 1) * nm * ph * pw];
            keep.par_iter()
                .map(|&k| {
                    let (bx, score, class) = cands[k];
                    let c: Vec<f32> = (0..nm).map(|m| at(i, 4 + nc + m, anchor_of[k])).collect();
                    Detection {
                        bbox: [bx[0], bx[1], bx[2] - bx[0], bx[3] - bx[1]],
                        score,
                        class,
                        mask: instance_mask(&c, proto_i, [ph, pw], input, bx),
                    }
                })
                .collect()
        })
        .collect()
}

/// Source index and weight pair of a bilinear sample (`align_corners = false`).
fn bilinear_src(dst: usize, scale: f32, size: usize) -> (usize, usize, f32) {
    let s = ((dst as f32 + 0.5) * scale - 0.5).max(0.0);
    let i0 = (s.floor() as usize).min(size - 1);
    let i1 = (i0 + 1).min(size - 1);
    (i0, i1, s - i0 as f32)
}

/// Mask of one instance at the input size: `coef · proto` logits, bilinearly upsampled,
/// `> 0`, cropped to the xyxy box (pixel `(x, y)` kept iff `x1 ≤ x < x2` and `y1 ≤ y < y2`).
///
/// - `coef`: `[nm]`; `proto`: `[nm, ph, pw]` row-major.
pub fn instance_mask(
    coef: &[f32],
    proto: &[f32],
    [ph, pw]: [usize; 2],
    [ih, iw]: [usize; 2],
    bx: [f32; 4],
) -> Vec<u8> {
    let mut mask = vec![0u8; ih * iw];
    let x_lo = bx[0].max(0.0).ceil() as usize;
    let y_lo = bx[1].max(0.0).ceil() as usize;
    let x_hi = (bx[2].min(iw as f32).ceil().max(0.0) as usize).min(iw);
    let y_hi = (bx[3].min(ih as f32).ceil().max(0.0) as usize).min(ih);
    if x_lo >= x_hi || y_lo >= y_hi {
        return mask;
    }
    let (sy, sx) = (ph as f32 / ih as f32, pw as f32 / iw as f32);
    let cols: Vec<(usize, usize, f32)> = (x_lo..x_hi).map(|x| bilinear_src(x, sx, pw)).collect();
    let rows: Vec<(usize, usize, f32)> = (y_lo..y_hi).map(|y| bilinear_src(y, sy, ph)).collect();
    // Logits of the prototype cells the box touches.
    let (pr0, pr1) = (rows[0].0, rows[rows.len() - 1].1);
    let (pc0, pc1) = (cols[0].0, cols[cols.len() - 1].1);
    let (rh, rw) = (pr1 - pr0 + 1, pc1 - pc0 + 1);
    let mut logit = vec![0f32; rh * rw];
    for (m, &cm) in coef.iter().enumerate() {
        let plane = &proto[m * ph * pw..(m + 1) * ph * pw];
        for r in 0..rh {
            let src = &plane[(pr0 + r) * pw + pc0..(pr0 + r) * pw + pc0 + rw];
            let dst = &mut logit[r * rw..(r + 1) * rw];
            for (d, s) in dst.iter_mut().zip(src) {
                *d += cm * s;
            }
        }
    }
    let at = |r: usize, c: usize| logit[(r - pr0) * rw + (c - pc0)];
    for (yi, &(r0, r1, fy)) in rows.iter().enumerate() {
        let y = y_lo + yi;
        if (y as f32) < bx[1] || (y as f32) >= bx[3] {
            continue;
        }
        for (xi, &(c0, c1, fx)) in cols.iter().enumerate() {
            let x = x_lo + xi;
            if (x as f32) < bx[0] || (x as f32) >= bx[2] {
                continue;
            }
            let top = at(r0, c0) * (1.0 - fx) + at(r0, c1) * fx;
            let bot = at(r1, c0) * (1.0 - fx) + at(r1, c1) * fx;
            if top * (1.0 - fy) + bot * fy > 0.0 {
                mask[y * iw + x] = 1;
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nms_is_class_wise_and_ordered() {
        let c = vec![
            ([0.0, 0.0, 10.0, 10.0], 0.9, 0),
            ([1.0, 1.0, 10.0, 10.0], 0.8, 0), // suppressed by 0
            ([1.0, 1.0, 10.0, 10.0], 0.7, 1), // other class: kept
            ([50.0, 50.0, 60.0, 60.0], 0.95, 0),
        ];
        assert_eq!(nms(&c, 0.7, 300), vec![3, 0, 2]);
        assert_eq!(nms(&c, 0.7, 2), vec![3, 0]);
        assert!(nms(&[], 0.7, 300).is_empty());
    }

    #[test]
    fn mask_is_cropped_to_box_after_upsampling() {
        // One prototype that is positive everywhere: the mask is exactly the box.
        let proto = vec![1.0f32; 4 * 4];
        let m = instance_mask(&[1.0], &proto, [4, 4], [16, 16], [2.0, 3.0, 9.5, 7.0]);
        for y in 0..16 {
            for x in 0..16 {
                let inside = x >= 2 && (x as f32) < 9.5 && (3..7).contains(&y);
                assert_eq!(m[y * 16 + x] == 1, inside, "({x}, {y})");
            }
        }
        // Degenerate and out-of-image boxes give empty masks without panicking.
        assert!(
            instance_mask(&[1.0], &proto, [4, 4], [16, 16], [5.0, 5.0, 5.0, 9.0])
                .iter()
                .all(|&v| v == 0)
        );
        assert!(
            instance_mask(&[1.0], &proto, [4, 4], [16, 16], [-9.0, -9.0, -1.0, -1.0])
                .iter()
                .all(|&v| v == 0)
        );
    }

    #[test]
    fn bilinear_matches_half_pixel_rule() {
        // 2 → 4 upsampling: dst 0 → src clamp(−0.25) = 0; dst 1 → 0.25; dst 3 → 1.25 → (1, 1).
        assert_eq!(bilinear_src(0, 0.5, 2), (0, 1, 0.0));
        assert_eq!(bilinear_src(1, 0.5, 2), (0, 1, 0.25));
        let (a, b, _) = bilinear_src(3, 0.5, 2);
        assert_eq!((a, b), (1, 1));
    }
}
