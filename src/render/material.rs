//! Surface appearance: raw poultry skin and the background (brushed stainless steel plate,
//! optionally a modular plastic belt, with optional water/blood stains).
//!
//! Materials only answer "what is the surface like here" ([`Surface`]: albedo, shading
//! normal, specular colour, roughness, metalness, wrap); the light transport lives in
//! `trace.rs`. Skin texture is evaluated at the rest-pose position, so it stays put on
//! the skin when the carcass is posed (notes: "Texture in 3D from rest-pose positions").

use glam::{Vec2, Vec3};
use rand::Rng;

use super::noise::{cellular3, fbm2, fbm3, value2, value3};
use super::surface::{srgb8, Surface};

/// Per-carcass skin parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct SkinMaterial {
    /// Base colour (linear RGB): cream-pink to yellow.
    pub base: Vec3,
    /// Colour of the redder regions (joints, wing tips, cut hocks, bruises).
    pub red: Vec3,
    pub seed: u64,
    /// Follicle cells per metre (~1 follicle per 3-5 mm).
    pub follicle_freq: f32,
    pub follicle_bump: f32,
    pub roughness: f32,
    /// Wet clear-coat strength (F0).
    pub wet: f32,
    pub wrap: f32,
    pub blotch: f32,
    /// Torn-skin patches (rest-space centre, radius): exposed meat, darker and matte.
    pub tears: Vec<(Vec3, f32)>,
    /// Fat deposits and bruises (carcass randomisation group; empty without it).
    pub marks: Vec<SkinMark>,
    /// Feather remnants (pin feathers, stubs): 0 = none … 1 = many (carcass group).
    pub pins: f32,
}

/// What a [`SkinMark`] is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MarkKind {
    /// Subcutaneous fat: yellower, smoother (fewer visible follicles), glossier.
    Fat,
    /// Bruise: blood under the skin, dark red (`hue` 0) to purple (`hue` 1).
    Bruise { hue: f32 },
}

/// A noisy-edged patch on the skin around a rest-space point of the carcass's surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkinMark {
    pub centre: Vec3,
    pub radius: f32,
    /// Opacity at the centre (0..1).
    pub strength: f32,
    pub kind: MarkKind,
}

/// Redness values above 1 are tissue codes of cut surfaces (the caps of removed wings
/// and legs, `render::parts`): [`CUT_MEAT`] on the cap, [`CUT_BONE`] at its centre where
/// a bone was cut through; interpolation between them shades the rim to the bone.
pub const CUT_MEAT: f32 = 2.0;
/// See [`CUT_MEAT`].
pub const CUT_BONE: f32 = 3.0;

/// Skin tone of the carcass group: 0 pale pink-white … 0.5 cream … 1 deep yellow
/// (corn-fed), linear RGB. Wider than the base look's pink…yellow ramp at both ends.
pub fn skin_tone(t: f32) -> Vec3 {
    let stops = [
        srgb8(250, 228, 218),
        srgb8(242, 204, 186),
        srgb8(245, 222, 190),
        srgb8(246, 212, 150),
        srgb8(238, 192, 116),
    ];
    let x = t.clamp(0.0, 1.0) * (stops.len() - 1) as f32;
    let i = (x as usize).min(stops.len() - 2);
    stops[i].lerp(stops[i + 1], x - i as f32)
}

impl SkinMaterial {
    pub fn sample<R: Rng>(rng: &mut R, yellow: [f32; 2]) -> SkinMaterial {
        // Cream-pink (white-skinned broilers) to yellow (corn-fed), sampled between the two.
        let pink = srgb8(242, 204, 184);
        let cream = srgb8(246, 222, 192);
        let yel = srgb8(246, 198, 118);
        let y = rng.random_range(yellow[0]..=yellow[1]);
        let base = if y < 0.5 {
            pink.lerp(cream, y * 2.0)
        } else {
            cream.lerp(yel, (y - 0.5) * 2.0)
        } * rng.random_range(0.88..1.05);
        SkinMaterial {
            base,
            red: srgb8(205, 118, 108).lerp(srgb8(190, 95, 95), rng.random_range(0.0..1.0)),
            seed: rng.random(),
            follicle_freq: rng.random_range(220.0..320.0),
            follicle_bump: rng.random_range(0.15..0.35),
            roughness: rng.random_range(0.22..0.4),
            wet: rng.random_range(0.035..0.06),
            wrap: rng.random_range(0.35..0.6),
            blotch: rng.random_range(0.0..0.35),
            tears: (0..if rng.random_bool(0.2) {
                rng.random_range(1..3)
            } else {
                0
            })
                .map(|_| {
                    // On the breast/back surface of the default carcass (rest frame).
                    let c = Vec3::new(
                        rng.random_range(-0.08..0.08),
                        rng.random_range(-0.06..0.06),
                        if rng.random_bool(0.6) { 0.06 } else { -0.05 },
                    );
                    (c, rng.random_range(0.008..0.02))
                })
                .collect(),
            marks: Vec::new(),
            pins: 0.0,
        }
    }

