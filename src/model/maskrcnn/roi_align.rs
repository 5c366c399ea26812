//! RoIAlign (He et al. 2017, §3) with detectron2's `aligned = True` convention, equal to
//! `torchvision.ops.roi_align(..., aligned=True)` with a fixed sampling ratio.
//!
//! Each output bin averages `s × s` bilinear samples. Their positions and weights depend only
//! on the boxes, so they are computed on the host ([`bin_samples`]), and the feature side is a
//! single `select` (row gather) over the channel-last features, a multiply by the weights and
//! a sum: plain Burn ops that run on flex and ndarray and are differentiable w.r.t. the
//! features (the boxes get no gradient, as in Mask R-CNN). `grid_sample_2d` was not used:
//! torchvision clamps samples in `[-1, 0]` to the border and zeroes those beyond, which none
//! of its padding modes reproduces.
//!
//! The same weights serve the host version ([`roi_align_mask`]) that builds mask targets
//! from GT masks (detectron2 `BitMasks.crop_and_resize`, adaptive sampling ratio).

use burn::tensor::{Device, Int, Tensor, TensorData};

/// Four bilinear taps of one sample along one axis (torchvision `bilinear_interpolate`):
/// `(low, high, w_low, w_high)`, or `None` outside `[-1, size]`.
fn axis_taps(mut v: f32, size: usize) -> Option<(usize, usize, f32, f32)> {
    if v < -1.0 || v > size as f32 {
        return None;
    }
    if v <= 0.0 {
        v = 0.0;
    }
    let mut lo = v as usize;
    let hi;
    if lo >= size - 1 {
        lo = size - 1;
        hi = size - 1;
        v = lo as f32;
    } else {
        hi = lo + 1;
    }
    let l = v - lo as f32;
    Some((lo, hi, 1.0 - l, l))
}

/// Pixel taps `(y·W + x, weight)` of output bin `(py, px)` of one RoI: `4 · s²` entries
/// (invalid samples carry weight 0 at index 0), weights already divided by `s²`.
///
/// `roi` is xyxy in input pixels, `scale` maps input pixels to feature pixels, `s` is the
/// sampling ratio (≥ 1) or 0 for torchvision's adaptive `ceil(roi_size / out_size)`.
pub fn bin_samples(
    roi: [f32; 4],
    scale: f32,
    [fh, fw]: [usize; 2],
    [oh, ow]: [usize; 2],
    s: usize,
    out: &mut Vec<(usize, f32)>,
) {
    let x0 = roi[0] * scale - 0.5;
    let y0 = roi[1] * scale - 0.5;
    let (rw, rh) = (roi[2] * scale - 0.5 - x0, roi[3] * scale - 0.5 - y0);
    let (bw, bh) = (rw / ow as f32, rh / oh as f32);
    let (gh, gw) = if s > 0 {
        (s, s)
    } else {
        (
            (rh / oh as f32).ceil().max(1.0) as usize,
            (rw / ow as f32).ceil().max(1.0) as usize,
        )
    };
    let norm = 1.0 / (gh * gw) as f32;
    for py in 0..oh {
        for px in 0..ow {
            for iy in 0..gh {
                let y = y0 + py as f32 * bh + (iy as f32 + 0.5) * bh / gh as f32;
                let ty = axis_taps(y, fh);
                for ix in 0..gw {
                    let x = x0 + px as f32 * bw + (ix as f32 + 0.5) * bw / gw as f32;
                    match (ty, axis_taps(x, fw)) {
                        (Some((ylo, yhi, wyl, wyh)), Some((xlo, xhi, wxl, wxh))) => {
                            out.push((ylo * fw + xlo, wyl * wxl * norm));
                            out.push((ylo * fw + xhi, wyl * wxh * norm));
                            out.push((yhi * fw + xlo, wyh * wxl * norm));
                            out.push((yhi * fw + xhi, wyh * wxh * norm));
                        }
                        _ => out.extend([(0, 0.0); 4]),
                    }
                }
            }
        }
    }
}

/// RoIAlign over one feature map.
///
/// - `rois`: `(batch index, xyxy in input pixels)`; `scale` = 1 / stride.
/// - `sampling`: samples per bin side, ≥ 1.
///
/// # Shapes
/// - `features`: `[B, C, H, W]` → `[N, C, out_h, out_w]` (`N = rois.len()`, may be 0)
pub fn roi_align(
    features: Tensor<4>,
    rois: &[(usize, [f32; 4])],
    scale: f32,
    [oh, ow]: [usize; 2],
    sampling: usize,
) -> Tensor<4> {
    assert!(
        sampling >= 1 && oh >= 1 && ow >= 1,
        "roi_align: sampling ratio and output size must be ≥ 1, got sampling {sampling}, output {oh}×{ow}"
    );
    let device = features.device();
    let [b, c, h, w] = features.dims();
    let n = rois.len();
    if n == 0 {
        return Tensor::zeros([0, c, oh, ow], &device);
    }
    let k = 4 * sampling * sampling;
    let mut taps = Vec::with_capacity(n * oh * ow * k);
    for &(bi, r) in rois {
        assert!(bi < b, "roi_align: RoI batch index {bi} for a batch of {b}");
        let start = taps.len();
        bin_samples(r, scale, [h, w], [oh, ow], sampling, &mut taps);
        for t in &mut taps[start..] {
            t.0 += bi * h * w;
        }
    }
    let (idx, wts): (Vec<i64>, Vec<f32>) = taps.into_iter().map(|(i, w)| (i as i64, w)).unzip();
    let rows = idx.len();
    let idx: Tensor<1, Int> = Tensor::from_data(TensorData::new(idx, [rows]), &device);
    let wts: Tensor<2> = Tensor::from_data(TensorData::new(wts, [rows, 1]), &device);
    // [B·H·W, C], channel-last rows so one select gathers whole pixels.
    let flat = features.permute([0, 2, 3, 1]).reshape([b * h * w, c]);
    let picked = flat.select(0, idx) * wts; // [rows, C]
    picked
        .reshape([n * oh * ow, k, c])
        .sum_dim(1)
        .reshape([n, oh, ow, c])
        .permute([0, 3, 1, 2])
}

