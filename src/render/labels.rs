//! Instance labels from a rendered frame.
//!
//! * Visible mask of instance k: exactly the pixels whose first-hit id is k (the id buffer
//!   is the single source of truth, so masks and pixels cannot disagree).
//! * Amodal mask: the instance alone, as if nothing occluded it. Rather than tracing each
//!   instance on its own (one more BVH and primary pass per carcass), its triangles are
//!   rasterised with the same pinhole projection and pixel-centre rule the tracer uses;
//!   the visible mask is OR-ed in so visible ⊆ amodal holds exactly.
//! * `visib_fract` = visible / amodal pixels; instances under `min_visible_px` or
//!   `min_visib_fract` are marked ignore (iscrowd in COCO), fully hidden ones dropped.

use glam::Vec2;
use rayon::prelude::*;

use super::noise::{fceil, ffloor};

use super::camera::Camera;
use super::screen::corners;
use super::trace::Geometry;

/// Thresholds for dropping / ignoring instances.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelThresholds {
    /// Instances with fewer visible pixels are dropped entirely.
    pub drop_below_px: u64,
    /// Instances with fewer visible pixels than this are kept but marked ignore.
    pub min_visible_px: u64,
    /// Instances with a smaller visible fraction are kept but marked ignore
    /// (BlenderProc's BOP export ignores < 0.1).
    pub min_visib_fract: f64,
}

impl Default for LabelThresholds {
    fn default() -> Self {
        LabelThresholds {
            drop_below_px: 1,
            min_visible_px: 100,
            min_visib_fract: 0.1,
        }
    }
}

/// Label of one carcass in one image. Boxes are COCO `[x, y, w, h]` in pixels.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InstanceLabel {
    /// Value of this instance in the id buffer.
    pub id: u16,
    pub visible_px: u64,
    pub amodal_px: u64,
    pub visib_fract: f64,
    pub bbox: [f64; 4],
    pub amodal_bbox: [f64; 4],
    /// Too small or too hidden to be a fair target: ignore region (COCO iscrowd = 1).
    pub ignore: bool,
    /// How the carcass lies: breast_up / breast_down / side.
    pub resting: String,
    /// Touches the image border (cut by it) in its amodal mask.
    pub truncated: bool,
}

/// Rasterises the triangles of each instance (pixel centre inside the projected
/// triangle, no depth test): one bit mask per instance, row-major.
pub fn amodal_masks(geo: &Geometry, cam: &Camera, n_instances: usize) -> Vec<Vec<bool>> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let proj: Vec<Option<Vec2>> = geo.positions.par_iter().map(|&p| cam.project(p)).collect();
    // Triangles of one instance are contiguous: find each instance's range, then
    // rasterise instances in parallel (each owns its mask).
    let mut ranges = vec![(usize::MAX, 0usize); n_instances];
    for (t, &inst) in geo.tri_instance.iter().enumerate() {
        // Distractors (instance numbers from `prop_material::PROP_BASE`) get no mask.
        let Some(r) = ranges.get_mut(inst as usize) else {
            continue;
        };
        r.0 = r.0.min(t);
        r.1 = r.1.max(t + 1);
    }
    ranges
        .par_iter()
        .map(|&(lo, hi)| {
            let mut m = vec![false; w * h];
            for tri in geo.triangles.get(lo..hi).unwrap_or(&[]) {
                let Some([a, b, c]) = corners(&proj, tri) else {
                    continue;
                };
                let area = (b - a).perp_dot(c - a);
                if area.abs() < 1e-12 {
                    continue;
                }
                let lo = a.min(b).min(c);
                let hi = a.max(b).max(c);
                let x0 = fceil(lo.x - 0.5).max(0.0) as i64;
                let y0 = fceil(lo.y - 0.5).max(0.0) as i64;
                let x1 = (ffloor(hi.x - 0.5) as i64).min(w as i64 - 1);
                let y1 = (ffloor(hi.y - 0.5) as i64).min(h as i64 - 1);
                if x0 > x1 || y0 > y1 {
                    continue;
                }
                let s = area.signum();
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                        let e0 = (b - a).perp_dot(p - a) * s;
                        let e1 = (c - b).perp_dot(p - b) * s;
                        let e2 = (a - c).perp_dot(p - c) * s;
                        if e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0 {
                            m[y as usize * w + x as usize] = true;
                        }
                    }
                }
            }
            m
        })
        .collect()
}

