//! A detection's mask as the model leaves it ([`MaskSource`]), decoded at whatever image
//! size the caller asks for: YOLO-seg's mask coefficients over the image's prototypes
//! ([`prototype_mask`], ultralytics' `process_mask_native`), Mask R-CNN's per-RoI mask
//! probabilities ([`paste_roi_mask`], detectron2's `paste_masks_in_image`).
//!
//! Why decode late: thresholding at the network input and resizing the binary mask to the
//! original photo gives stair-stepped edges (a 256 px model on 640 px images); ultralytics
//! (`retina_masks=True`) and detectron2 interpolate the soft mask to the original size and
//! threshold there. Eval and predict do that, once, and only inside the box: the result is
//! a [`CroppedMask`] whose RLE is built from the window, never a full-image mask per
//! detection. Decoding at the input size is the same call with the input as the image.

use std::sync::Arc;

use crate::annotations::mask::{CroppedMask, Mask};

/// One image's mask prototypes, shared by all its detections.
#[derive(Debug, Clone, PartialEq)]
pub struct Prototypes {
    /// `[channels, height, width]` row-major.
    pub data: Vec<f32>,
    pub channels: usize,
    pub height: usize,
    pub width: usize,
    /// Input pixels per prototype cell (4 with a P3 head, as in ultralytics).
    pub stride: usize,
}

/// What a detection's mask is decoded from.
#[derive(Debug, Clone, PartialEq)]
pub enum MaskSource {
    /// YOLO-seg: `coef · protos` are the mask logits at prototype resolution.
    Prototypes {
        coef: Vec<f32>,
        protos: Arc<Prototypes>,
    },
    /// Mask R-CNN: the `size × size` mask probabilities of the box, kept where the pasted
    /// probability is `≥ threshold`.
    RoiProbs {
        probs: Vec<f32>,
        size: usize,
        threshold: f32,
    },
}

impl MaskSource {
    /// The binary mask in an image of `(width, height)` pixels, for the xyxy box `bx` in
    /// that image's pixels. YOLO: the image is the one that was letterboxed into the
    /// network input (ultralytics' letterbox, which chicktrain's is); Mask R-CNN: any.
    pub fn decode(&self, image: (u32, u32), bx: [f32; 4]) -> CroppedMask {
        match self {
            MaskSource::Prototypes { coef, protos } => prototype_mask(coef, protos, image, bx),
            MaskSource::RoiProbs {
                probs,
                size,
                threshold,
            } => paste_roi_mask(probs, *size, bx, image, *threshold),
        }
    }
}

/// Source indices and weight of a bilinear sample (`align_corners = False`), as PyTorch's
/// `upsample_bilinear2d` computes them in f32: `src = max(scale·(dst + 0.5) − 0.5, 0)`.
fn bilinear_src(dst: usize, scale: f32, size: usize) -> (usize, usize, f32) {
    let s = ((dst as f32 + 0.5) * scale - 0.5).max(0.0);
    let i0 = (s.floor() as usize).min(size - 1);
    let i1 = (i0 + 1).min(size - 1);
    (i0, i1, (s - i0 as f32).clamp(0.0, 1.0))
}

/// Pixel range `[lo, hi)` of `x ≥ a && x < b` (ultralytics' `crop_mask`), within `[0, n)`.
fn box_range(a: f32, b: f32, n: u32) -> (u32, u32) {
    if a.is_nan() || b.is_nan() {
        return (0, 0); // every comparison with NaN is false: nothing is kept
    }
    let lo = a.max(0.0).ceil();
    let hi = b.min(n as f32).ceil();
    if lo >= hi {
        return (0, 0);
    }
    (lo as u32, (hi as u32).min(n))
}

/// Python's `round` (ties to even), which ultralytics' letterbox arithmetic uses.
fn py_round(x: f64) -> i64 {
    x.round_ties_even() as i64
}

fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 {
        a.abs()
    } else {
        gcd(b, a % b)
    }
}

