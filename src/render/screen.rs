//! Screen-space passes of the renderer, the ones that cast no rays: z-buffer
//! rasterisation of primary visibility (which triangle covers each pixel centre), the
//! edge-aware filter that turns one shadow/reflection ray per pixel into soft terms, and
//! depth darkening of crevices. Each works on a `width × height` pixel grid; `trace`
//! (the rays and the shading) calls them and this file knows nothing of rays.

use glam::Vec3;
use rayon::prelude::*;

use super::camera::Camera;
use super::noise::{fceil, ffloor};

/// One shaded pixel as the tracer leaves it, before the shadow filter: the final
/// radiance is `direct · filtered vis + filtered refl + other`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PixelOut {
    /// Key light, unshadowed.
    pub(super) direct: Vec3,
    /// Fraction of the shadow rays that reached the light.
    pub(super) vis: f32,
    /// 1 where shadow/reflection rays were traced, 0 where the filter fills in.
    pub(super) wt: f32,
    /// Glossy reflection (one ray, filtered like the visibility).
    pub(super) refl: Vec3,
    /// Ambient and room specular (not filtered).
    pub(super) other: Vec3,
    /// Distance along the primary ray; the filter compares it between neighbours.
    pub(super) depth: f32,
    /// First-hit instance id (0 = background); the filter never crosses it.
    pub(super) id: u16,
}

/// The projected corners of triangle `tri`; `None` when one of them did not project
/// (behind the camera).
pub fn corners<T: Copy>(proj: &[Option<T>], tri: &[u32; 3]) -> Option<[T; 3]> {
    Some([
        proj[tri[0] as usize]?,
        proj[tri[1] as usize]?,
        proj[tri[2] as usize]?,
    ])
}

/// Z-buffer rasterisation of all triangles: per pixel the nearest triangle whose
/// projection covers the pixel centre (u32::MAX = none). Rows are split into bands
/// rasterised in parallel; depth is 1/z interpolated linearly in screen space.
pub fn raster_primary(positions: &[Vec3], triangles: &[[u32; 3]], cam: &Camera) -> Vec<u32> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let proj: Vec<Option<(f32, f32, f32)>> = positions
        .par_iter()
        .map(|&p| {
            let z = (p - cam.eye).dot(cam.forward);
            cam.project(p).map(|q| (q.x, q.y, 1.0 / z))
        })
        .collect();
    let band = 16usize;
    let nbands = h.div_ceil(band);
    // Bin triangles by the bands their rows touch (in triangle order, so ties resolve
    // the same way whatever the band layout).
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); nbands];
    for (t, tri) in triangles.iter().enumerate() {
        let Some([a, b, c]) = corners(&proj, tri) else {
            continue;
        };
        let y0 = fceil(a.1.min(b.1).min(c.1) - 0.5).max(0.0);
        let y1 = ffloor(a.1.max(b.1).max(c.1) - 0.5).min(h as f32 - 1.0);
        if y0 > y1 {
            continue;
        }
        for bin in bins
            .iter_mut()
            .take(y1 as usize / band + 1)
            .skip(y0 as usize / band)
        {
            bin.push(t as u32);
        }
    }
    let mut out = vec![u32::MAX; w * h];
    out.par_chunks_mut(w * band)
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(bi, (chunk, bin))| {
            let y_lo = bi * band;
            let y_hi = (y_lo + band).min(h);
            let mut zbuf = vec![0.0f32; chunk.len()];
            for &t in bin {
                let t = t as usize;
                let tri = &triangles[t];
                let Some([a, b, c]) = corners(&proj, tri) else {
                    continue;
                };
                let ymin = a.1.min(b.1).min(c.1);
                let ymax = a.1.max(b.1).max(c.1);
                let y0 = (fceil(ymin - 0.5).max(y_lo as f32)) as i64;
                let y1 = (ffloor(ymax - 0.5) as i64).min(y_hi as i64 - 1);
                if y0 > y1 {
                    continue;
                }
                let xmin = a.0.min(b.0).min(c.0);
                let xmax = a.0.max(b.0).max(c.0);
                let x0 = fceil(xmin - 0.5).max(0.0) as i64;
                let x1 = (ffloor(xmax - 0.5) as i64).min(w as i64 - 1);
                if x0 > x1 {
                    continue;
                }
                let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
                if area.abs() < 1e-12 {
                    continue;
                }
                let inv = 1.0 / area;
                for y in y0..=y1 {
                    let py = y as f32 + 0.5;
                    for x in x0..=x1 {
                        let px = x as f32 + 0.5;
                        let w0 = ((b.0 - px) * (c.1 - py) - (b.1 - py) * (c.0 - px)) * inv;
                        let w1 = ((c.0 - px) * (a.1 - py) - (c.1 - py) * (a.0 - px)) * inv;
                        let w2 = 1.0 - w0 - w1;
                        if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                            continue;
                        }
                        let iz = w0 * a.2 + w1 * b.2 + w2 * c.2;
                        let k = (y as usize - y_lo) * w + x as usize;
                        if iz > zbuf[k] {
                            zbuf[k] = iz;
                            chunk[k] = t as u32;
                        }
                    }
                }
            }
        });
    out
}

