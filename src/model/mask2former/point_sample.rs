//! Point sampling of masks (PointRend, Kirillov et al. 2020, as detectron2's
//! `point_sample`): bilinear `grid_sample` at normalised points `(x, y) ∈ [0, 1]²` with
//! `align_corners = False` and zero padding, so the pixel of point `x` is `x·W − 0.5`.
//! Mask2Former computes its matching costs and its mask losses on K sampled points instead
//! of whole masks (§3.2, "Improving training efficiency"): uniform points for matching,
//! importance-sampled points (PointRend's `get_uncertain_point_coords_with_randomness`) for
//! the losses.
//!
//! Points are drawn on the host from the caller's RNG (seeded from the config seed and
//! the step), so a run is deterministic. Targets are sampled on the host from the byte
//! masks; predictions through [`PointTaps`] (a `gather` of the four corner pixels with
//! bilinear weights), which is differentiable on every backend.

use burn::tensor::{Device, Int, Tensor, TensorData};
use rand::Rng;

/// A normalised point `(x, y)`.
pub type Point = [f32; 2];

/// `n` uniform points in `[0, 1)²`.
pub fn uniform_points<R: Rng>(n: usize, rng: &mut R) -> Vec<Point> {
    (0..n)
        .map(|_| [rng.random::<f32>(), rng.random::<f32>()])
        .collect()
}

/// The four bilinear taps `(flat index, weight)` of point `p` on an `h × w` grid; taps
/// outside the grid get weight 0 (and index 0), like `grid_sample`'s zero padding.
pub fn taps(p: Point, h: usize, w: usize) -> [(usize, f32); 4] {
    let x = p[0] * w as f32 - 0.5;
    let y = p[1] * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let tap = |xi: i64, yi: i64, wt: f32| {
        if xi < 0 || yi < 0 || xi >= w as i64 || yi >= h as i64 || !wt.is_finite() {
            (0, 0.0)
        } else {
            (yi as usize * w + xi as usize, wt)
        }
    };
    [
        tap(x0, y0, (1.0 - fx) * (1.0 - fy)),
        tap(x0 + 1, y0, fx * (1.0 - fy)),
        tap(x0, y0 + 1, (1.0 - fx) * fy),
        tap(x0 + 1, y0 + 1, fx * fy),
    ]
}

/// Bilinear value of the row-major `h × w` grid `v` at `p` (host `point_sample`).
pub fn sample_host(v: &[f32], h: usize, w: usize, p: Point) -> f32 {
    taps(p, h, w).iter().map(|&(i, wt)| wt * v[i]).sum()
}

/// A byte mask (nonzero = inside) sampled at `points`, as the float mask would be.
pub fn sample_mask(mask: &[u8], h: usize, w: usize, points: &[Point]) -> Vec<f32> {
    points
        .iter()
        .map(|&p| {
            taps(p, h, w)
                .iter()
                .map(|&(i, wt)| if mask[i] != 0 { wt } else { 0.0 })
                .sum()
        })
        .collect()
}

/// Bilinear taps of `K` points for each of `N` rows, to sample an `[N, h·w]` tensor.
#[derive(Debug, Clone)]
pub struct PointTaps {
    pub rows: usize,
    pub points: usize,
    index: Vec<i64>,
    weight: Vec<f32>,
}

impl PointTaps {
    /// `points[r]` are the points of row `r` (all rows the same length).
    pub fn new(points: &[Vec<Point>], h: usize, w: usize) -> Self {
        let k = points.first().map_or(0, |p| p.len());
        let mut index = Vec::with_capacity(points.len() * k * 4);
        let mut weight = Vec::with_capacity(points.len() * k * 4);
        for row in points {
            assert_eq!(row.len(), k, "PointTaps: rows with different point counts");
            for &p in row {
                for (i, wt) in taps(p, h, w) {
                    index.push(i as i64);
                    weight.push(wt);
                }
            }
        }
        Self {
            rows: points.len(),
            points: k,
            index,
            weight,
        }
    }

