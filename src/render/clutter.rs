//! Clutter images, the negatives knob's `clutter` share: a dead-leaves picture (Lee,
//! Mumford & Huang 2001; used as pre-training data by Baradad et al. 2021, "Learning to
//! see by looking at noise") drawn in 2D instead of a render, never labelled.
//!
//! Why: the renders only ever show belts, plates and crates, so a face, a cup or a cat is
//! a scene the model has never been told holds no carcass, and it calls them carcasses
//! (BENCHMARKS "No carcasses where there are none"). Dead leaves — shapes of power-law
//! sizes, random colours, shading and texture, each hiding what lies under it — have the
//! occlusions, scales and colour spread of ordinary photos and no carcass in them. The
//! shapes are flat 2D figures (discs, ellipses, boxes, strokes), not shaded 3D blobs, so
//! they never look like a rendered carcass (shaded 3D solids were tried and did not cut the
//! false carcasses: bench/results/negatives/2026-12-08). A change to what is drawn here
//! bumps `render::CLUTTER_VERSION`, or runs reuse the old pictures from the render cache.

use image::RgbImage;
use rand::Rng;

use super::noise;

/// Shapes of one picture; later ones cover earlier ones (painter's order).
const SHAPES: [usize; 2] = [500, 1000];

/// A dead-leaves picture of `w` × `h` pixels drawn from `rng`.
pub fn dead_leaves<R: Rng>(rng: &mut R, w: u32, h: u32) -> RgbImage {
    let (wu, hu) = (w as usize, h as usize);
    let side = w.max(h) as f32;
    let mut px = vec![random_colour(rng); wu * hu];
    // Radii with density ∝ r⁻³ between r_min and r_max (scale invariance: as many shapes
    // per octave of area), by inverting the distribution function.
    let (r_min, r_max) = ((side / 64.0).max(1.0), side * 0.45);
    let (a, b) = (r_min.powi(-2), r_max.powi(-2));
    let n = rng.random_range(SHAPES[0]..=SHAPES[1]);
    for _ in 0..n {
        let r = (a - rng.random::<f32>() * (a - b)).powf(-0.5);
        let shape = Shape::sample(rng, r, w as f32, h as f32);
        shape.paint(&mut px, wu, hu);
    }
    // Sensor-like grain so the picture is not noise-free as no photo is.
    let sigma = rng.random_range(0.0..0.025f32);
    let grain_seed: u64 = rng.random();
    let mut img = RgbImage::new(w, h);
    for (i, (p, out)) in px.iter().zip(img.pixels_mut()).enumerate() {
        let h = crate::util::hash::mix64(grain_seed ^ i as u64);
        let g = (noise::unit(h) + noise::unit(h.rotate_left(24)) - 1.0) * sigma * 2.45;
        for c in 0..3 {
            out.0[c] = ((p[c] + g).clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        }
    }
    img
}

/// A colour in display space: any hue, saturation biased low (as in photos), value from
/// dark to bright.
fn random_colour<R: Rng>(rng: &mut R) -> [f32; 3] {
    let hue = rng.random_range(0.0..6.0f32);
    let sat = rng.random::<f32>().powf(1.5);
    let val = rng.random_range(0.08..1.0f32);
    let c = val * sat;
    let x = c * (1.0 - ((hue % 2.0) - 1.0).abs());
    let (r, g, b) = match hue as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = val - c;
    [r + m, g + m, b + m]
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Ellipse,
    Rect,
}

/// One leaf: an ellipse or a box (thin ones are strokes) with a linear shading ramp and
/// a value-noise texture.
struct Shape {
    kind: Kind,
    centre: [f32; 2],
    /// Half axes along the rotated frame.
    half: [f32; 2],
    /// Rotation as (cos, sin).
    rot: [f32; 2],
    colour: [f32; 3],
    /// Shading ramp: brightness changes by `ramp · (d · dir) / r` across the shape.
    ramp: f32,
    ramp_dir: [f32; 2],
    texture: f32,
    texture_freq: f32,
    texture_seed: u64,
}

impl Shape {
    fn sample<R: Rng>(rng: &mut R, r: f32, w: f32, h: f32) -> Shape {
        let kind = if rng.random_bool(0.6) {
            Kind::Ellipse
        } else {
            Kind::Rect
        };
        // Aspect: mostly round-ish, a tenth long strokes.
        let aspect = if rng.random_bool(0.1) {
            rng.random_range(4.0..12.0f32)
        } else {
            rng.random_range(1.0..2.5f32)
        };
        let long = r * aspect.sqrt();
        let half = [long, (r / aspect.sqrt()).max(0.6)];
        let angle = rng.random_range(0.0..std::f32::consts::TAU);
        let dir = rng.random_range(0.0..std::f32::consts::TAU);
        Shape {
            kind,
            centre: [
                rng.random_range(-0.1..1.1) * w,
                rng.random_range(-0.1..1.1) * h,
            ],
            half,
            rot: [angle.cos(), angle.sin()],
            colour: random_colour(rng),
            ramp: rng.random_range(0.0..0.5),
            ramp_dir: [dir.cos(), dir.sin()],
            texture: if rng.random_bool(0.5) {
                rng.random_range(0.0..0.3)
            } else {
                0.0
            },
            texture_freq: rng.random_range(0.05..0.6),
            texture_seed: rng.random(),
        }
    }

    /// Signed distance in pixels (approximate for ellipses): < 0 inside.
    fn distance(&self, dx: f32, dy: f32) -> f32 {
        let (u, v) = (
            dx * self.rot[0] + dy * self.rot[1],
            -dx * self.rot[1] + dy * self.rot[0],
        );
        match self.kind {
            Kind::Ellipse => {
                let q = ((u / self.half[0]).powi(2) + (v / self.half[1]).powi(2)).sqrt();
                (q - 1.0) * self.half[1].min(self.half[0])
            }
            Kind::Rect => (u.abs() - self.half[0]).max(v.abs() - self.half[1]),
        }
    }

    /// Blends the shape over `px` with a one-pixel anti-aliased edge.
    fn paint(&self, px: &mut [[f32; 3]], w: usize, h: usize) {
        let reach = self.half[0].max(self.half[1]) + 1.0;
        let x0 = (self.centre[0] - reach).floor().max(0.0) as usize;
        let y0 = (self.centre[1] - reach).floor().max(0.0) as usize;
        let x1 = ((self.centre[0] + reach).ceil().max(0.0) as usize).min(w);
        let y1 = ((self.centre[1] + reach).ceil().max(0.0) as usize).min(h);
        let scale = self.half[0].max(self.half[1]);
        for y in y0..y1 {
            for x in x0..x1 {
                let (dx, dy) = (
                    x as f32 + 0.5 - self.centre[0],
                    y as f32 + 0.5 - self.centre[1],
                );
                let cover = (0.5 - self.distance(dx, dy)).clamp(0.0, 1.0);
                if cover == 0.0 {
                    continue;
                }
                let along = (dx * self.ramp_dir[0] + dy * self.ramp_dir[1]) / scale;
                let mut shade = 1.0 + self.ramp * along;
                if self.texture > 0.0 {
                    let t = noise::fbm2(
                        self.texture_seed,
                        x as f32 * self.texture_freq,
                        y as f32 * self.texture_freq,
                        3,
                    );
                    shade *= 1.0 + self.texture * (2.0 * t - 1.0);
                }
                let p = &mut px[y * w + x];
                for c in 0..3 {
                    let v = (self.colour[c] * shade).clamp(0.0, 1.0);
                    p[c] += (v - p[c]) * cover;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn pictures_are_deterministic_varied_and_span_the_range() {
        let draw = |s| dead_leaves(&mut ChaCha8Rng::seed_from_u64(s), 96, 64);
        let (a, b) = (draw(3), draw(4));
        assert_eq!(a, draw(3));
        assert_ne!(a, b);
        assert_eq!(a.dimensions(), (96, 64));
        for img in [&a, &b] {
            // Many distinct colours (shapes, ramps, grain) and real contrast: not a flat
            // fill or a single shape.
            let mut colours: Vec<[u8; 3]> = img.pixels().map(|p| p.0).collect();
            colours.sort_unstable();
            colours.dedup();
            assert!(colours.len() > 500, "{} colours", colours.len());
            let luma: Vec<f32> = img
                .pixels()
                .map(|p| p.0.iter().map(|&v| v as f32).sum::<f32>() / 3.0)
                .collect();
            let (lo, hi) = luma
                .iter()
                .fold((f32::MAX, f32::MIN), |(l, h), &v| (l.min(v), h.max(v)));
            assert!(hi - lo > 80.0, "luma range {lo}..{hi}");
        }
    }

    #[test]
    fn shapes_cover_their_inside_and_leave_the_outside() {
        let s = Shape {
            kind: Kind::Rect,
            centre: [10.0, 10.0],
            half: [4.0, 2.0],
            rot: [1.0, 0.0],
            colour: [1.0, 0.0, 0.0],
            ramp: 0.0,
            ramp_dir: [1.0, 0.0],
            texture: 0.0,
            texture_freq: 0.1,
            texture_seed: 0,
        };
        let mut px = vec![[0.0f32; 3]; 20 * 20];
        s.paint(&mut px, 20, 20);
        assert_eq!(px[10 * 20 + 10], [1.0, 0.0, 0.0]);
        assert_eq!(px[10 * 20 + 16], [0.0; 3]);
        assert_eq!(px[14 * 20 + 10], [0.0; 3]);
        let e = Shape {
            kind: Kind::Ellipse,
            ..s
        };
        assert!(e.distance(0.0, 0.0) < 0.0 && e.distance(0.0, 3.0) > 0.0);
        // Off-image shapes paint nothing and do not panic.
        let far = Shape {
            centre: [-50.0, 90.0],
            ..e
        };
        let mut px = vec![[0.0f32; 3]; 20 * 20];
        far.paint(&mut px, 20, 20);
        assert!(px.iter().all(|p| *p == [0.0; 3]));
    }
}
