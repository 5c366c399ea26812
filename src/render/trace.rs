//! The ray tracer: one obvhs BVH2 over every world-space carcass triangle of an image
//! (carcasses are deformed per instance, so one fresh BVH per image; obvhs' TLAS path is
//! reference-only, `notes/renderer.md`), the plate as the analytic plane z = 0, and per
//! pixel one primary ray, `shadow_samples` stratified shadow rays to the area light and,
//! on the plate, one glossy reflection ray (steel mirrors the carcasses, blurred).
//! Rows run in parallel with rayon; every random number is a hash of (seed, pixel,
//! sample), so the image does not depend on thread scheduling.
//!
//! Output: linear radiance, first-hit distance and the first-hit instance id buffer
//! (u16, 0 = background) from which the visible masks are read. The passes that cast no
//! rays (rasterised primary visibility, the shadow filter, crevice darkening) live in
//! `screen`.

use std::time::{Duration, Instant};

use glam::{Vec3, Vec3A};
use obvhs::{
    bvh2::{builder::build_bvh2_from_tris, Bvh2},
    ray::{Ray, RayHit},
    triangle::Triangle,
    BvhBuildParams,
};
use rayon::prelude::*;

use super::camera::Camera;
use super::light::{AreaLight, Environment};
use super::material::{Background, SkinMaterial};
use super::noise::unit;
use super::prop_material::{PropMaterial, PROP_BASE};
use super::screen::{self, PixelOut};
use super::surface::Surface;
use crate::util::hash::hash;

/// World-space triangles of all carcasses of one image, with shading attributes.
#[derive(Clone, Debug, Default)]
pub struct Geometry {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// Rest-pose position per vertex (texture space of the skin).
    pub rest: Vec<Vec3>,
    /// Joint redness per vertex (0..1); above 1, cut-surface codes (`material::CUT_MEAT`).
    pub redness: Vec<f32>,
    pub triangles: Vec<[u32; 3]>,
    /// Instance index (0-based) per triangle; distractors from
    /// [`super::prop_material::PROP_BASE`] up.
    pub tri_instance: Vec<u16>,
}

/// Everything about an image's appearance that is not geometry.
#[derive(Clone, Debug)]
pub struct Look {
    pub camera: Camera,
    pub light: AreaLight,
    /// Further lights (the `lighting` group): soft boxes and near point-like lamps, one
    /// shadow ray each; empty in the base look.
    pub fill: Vec<AreaLight>,
    pub env: Environment,
    pub background: Background,
    /// One skin per instance.
    pub skins: Vec<SkinMaterial>,
    /// One material per distractor (instance `PROP_BASE + k`).
    pub props: Vec<PropMaterial>,
    pub shadow_samples: u32,
    /// Radius (pixels) of the edge-aware shadow-visibility filter; 0 = off.
    pub shadow_filter: usize,
    pub reflections: bool,
    /// Primary visibility by rasterisation (fast) instead of primary rays.
    pub raster_primary: bool,
    pub seed: u64,
}

/// A traced image before the sensor.
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub radiance: Vec<Vec3>,
    /// Distance along the primary ray (plate or carcass; +inf for sky).
    pub depth: Vec<f32>,
    /// First-hit instance id, `instance index + 1`; 0 = background.
    pub ids: Vec<u16>,
}

/// BVH over one image's geometry, triangles stored in BVH order.
pub struct Tracer {
    bvh: Bvh2,
    tris: Vec<Triangle>,
    tri_src: Vec<u32>,
    pub build_time: Duration,
}

impl Tracer {
    pub fn build(geo: &Geometry) -> Tracer {
        let t0 = Instant::now();
        let tris: Vec<Triangle> = geo
            .triangles
            .iter()
            .map(|t| Triangle {
                v0: geo.positions[t[0] as usize].into(),
                v1: geo.positions[t[1] as usize].into(),
                v2: geo.positions[t[2] as usize].into(),
            })
            .collect();
        if tris.is_empty() {
            return Tracer {
                bvh: Bvh2::default(),
                tris,
                tri_src: Vec::new(),
                build_time: t0.elapsed(),
            };
        }
        let bvh = build_bvh2_from_tris(
            &tris,
            BvhBuildParams::fastest_build(),
            &mut Duration::default(),
        );
        // Reorder once so hit ids index triangles directly (no indirection per test).
        let tri_src: Vec<u32> = bvh.primitive_indices.clone();
        let tris = tri_src.iter().map(|&i| tris[i as usize]).collect();
        Tracer {
            bvh,
            tris,
            tri_src,
            build_time: t0.elapsed(),
        }
    }

