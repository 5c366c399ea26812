//! The `distractors` group: non-carcass objects on and among the pile — gloves,
//! bare hands and forearms (skin-coloured: the hard negative), shackles (metal hooks),
//! knives, scrapers, bits of packaging and loose fat scraps — as small procedural meshes
//! (tubes, ellipsoids, slabs) added to the image's geometry. They occlude carcasses and
//! cast shadows like any triangle, but are never labelled: their triangles carry
//! instance numbers from [`PROP_BASE`] up, the tracer shades them with a
//! [`PropMaterial`], and the label step turns their ids into background
//! ([`super::prop_material::is_prop_id`]), so a carcass's visible mask loses the pixels
//! a distractor covers.

use glam::{Quat, Vec2, Vec3};
use rand::Rng;

use super::prop_material::{PropKind, PropMaterial, PROP_BASE};
use super::surface::srgb8;
use super::trace::Geometry;

/// Triangles of one prop in its local frame (z up, resting on z = 0 where it lies).
#[derive(Default)]
struct Parts {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    indices: Vec<u32>,
}

impl Parts {
    /// A tube along `path` with radius `radii[i]` at point i, capped at both ends.
    fn tube(&mut self, path: &[Vec3], radii: &[f32], sides: usize) {
        let base = self.positions.len() as u32;
        let n = path.len();
        for i in 0..n {
            let t = if i + 1 < n {
                path[i + 1] - path[i]
            } else {
                path[i] - path[i - 1]
            }
            .normalize_or(Vec3::X);
            let reference = if t.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
            let a = t.cross(reference).normalize();
            let b = t.cross(a);
            for s in 0..sides {
                let ang = s as f32 / sides as f32 * std::f32::consts::TAU;
                let d = a * ang.cos() + b * ang.sin();
                self.positions.push(path[i] + d * radii[i]);
                self.normals.push(d);
            }
        }
        for i in 0..n as u32 - 1 {
            for s in 0..sides as u32 {
                let s1 = (s + 1) % sides as u32;
                let (a, b) = (base + i * sides as u32 + s, base + i * sides as u32 + s1);
                let (c, d) = (a + sides as u32, b + sides as u32);
                self.indices.extend_from_slice(&[a, b, d, a, d, c]);
            }
        }
        for (end, ring) in [(0usize, 0u32), (n - 1, n as u32 - 1)] {
            let c = self.positions.len() as u32;
            let t = if end == 0 {
                path[0] - path[1]
            } else {
                path[n - 1] - path[n - 2]
            }
            .normalize_or(Vec3::X);
            self.positions.push(path[end]);
            self.normals.push(t);
            for s in 0..sides as u32 {
                let s1 = (s + 1) % sides as u32;
                let r = base + ring * sides as u32;
                self.indices.extend_from_slice(&[c, r + s, r + s1]);
            }
        }
    }

    /// An ellipsoid with semi-axes `r`, rotated by `q`, centred at `c`.
    fn ellipsoid(&mut self, c: Vec3, r: Vec3, q: Quat) {
        let (stacks, slices) = (6u32, 10u32);
        let base = self.positions.len() as u32;
        for i in 0..=stacks {
            let th = i as f32 / stacks as f32 * std::f32::consts::PI;
            for j in 0..slices {
                let ph = j as f32 / slices as f32 * std::f32::consts::TAU;
                let u = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                self.positions.push(c + q * (u * r));
                self.normals.push((q * (u / r)).normalize_or(Vec3::Z));
            }
        }
        for i in 0..stacks {
            for j in 0..slices {
                let j1 = (j + 1) % slices;
                let (a, b) = (base + i * slices + j, base + i * slices + j1);
                let (c, d) = (a + slices, b + slices);
                self.indices.extend_from_slice(&[a, b, d, a, d, c]);
            }
        }
    }

    /// A box with half extents `h`, rotated by `q`, centred at `c` (flat faces).
    fn slab(&mut self, c: Vec3, h: Vec3, q: Quat) {
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let mut n = Vec3::ZERO;
                n[axis] = sign;
                let (u, v) = (Vec3::new(n.y, n.z, n.x), Vec3::new(n.z, n.x, n.y));
                let base = self.positions.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    let p = (n + u * a + v * b) * h;
                    self.positions.push(c + q * p);
                    self.normals.push(q * n);
                }
                self.indices.extend_from_slice(&[
                    base,
                    base + 1,
                    base + 2,
                    base,
                    base + 2,
                    base + 3,
                ]);
            }
        }
    }
}

