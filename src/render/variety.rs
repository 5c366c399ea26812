//! Carcass variety (the `carcass` randomisation group): per carcass, a body family and
//! size, an aspect jitter, a parts plan (wings and legs posed or cut off, `parts`), a
//! wider skin tone, fat deposits, bruises, feather remnants and torn skin that is
//! indented, not only recoloured. Every draw comes from the carcass's own sub-stream of
//! the image's "carcass" stream, so the group never moves another group's choices, and
//! carcass k's look depends only on (seed, image, k).
//!
//! | parameter | range | drawn per |
//! |---|---|---|
//! | body family | broiler 30 %, heavy broiler, spent hen, long, round 15 % each, poussin 10 % | instance |
//! | size (× today's broiler) | by family, 0.70–1.30 overall (`family`) | instance |
//! | aspect jitter (trunk x / y / z) | ×0.94–1.06 / 0.92–1.08 / 0.92–1.08 | instance |
//! | wings | folded / natural / spread, cut at wrist 5 %, elbow 3 %, shoulder 3 % (`parts`) | instance, per side |
//! | legs | bent / natural / straight, cut at knee 3 %, hip 2 % (`parts`) | instance, per side |
//! | skin tone | pale pink-white … cream … deep yellow (`material::skin_tone`), × 0.88–1.05 brightness | instance |
//! | fat deposits | 45 %: 1–3 patches, radius 12–35 mm, opacity 0.3–0.75 | instance |
//! | bruises | 30 %: 1–3 patches, radius 5–22 mm, opacity 0.35–0.85, dark red … purple | instance |
//! | feather remnants | 35 %: density 0.2–1 (dark stubs ~1×4 mm, clustered) | instance |
//! | torn skin | 20 %: 1–2 tears, radius 8–22 mm, indented 1.5–4 mm with a raised rim | instance |

use std::borrow::Cow;
use std::sync::Arc;

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::asset::Asset;
use super::family::Family;
use super::material::{skin_tone, MarkKind, SkinMark, SkinMaterial};
use super::mesh::Mesh;
use super::parts::Parts;
use super::skin::Pose;

/// An indentation of the skin: rest-space centre on the surface, radius, depth (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tear {
    pub centre: Vec3,
    pub radius: f32,
    pub depth: f32,
}

/// Everything the carcass group decided about one carcass's geometry.
#[derive(Clone)]
pub struct Variety {
    pub family: Family,
    /// The family's mesh; None = the image's own asset (broiler, or a user mesh).
    mesh: Option<Arc<Asset>>,
    pub parts: Parts,
    pub tears: Vec<Tear>,
}

/// A random surface vertex of `mesh` for which `ok(vertex index)` holds (any if none
/// does within a few tries).
fn surface_point<R: Rng>(rng: &mut R, mesh: &Mesh, ok: impl Fn(usize) -> bool) -> Vec3 {
    let n = mesh.positions.len().max(1);
    let mut i = rng.random_range(0..n);
    for _ in 0..32 {
        if ok(i) {
            break;
        }
        i = rng.random_range(0..n);
    }
    mesh.positions.get(i).copied().unwrap_or(Vec3::ZERO)
}

impl Variety {
    /// The sub-stream of carcass `k`: seeded from the image's carcass stream in instance
    /// order, so the k-th carcass's draws do not depend on how many draws another made.
    pub fn instance_rng<R: Rng>(carcass_stream: &mut R) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(carcass_stream.random())
    }

    /// Draws one carcass's variety from its sub-stream `rng`, overriding the size, body
    /// proportions and limb angles of `pose` and the tone, tears and marks of `skin`.
    /// `image` is the image's asset; `user_mesh` keeps it (families are the generator's).
    pub fn sample<R: Rng>(
        rng: &mut R,
        image: &Asset,
        user_mesh: bool,
        pose: &mut Pose,
        skin: &mut SkinMaterial,
    ) -> Variety {
        let family = Family::sample(rng);
        let mesh = if user_mesh { None } else { family.asset() };
        let base = mesh.as_deref().unwrap_or(image);
        let size = family.size();
        pose.scale = rng.random_range(size[0]..size[1]);
        pose.body_scale *= Vec3::new(
            rng.random_range(0.94..1.06),
            rng.random_range(0.92..1.08),
            rng.random_range(0.92..1.08),
        );
        let parts = Parts::sample(rng);
        parts.pose(rng, pose);
        // Skin tone: uniform over the whole pale … yellow ramp.
        skin.base = skin_tone(rng.random_range(0.0..1.0)) * rng.random_range(0.88..1.05);
        let m = &base.mesh;
        let dominant = |i: usize| m.skin.as_ref().map_or(0, |s| s.vertex_joints[i][0]);
        let (lo, hi) = m.bounds();
        skin.marks.clear();
        if rng.random_bool(0.45) {
            for _ in 0..rng.random_range(1..=3) {
                // Fat collects on the rear half (abdomen, vent, tail) more than elsewhere.
                let rear = rng.random_bool(0.6);
                let centre = surface_point(rng, m, |i| {
                    dominant(i) == 0 && (!rear || m.positions[i].x < lo.x + (hi.x - lo.x) * 0.4)
                });
                skin.marks.push(SkinMark {
                    centre,
                    radius: rng.random_range(0.012..0.035),
                    strength: rng.random_range(0.3..0.75),
                    kind: MarkKind::Fat,
                });
            }
        }
        if rng.random_bool(0.3) {
            for _ in 0..rng.random_range(1..=3) {
                let centre = surface_point(rng, m, |_| true);
                skin.marks.push(SkinMark {
                    centre,
                    radius: rng.random_range(0.005..0.022),
                    strength: rng.random_range(0.35..0.85),
                    kind: MarkKind::Bruise {
                        hue: rng.random_range(0.0..1.0),
                    },
                });
            }
        }
        skin.pins = if rng.random_bool(0.35) {
            rng.random_range(0.2..1.0)
        } else {
            0.0
        };
        let mut tears = Vec::new();
        if rng.random_bool(0.2) {
            for _ in 0..rng.random_range(1..=2) {
                // On the trunk or the thighs, where skin is stretched and tears in handling.
                let centre = surface_point(rng, m, |i| matches!(dominant(i), 0 | 1 | 3));
                tears.push(Tear {
                    centre,
                    radius: rng.random_range(0.008..0.022),
                    depth: rng.random_range(0.0015..0.004),
                });
            }
        }
        skin.tears = tears.iter().map(|t| (t.centre, t.radius)).collect();
        Variety {
            family,
            mesh,
            parts,
            tears,
        }
    }

    /// The carcass's rest mesh: its family's, with missing parts cut and capped and torn
    /// skin indented. Borrows the shared mesh when nothing is cut or torn.
    pub fn build<'a>(&'a self, image: &'a Asset) -> Cow<'a, Asset> {
        let base = self.mesh.as_deref().unwrap_or(image);
        if !self.parts.has_cuts() && self.tears.is_empty() {
            return Cow::Borrowed(base);
        }
        let (mut mesh, redness) = self.parts.apply(&base.mesh, &base.redness);
        indent(&mut mesh, &self.tears);
        Cow::Owned(Asset { mesh, redness })
    }
}

