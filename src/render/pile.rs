//! Piling carcasses on the plate without a physics engine: a heightfield drop.
//!
//! The plate (z = 0) is covered by a height map (4 mm cells). Each carcass, already posed
//! and turned into its resting mode (breast up / breast down / side) and yaw, is tried at
//! K candidate positions; at each it is lowered until it touches the map, and the
//! candidate with the lowest resting height wins (a falling body settles low). The
//! winner is then draped: every column of the carcass moves up or down to lie on what is
//! under it, smoothed so the carcass bends like a soft body instead of hovering on one
//! contact point, and never pushed into what is below. The map is then raised to the
//! carcass's top surface. See `shared/notes/renderer.md` ("Piles without a physics engine").

use glam::{Quat, Vec2, Vec3};
use rand::Rng;

use super::noise::ffloor;

/// How a carcass lies on the plate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RestingMode {
    BreastUp,
    BreastDown,
    Side,
}

impl RestingMode {
    pub fn name(self) -> &'static str {
        match self {
            RestingMode::BreastUp => "breast_up",
            RestingMode::BreastDown => "breast_down",
            RestingMode::Side => "side",
        }
    }
}

/// Rotation from the carcass frame to the plate for a resting mode, yaw and jitter.
pub fn resting_rotation<R: Rng>(rng: &mut R, mode: RestingMode, yaw: f32) -> Quat {
    let roll = match mode {
        RestingMode::BreastUp => rng.random_range(-0.12..0.12),
        RestingMode::BreastDown => std::f32::consts::PI + rng.random_range(-0.12..0.12),
        RestingMode::Side => {
            let s = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            // Side lies are rarely exactly 90°: ±15° either way (notes).
            s * (std::f32::consts::FRAC_PI_2 + rng.random_range(-0.26..0.26))
        }
    };
    let pitch = rng.random_range(-0.08..0.08);
    Quat::from_rotation_z(yaw) * Quat::from_rotation_y(pitch) * Quat::from_rotation_x(roll)
}

/// The plate's height map.
pub struct HeightField {
    origin: Vec2,
    cell: f32,
    n: usize,
    h: Vec<f32>,
}

impl HeightField {
    /// A flat map covering the square of half-size `half` around the origin.
    pub fn new(half: f32, cell: f32) -> HeightField {
        Self::around(Vec2::ZERO, half, cell)
    }

    /// A flat map covering the square of half-size `half` around `centre`.
    pub fn around(centre: Vec2, half: f32, cell: f32) -> HeightField {
        let n = ((2.0 * half / cell).ceil() as usize).max(2);
        HeightField {
            origin: centre - Vec2::splat(half),
            cell,
            n,
            h: vec![0.0; n * n],
        }
    }

    fn cell_of(&self, x: f32, y: f32) -> Option<usize> {
        let i = ffloor((x - self.origin.x) / self.cell);
        let j = ffloor((y - self.origin.y) / self.cell);
        if i < 0.0 || j < 0.0 || i >= self.n as f32 || j >= self.n as f32 {
            return None;
        }
        Some(j as usize * self.n + i as usize)
    }

    /// Height at a point (0 = plate; outside the map is plate too).
    pub fn at(&self, x: f32, y: f32) -> f32 {
        self.cell_of(x, y).map_or(0.0, |c| self.h[c])
    }

    /// How far a point set (relative to `offset`) must be raised to clear the map.
    fn lift(&self, pts: &[Vec3], offset: Vec2) -> f32 {
        pts.iter()
            .map(|p| self.at(p.x + offset.x, p.y + offset.y) - p.z)
            .fold(0.0, f32::max)
    }
}