    /// Cut surface (redness code above 1, see [`CUT_MEAT`]): dark red muscle, wet, with
    /// cream bone / cartilage where a limb bone was cut.
    fn cut_surface(&self, rest: Vec3, n: Vec3, code: f32) -> Surface {
        let v = fbm3(self.seed ^ 0xC07, rest * 160.0, 2);
        let meat = srgb8(170, 62, 60).lerp(srgb8(205, 100, 96), v);
        let bone = ((code - CUT_MEAT - 0.72) * 6.0).clamp(0.0, 1.0);
        let albedo = meat.lerp(srgb8(236, 222, 200), bone);
        Surface {
            albedo,
            normal: n,
            f0: Vec3::splat(0.05),
            roughness: 0.3 + 0.2 * v,
            metallic: 0.0,
            wrap: 0.5,
            sss_tint: Vec3::new(1.0, 0.3, 0.25),
            coat: 0.03,
        }
    }

    /// Fat and bruise cover at `rest`: (fat opacity, bruise opacity, bruise colour).
    fn marks_at(&self, rest: Vec3) -> (f32, f32, Vec3) {
        let (mut fat, mut bruise, mut colour) = (0.0f32, 0.0f32, Vec3::ZERO);
        for (k, m) in self.marks.iter().enumerate() {
            let d = (rest - m.centre).length() / m.radius;
            if d >= 1.4 {
                continue;
            }
            // Irregular outline: a coarse and a fine noise push the edge in and out.
            let edge = fbm3(self.seed ^ (0xFA7 + k as u64), rest * 90.0, 2);
            let lobe = value3(self.seed ^ (0x10BE + k as u64), rest / m.radius * 1.5);
            let a = ((1.15 - d - 0.5 * (edge - 0.5) - 0.7 * (lobe - 0.5)) * 2.5).clamp(0.0, 1.0)
                * m.strength;
            match m.kind {
                MarkKind::Fat => fat = fat.max(a),
                MarkKind::Bruise { hue } => {
                    if a > bruise {
                        bruise = a;
                        // Mottled: darker where the noise is high (blood pooled).
                        colour =
                            srgb8(150, 38, 42).lerp(srgb8(98, 46, 84), hue) * (0.8 + 0.4 * edge);
                    }
                }
            }
        }
        (fat, bruise, colour)
    }

    /// Skin at a hit: `rest` is the rest-pose position, `n` the interpolated normal,
    /// `redness` the interpolated joint redness (0..1).
    pub fn surface(&self, rest: Vec3, n: Vec3, redness: f32) -> Surface {
        if redness > 1.0 {
            return self.cut_surface(rest, n, redness);
        }
        // Low-frequency colour variation and blotchy redness (bruising, blood under skin).
        let v = fbm3(self.seed, rest * 28.0, 2);
        let blotch = (fbm3(self.seed ^ 0xB10, rest * 45.0, 2) - 0.55).max(0.0) * 2.2 * self.blotch;
        let r = (redness * 0.85 + blotch).clamp(0.0, 0.9);
        let mut albedo = self.base.lerp(self.red, r) * (0.86 + 0.26 * v);
        // Feather follicles: small bumps (raised rim, dimpled centre) on a jittered lattice.
        let (d, off) = cellular3(self.seed ^ 0xF011, rest * self.follicle_freq);
        // Torn skin: meat shows through (deeper red-pink, wetter but less glossy film).
        let mut torn = 0.0f32;
        for (c, r) in &self.tears {
            let d = (rest - *c).length() / r;
            let edge = 1.0 + 0.35 * (v - 0.5);
            if d < edge {
                torn = torn.max(((edge - d) * 3.0).min(1.0));
            }
        }
        if torn > 0.0 {
            albedo = albedo.lerp(srgb8(196, 96, 92), torn * 0.85);
        }
        let (fat, bruise, bruise_rgb) = if self.marks.is_empty() {
            (0.0, 0.0, Vec3::ZERO)
        } else {
            self.marks_at(rest)
        };
        if fat > 0.0 {
            albedo = albedo.lerp(srgb8(240, 212, 140) * (0.9 + 0.2 * v), fat * 0.8);
        }
        if bruise > 0.0 {
            albedo = albedo.lerp(bruise_rgb, bruise);
        }
        let mut normal = n;
        // Fat smooths the skin over the follicles.
        let bump = self.follicle_bump * (1.0 - 0.8 * fat);
        if d < 0.45 {
            let t = off - n * off.dot(n);
            let profile = (1.0 - d / 0.45) * bump;
            normal = (n - t.normalize_or_zero() * profile).normalize_or(n);
            albedo *= 1.0 - 0.03 * (1.0 - d / 0.45);
        }
        if self.pins > 0.0 && torn < 0.5 {
            // Feather remnants: sparse dark stubs, ~1 x 3 mm (stretched along the body
            // axis, as feathers lie), in clusters where a low-frequency mask is high.
            let cluster = value3(self.seed ^ 0x9E11, rest * 20.0);
            if cluster > 1.0 - 0.45 * self.pins {
                let (dp, offp) =
                    cellular3(self.seed ^ 0x9175, rest * Vec3::new(55.0, 140.0, 140.0));
                if dp < 0.22 {
                    let k = 1.0 - dp / 0.22;
                    albedo = albedo.lerp(srgb8(70, 56, 48), k * 0.85);
                    let t = offp - n * offp.dot(n);
                    normal = (normal + t.normalize_or_zero() * k * 0.6).normalize_or(n);
                }
            }
        }
        Surface {
            albedo,
            normal,
            f0: Vec3::splat(self.wet * (1.0 + 0.4 * fat)),
            roughness: self.roughness * (0.8 + 0.4 * v) * (1.0 - 0.3 * fat) + 0.15 * torn,
            metallic: 0.0,
            wrap: self.wrap,
            sss_tint: Vec3::new(1.0, 0.42, 0.32),
            coat: self.wet * 0.3,
        }
    }
}