fn skin_tone<R: Rng>(rng: &mut R) -> Vec3 {
    // Light to dark human skin (sRGB ramp), the hard negative next to raw poultry skin.
    let light = srgb8(236, 200, 172);
    let mid = srgb8(198, 140, 105);
    let dark = srgb8(96, 62, 44);
    let t = rng.random_range(0.0..1.0f32);
    if t < 0.5 {
        light.lerp(mid, t * 2.0)
    } else {
        mid.lerp(dark, (t - 0.5) * 2.0)
    }
}

fn material<R: Rng>(rng: &mut R, kind: PropKind) -> PropMaterial {
    let m = |albedo: Vec3, f0: f32, roughness: f32, metallic: f32, wrap: f32| PropMaterial {
        kind,
        albedo,
        f0,
        roughness,
        metallic,
        wrap,
        sss_tint: Vec3::ONE,
        texture: 0.15,
        seed: 0,
    };
    let steel = |rng: &mut R| {
        m(
            Vec3::splat(0.06),
            0.55,
            rng.random_range(0.15..0.35),
            0.45,
            0.0,
        )
    };
    let mut out = match kind {
        PropKind::Glove => {
            let c = match rng.random_range(0..6) {
                0 => srgb8(40, 90, 190),
                1 => srgb8(235, 235, 230),
                2 => srgb8(230, 190, 40),
                3 => srgb8(25, 25, 28),
                4 => srgb8(225, 110, 40),
                _ => srgb8(60, 150, 90),
            };
            m(c, 0.05, rng.random_range(0.25..0.6), 0.0, 0.1)
        }
        PropKind::Hand | PropKind::FatScrap => {
            let c = if kind == PropKind::Hand {
                skin_tone(rng)
            } else {
                srgb8(240, 224, 180) * rng.random_range(0.85..1.05)
            };
            let mut p = m(c, 0.035, rng.random_range(0.3..0.5), 0.0, 0.45);
            p.sss_tint = Vec3::new(1.0, 0.45, 0.35);
            p
        }
        PropKind::Shackle | PropKind::Knife => steel(rng),
        PropKind::Scraper => {
            if rng.random_bool(0.5) {
                steel(rng)
            } else {
                m(
                    [srgb8(230, 230, 225), srgb8(40, 95, 170), srgb8(200, 40, 40)]
                        [rng.random_range(0..3)],
                    0.04,
                    0.4,
                    0.0,
                    0.0,
                )
            }
        }
        PropKind::Packaging => {
            let c = match rng.random_range(0..4) {
                0 => srgb8(200, 205, 208),
                1 => srgb8(150, 110, 70),
                2 => srgb8(60, 120, 190),
                _ => srgb8(
                    rng.random_range(30..240),
                    rng.random_range(30..240),
                    rng.random_range(30..240),
                ),
            };
            m(c, 0.06, rng.random_range(0.1..0.5), 0.0, 0.05)
        }
    };
    out.seed = rng.random();
    out
}

/// A hand (and forearm) in local coordinates: palm at the origin, arm along -x,
/// fingers along +x. `cuff` adds a glove's gauntlet.
fn hand<R: Rng>(rng: &mut R, parts: &mut Parts, cuff: bool) {
    let s = rng.random_range(0.9..1.15);
    let arm = rng.random_range(0.3..0.5);
    parts.tube(
        &[
            Vec3::new(-arm, 0.0, 0.0),
            Vec3::new(-arm * 0.5, 0.0, 0.0),
            Vec3::new(-0.03 * s, 0.0, 0.0),
        ],
        &[0.045 * s, 0.04 * s, 0.028 * s],
        10,
    );
    if cuff {
        parts.tube(
            &[
                Vec3::new(-0.16 * s, 0.0, 0.0),
                Vec3::new(-0.03 * s, 0.0, 0.0),
            ],
            &[0.05 * s, 0.042 * s],
            10,
        );
    }
    parts.ellipsoid(
        Vec3::new(0.04 * s, 0.0, 0.0),
        Vec3::new(0.055, 0.045, 0.016) * s,
        Quat::IDENTITY,
    );
    let curl = rng.random_range(0.0..0.6f32);
    for k in 0..4 {
        let y = (-0.03 + 0.02 * k as f32) * s;
        let len = [0.07, 0.08, 0.075, 0.06][k] * s;
        let p0 = Vec3::new(0.085 * s, y, 0.0);
        let p1 = p0 + Vec3::new(len * 0.5, 0.0, -len * 0.5 * curl * 0.3);
        let p2 = p1 + Vec3::new(len * 0.5 * (1.0 - curl * 0.5), 0.0, -len * 0.5 * curl);
        parts.tube(&[p0, p1, p2], &[0.0095 * s, 0.009 * s, 0.008 * s], 6);
    }
    let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let t0 = Vec3::new(0.02 * s, side * 0.04 * s, 0.0);
    parts.tube(
        &[
            t0,
            t0 + Vec3::new(0.03, side * 0.025, 0.0) * s,
            t0 + Vec3::new(0.06, side * 0.03, 0.0) * s,
        ],
        &[0.011 * s, 0.01 * s, 0.009 * s],
        6,
    );
}