    /// Closest carcass hit before `tmax`: (t, triangle index in `Geometry`).
    #[inline]
    pub fn closest(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, usize)> {
        if self.tris.is_empty() {
            return None;
        }
        let ray = Ray::new(Vec3A::from(o), Vec3A::from(d), 0.0, tmax);
        let mut hit = RayHit::none();
        if self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| self.tris[id].intersect(r))
        {
            Some((hit.t, self.tri_src[hit.primitive_id as usize] as usize))
        } else {
            None
        }
    }

    /// True when nothing blocks the segment from `o` along `d` up to `tmax`.
    #[inline]
    pub fn unoccluded(&self, o: Vec3, d: Vec3, tmax: f32) -> bool {
        if self.tris.is_empty() {
            return true;
        }
        let ray = Ray::new(Vec3A::from(o), Vec3A::from(d), 0.0, tmax);
        self.bvh
            .ray_traverse_miss(ray, |r, id| self.tris[id].intersect(r))
    }

    /// Renders the image: primary visibility by z-buffer rasterisation (same pixel-centre
    /// rule and projection as the rays, ~10x cheaper than primary rays) or by primary rays
    /// (`look.raster_primary = false`), then shading with shadow and reflection rays.
    /// Shadow visibility is filtered edge-aware (same instance, similar depth) before it
    /// multiplies the unshadowed key light: one shadow ray per pixel then reads as soft
    /// penumbra, not speckle.
    pub fn render(&self, geo: &Geometry, look: &Look) -> Frame {
        let cam = &look.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let primary = if look.raster_primary {
            Some(screen::raster_primary(&geo.positions, &geo.triangles, cam))
        } else {
            None
        };
        let mut px: Vec<PixelOut> = vec![PixelOut::default(); w * h];
        px.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let hint = primary.as_ref().map(|p| p[y * w + x]);
                *out = self.pixel(geo, look, x as u32, y as u32, hint);
            }
        });
        let (vis, refl) = screen::filter_noisy(&px, w, h, look.shadow_filter);
        Frame {
            width: cam.width,
            height: cam.height,
            radiance: px
                .iter()
                .zip(vis.iter().zip(&refl))
                .map(|(p, (v, r))| p.direct * *v + *r + p.other)
                .collect(),
            depth: px.iter().map(|p| p.depth).collect(),
            ids: px.iter().map(|p| p.id).collect(),
        }
    }

    /// `hint`: the rasterised primary triangle (u32::MAX = none), or None to trace.
    fn pixel(&self, geo: &Geometry, look: &Look, x: u32, y: u32, hint: Option<u32>) -> PixelOut {
        let cam = &look.camera;
        let d = cam.dir(x as f32 + 0.5, y as f32 + 0.5);
        let o = cam.eye;
        let t_plate = if d.z < -1e-6 {
            -o.z / d.z
        } else {
            f32::INFINITY
        };
        let pix = (y as u64) << 32 | x as u64;
        // With the filter on, shadow and reflection rays go to half the pixels (a
        // checkerboard); the edge-aware filter fills the others from their neighbours.
        let sparse = look.shadow_filter > 0 && (x + y) & 1 == 1;
        let wt = if sparse { 0.0 } else { 1.0 };
        let hit = match hint {
            None => self.closest(o, d, t_plate),
            Some(u32::MAX) => None,
            Some(tri) => {
                // Exact distance to the rasterised triangle's plane along this pixel's ray.
                let [a, b, c] = geo.triangles[tri as usize].map(|i| geo.positions[i as usize]);
                let n = (b - a).cross(c - a);
                let den = n.dot(d);
                let t = if den.abs() > 1e-12 {
                    n.dot(a - o) / den
                } else {
                    (a - o).length()
                };
                Some((t.max(0.0), tri as usize))
            }
        };
        if let Some((t, tri)) = hit {
            let p = o + d * t;
            let (s, ng) = self.skin_surface(geo, look, tri, p, d);
            let inst = geo.tri_instance[tri];
            let (direct, vis, other) = self.shade(look, &s, p, ng, -d, pix, sparse);
            return PixelOut {
                direct,
                vis,
                wt,
                refl: Vec3::ZERO,
                other,
                depth: t,
                id: inst + 1,
            };
        }
        if t_plate.is_finite() {
            let p = o + d * t_plate;
            let s = look.background.surface(p);
            let (direct, vis, other) = self.shade(look, &s, p, Vec3::Z, -d, pix, sparse);
            let refl = if look.reflections && s.metallic > 0.5 && !sparse {
                self.glossy_reflection(geo, look, &s, p, d, pix)
            } else {
                Vec3::ZERO
            };
            return PixelOut {
                direct,
                vis,
                wt,
                refl,
                other,
                depth: t_plate,
                id: 0,
            };
        }
        PixelOut {
            direct: Vec3::ZERO,
            vis: 1.0,
            wt: 1.0,
            refl: Vec3::ZERO,
            other: look.env.radiance(d),
            depth: f32::INFINITY,
            id: 0,
        }
    }

    /// Skin surface at a hit on triangle `tri`, with the geometric normal facing the ray.
    fn skin_surface(
        &self,
        geo: &Geometry,
        look: &Look,
        tri: usize,
        p: Vec3,
        d: Vec3,
    ) -> (Surface, Vec3) {
        let [a, b, c] = geo.triangles[tri].map(|i| i as usize);
        let (pa, pb, pc) = (geo.positions[a], geo.positions[b], geo.positions[c]);
        let (e1, e2, ep) = (pb - pa, pc - pa, p - pa);
        let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (d20, d21) = (ep.dot(e1), ep.dot(e2));
        let den = (d00 * d11 - d01 * d01).max(1e-20);
        let v = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
        let w = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0);
        let u = (1.0 - v - w).max(0.0);
        let mut ng = e1.cross(e2).normalize_or(Vec3::Z);
        if ng.dot(d) > 0.0 {
            ng = -ng;
        }
        let mut n = (geo.normals[a] * u + geo.normals[b] * v + geo.normals[c] * w).normalize_or(ng);
        if n.dot(ng) < 0.0 {
            n = (n - ng * 2.0 * n.dot(ng)).normalize_or(ng);
        }
        let rest = geo.rest[a] * u + geo.rest[b] * v + geo.rest[c] * w;
        let red = geo.redness[a] * u + geo.redness[b] * v + geo.redness[c] * w;
        let inst = geo.tri_instance[tri];
        if inst >= PROP_BASE {
            return (look.props[(inst - PROP_BASE) as usize].surface(p, n), ng);
        }
        (look.skins[inst as usize].surface(rest, n, red), ng)
    }

    /// Key light (unshadowed, and the fraction of shadow rays that reached it) plus the
    /// room's ambient and specular light: (direct, visibility, other).
    #[allow(clippy::too_many_arguments)]
    fn shade(
        &self,
        look: &Look,
        s: &Surface,
        p: Vec3,
        ng: Vec3,
        v: Vec3,
        pix: u64,
        skip_shadow: bool,
    ) -> (Vec3, f32, Vec3) {
        let n = s.normal;
        let light = &look.light;
        let ns = look.shadow_samples.max(1);
        let side = (ns as f32).sqrt().ceil() as u32;
        let mut direct = Vec3::ZERO;
        let (mut seen, mut tried) = (0u32, 0u32);
        let origin = p + ng * 4e-4;
        for k in 0..ns {
            let hsh = hash(look.seed, pix, k as u64, 0x11);
            let a = ((k % side) as f32 + unit(hsh)) / side as f32;
            let b = ((k / side) as f32 + unit(hsh.rotate_left(29))) / side as f32;
            let lp = light.point(a, b);
            let lv = lp - p;
            let dist2 = lv.length_squared();
            let dist = dist2.sqrt();
            let l = lv / dist;
            let cos_l = (-l.z).max(0.0);
            let ndl = n.dot(l);
            let wrapped = ((ndl + s.wrap) / (1.0 + s.wrap)).max(0.0);
            if cos_l <= 0.0 || wrapped <= 0.0 {
                continue;
            }
            if !skip_shadow {
                tried += 1;
                if self.unoccluded(origin, l, dist - 1e-3) {
                    seen += 1;
                }
            }
            let e = light.color * (cos_l / dist2);
            direct += e * diffuse(s, ndl, wrapped);
        }
        direct *= light.area() / ns as f32;
        // Specular: the soft box mirrored in the surface, blurred by the lobe width (a
        // smooth "window" highlight instead of sparse one-sample sparkles).
        let r = reflect(-v, n);
        let fr = schlick(s.f0, n.dot(v).max(0.0));
        let mut spec = fr * light.color * light_coverage(light, p, r, s.roughness);
        if s.coat > 0.0 {
            spec += schlick(Vec3::splat(s.coat), n.dot(v).max(0.0))
                * light.color
                * light_coverage(light, p, r, 0.1);
        }
        direct += spec;
        let mut vis = if tried == 0 {
            1.0
        } else {
            seen as f32 / tried as f32
        };
        if !look.fill.is_empty() {
            // Further lights, one shadow ray each; the filtered visibility becomes the
            // luminance-weighted mean of the lights' visibilities.
            let lum = |c: Vec3| c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
            let (mut num, mut den) = (lum(direct) * vis, lum(direct));
            for (i, fl) in look.fill.iter().enumerate() {
                let hsh = hash(look.seed, pix, 1000 + i as u64, 0x33);
                let lp = fl.point(unit(hsh), unit(hsh.rotate_left(31)));
                let lv = lp - p;
                let dist2 = lv.length_squared();
                let dist = dist2.sqrt();
                let l = lv / dist;
                let cos_l = (-l.z).max(0.0);
                let ndl = n.dot(l);
                let wrapped = ((ndl + s.wrap) / (1.0 + s.wrap)).max(0.0);
                let mut d_i = Vec3::ZERO;
                if cos_l > 0.0 && wrapped > 0.0 {
                    d_i = fl.color * (cos_l / dist2) * fl.area() * diffuse(s, ndl, wrapped);
                }
                d_i += fr * fl.color * light_coverage(fl, p, r, s.roughness);
                let v_i = if skip_shadow || d_i == Vec3::ZERO {
                    1.0
                } else if self.unoccluded(origin, l, dist - 1e-3) {
                    1.0
                } else {
                    0.0
                };
                num += lum(d_i) * v_i;
                den += lum(d_i);
                direct += d_i;
            }
            vis = if den > 1e-12 { num / den } else { vis };
        }
        let amb = look.env.ambient * (0.55 + 0.45 * n.z.max(-1.0));
        let ambient = s.albedo * (1.0 - s.metallic) * amb;
        // Specular of the room for dielectrics (wet sheen); metals get a traced reflection.
        let env_spec = if s.metallic < 0.5 {
            schlick(s.f0, n.dot(v).max(0.0)) * look.env.radiance(r) * (1.0 - s.roughness)
        } else if !look.reflections {
            schlick(s.f0, n.dot(v).max(0.0)) * look.env.radiance(r)
        } else {
            Vec3::ZERO
        };
        (direct, vis, ambient + env_spec)
    }

    /// One glossy reflection ray off the plate: carcasses seen in the steel, blurred by
    /// the roughness; the room otherwise.
    fn glossy_reflection(
        &self,
        geo: &Geometry,
        look: &Look,
        s: &Surface,
        p: Vec3,
        d: Vec3,
        pix: u64,
    ) -> Vec3 {
        let hsh = hash(look.seed, pix, 99, 0x22);
        let jitter = Vec3::new(
            unit(hsh) - 0.5,
            unit(hsh.rotate_left(21)) - 0.5,
            unit(hsh.rotate_left(42)) - 0.5,
        );
        let r0 = reflect(d, s.normal);
        let r = (r0 + jitter * (s.roughness * s.roughness * 1.6)).normalize();
        let r = if r.z < 0.02 { r0 } else { r };
        let f = schlick(s.f0, s.normal.dot(-d).max(0.0));
        if let Some((t, tri)) = self.closest(p + Vec3::Z * 1e-4, r, 10.0) {
            // The reflected carcass: its skin under the key light, unshadowed (cheap).
            let q = p + r * t;
            let (sk, _) = self.skin_surface(geo, look, tri, q, r);
            let l = (look.light.centre - q).normalize();
            let e = look.light.color * look.light.area() * (-l.z).max(0.0)
                / (look.light.centre - q).length_squared();
            let lit = sk.albedo
                * (e * sk.normal.dot(l).max(0.0) / std::f32::consts::PI + look.env.ambient * 0.5);
            f * lit
        } else {
            f * look.env.radiance(r)
        }
    }
}