/// Host RoIAlign of one binary mask (`H × W`, non-zero inside) over `roi` (xyxy px) to
/// `size × size` with torchvision's adaptive sampling ratio (`sampling_ratio = 0`), as
/// detectron2 crops GT masks for the mask loss (`BitMasks.crop_and_resize`). Returns soft
/// values in `[0, 1]`, row-major.
pub fn roi_align_mask(mask: &[u8], [h, w]: [usize; 2], roi: [f32; 4], size: usize) -> Vec<f32> {
    assert_eq!(
        mask.len(),
        h * w,
        "roi_align_mask: mask has {} bytes for {h}×{w}",
        mask.len()
    );
    let mut taps = Vec::new();
    bin_samples(roi, 1.0, [h, w], [size, size], 0, &mut taps);
    let k = taps.len() / (size * size);
    (0..size * size)
        .map(|bin| {
            taps[bin * k..(bin + 1) * k]
                .iter()
                .map(|&(i, wt)| if mask[i] != 0 { wt } else { 0.0 })
                .sum()
        })
        .collect()
}

/// Device-free helper for tests and callers that hold host features: RoIAlign of
/// `[C, H, W]` row-major features for one RoI, returns `[C, oh, ow]`.
pub fn roi_align_host(
    feat: &[f32],
    [c, h, w]: [usize; 3],
    roi: [f32; 4],
    scale: f32,
    [oh, ow]: [usize; 2],
    sampling: usize,
) -> Vec<f32> {
    let mut taps = Vec::new();
    bin_samples(roi, scale, [h, w], [oh, ow], sampling, &mut taps);
    let k = taps.len() / (oh * ow);
    let mut out = vec![0f32; c * oh * ow];
    for ch in 0..c {
        let plane = &feat[ch * h * w..(ch + 1) * h * w];
        for bin in 0..oh * ow {
            out[ch * oh * ow + bin] = taps[bin * k..(bin + 1) * k]
                .iter()
                .map(|&(i, wt)| plane[i] * wt)
                .sum();
        }
    }
    out
}

/// Index tensor helper shared by the heads.
pub(crate) fn index_tensor(v: &[usize], device: &Device) -> Tensor<1, Int> {
    let d: Vec<i64> = v.iter().map(|&i| i as i64).collect();
    Tensor::from_data(TensorData::new(d, [v.len()]), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_map_gives_constant_bins_inside() {
        let feat = vec![2.5f32; 8 * 8];
        let out = roi_align_host(&feat, [1, 8, 8], [1.0, 1.0, 7.0, 6.0], 1.0, [3, 3], 2);
        assert!(out.iter().all(|v| (v - 2.5).abs() < 1e-6), "{out:?}");
    }

    #[test]
    fn ramp_is_sampled_at_bin_centres() {
        // f(y, x) = x on pixel centres; aligned RoI [0, 8) in x → 4 bins of width 2 whose
        // sample means sit at x = 0.5, 2.5, 4.5, 6.5 in pixel-centre coordinates.
        let feat: Vec<f32> = (0..8 * 8).map(|i| (i % 8) as f32).collect();
        let out = roi_align_host(&feat, [1, 8, 8], [0.0, 0.0, 8.0, 8.0], 1.0, [1, 4], 2);
        for (v, e) in out.iter().zip([0.5, 2.5, 4.5, 6.5]) {
            assert!((v - e).abs() < 1e-5, "{out:?}");
        }
    }

    #[test]
    fn mask_targets_are_soft_box_fractions() {
        // Left half of a 16×16 image filled: a RoI over the whole image gives ~1 on the left
        // half of the 4×4 target and ~0 on the right.
        let mut m = vec![0u8; 16 * 16];
        for y in 0..16 {
            for x in 0..8 {
                m[y * 16 + x] = 1;
            }
        }
        let t = roi_align_mask(&m, [16, 16], [0.0, 0.0, 16.0, 16.0], 4);
        for r in 0..4 {
            assert!(t[r * 4] > 0.99 && t[r * 4 + 1] > 0.99, "{t:?}");
            assert!(t[r * 4 + 2] < 0.01 && t[r * 4 + 3] < 0.01, "{t:?}");
        }
    }

    #[test]
    #[should_panic(expected = "sampling ratio and output size must be ≥ 1, got sampling 0")]
    fn rejects_zero_sampling() {
        let d = Device::flex();
        roi_align(
            Tensor::zeros([1, 1, 4, 4], &d),
            &[(0, [0.0, 0.0, 2.0, 2.0])],
            1.0,
            [2, 2],
            0,
        );
    }
}