fn shackle<R: Rng>(rng: &mut R, parts: &mut Parts) {
    // A U-shaped hook of round bar: two legs joined by a half circle, bent ends.
    let (leg, half) = (rng.random_range(0.08..0.15), rng.random_range(0.02..0.035));
    let r = rng.random_range(0.004..0.007);
    let mut path = vec![
        Vec3::new(leg + 0.02, half + 0.015, 0.0),
        Vec3::new(leg, half, 0.0),
    ];
    for i in 0..=8 {
        let a = std::f32::consts::FRAC_PI_2 + i as f32 / 8.0 * std::f32::consts::PI;
        path.push(Vec3::new(a.cos() * half, a.sin() * half, 0.0));
    }
    path.push(Vec3::new(leg, -half, 0.0));
    path.push(Vec3::new(leg + 0.02, -half - 0.015, 0.0));
    let radii = vec![r; path.len()];
    parts.tube(&path, &radii, 6);
}

fn knife<R: Rng>(rng: &mut R, parts: &mut Parts, scraper: bool) -> usize {
    // Blade (returns its triangle count: it takes the metal, the handle a colour).
    let (bl, bw) = if scraper {
        (rng.random_range(0.06..0.1), rng.random_range(0.05..0.1))
    } else {
        (rng.random_range(0.12..0.2), rng.random_range(0.02..0.035))
    };
    parts.slab(
        Vec3::new(bl * 0.5, 0.0, 0.0015),
        Vec3::new(bl * 0.5, bw * 0.5, 0.0015),
        Quat::IDENTITY,
    );
    let blade_tris = parts.indices.len() / 3;
    let hl = rng.random_range(0.09..0.13);
    if scraper {
        parts.tube(
            &[Vec3::new(-hl, 0.0, 0.012), Vec3::new(0.0, 0.0, 0.006)],
            &[0.013, 0.011],
            8,
        );
    } else {
        parts.slab(
            Vec3::new(-hl * 0.5, 0.0, 0.009),
            Vec3::new(hl * 0.5, 0.013, 0.009),
            Quat::IDENTITY,
        );
    }
    blade_tris
}

/// Where distractors may go: around the pile, inside the view.
pub struct Area {
    pub pile_centre: Vec2,
    pub pile_radius: f32,
    pub view_centre: Vec2,
    pub half_view: f32,
}

/// Which prop: hands 4 in 20, gloves and shackles 3, knives 2, scrapers 1, packaging 3,
/// fat scraps 4.
fn draw_kind<R: Rng>(rng: &mut R) -> PropKind {
    match rng.random_range(0..20) {
        0..=3 => PropKind::Hand,
        4..=6 => PropKind::Glove,
        7..=9 => PropKind::Shackle,
        10..=11 => PropKind::Knife,
        12 => PropKind::Scraper,
        13..=15 => PropKind::Packaging,
        _ => PropKind::FatScrap,
    }
}