/// YOLO-seg mask of one detection in an `image = (w, h)` image, ultralytics 8.4.190's
/// `process_mask_native` restricted to the box: the prototypes are first upsampled ×f
/// (1, 2 or 4: the smallest that puts the letterbox padding on whole cells), the
/// padding is cut off, the rest is resized bilinearly (`align_corners = False`) to the
/// image, thresholded at logit > 0 and cropped to the box (`x1 ≤ x < x2`, same for y).
/// With the network input as the image (no padding) this is `process_mask(...,
/// upsample=True)`. Only the prototype cells under the box are evaluated.
///
/// `stride` replaces ultralytics' hard-coded 4 (prototypes at 1/4 of the input), so a
/// model with 1/8 prototypes decodes the same way.
pub fn prototype_mask(
    coef: &[f32],
    p: &Prototypes,
    (w, h): (u32, u32),
    bx: [f32; 4],
) -> CroppedMask {
    let (mh, mw, s) = (p.height, p.width, p.stride as i64);
    let (x_lo, x_hi) = box_range(bx[0], bx[2], w);
    let (y_lo, y_hi) = box_range(bx[1], bx[3], h);
    if x_lo >= x_hi || y_lo >= y_hi || mh == 0 || mw == 0 {
        return CroppedMask::empty(w, h);
    }
    // process_mask_native: the pre-upsampling factor f.
    let (hf, wf) = (h as f64, w as f64);
    let gain = (s as f64 * mh as f64 / hf).min(s as f64 * mw as f64 / wf);
    let pad =
        (s * mh as i64 - py_round(hf * gain).max(1)) | (s * mw as i64 - py_round(wf * gain).max(1));
    let f = (s / gcd(s, pad | (pad / 2))).max(1) as usize;
    // scale_masks on the f-upsampled map: crop the padding.
    let (ah, aw) = (f * mh, f * mw);
    let g2 = (ah as f64 / hf).min(aw as f64 / wf);
    let (nh, nw) = (py_round(hf * g2).max(1), py_round(wf * g2).max(1));
    let top = py_round((ah as f64 - nh as f64) / 2.0 - 0.1).max(0) as usize;
    let left = py_round((aw as f64 - nw as f64) / 2.0 - 0.1).max(0) as usize;
    let bottom = (top + nh as usize).min(ah);
    let right = (left + nw as usize).min(aw);
    let (ch, cw) = (bottom - top, right - left);
    // Output pixel → crop cell (stage B) → upsampled cell → prototype cell (stage A).
    let rows_b: Vec<_> = (y_lo..y_hi)
        .map(|y| bilinear_src(y as usize, ch as f32 / h as f32, ch))
        .collect();
    let cols_b: Vec<_> = (x_lo..x_hi)
        .map(|x| bilinear_src(x as usize, cw as f32 / w as f32, cw))
        .collect();
    let (ra0, ra1) = (top + rows_b[0].0, top + rows_b[rows_b.len() - 1].1);
    let (ca0, ca1) = (left + cols_b[0].0, left + cols_b[cols_b.len() - 1].1);
    let stage_a = |lo: usize, hi: usize, size: usize| -> Vec<(usize, usize, f32)> {
        (lo..=hi)
            .map(|i| {
                if f == 1 {
                    (i, i, 0.0)
                } else {
                    bilinear_src(i, 1.0 / f as f32, size)
                }
            })
            .collect()
    };
    let rows_a = stage_a(ra0, ra1, mh);
    let cols_a = stage_a(ca0, ca1, mw);
    // Prototype logits under the box.
    let (pr0, pr1) = (rows_a[0].0, rows_a[rows_a.len() - 1].1);
    let (pc0, pc1) = (cols_a[0].0, cols_a[cols_a.len() - 1].1);
    let (lh, lw) = (pr1 - pr0 + 1, pc1 - pc0 + 1);
    let mut logit = vec![0f32; lh * lw];
    for (m, &cm) in coef.iter().enumerate().take(p.channels) {
        let plane = &p.data[m * mh * mw..(m + 1) * mh * mw];
        for r in 0..lh {
            let src = &plane[(pr0 + r) * mw + pc0..(pr0 + r) * mw + pc0 + lw];
            for (d, v) in logit[r * lw..(r + 1) * lw].iter_mut().zip(src) {
                *d += cm * v;
            }
        }
    }
    let lerp2 = |at: &dyn Fn(usize, usize) -> f32,
                 (r0, r1, fy): (usize, usize, f32),
                 (c0, c1, fx): (usize, usize, f32)| {
        let top = at(r0, c0) * (1.0 - fx) + at(r0, c1) * fx;
        let bot = at(r1, c0) * (1.0 - fx) + at(r1, c1) * fx;
        top * (1.0 - fy) + bot * fy
    };
    // Stage A: the ×f upsampled logits over the cells stage B reads.
    let (ah_n, aw_n) = (rows_a.len(), cols_a.len());
    let up: Vec<f32> = if f == 1 {
        logit.clone()
    } else {
        let at = |r: usize, c: usize| logit[(r - pr0) * lw + (c - pc0)];
        let mut v = Vec::with_capacity(ah_n * aw_n);
        for &ry in &rows_a {
            for &cx in &cols_a {
                v.push(lerp2(&at, ry, cx));
            }
        }
        v
    };
    // Stage B: the image pixels inside the box.
    let at = |r: usize, c: usize| up[(r + top - ra0) * aw_n + (c + left - ca0)];
    let (ww, wh) = (x_hi - x_lo, y_hi - y_lo);
    let mut window = Mask::new(wh, ww);
    for (yi, &ry) in rows_b.iter().enumerate() {
        for (xi, &cx) in cols_b.iter().enumerate() {
            if lerp2(&at, ry, cx) > 0.0 {
                window.data[yi * ww as usize + xi] = 1;
            }
        }
    }
    CroppedMask {
        width: w,
        height: h,
        x0: x_lo,
        y0: y_lo,
        window,
    }
}

