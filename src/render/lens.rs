//! Radial lens distortion (Brown–Conrady k1, k2) as a warp of the traced frame: every
//! output pixel reads the pinhole frame at its undistorted position. Radiance is read
//! bilinearly; the depth, the instance-id buffer and the amodal masks are read at the
//! nearest source pixel of the very same position, so masks stay aligned with the image
//! (one mapping for all buffers). Warping after tracing, rather than bending primary
//! rays, keeps the rasterised primary visibility and the amodal rasteriser pinhole.
//!
//! Radii are normalised so the image corner is r = 1, and the mapping is scaled so the
//! corners stay where they are: barrel (k1 < 0) and pincushion (k1 > 0) lenses then cover
//! the same frame and never read outside the traced one.

use glam::Vec3;
use rayon::prelude::*;

/// Radial distortion of one image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lens {
    pub k1: f32,
    pub k2: f32,
}

impl Lens {
    /// Source (pinhole) position of output pixel centre (x, y) in a `w`×`h` frame.
    #[inline]
    pub fn source(&self, x: f32, y: f32, w: usize, h: usize) -> (f32, f32) {
        let (cx, cy) = (w as f32 * 0.5, h as f32 * 0.5);
        let rn = (cx * cx + cy * cy).sqrt();
        let (dx, dy) = ((x - cx) / rn, (y - cy) / rn);
        let r2 = dx * dx + dy * dy;
        let f = (1.0 + self.k1 * r2 + self.k2 * r2 * r2) / (1.0 + self.k1 + self.k2);
        (cx + dx * f * rn, cy + dy * f * rn)
    }

    /// Source pixel positions of every output pixel (row-major).
    fn map(&self, w: usize, h: usize) -> Vec<(f32, f32)> {
        (0..w * h)
            .into_par_iter()
            .map(|i| self.source((i % w) as f32 + 0.5, (i / w) as f32 + 0.5, w, h))
            .collect()
    }

    /// Warps radiance (bilinear), depth and ids (nearest) and the amodal masks (nearest)
    /// of a `w`×`h` frame in place.
    pub fn warp(
        &self,
        radiance: &mut Vec<Vec3>,
        depth: &mut Vec<f32>,
        ids: &mut Vec<u16>,
        masks: &mut [Vec<bool>],
        w: usize,
        h: usize,
    ) {
        let map = self.map(w, h);
        let nearest = |&(sx, sy): &(f32, f32)| {
            let x = (sx.floor() as isize).clamp(0, w as isize - 1) as usize;
            let y = (sy.floor() as isize).clamp(0, h as isize - 1) as usize;
            y * w + x
        };
        let src = std::mem::take(radiance);
        *radiance = map
            .par_iter()
            .map(|&(sx, sy)| {
                let (fx, fy) = (sx - 0.5, sy - 0.5);
                let (x0, y0) = (fx.floor(), fy.floor());
                let (tx, ty) = (fx - x0, fy - y0);
                let at = |x: f32, y: f32| {
                    let x = (x as isize).clamp(0, w as isize - 1) as usize;
                    let y = (y as isize).clamp(0, h as isize - 1) as usize;
                    src[y * w + x]
                };
                let top = at(x0, y0).lerp(at(x0 + 1.0, y0), tx);
                let bottom = at(x0, y0 + 1.0).lerp(at(x0 + 1.0, y0 + 1.0), tx);
                top.lerp(bottom, ty)
            })
            .collect();
        let idx: Vec<usize> = map.iter().map(nearest).collect();
        let d = std::mem::take(depth);
        *depth = idx.iter().map(|&i| d[i]).collect();
        let s = std::mem::take(ids);
        *ids = idx.iter().map(|&i| s[i]).collect();
        masks.par_iter_mut().for_each(|m| {
            let src = std::mem::take(m);
            *m = idx.iter().map(|&i| src[i]).collect();
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_and_centre_stay_and_barrel_pulls_edges_in() {
        let l = Lens { k1: -0.2, k2: 0.02 };
        let (w, h) = (64, 48);
        let (sx, sy) = l.source(32.0, 24.0, w, h);
        assert!((sx - 32.0).abs() < 1e-4 && (sy - 24.0).abs() < 1e-4);
        let (sx, sy) = l.source(0.0, 0.0, w, h);
        assert!(sx.abs() < 1e-3 && sy.abs() < 1e-3, "{sx} {sy}");
        // Barrel: the middle of the top edge reads from further out than it sits.
        let (_, sy) = l.source(32.0, 2.0, w, h);
        assert!(sy < 2.0, "{sy}");
    }

    #[test]
    fn image_ids_and_masks_are_warped_identically() {
        // A frame whose colour encodes its id: after the warp every pixel whose bilinear
        // footprint lies in one region must carry that region's colour AND id, and the
        // amodal mask of a region must be exactly its warped ids where nothing covers it.
        let (w, h) = (80usize, 60usize);
        let id_at = |x: usize, y: usize| -> u16 {
            let (dx, dy) = (x as f32 - 30.0, y as f32 - 25.0);
            if dx * dx + dy * dy < 300.0 {
                1
            } else if x > 55 && y > 10 && y < 50 {
                2
            } else {
                0
            }
        };
        // Affinely independent colours: a blend of regions never equals a pure one.
        let colour = |id: u16| Vec3::new((id == 1) as u8 as f32, (id == 2) as u8 as f32, 0.5);
        let mut ids: Vec<u16> = (0..w * h).map(|i| id_at(i % w, i / w)).collect();
        let mut rad: Vec<Vec3> = ids.iter().map(|&k| colour(k)).collect();
        let mut depth: Vec<f32> = ids.iter().map(|&k| k as f32).collect();
        let mut masks = vec![ids.iter().map(|&k| k == 1).collect::<Vec<bool>>()];
        let l = Lens {
            k1: -0.25,
            k2: 0.03,
        };
        l.warp(&mut rad, &mut depth, &mut ids, &mut masks, w, h);
        let mut pure = 0;
        for i in 0..w * h {
            assert_eq!(masks[0][i], ids[i] == 1, "mask and ids disagree at {i}");
            assert_eq!(depth[i], ids[i] as f32);
            if let Some(k) = (0..3u16).find(|&k| (rad[i] - colour(k)).length() < 1e-5) {
                pure += 1;
                assert_eq!(
                    ids[i], k,
                    "pixel {i}: image shows region {k}, id {}",
                    ids[i]
                );
            }
        }
        assert!(pure > w * h * 8 / 10, "only {pure} pure pixels");
        // The warp really moved things: the disc is not where it was.
        let moved = (0..w * h)
            .filter(|&i| ids[i] != id_at(i % w, i / w))
            .count();
        assert!(moved > 20, "{moved} pixels moved");
    }
}
