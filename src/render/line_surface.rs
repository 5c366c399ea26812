//! The `scene` group's surfaces under the pile: stainless plates in three finishes
//! (brushed, 2B matte, polished) with scratches, plastic belts (flat and modular slats)
//! and crate floors in several colours, wet or dry (wet = darker, glossier, specular
//! puddles), with blood and fat smears — plus generic non-line surfaces (random
//! textured or coloured patterns) so a model also sees what is *not* a processing line.
//! Everything is drawn once per image from the "scene" stream; the surface is then a
//! pure function of the plate point, like the base [`super::material::Background`].

use glam::{Vec2, Vec3};
use rand::Rng;

use super::noise::{cellular3, fbm2, value2};
use super::ranges::DomainRanges;
use super::surface::{srgb8, Surface};

/// Stainless finishes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Finish {
    /// Fine streaks along one direction, medium gloss.
    Brushed,
    /// Cold-rolled 2B: matte, mottled, no direction.
    Matte2B,
    /// Near-mirror.
    Polished,
}

/// Patterns of the generic (non-line) surfaces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pattern {
    /// Smooth two-colour noise (concrete, cloth, stone).
    Noise,
    /// Noisy stripes (wood, corrugation, fabric).
    Stripes,
    /// Tiles / checker.
    Checker,
    /// Cellular blobs (terrazzo, gravel).
    Cells,
    /// Fine high-frequency speckle.
    Speckle,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Kind {
    Steel {
        finish: Finish,
        f0: Vec3,
        roughness: f32,
        /// Unit brushing direction.
        brush: Vec2,
        /// Scratch density (0 = none).
        scratches: f32,
    },
    Belt {
        color: Vec3,
        /// Modular slats with hinge gaps (true) or a flat belt with seams (false).
        modular: bool,
        pitch: f32,
        dir: Vec2,
    },
    /// A plastic crate floor: a grid of openings between ribs.
    Crate { color: Vec3, cell: f32, dir: Vec2 },
    Generic {
        a: Vec3,
        b: Vec3,
        scale: f32,
        pattern: Pattern,
        roughness: f32,
        dir: Vec2,
    },
}

/// A stretched blob on the surface (smear or puddle).
#[derive(Clone, Debug, PartialEq)]
pub struct Blob {
    pub centre: Vec2,
    pub radius: f32,
    /// Unit stretch direction and its length factor (1 = round).
    pub dir: Vec2,
    pub stretch: f32,
    /// Smears: blood (true) or fat (false); puddles ignore it.
    pub blood: bool,
}

/// One image's surface.
#[derive(Clone, Debug, PartialEq)]
pub struct LineSurface {
    pub kind: Kind,
    /// 0 = dry; up to 1 = soaking (darker, glossier).
    pub wet: f32,
    pub puddles: Vec<Blob>,
    pub smears: Vec<Blob>,
    pub seed: u64,
}

/// Plastic colours of belts and crates: white, blue, light blue, red, green, grey, dark.
fn plastic<R: Rng>(rng: &mut R) -> Vec3 {
    let c = match rng.random_range(0..7) {
        0 => srgb8(226, 228, 225),
        1 => srgb8(40, 95, 160),
        2 => srgb8(125, 172, 212),
        3 => srgb8(178, 42, 40),
        4 => srgb8(52, 128, 72),
        5 => srgb8(122, 124, 127),
        _ => srgb8(36, 37, 40),
    };
    c * rng.random_range(0.85..1.1)
}

/// A random colour for generic surfaces (any hue, muted to vivid, dark to light).
fn any_colour<R: Rng>(rng: &mut R) -> Vec3 {
    let h = rng.random_range(0.0..6.0f32);
    let s = rng.random_range(0.0..0.9f32);
    let v = rng.random_range(0.08..0.9f32);
    let f = |n: f32| {
        let k = (n + h) % 6.0;
        v - v * s * (k.min(4.0 - k).clamp(0.0, 1.0))
    };
    let srgb = Vec3::new(f(5.0), f(3.0), f(1.0));
    let lin = super::sensor::srgb_to_linear;
    Vec3::new(lin(srgb.x), lin(srgb.y), lin(srgb.z))
}

fn blob<R: Rng>(rng: &mut R, extent: f32, radius: [f32; 2], blood: bool) -> Blob {
    let a = rng.random_range(0.0..std::f32::consts::TAU);
    Blob {
        centre: Vec2::new(
            rng.random_range(-extent..extent),
            rng.random_range(-extent..extent),
        ),
        radius: rng.random_range(radius[0]..radius[1]),
        dir: Vec2::new(a.cos(), a.sin()),
        stretch: rng.random_range(1.0..2.5),
        blood,
    }
}