/// Pastes an `m × m` probability map onto its xyxy box in a `(w, h)` image and keeps the
/// pixels with probability `≥ threshold`: detectron2's `paste_masks_in_image` on the CPU.
/// Pixel `(x, y)` samples the map with `F.grid_sample` (bilinear, `align_corners = False`,
/// zero padding) at `gx = ((x + 0.5 − x0) / (x1 − x0))·2 − 1` (same for y), within one
/// pixel around the box (its `skip_empty` window); the f32 arithmetic follows PyTorch's
/// CPU kernel so that results match pixel for pixel away from ties.
pub fn paste_roi_mask(
    prob: &[f32],
    m: usize,
    bx: [f32; 4],
    (w, h): (u32, u32),
    threshold: f32,
) -> CroppedMask {
    let (bw, bh) = (bx[2] - bx[0], bx[3] - bx[1]);
    if !(bw > 0.0 && bh > 0.0 && bw.is_finite() && bh.is_finite()) || m == 0 {
        return CroppedMask::empty(w, h);
    }
    let window = |lo: f32, hi: f32, n: u32| {
        let a = (lo.floor() - 1.0).max(0.0).min(n as f32) as u32;
        let b = (hi.ceil() + 1.0).min(n as f32).max(0.0) as u32;
        (a, b.max(a))
    };
    let (xa, xb) = window(bx[0], bx[2], w);
    let (ya, yb) = window(bx[1], bx[3], h);
    let half = m as f32 / 2.0;
    let taps = |v: usize, lo: f32, len: f32| -> (isize, f32) {
        let g = (v as f32 + 0.5 - lo) / len * 2.0 - 1.0;
        let i = (g + 1.0) * half - 0.5;
        let fl = i.floor();
        (fl as isize, i - fl)
    };
    let at = |r: isize, c: isize| {
        if r < 0 || c < 0 || r >= m as isize || c >= m as isize {
            0.0
        } else {
            prob[r as usize * m + c as usize]
        }
    };
    let cols: Vec<(isize, f32)> = (xa..xb).map(|x| taps(x as usize, bx[0], bw)).collect();
    let (ww, wh) = (xb - xa, yb - ya);
    let mut out = Mask::new(wh, ww);
    for (yi, y) in (ya..yb).enumerate() {
        let (r, n) = taps(y as usize, bx[1], bh);
        let s = 1.0 - n;
        for (xi, &(c, wgt)) in cols.iter().enumerate() {
            let e = 1.0 - wgt;
            let p = at(r, c) * (s * e)
                + at(r, c + 1) * (s * wgt)
                + at(r + 1, c) * (n * e)
                + at(r + 1, c + 1) * (n * wgt);
            if p >= threshold {
                out.data[yi * ww as usize + xi] = 1;
            }
        }
    }
    CroppedMask {
        width: w,
        height: h,
        x0: xa,
        y0: ya,
        window: out,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn protos(data: Vec<f32>, [c, h, w]: [usize; 3], stride: usize) -> Prototypes {
        Prototypes {
            data,
            channels: c,
            height: h,
            width: w,
            stride,
        }
    }

    #[test]
    fn prototype_mask_is_cropped_to_the_box_after_upsampling() {
        // One prototype that is positive everywhere: the mask is exactly the box.
        let p = protos(vec![1.0; 16], [1, 4, 4], 4);
        let m = prototype_mask(&[1.0], &p, (16, 16), [2.0, 3.0, 9.5, 7.0]).full();
        for y in 0..16 {
            for x in 0..16 {
                let inside = x >= 2 && (x as f32) < 9.5 && (3..7).contains(&y);
                assert_eq!(m.get(x, y), inside, "({x}, {y})");
            }
        }
        // Degenerate, NaN and out-of-image boxes give empty masks without panicking.
        for bx in [
            [5.0, 5.0, 5.0, 9.0],
            [-9.0, -9.0, -1.0, -1.0],
            [20.0, 0.0, 30.0, 16.0],
            [f32::NAN, 0.0, 4.0, 4.0],
        ] {
            assert_eq!(prototype_mask(&[1.0], &p, (16, 16), bx).area(), 0, "{bx:?}");
        }
    }

    #[test]
    fn prototype_mask_at_the_original_size_follows_the_letterbox() {
        // A 16×8 image letterboxed into 16×16 sits in rows 4..12; prototypes positive in
        // the top half of the image content (rows 4..8 of the input = prototype row 1)
        // must come back as the top half of the original image.
        let mut d = vec![-1.0f32; 16];
        for c in 0..4 {
            d[4 + c] = 1.0;
            d[8 + c] = -1.0;
        }
        let p = protos(d, [1, 4, 4], 4);
        let m = prototype_mask(&[1.0], &p, (32, 16), [0.0, 0.0, 32.0, 16.0]).full();
        assert!(m.get(5, 1) && m.get(30, 5), "top half on");
        assert!(!m.get(5, 12) && !m.get(30, 15), "bottom half off");
    }

    #[test]
    fn paste_full_map_fills_the_box() {
        let prob = vec![1.0f32; 28 * 28];
        let m = paste_roi_mask(&prob, 28, [4.0, 2.0, 12.0, 10.0], (16, 16), 0.5);
        assert_eq!(
            (m.x0, m.y0, m.window.width, m.window.height),
            (3, 1, 10, 10)
        );
        let m = m.full();
        for y in 0..16 {
            for x in 0..16 {
                let inside = (4..12).contains(&x) && (2..10).contains(&y);
                assert_eq!(m.get(x, y), inside, "pixel ({x}, {y})");
            }
        }
        for bx in [
            [4.0, 2.0, 4.0, 9.0],
            [f32::NAN, 0.0, 3.0, 3.0],
            [30.0, 30.0, 40.0, 40.0],
        ] {
            assert_eq!(
                paste_roi_mask(&prob, 28, bx, (16, 16), 0.5).area(),
                0,
                "{bx:?}"
            );
        }
    }

    #[test]
    fn bilinear_matches_half_pixel_rule() {
        // 2 → 4 upsampling: dst 0 → src clamp(−0.25) = 0; dst 1 → 0.25; dst 3 → 1.25 → (1, 1).
        assert_eq!(bilinear_src(0, 0.5, 2), (0, 1, 0.0));
        assert_eq!(bilinear_src(1, 0.5, 2), (0, 1, 0.25));
        let (a, b, _) = bilinear_src(3, 0.5, 2);
        assert_eq!((a, b), (1, 1));
    }

    #[test]
    fn python_rounding_ties_to_even() {
        assert_eq!((py_round(2.5), py_round(3.5), py_round(-0.1)), (2, 4, 0));
    }
}