/// Drops one carcass (positions with min z = 0, centred in xy) onto the map. `candidates`
/// are xy positions to try; returns the placed positions (normals follow the drape)
/// and raises the map.
pub fn drop_one(
    hf: &mut HeightField,
    local: &[Vec3],
    nor: &mut [Vec3],
    candidates: &[Vec2],
) -> Vec<Vec3> {
    // A sparse subset is enough to find the contact height (vertices are ~4 mm apart).
    let probe: Vec<Vec3> = local.iter().step_by(5).copied().collect();
    let mut best = (f32::INFINITY, Vec2::ZERO);
    for &c in candidates {
        let l = hf.lift(&probe, c);
        if l < best.0 - 1e-4 {
            best = (l, c);
        }
    }
    let (lift, off) = best;
    let mut pos: Vec<Vec3> = local
        .iter()
        .map(|p| Vec3::new(p.x + off.x, p.y + off.y, p.z + lift))
        .collect();
    if lift > 0.0 {
        drape(hf, &mut pos, nor);
    }
    // Raise the map to the carcass top (3x3 splat closes gaps between vertices).
    for p in &pos {
        for dj in -1i32..=1 {
            for di in -1i32..=1 {
                let x = p.x + di as f32 * hf.cell;
                let y = p.y + dj as f32 * hf.cell;
                if let Some(c) = hf.cell_of(x, y) {
                    hf.h[c] = hf.h[c].max(p.z);
                }
            }
        }
    }
    pos
}

/// Moves each column of the carcass to rest on the map: target shift d = H - bottom,
/// smoothed over ~3 cm (soft-body bending), then never below the raw shift where the
/// raw shift pushes up (no interpenetration with what is underneath).
fn drape(hf: &HeightField, pos: &mut [Vec3], nor: &mut [Vec3]) {
    let (lo, hi) = pos.iter().fold(
        (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p.truncate()), hi.max(p.truncate())),
    );
    let c = hf.cell * 2.0;
    let nx = ((hi.x - lo.x) / c).ceil() as usize + 1;
    let ny = ((hi.y - lo.y) / c).ceil() as usize + 1;
    let cell = |p: Vec3| {
        let i = (((p.x - lo.x) / c) as usize).min(nx - 1);
        let j = (((p.y - lo.y) / c) as usize).min(ny - 1);
        j * nx + i
    };
    let mut bottom = vec![f32::INFINITY; nx * ny];
    let mut support = vec![0.0f32; nx * ny];
    for p in pos.iter() {
        let k = cell(*p);
        if p.z < bottom[k] {
            bottom[k] = p.z;
            support[k] = hf.at(p.x, p.y);
        }
    }
    let raw: Vec<Option<f32>> = bottom
        .iter()
        .zip(&support)
        .map(|(&b, &s)| b.is_finite().then_some(s + 0.0005 - b))
        .collect();
    // A carcass is semi-rigid: first a plane (tilt) fitted to the shifts, slope limited
    // to ~35°, then a soft residual on top of it that may sag at most 2 cm.
    let coef = fit_plane(&raw, nx, ny, c);
    let slope = Vec2::new(coef.y, coef.z);
    let slope = slope * (0.7 / slope.length().max(0.7));
    let plane = |i: usize, j: usize| coef.x + slope.x * i as f32 * c + slope.y * j as f32 * c;
    // Relaxation of the residual: box blur (radius ~2.5 cm) then clamp to the raw shift
    // where that pushes up, repeated, so nothing sinks into the support.
    let r = (0.025 / c).round() as i32;
    let mut smooth: Vec<f32> = (0..nx * ny).map(|k| plane(k % nx, k / nx)).collect();
    for k in 0..nx * ny {
        if let Some(v) = raw[k] {
            smooth[k] = smooth[k].max(v);
        }
    }
    for _ in 0..4 {
        let prev = smooth.clone();
        for j in 0..ny as i32 {
            for i in 0..nx as i32 {
                let (mut s, mut w) = (0.0, 0.0);
                for dj in -r..=r {
                    for di in -r..=r {
                        let (x, y) = (i + di, j + dj);
                        if x >= 0 && y >= 0 && x < nx as i32 && y < ny as i32 {
                            let kk = y as usize * nx + x as usize;
                            if raw[kk].is_some() {
                                s += prev[kk] - plane(x as usize, y as usize);
                                w += 1.0;
                            }
                        }
                    }
                }
                let k = j as usize * nx + i as usize;
                let p0 = plane(i as usize, j as usize);
                let sm = p0 + if w > 0.0 { (s / w).max(-0.02) } else { 0.0 };
                smooth[k] = match raw[k] {
                    Some(v) if v > sm => v,
                    _ => sm,
                };
            }
        }
    }
    // A last light blur without the clamp: the clamp alone leaves cell-sized steps where
    // the support is bumpy (a few mm of give is what soft skin does anyway).
    blur3(&mut smooth, nx, ny);
    // Bilinear shift (and its slope, for the normals) at a point: nearest-cell lookup
    // would crinkle the surface into cell-sized terraces.
    let at = |x: f32, y: f32| -> (f32, Vec2) {
        let fx = ((x - lo.x) / c - 0.5).clamp(0.0, (nx - 1) as f32);
        let fy = ((y - lo.y) / c - 0.5).clamp(0.0, (ny - 1) as f32);
        let (i0, j0) = (fx as usize, fy as usize);
        let (i1, j1) = ((i0 + 1).min(nx - 1), (j0 + 1).min(ny - 1));
        let (tx, ty) = (fx - i0 as f32, fy - j0 as f32);
        let g = |i: usize, j: usize| smooth[j * nx + i];
        let (a, b, cc, d) = (g(i0, j0), g(i1, j0), g(i0, j1), g(i1, j1));
        let v = (a * (1.0 - tx) + b * tx) * (1.0 - ty) + (cc * (1.0 - tx) + d * tx) * ty;
        let dx = ((b - a) * (1.0 - ty) + (d - cc) * ty) / c;
        let dy = ((cc - a) * (1.0 - tx) + (d - b) * tx) / c;
        (v, Vec2::new(dx, dy))
    };
    for (p, n) in pos.iter_mut().zip(nor.iter_mut()) {
        let (d, g) = at(p.x, p.y);
        p.z += d;
        // Surface z += d(x, y): normals tilt by the slope of d.
        *n = Vec3::new(n.x - n.z * g.x, n.y - n.z * g.y, n.z).normalize_or(*n);
    }
}