/// Edge-aware separable box filter (radius `r` pixels) of the two one-sample terms, shadow
/// visibility and glossy reflection: only neighbours of the same instance at a similar
/// depth contribute, so edges stay sharp while the noise averages out.
#[allow(clippy::needless_range_loop)]
pub(super) fn filter_noisy(px: &[PixelOut], w: usize, h: usize, r: usize) -> (Vec<f32>, Vec<Vec3>) {
    // (visibility, reflection, weight): weight 0 marks pixels whose rays were skipped.
    let mut v: Vec<(f32, Vec3, f32)> = px.iter().map(|p| (p.vis, p.refl, p.wt)).collect();
    if r > 0 {
        let same = |i: usize, j: usize| {
            let (a, b) = (&px[i], &px[j]);
            a.id == b.id && (a.depth - b.depth).abs() <= 0.01 * a.depth.min(b.depth) + 2e-3
        };
        for horizontal in [true, false] {
            let src = v.clone();
            v.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
                for x in 0..w {
                    let i = y * w + x;
                    let (mut s, mut sr, mut n) = (0.0, Vec3::ZERO, 0.0);
                    for o in -(r as isize)..=(r as isize) {
                        let (xx, yy) = if horizontal {
                            (x as isize + o, y as isize)
                        } else {
                            (x as isize, y as isize + o)
                        };
                        if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                            continue;
                        }
                        let j = yy as usize * w + xx as usize;
                        if same(i, j) {
                            let wj = src[j].2;
                            s += src[j].0 * wj;
                            sr += src[j].1 * wj;
                            n += wj;
                        }
                    }
                    row[x] = if n > 0.0 {
                        (s / n, sr / n, 1.0)
                    } else {
                        (1.0, Vec3::ZERO, 0.0)
                    };
                }
            });
        }
    }
    (
        v.iter().map(|x| x.0).collect(),
        v.iter().map(|x| x.1).collect(),
    )
}

/// Screen-space occlusion by depth darkening (Luft et al. 2006): a pixel farther
/// away than its neighbourhood (a crevice between carcasses, the plate right next to
/// one) receives less room light. Cheap stand-in for ambient-occlusion rays.
/// `radiance` and `depth` are the `w × h` buffers of one frame.
pub fn darken_crevices(radiance: &mut [Vec3], depth: &[f32], w: usize, h: usize, strength: f32) {
    let far = depth
        .iter()
        .cloned()
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let d: Vec<f32> = depth
        .iter()
        .map(|&v| if v.is_finite() { v } else { far })
        .collect();
    let r = (w.max(h) / 48).max(2);
    let blurred = box_blur(&box_blur(&d, w, h, r, true), w, h, r, false);
    for i in 0..w * h {
        let diff = (d[i] - blurred[i]).max(0.0);
        let occl = 1.0 - (-diff / 0.02).exp();
        radiance[i] *= 1.0 - strength * occl;
    }
}

/// Running-sum box blur along rows (`horizontal`) or columns, clamped at the borders.
fn box_blur(src: &[f32], w: usize, h: usize, r: usize, horizontal: bool) -> Vec<f32> {
    let mut out = vec![0.0; src.len()];
    let (n, lines) = if horizontal { (w, h) } else { (h, w) };
    let at = |line: usize, i: usize| {
        if horizontal {
            line * w + i
        } else {
            i * w + line
        }
    };
    for line in 0..lines {
        let mut acc = 0.0f32;
        let get = |i: isize| src[at(line, i.clamp(0, n as isize - 1) as usize)];
        for i in -(r as isize)..=(r as isize) {
            acc += get(i);
        }
        let norm = 1.0 / (2 * r + 1) as f32;
        for i in 0..n {
            out[at(line, i)] = acc * norm;
            acc += get(i as isize + r as isize + 1) - get(i as isize - r as isize);
        }
    }
    out
}