/// Adds `count` distractors to `geo` (after the carcasses), resting on whatever lies
/// under them, and returns their materials (index k = instance `PROP_BASE + k`).
pub fn place<R: Rng>(
    rng: &mut R,
    geo: &mut Geometry,
    area: &Area,
    count: usize,
) -> Vec<PropMaterial> {
    let mut mats = Vec::with_capacity(count);
    for _ in 0..count {
        let kind = draw_kind(rng);
        let mut parts = Parts::default();
        let mat = material(rng, kind);
        let mut second: Option<(usize, PropMaterial)> = None;
        // Pitch (hands rise towards the elbow) and the footprint that sets the height.
        let mut pitch = 0.0f32;
        let mut footprint = 0.12f32;
        match kind {
            PropKind::Hand | PropKind::Glove => {
                let cuff = kind == PropKind::Glove && rng.random_bool(0.5);
                hand(rng, &mut parts, cuff);
                pitch = rng.random_range(0.1..0.45);
                footprint = 0.1;
            }
            PropKind::Shackle => shackle(rng, &mut parts),
            PropKind::Knife | PropKind::Scraper => {
                let blade = knife(rng, &mut parts, kind == PropKind::Scraper);
                let handle = material(rng, PropKind::Glove);
                second = Some((blade, handle));
            }
            PropKind::Packaging => {
                let h = Vec3::new(
                    rng.random_range(0.02..0.08),
                    rng.random_range(0.015..0.06),
                    0.0008,
                );
                let q = Quat::from_rotation_x(rng.random_range(-0.2..0.2));
                parts.slab(Vec3::new(0.0, 0.0, 0.004), h, q);
                footprint = h.x.max(h.y);
            }
            PropKind::FatScrap => {
                let r = Vec3::new(
                    rng.random_range(0.012..0.04),
                    rng.random_range(0.01..0.03),
                    rng.random_range(0.004..0.012),
                );
                parts.ellipsoid(Vec3::new(0.0, 0.0, r.z), r, Quat::IDENTITY);
                footprint = r.x;
            }
        }
        // Position: mostly on or next to the pile, sometimes anywhere in view.
        let at = if rng.random_bool(0.75) {
            let a = rng.random_range(0.0..std::f32::consts::TAU);
            let d = rng.random_range(0.0..1.0f32).sqrt() * (area.pile_radius + 0.15);
            area.pile_centre + Vec2::new(a.cos(), a.sin()) * d
        } else {
            area.view_centre
                + Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                    * area.half_view
        };
        let yaw = rng.random_range(0.0..std::f32::consts::TAU);
        let q = Quat::from_rotation_z(yaw) * Quat::from_rotation_y(pitch);
        // Rest on the highest thing under the footprint (carcasses or earlier props).
        let r2 = footprint * footprint;
        let under = geo
            .positions
            .iter()
            .filter(|p| (p.truncate() - at).length_squared() < r2)
            .fold(0.0f32, |m, p| m.max(p.z));
        let low = parts
            .positions
            .iter()
            .filter(|p| p.x >= -0.05)
            .map(|p| (q * *p).z)
            .fold(f32::INFINITY, f32::min);
        let lift = rng.random_range(0.0..0.01)
            + if matches!(kind, PropKind::Hand | PropKind::Glove) {
                rng.random_range(0.0..0.06)
            } else {
                0.0
            };
        let offset = Vec3::new(at.x, at.y, under - low.min(0.0) + lift);
        let base = geo.positions.len() as u32;
        let inst = PROP_BASE + mats.len() as u16;
        for (p, n) in parts.positions.iter().zip(&parts.normals) {
            let w = q * *p + offset;
            geo.positions.push(w);
            geo.normals.push((q * *n).normalize_or(Vec3::Z));
            geo.rest.push(w);
            geo.redness.push(0.0);
        }
        let split = second.as_ref().map_or(usize::MAX, |s| s.0);
        for (t, tri) in parts.indices.chunks_exact(3).enumerate() {
            geo.triangles
                .push([tri[0] + base, tri[1] + base, tri[2] + base]);
            geo.tri_instance
                .push(if t < split { inst } else { inst + 1 });
        }
        mats.push(mat);
        if let Some((_, handle)) = second {
            mats.push(handle);
        }
    }
    mats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::prop_material::is_prop_id;
    use rand::SeedableRng;

    #[test]
    fn props_are_finite_above_the_plate_and_numbered_from_prop_base() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let mut geo = Geometry::default();
        let area = Area {
            pile_centre: Vec2::new(0.1, 0.0),
            pile_radius: 0.2,
            view_centre: Vec2::ZERO,
            half_view: 0.5,
        };
        let mats = place(&mut rng, &mut geo, &area, 12);
        assert!(mats.len() >= 12);
        assert_eq!(geo.positions.len(), geo.normals.len());
        assert_eq!(geo.rest.len(), geo.redness.len());
        assert_eq!(geo.triangles.len(), geo.tri_instance.len());
        for t in &geo.triangles {
            assert!(t.iter().all(|&i| (i as usize) < geo.positions.len()));
        }
        assert!(geo.positions.iter().all(|p| p.is_finite() && p.z > -1e-3));
        assert!(geo
            .tri_instance
            .iter()
            .all(|&i| i >= PROP_BASE && ((i - PROP_BASE) as usize) < mats.len()));
        assert!(is_prop_id(PROP_BASE + 1) && !is_prop_id(64));
    }
}