/// Least-squares plane `coef.x + coef.y · x + coef.z · y` through the cells that have a
/// shift (`raw`, `nx × ny` cells of `c` m); only an offset when the fit is degenerate.
fn fit_plane(raw: &[Option<f32>], nx: usize, ny: usize, c: f32) -> Vec3 {
    let (mut m, mut rhs) = (glam::Mat3::ZERO, Vec3::ZERO);
    for j in 0..ny {
        for i in 0..nx {
            if let Some(v) = raw[j * nx + i] {
                let f = Vec3::new(1.0, i as f32 * c, j as f32 * c);
                m += glam::Mat3::from_cols(f * f.x, f * f.y, f * f.z);
                rhs += f * v;
            }
        }
    }
    if m.determinant().abs() > 1e-12 {
        m.inverse() * rhs
    } else {
        Vec3::new(rhs.x / m.x_axis.x.max(1.0), 0.0, 0.0)
    }
}

/// A 3 × 3 box blur of an `nx × ny` grid, in place (edges average what they have).
fn blur3(grid: &mut [f32], nx: usize, ny: usize) {
    let prev = grid.to_vec();
    for j in 0..ny {
        for i in 0..nx {
            let (mut s, mut w) = (0.0, 0.0);
            for y in j.saturating_sub(1)..(j + 2).min(ny) {
                for x in i.saturating_sub(1)..(i + 2).min(nx) {
                    s += prev[y * nx + x];
                    w += 1.0;
                }
            }
            grid[j * nx + i] = s / w;
        }
    }
}

/// Candidate positions for carcass `k` of a pile: uniform in a disc of radius `radius`.
pub fn candidates<R: Rng>(rng: &mut R, centre: Vec2, radius: f32, k: usize) -> Vec<Vec2> {
    (0..k)
        .map(|_| {
            let a = rng.random_range(0.0..std::f32::consts::TAU);
            let r = radius * rng.random_range(0.0f32..1.0).sqrt();
            centre + Vec2::new(a.cos(), a.sin()) * r
        })
        .collect()
}