impl Frame {
    /// Screen-space occlusion by depth darkening ([`screen::darken_crevices`]).
    pub fn darken_crevices(&mut self, strength: f32) {
        let (w, h) = (self.width as usize, self.height as usize);
        screen::darken_crevices(&mut self.radiance, &self.depth, w, h, strength);
    }
}

/// Fraction of a specular lobe around direction `r` (from `p`) that lands on the
/// rectangular light: the lobe's footprint on the light plane is a square of half-width
/// α·distance (GGX keeps most of its energy within atan α of the mirror direction), and
/// the fraction is the box-box overlap per axis. Normalised, so rough surfaces spread the
/// mirror image wider and dimmer instead of just wider.
fn light_coverage(light: &AreaLight, p: Vec3, r: Vec3, roughness: f32) -> f32 {
    if r.z <= 1e-4 {
        return 0.0;
    }
    let t = (light.centre.z - p.z) / r.z;
    if t <= 0.0 {
        return 0.0;
    }
    let q = p + r * t - light.centre;
    let (ul, vl) = (light.u.length(), light.v.length());
    let x = q.dot(light.u) / ul;
    let y = q.dot(light.v) / vl;
    let alpha = (roughness * roughness).max(0.002);
    let w = alpha * t + 0.002;
    let f =
        |x: f32, half: f32| (((x + w).min(half) - (x - w).max(-half)) / (2.0 * w)).clamp(0.0, 1.0);
    f(x, ul) * f(y, vl)
}