/// Presses each tear into the surface along the normals: a smooth pit of the tear's
/// depth inside its radius, and a rim raised by a quarter of it just outside (the skin
/// pulled back); normals there are recomputed from the faces.
fn indent(mesh: &mut Mesh, tears: &[Tear]) {
    if tears.is_empty() {
        return;
    }
    let mut touched = vec![false; mesh.positions.len()];
    for t in tears {
        for (i, p) in mesh.positions.iter_mut().enumerate() {
            let s = (*p - t.centre).length() / t.radius;
            if s >= 1.4 {
                continue;
            }
            let pit = if s < 1.0 { (1.0 - s * s).powi(2) } else { 0.0 };
            let rim = (-((s - 1.05) / 0.12).powi(2)).exp() * 0.25;
            *p += mesh.normals[i] * t.depth * (rim - pit);
            touched[i] = true;
        }
    }
    let fresh = Mesh::compute_normals(&mesh.positions, &mesh.indices);
    for (i, n) in mesh.normals.iter_mut().enumerate() {
        if touched[i] {
            *n = fresh[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::carcass;

    #[test]
    fn variety_is_deterministic_and_tears_press_in() {
        let image = Asset::new(carcass::generate(0.008));
        let draw = |seed: u64| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut pose = Pose::rest();
            let mut skin = SkinMaterial::sample(&mut rng, [0.0, 1.0]);
            // User-mesh mode keeps the test off the family mesh generation.
            let v = Variety::sample(&mut rng, &image, true, &mut pose, &mut skin);
            (v, pose, skin)
        };
        let (a, pa, sa) = draw(11);
        let (b, pb, sb) = draw(11);
        assert_eq!((a.family, a.parts, &a.tears), (b.family, b.parts, &b.tears));
        assert_eq!((pa, sa), (pb, sb));
        // Across many carcasses: sizes span poussin to heavy broiler, skins pale to yellow.
        let mut sizes = Vec::new();
        let mut yellowness = Vec::new();
        for seed in 0..200 {
            let (_, p, s) = draw(seed);
            sizes.push(p.scale);
            yellowness.push(s.base.z / s.base.x);
        }
        let range = |v: &[f32]| {
            (
                v.iter().cloned().fold(f32::MAX, f32::min),
                v.iter().cloned().fold(f32::MIN, f32::max),
            )
        };
        let (s0, s1) = range(&sizes);
        assert!(s0 < 0.78 && s1 > 1.2, "sizes {s0}..{s1}");
        let (y0, y1) = range(&yellowness);
        assert!(y0 < 0.35 && y1 > 0.7, "blue/red {y0}..{y1}");
        // A tear really indents the mesh at its centre.
        let c = image.mesh.positions[1234];
        let v = Variety {
            family: Family::Broiler,
            mesh: None,
            parts: Parts::whole(),
            tears: vec![Tear {
                centre: c,
                radius: 0.015,
                depth: 0.003,
            }],
        };
        let built = v.build(&image);
        let moved = built.mesh.positions[1234] - c;
        assert!(moved.dot(image.mesh.normals[1234]) < -0.0025, "{moved:?}");
        assert!(built.mesh.normals.iter().all(|n| n.is_finite()));
        assert_eq!(built.mesh.triangle_count(), image.mesh.triangle_count());
    }
}