/// A stain on the plate: a noisy blob.
#[derive(Clone, Debug, PartialEq)]
pub struct Stain {
    pub centre: Vec2,
    pub radius: f32,
    /// true: diluted blood (reddish tint); false: water (smoother, darker).
    pub blood: bool,
}

/// The surface under the carcasses.
#[derive(Clone, Debug, PartialEq)]
pub enum Background {
    /// Brushed stainless steel.
    Steel {
        f0: Vec3,
        roughness: f32,
        /// Unit brushing direction in the plate plane.
        brush: Vec2,
        seed: u64,
        stains: Vec<Stain>,
    },
    /// Modular plastic conveyor belt (white or blue), modules `pitch` metres long.
    Belt {
        color: Vec3,
        pitch: f32,
        dir: Vec2,
        stains: Vec<Stain>,
    },
    /// The `scene` randomisation group's surfaces (plates, belts, crates, generic; wet,
    /// smeared), see [`super::line_surface`].
    Line(Box<super::line_surface::LineSurface>),
}

impl Background {
    pub fn sample<R: Rng>(
        rng: &mut R,
        p_belt: f32,
        p_stains: f32,
        steel_roughness: [f32; 2],
        extent: f32,
    ) -> Background {
        let a = rng.random_range(0.0..std::f32::consts::TAU);
        let dir = Vec2::new(a.cos(), a.sin());
        let mut stains = Vec::new();
        if rng.random_bool(p_stains as f64) {
            for _ in 0..rng.random_range(1..6) {
                stains.push(Stain {
                    centre: Vec2::new(
                        rng.random_range(-extent..extent),
                        rng.random_range(-extent..extent),
                    ),
                    radius: rng.random_range(0.03..0.15),
                    blood: rng.random_bool(0.4),
                });
            }
        }
        if rng.random_bool(p_belt as f64) {
            let color = if rng.random_bool(0.5) {
                srgb8(225, 228, 226)
            } else {
                srgb8(40, 95, 160)
            };
            Background::Belt {
                color,
                pitch: rng.random_range(0.025..0.05),
                dir,
                stains,
            }
        } else {
            Background::Steel {
                f0: srgb8(196, 199, 202) * rng.random_range(0.9..1.05),
                roughness: if steel_roughness[1] > steel_roughness[0] {
                    rng.random_range(steel_roughness[0]..steel_roughness[1])
                } else {
                    steel_roughness[0]
                },
                brush: dir,
                seed: rng.random(),
                stains,
            }
        }
    }

    fn stain_at(stains: &[Stain], p: Vec2) -> (f32, bool) {
        let mut best = (0.0f32, false);
        for (i, s) in stains.iter().enumerate() {
            let d = (p - s.centre).length() / s.radius;
            if d < 1.6 {
                let n = fbm2(i as u64 * 31 + 5, p.x * 18.0, p.y * 18.0, 3);
                let m = (1.25 - d - 0.6 * (n - 0.5)).clamp(0.0, 0.25) * 4.0;
                if m > best.0 {
                    best = (m, s.blood);
                }
            }
        }
        best
    }