impl LineSurface {
    /// Draws a surface for a view of half-width `extent` around `centre` (m).
    pub fn sample<R: Rng>(
        rng: &mut R,
        ranges: &DomainRanges,
        centre: Vec2,
        extent: f32,
    ) -> LineSurface {
        let a = rng.random_range(0.0..std::f32::consts::TAU);
        let dir = Vec2::new(a.cos(), a.sin());
        let generic = rng.random_bool(ranges.p_generic as f64);
        let kind = if generic {
            let pattern = match rng.random_range(0..5) {
                0 => Pattern::Noise,
                1 => Pattern::Stripes,
                2 => Pattern::Checker,
                3 => Pattern::Cells,
                _ => Pattern::Speckle,
            };
            Kind::Generic {
                a: any_colour(rng),
                b: any_colour(rng),
                scale: rng.random_range(2.0..60.0),
                pattern,
                roughness: rng.random_range(0.25..0.95),
                dir,
            }
        } else {
            match rng.random_range(0..10) {
                0..=3 => {
                    let finish = match rng.random_range(0..3) {
                        0 => Finish::Brushed,
                        1 => Finish::Matte2B,
                        _ => Finish::Polished,
                    };
                    let roughness = match finish {
                        Finish::Brushed => rng.random_range(0.18..0.35),
                        Finish::Matte2B => rng.random_range(0.38..0.6),
                        Finish::Polished => rng.random_range(0.06..0.14),
                    };
                    Kind::Steel {
                        finish,
                        f0: srgb8(196, 199, 202) * rng.random_range(0.85..1.05),
                        roughness,
                        brush: dir,
                        scratches: if rng.random_bool(0.6) {
                            rng.random_range(0.2..1.0)
                        } else {
                            0.0
                        },
                    }
                }
                4..=6 => Kind::Belt {
                    color: plastic(rng),
                    modular: rng.random_bool(0.6),
                    pitch: rng.random_range(0.02..0.06),
                    dir,
                },
                _ => Kind::Crate {
                    color: plastic(rng),
                    cell: rng.random_range(0.012..0.04),
                    dir,
                },
            }
        };
        let wet = if rng.random_bool(ranges.p_wet as f64) {
            rng.random_range(0.3..1.0)
        } else {
            0.0
        };
        let ext = extent.max(0.05);
        let puddles = if wet > 0.0 {
            (0..rng.random_range(1..5))
                .map(|_| blob(rng, ext, [0.04, 0.25], false))
                .collect()
        } else {
            Vec::new()
        };
        let smears = if rng.random_bool(ranges.p_smears as f64) {
            (0..rng.random_range(1..7))
                .map(|_| {
                    let blood = rng.random_bool(0.6);
                    blob(rng, ext, [0.01, 0.06], blood)
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut s = LineSurface {
            kind,
            wet,
            puddles,
            smears,
            seed: rng.random(),
        };
        for b in s.puddles.iter_mut().chain(s.smears.iter_mut()) {
            b.centre += centre;
        }
        s
    }

    /// Coverage (0..1) of the nearest blob of `blobs` at `p`, and its blood flag.
    fn cover(blobs: &[Blob], seed: u64, p: Vec2) -> (f32, bool) {
        let mut best = (0.0f32, false);
        for (i, b) in blobs.iter().enumerate() {
            let q = p - b.centre;
            let along = q.dot(b.dir) / b.stretch;
            let across = q.dot(b.dir.perp());
            let d = (along * along + across * across).sqrt() / b.radius;
            if d < 1.8 {
                let n = fbm2(seed ^ (i as u64 * 0x9E37 + 3), p.x * 25.0, p.y * 25.0, 3);
                let m = ((1.2 - d - 0.7 * (n - 0.5)) * 5.0).clamp(0.0, 1.0);
                if m > best.0 {
                    best = (m, b.blood);
                }
            }
        }
        best
    }

    /// The surface at plate point `p` (z = 0).
    pub fn surface(&self, p: Vec3) -> Surface {
        let q = p.truncate();
        let seed = self.seed;
        let grime = fbm2(seed ^ 7, q.x * 9.0, q.y * 9.0, 3);
        let s = match &self.kind {
            Kind::Steel {
                finish,
                f0,
                roughness,
                brush,
                scratches,
            } => {
                let along = q.dot(*brush);
                let across = q.dot(brush.perp());
                let (streak_amp, mottle_amp) = match finish {
                    Finish::Brushed => (0.4, 0.12),
                    Finish::Matte2B => (0.08, 0.3),
                    Finish::Polished => (0.03, 0.06),
                };
                let streak = value2(seed, across * 700.0, along * 6.0) * 0.5
                    + value2(seed ^ 1, across * 220.0, along * 3.0) * 0.5;
                let mottle = fbm2(seed ^ 2, q.x * 14.0, q.y * 14.0, 3);
                let mut f = *f0
                    * (1.0 - streak_amp * 0.5 + streak_amp * streak)
                    * (1.0 - mottle_amp * 0.5 + mottle_amp * mottle);
                let mut rough = (roughness + 0.1 * (grime - 0.5)).clamp(0.04, 0.7);
                if *scratches > 0.0 {
                    // Scratches: thin random lines in two directions.
                    let d2 = brush.rotate(Vec2::new(0.8, 0.6));
                    let s1 = value2(seed ^ 3, q.dot(*brush) * 4.0, across * 1500.0);
                    let s2 = value2(seed ^ 4, q.dot(d2) * 3.0, q.dot(d2.perp()) * 1200.0);
                    let t = 1.0 - 0.06 * scratches;
                    if s1.max(s2) > t {
                        f *= 1.25;
                        rough = (rough + 0.25).min(0.8);
                    }
                }
                Surface {
                    albedo: Vec3::splat(0.02),
                    normal: Vec3::Z,
                    f0: f,
                    roughness: rough,
                    metallic: 1.0,
                    wrap: 0.0,
                    sss_tint: Vec3::ONE,
                    coat: 0.0,
                }
            }
            Kind::Belt {
                color,
                modular,
                pitch,
                dir,
            } => belt(seed, q, grime, *color, *modular, *pitch, *dir),
            Kind::Crate { color, cell, dir } => {
                let u = q.dot(*dir) / cell;
                let v = q.dot(dir.perp()) / (cell * 1.6);
                let (fu, fv) = (u.rem_euclid(1.0), v.rem_euclid(1.0));
                let hole = fu > 0.3 && fu < 0.85 && fv > 0.2 && fv < 0.9;
                let rib = (fu - 0.15).abs() < 0.05;
                let albedo = if hole {
                    // The opening: the floor below the crate, in shadow.
                    Vec3::splat(0.02 + 0.03 * grime)
                } else if rib {
                    *color * 1.08
                } else {
                    *color * (0.85 + 0.2 * grime)
                };
                dielectric(albedo, 0.4)
            }
            Kind::Generic {
                a,
                b,
                scale,
                pattern,
                roughness,
                dir,
            } => {
                let (u, v) = (q.dot(*dir) * scale, q.dot(dir.perp()) * scale);
                let t = match pattern {
                    Pattern::Noise => fbm2(seed ^ 9, u, v, 4),
                    Pattern::Stripes => {
                        let w = fbm2(seed ^ 10, u * 0.3, v * 0.3, 2);
                        (((u + 2.0 * w) * 3.0).sin() * 0.5 + 0.5).powf(1.5)
                    }
                    Pattern::Checker => {
                        let c = (u.floor() as i64 + v.floor() as i64).rem_euclid(2) as f32;
                        c * 0.85 + 0.15 * fbm2(seed ^ 11, u * 4.0, v * 4.0, 2)
                    }
                    Pattern::Cells => cellular3(seed ^ 12, Vec3::new(u, v, 0.0)).0.min(1.0),
                    Pattern::Speckle => value2(seed ^ 13, u * 8.0, v * 8.0),
                };
                dielectric(a.lerp(*b, t.clamp(0.0, 1.0)), *roughness)
            }
        };
        self.films(s, q, grime)
    }

    /// The water film (`wet`, puddles) and the smears (blood, fat) over surface `s` at
    /// plate point `q`.
    fn films(&self, mut s: Surface, q: Vec2, grime: f32) -> Surface {
        let seed = self.seed;
        if self.wet > 0.0 {
            // A water film: dielectrics darken (less diffuse light escapes) and gloss up;
            // steel gets a little duller in colour, much smoother.
            let (puddle, _) = Self::cover(&self.puddles, seed ^ 0x77, q);
            let wet = (self.wet * (0.6 + 0.4 * grime)).max(puddle);
            s.albedo *= 1.0 - 0.4 * wet;
            s.roughness = s.roughness * (1.0 - 0.75 * wet) + 0.03 * wet;
            if s.metallic < 0.5 {
                s.f0 = s.f0.max(Vec3::splat(0.02 + 0.02 * wet));
                s.coat = s.coat.max(0.02 * wet + 0.03 * puddle);
            }
        }
        let (m, blood) = Self::cover(&self.smears, seed ^ 0x55, q);
        if m > 0.0 {
            // Smears are dielectric films: blend towards their colour and away from metal.
            let col = if blood {
                srgb8(110, 18, 16) * (0.7 + 0.5 * grime)
            } else {
                srgb8(232, 214, 170) * (0.85 + 0.2 * grime)
            };
            let k = m * if blood { 0.85 } else { 0.7 };
            s.albedo = s.albedo.lerp(col, k);
            s.metallic *= 1.0 - k;
            s.f0 = s.f0.lerp(Vec3::splat(0.04), k);
            s.roughness += ((if blood { 0.15 } else { 0.3 }) - s.roughness) * k;
        }
        s
    }
}

/// A conveyor belt at plate point `q`: modular slats with hinge gaps, or a flat fabric
/// belt with a seam every ~20 pitches.
fn belt(
    seed: u64,
    q: Vec2,
    grime: f32,
    color: Vec3,
    modular: bool,
    pitch: f32,
    dir: Vec2,
) -> Surface {
    let along = q.dot(dir) / pitch;
    let across = q.dot(dir.perp()) / (pitch * 0.5);
    let albedo = if modular {
        let row = along.floor();
        let shift = if (row as i64).rem_euclid(2) == 0 {
            0.0
        } else {
            0.5
        };
        let fu = along.rem_euclid(1.0);
        let fv = (across + shift).rem_euclid(1.0);
        if fu < 0.08 || fv < 0.06 {
            color * 0.12
        } else {
            // Slat ridges: a faint brightness ramp across each module.
            color * (0.82 + 0.2 * grime + 0.06 * (fu * std::f32::consts::PI).sin())
        }
    } else {
        // Flat belt: fabric-like fine texture and a seam every ~20 pitches.
        let fine = value2(seed ^ 5, q.x * 400.0, q.y * 400.0);
        let seam = (along / 20.0).rem_euclid(1.0) < 0.01;
        let k = if seam { 0.6 } else { 0.88 + 0.08 * fine };
        color * (k + 0.15 * (grime - 0.5))
    };
    dielectric(albedo, 0.45 + 0.1 * grime)
}

/// A matte dielectric (belt, crate, generic floor): `albedo`, `roughness`, F0 0.04.
fn dielectric(albedo: Vec3, roughness: f32) -> Surface {
    Surface {
        albedo,
        normal: Vec3::Z,
        f0: Vec3::splat(0.04),
        roughness,
        metallic: 0.0,
        wrap: 0.0,
        sss_tint: Vec3::ONE,
        coat: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn every_kind_gives_finite_in_range_surfaces() {
        let r = DomainRanges {
            p_wet: 0.5,
            p_smears: 1.0,
            p_generic: 0.3,
            ..Default::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let (mut steel, mut generic, mut wet) = (0, 0, 0);
        for _ in 0..60 {
            let s = LineSurface::sample(&mut rng, &r, Vec2::new(0.1, -0.2), 0.6);
            steel += matches!(s.kind, Kind::Steel { .. }) as u32;
            generic += matches!(s.kind, Kind::Generic { .. }) as u32;
            wet += (s.wet > 0.0) as u32;
            for i in 0..50 {
                let p = Vec3::new(
                    i as f32 * 0.023 - 0.5,
                    (i * 7 % 50) as f32 * 0.02 - 0.5,
                    0.0,
                );
                let f = s.surface(p);
                assert!(f.albedo.is_finite() && f.albedo.min_element() >= 0.0);
                assert!(f.albedo.max_element() <= 1.2, "{:?}", f.albedo);
                assert!((0.0..=1.0).contains(&f.roughness) && (0.0..=1.0).contains(&f.metallic));
            }
        }
        assert!(
            steel > 5 && generic > 5 && wet > 10,
            "{steel} {generic} {wet}"
        );
    }

    #[test]
    fn wet_is_darker_and_glossier_than_dry() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut s = LineSurface::sample(&mut rng, &DomainRanges::default(), Vec2::ZERO, 0.5);
        s.kind = Kind::Belt {
            color: srgb8(226, 228, 225),
            modular: false,
            pitch: 0.04,
            dir: Vec2::X,
        };
        s.smears.clear();
        s.wet = 0.0;
        let p = Vec3::new(0.013, 0.021, 0.0);
        let dry = s.surface(p);
        s.wet = 1.0;
        let wet = s.surface(p);
        assert!(wet.albedo.x < dry.albedo.x && wet.roughness < dry.roughness);
    }
}