/// Pixel bbox `[x, y, w, h]` of a predicate over a `w`×`h` grid, or zeros when empty.
pub fn bbox_of(w: usize, h: usize, on: impl Fn(usize) -> bool) -> ([f64; 4], u64, bool) {
    let (mut x0, mut y0, mut x1, mut y1, mut n) = (usize::MAX, usize::MAX, 0, 0, 0u64);
    for y in 0..h {
        for x in 0..w {
            if on(y * w + x) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
                n += 1;
            }
        }
    }
    if n == 0 {
        return ([0.0; 4], 0, false);
    }
    let touches = x0 == 0 || y0 == 0 || x1 == w - 1 || y1 == h - 1;
    (
        [
            x0 as f64,
            y0 as f64,
            (x1 - x0 + 1) as f64,
            (y1 - y0 + 1) as f64,
        ],
        n,
        touches,
    )
}

/// Builds the labels of every instance from the id buffer and the amodal masks.
pub fn instance_labels(
    ids: &[u16],
    amodal: &mut [Vec<bool>],
    w: usize,
    h: usize,
    resting: &[&str],
    th: &LabelThresholds,
) -> Vec<InstanceLabel> {
    let mut out = Vec::new();
    for (k, am) in amodal.iter_mut().enumerate() {
        let id = (k + 1) as u16;
        for (i, &v) in ids.iter().enumerate() {
            if v == id {
                am[i] = true;
            }
        }
        let (bbox, visible_px, _) = bbox_of(w, h, |i| ids[i] == id);
        let (amodal_bbox, amodal_px, truncated) = bbox_of(w, h, |i| am[i]);
        if visible_px < th.drop_below_px.max(1) {
            continue;
        }
        let visib_fract = visible_px as f64 / amodal_px.max(1) as f64;
        out.push(InstanceLabel {
            id,
            visible_px,
            amodal_px,
            visib_fract,
            bbox,
            amodal_bbox,
            ignore: visible_px < th.min_visible_px || visib_fract < th.min_visib_fract,
            resting: resting.get(k).unwrap_or(&"unknown").to_string(),
            truncated,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn raster_matches_projection_and_labels_follow_ids() {
        let cam = Camera::top_view(Vec3::new(0.0, 0.0, 1.0), 0.0, 0.0, 0.0, 0.9, 64, 64);
        // Two squares: instance 0 at the centre, instance 1 half under it, lower.
        let sq = |c: Vec3, s: f32| {
            vec![
                c + Vec3::new(-s, -s, 0.0),
                c + Vec3::new(s, -s, 0.0),
                c + Vec3::new(s, s, 0.0),
                c + Vec3::new(-s, s, 0.0),
            ]
        };
        let mut positions = sq(Vec3::new(0.0, 0.0, 0.2), 0.1);
        positions.extend(sq(Vec3::new(0.1, 0.0, 0.1), 0.1));
        let geo = Geometry {
            normals: vec![Vec3::Z; 8],
            rest: positions.clone(),
            redness: vec![0.0; 8],
            triangles: vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]],
            tri_instance: vec![0, 0, 1, 1],
            positions,
        };
        let tr = super::super::trace::Tracer::build(&geo);
        let mut ids = vec![0u16; 64 * 64];
        for y in 0..64 {
            for x in 0..64 {
                let d = cam.dir(x as f32 + 0.5, y as f32 + 0.5);
                if let Some((_, t)) = tr.closest(cam.eye, d, 10.0) {
                    ids[y * 64 + x] = geo.tri_instance[t] + 1;
                }
            }
        }
        let mut am = amodal_masks(&geo, &cam, 2);
        // The unoccluded instance's raster equals its traced pixels (same pixel centres).
        let traced0: usize = ids.iter().filter(|&&v| v == 1).count();
        let raster0: usize = am[0].iter().filter(|&&v| v).count();
        assert!(
            (traced0 as i64 - raster0 as i64).abs() <= 2,
            "{traced0} vs {raster0}"
        );
        let labels = instance_labels(
            &ids,
            &mut am,
            64,
            64,
            &["a", "b"],
            &LabelThresholds::default(),
        );
        assert_eq!(labels.len(), 2);
        assert_eq!(labels[0].visib_fract, 1.0);
        // Instance 1's projection spans x in [0, 0.222] (0.2 m at 0.9 m), instance 0's
        // covers [-0.125, 0.125]: 1 - 0.125 / 0.222 = 0.44 of instance 1 stays visible.
        assert!(
            labels[1].visib_fract > 0.4 && labels[1].visib_fract < 0.5,
            "{}",
            labels[1].visib_fract
        );
        assert_eq!(
            labels[1].visible_px,
            ids.iter().filter(|&&v| v == 2).count() as u64
        );
        // Thresholds: raise min visib_fract above instance 1's and it becomes ignore.
        let th = LabelThresholds {
            min_visib_fract: 0.9,
            ..Default::default()
        };
        let mut am = amodal_masks(&geo, &cam, 2);
        let labels = instance_labels(&ids, &mut am, 64, 64, &["a", "b"], &th);
        assert!(!labels[0].ignore && labels[1].ignore);
    }
}