    /// Plate surface at plate point `p` (z = 0).
    pub fn surface(&self, p: Vec3) -> Surface {
        let q = p.truncate();
        match self {
            Background::Line(line) => line.surface(p),
            Background::Steel {
                f0,
                roughness,
                brush,
                seed,
                stains,
            } => {
                let along = q.dot(*brush);
                let across = q.dot(brush.perp());
                // Brushed: fine streaks across the brushing direction, stretched along it.
                // Streak widths ~1-4 mm: at ~1 mm per pixel finer ones would average away.
                let streak = value2(*seed, across * 700.0, along * 6.0) * 0.5
                    + value2(*seed ^ 1, across * 220.0, along * 3.0) * 0.5;
                let smudge = fbm2(*seed ^ 2, q.x * 6.0, q.y * 6.0, 3);
                let (stain, blood) = Self::stain_at(stains, q);
                let mut f0 = *f0 * (0.74 + 0.4 * streak) * (0.9 + 0.16 * smudge);
                // Streaks modulate brightness only: modulating the lobe width per streak
                // turns the light's mirror image into saw-tooth spikes.
                let mut rough = (roughness + 0.12 * (smudge - 0.5)).clamp(0.08, 0.6);
                let mut albedo = Vec3::splat(0.02);
                if stain > 0.0 {
                    if blood {
                        f0 = f0.lerp(f0 * Vec3::new(0.8, 0.5, 0.48), stain * 0.45);
                        albedo = albedo.lerp(Vec3::new(0.2, 0.03, 0.03), stain * 0.25);
                    } else {
                        f0 *= 1.0 - 0.12 * stain;
                    }
                    rough = rough * (1.0 - 0.6 * stain) + 0.05 * stain;
                }
                Surface {
                    albedo,
                    normal: Vec3::Z,
                    f0,
                    roughness: rough,
                    metallic: 1.0,
                    wrap: 0.0,
                    sss_tint: Vec3::ONE,
                    coat: 0.0,
                }
            }
            Background::Belt {
                color,
                pitch,
                dir,
                stains,
            } => {
                let along = q.dot(*dir) / pitch;
                let across = q.dot(dir.perp()) / (pitch * 0.5);
                let row = along.floor();
                // Modules are staggered row by row; dark hinge gaps between them.
                let shift = if (row as i64).rem_euclid(2) == 0 {
                    0.0
                } else {
                    0.5
                };
                let fu = along.rem_euclid(1.0);
                let fv = (across + shift).rem_euclid(1.0);
                let gap = (fu < 0.08) || (fv < 0.06);
                let grime = fbm2(11, q.x * 10.0, q.y * 10.0, 3);
                let mut albedo = if gap {
                    *color * 0.12
                } else {
                    *color * (0.85 + 0.2 * grime)
                };
                let (stain, blood) = Self::stain_at(stains, q);
                if stain > 0.0 && blood {
                    albedo = albedo.lerp(albedo * Vec3::new(0.8, 0.3, 0.3), stain * 0.7);
                }
                Surface {
                    albedo,
                    normal: Vec3::Z,
                    f0: Vec3::splat(0.04),
                    roughness: if stain > 0.0 { 0.15 } else { 0.45 },
                    metallic: 0.0,
                    wrap: 0.0,
                    sss_tint: Vec3::ONE,
                    coat: 0.0,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn skin_is_warm_and_steel_is_metal() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for _ in 0..20 {
            let m = SkinMaterial::sample(&mut rng, [0.0, 1.0]);
            let s = m.surface(Vec3::new(0.01, 0.02, 0.03), Vec3::Z, 0.0);
            assert!(
                s.albedo.x >= s.albedo.y && s.albedo.y >= s.albedo.z,
                "{:?}",
                s.albedo
            );
            assert!((s.normal.length() - 1.0).abs() < 1e-4);
            let red = m.surface(Vec3::new(0.01, 0.02, 0.03), Vec3::Z, 1.0);
            assert!(red.albedo.y / red.albedo.x < s.albedo.y / s.albedo.x);
        }
        let bg = Background::sample(&mut rng, 0.0, 0.0, [0.2, 0.4], 0.5);
        let s = bg.surface(Vec3::new(0.1, 0.2, 0.0));
        assert_eq!(s.metallic, 1.0);
        assert!(s.roughness >= 0.08 && s.roughness <= 0.6);
    }
}