/// Rotates posed positions/normals into the resting orientation and recentres them so
/// the lowest point is at z = 0 and the xy bounding-box centre at the origin.
pub fn orient(pos: &[Vec3], nor: &[Vec3], q: Quat) -> (Vec<Vec3>, Vec<Vec3>) {
    let p: Vec<Vec3> = pos.iter().map(|&v| q * v).collect();
    let (lo, hi) = p.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &v| (lo.min(v), hi.max(v)),
    );
    let shift = Vec3::new(-(lo.x + hi.x) * 0.5, -(lo.y + hi.y) * 0.5, -lo.z);
    (
        p.into_iter().map(|v| v + shift).collect(),
        nor.iter().map(|&n| q * n).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob() -> Vec<Vec3> {
        // A 10 x 10 cm slab, 4 cm thick, sampled densely.
        let mut v = Vec::new();
        for i in 0..26 {
            for j in 0..26 {
                for z in [0.0, 0.04] {
                    v.push(Vec3::new(
                        i as f32 * 0.004 - 0.05,
                        j as f32 * 0.004 - 0.05,
                        z,
                    ));
                }
            }
        }
        v
    }

    #[test]
    fn second_carcass_stacks_on_first_and_first_rests_on_plate() {
        let mut hf = HeightField::new(0.5, 0.004);
        let a = drop_one(
            &mut hf,
            &blob(),
            &mut vec![Vec3::Z; blob().len()],
            &[Vec2::ZERO],
        );
        assert!(a.iter().map(|p| p.z).fold(f32::INFINITY, f32::min).abs() < 1e-6);
        let b = drop_one(
            &mut hf,
            &blob(),
            &mut vec![Vec3::Z; blob().len()],
            &[Vec2::new(0.02, 0.0)],
        );
        // Over the first slab it rests on top (no penetration); the 2 cm overhang may sag
        // a little but stays well above the plate.
        let over = b
            .iter()
            .filter(|p| p.x < 0.045)
            .map(|p| p.z)
            .fold(f32::INFINITY, f32::min);
        assert!(
            over >= 0.0395,
            "penetrates: bottom over the first slab at {over}"
        );
        let bmin = b.iter().map(|p| p.z).fold(f32::INFINITY, f32::min);
        assert!(bmin > 0.02, "stacked bottom at {bmin}");
        // Given a free spot among the candidates, the drop takes it.
        let c = drop_one(
            &mut hf,
            &blob(),
            &mut vec![Vec3::Z; blob().len()],
            &[Vec2::new(0.01, 0.0), Vec2::new(0.3, 0.3)],
        );
        assert!(c.iter().all(|p| p.x > 0.2));
    }

    #[test]
    fn overhanging_carcass_drapes_down_to_the_plate() {
        let mut hf = HeightField::new(0.5, 0.004);
        drop_one(
            &mut hf,
            &blob(),
            &mut vec![Vec3::Z; blob().len()],
            &[Vec2::ZERO],
        );
        // Drop a 30 cm long slab half over the first one.
        let long: Vec<Vec3> = blob()
            .iter()
            .map(|p| Vec3::new(p.x * 3.0, p.y, p.z * 0.5))
            .collect();
        let b = drop_one(
            &mut hf,
            &long,
            &mut vec![Vec3::Z; long.len()],
            &[Vec2::new(0.15, 0.0)],
        );
        // The far end sinks to the plate; the part above the first slab stays above it.
        let far = b
            .iter()
            .filter(|p| p.x > 0.25)
            .map(|p| p.z)
            .fold(f32::INFINITY, f32::min);
        let near = b
            .iter()
            .filter(|p| p.x.abs() < 0.03)
            .map(|p| p.z)
            .fold(f32::INFINITY, f32::min);
        assert!(far < 0.01, "far end floats at {far}");
        assert!(near >= 0.039, "penetrates at {near}");
    }
}