#[inline]
fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * 2.0 * d.dot(n)
}

#[inline]
fn schlick(f0: Vec3, cos: f32) -> Vec3 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    f0 + (Vec3::ONE - f0) * (m2 * m2 * m)
}

/// Lambert diffuse with wrap lighting and a subsurface tint: what `s` scatters towards
/// the eye per unit irradiance from a light at `n · l = ndl` (`wrapped` is the wrapped
/// cosine), metals scattering none.
fn diffuse(s: &Surface, ndl: f32, wrapped: f32) -> Vec3 {
    let lambert = ndl.max(0.0);
    s.albedo * (1.0 - s.metallic) * (Vec3::splat(lambert) + (wrapped - lambert) * s.sss_tint)
        / std::f32::consts::PI
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_geo() -> Geometry {
        // A 20 cm square at height 10 cm, centred under the camera.
        let positions = vec![
            Vec3::new(-0.1, -0.1, 0.1),
            Vec3::new(0.1, -0.1, 0.1),
            Vec3::new(0.1, 0.1, 0.1),
            Vec3::new(-0.1, 0.1, 0.1),
        ];
        Geometry {
            normals: vec![Vec3::Z; 4],
            rest: positions.clone(),
            positions,
            redness: vec![0.0; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            tri_instance: vec![0, 0],
        }
    }

    #[test]
    fn primary_hits_shadow_and_degenerate_rays() {
        let geo = quad_geo();
        let tr = Tracer::build(&geo);
        let hit = tr
            .closest(Vec3::new(0.0, 0.0, 1.0), Vec3::NEG_Z, 10.0)
            .unwrap();
        assert!((hit.0 - 0.9).abs() < 1e-5);
        assert!(tr
            .closest(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z, 10.0)
            .is_none());
        // tmax before the quad: no hit; grazing ray parallel to the quad: no hit.
        assert!(tr
            .closest(Vec3::new(0.0, 0.0, 1.0), Vec3::NEG_Z, 0.5)
            .is_none());
        assert!(tr
            .closest(Vec3::new(-1.0, 0.0, 0.1), Vec3::X, 10.0)
            .is_none_or(|h| h.0.is_finite()));
        assert!(!tr.unoccluded(Vec3::new(0.03, -0.02, 0.0), Vec3::Z, 1.0));
        assert!(tr.unoccluded(Vec3::new(0.03, -0.02, 0.0), Vec3::Z, 0.05));
        assert!(tr.unoccluded(Vec3::new(0.3, 0.0, 0.0), Vec3::Z, 1.0));
        // Empty geometry never hits.
        let empty = Tracer::build(&Geometry::default());
        assert!(empty.closest(Vec3::Z, Vec3::NEG_Z, 10.0).is_none());
        assert!(empty.unoccluded(Vec3::Z, Vec3::NEG_Z, 10.0));
    }
}