    /// Values of `x` at the points.
    ///
    /// # Shapes
    /// - `x`: `[N, h·w]` → `[N, K]`
    pub fn sample(&self, x: Tensor<2>) -> Tensor<2> {
        let device = x.device();
        let (n, k) = (self.rows, self.points);
        assert_eq!(
            x.dims()[0],
            n,
            "PointTaps: {} rows for {n} point sets",
            x.dims()[0]
        );
        let idx: Tensor<2, Int> =
            Tensor::from_data(TensorData::new(self.index.clone(), [n, k * 4]), &device);
        let wt = weights(&self.weight, [n, k * 4], &device);
        (x.gather(1, idx) * wt)
            .reshape([n, k, 4])
            .sum_dim(2)
            .reshape([n, k])
    }
}

fn weights(v: &[f32], shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(v.to_vec(), shape), device)
}

/// PointRend's importance sampling of one mask: `oversample · k` uniform candidates, the
/// `⌊ratio · k⌋` most uncertain of them (uncertainty `−|logit|`, the mask boundary), then
/// uniform points for the rest. `logits` is the row-major `h × w` mask (host copy; no
/// gradient flows through the choice of points).
pub fn importance_points<R: Rng>(
    logits: &[f32],
    h: usize,
    w: usize,
    k: usize,
    oversample: usize,
    ratio: f32,
    rng: &mut R,
) -> Vec<Point> {
    let cand = uniform_points(k * oversample.max(1), rng);
    let n_unc = ((ratio.clamp(0.0, 1.0) * k as f32) as usize).min(cand.len());
    let mut unc: Vec<(f32, usize)> = cand
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let v = sample_host(logits, h, w, p);
            // A NaN logit is as uncertain as it gets; keep the order total.
            (if v.is_nan() { 0.0 } else { -v.abs() }, i)
        })
        .collect();
    // Most uncertain first; equal uncertainty keeps the candidate order.
    unc.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut pts: Vec<Point> = unc[..n_unc].iter().map(|&(_, i)| cand[i]).collect();
    pts.extend(uniform_points(k - n_unc, rng));
    pts
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn taps_follow_align_corners_false() {
        // Pixel centres sit at (i + 0.5) / n: sampling there returns the pixel itself.
        let v: Vec<f32> = (0..12).map(|i| i as f32).collect();
        for y in 0..3 {
            for x in 0..4 {
                let p = [(x as f32 + 0.5) / 4.0, (y as f32 + 0.5) / 3.0];
                assert!((sample_host(&v, 3, 4, p) - (y * 4 + x) as f32).abs() < 1e-5);
            }
        }
        // At the border half the taps fall outside (zero padding): the corner halves.
        assert!((sample_host(&[1.0; 4], 2, 2, [0.0, 0.5]) - 0.5).abs() < 1e-6);
        assert!((sample_host(&[1.0; 4], 2, 2, [0.0, 0.0]) - 0.25).abs() < 1e-6);
    }

    #[test]
    fn importance_points_pick_the_boundary() {
        // Left half strongly negative, right half strongly positive, a thin band at 0.
        let (h, w) = (8, 64);
        let logits: Vec<f32> = (0..h * w).map(|i| ((i % w) as f32 - 31.5) * 10.0).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let pts = importance_points(&logits, h, w, 100, 3, 0.75, &mut rng);
        assert_eq!(pts.len(), 100);
        let near = pts[..75]
            .iter()
            .filter(|p| (p[0] - 0.5).abs() < 0.2)
            .count();
        assert!(
            near >= 70,
            "{near} of 75 importance points near the boundary"
        );
        let again = importance_points(
            &logits,
            h,
            w,
            100,
            3,
            0.75,
            &mut ChaCha8Rng::seed_from_u64(3),
        );
        assert_eq!(pts, again, "same seed, same points");
    }
}
