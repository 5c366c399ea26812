//! Rotation, scale and translation as one affine warp (ultralytics' `RandomPerspective`
//! without shear or perspective): bilinear for the image, nearest for the masks, the
//! border filled with ultralytics' grey 114. One warp instead of three keeps the image
//! resampled once, and masks sampled at exactly the points the image was.
//!
//! Coordinates are continuous with pixel centres at `i + 0.5`, so a quarter turn of a
//! square image maps pixel centres onto pixel centres and is exact.

use std::borrow::Cow;

use image::{Rgb, RgbImage};
use rand::Rng;

use super::augment::step::{Augment, AugmentState, MIN_INSTANCE_PX};
use super::dataset::{Instance, Sample};
use super::letterbox::PAD_GREY;
use crate::annotations::mask::Mask;

/// `dst = m · [x, y, 1]` in continuous pixel coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Affine {
    pub m: [[f64; 3]; 2],
}

/// Cosine and sine of `degrees`, exact at multiples of 90° (a pile seen from above
/// has no up, so quarter turns are common draws of `degrees = 180` tests and recipes).
fn cos_sin(degrees: f64) -> (f64, f64) {
    let q = degrees / 90.0;
    if q == q.round() {
        match (q as i64).rem_euclid(4) {
            0 => (1.0, 0.0),
            1 => (0.0, 1.0),
            2 => (-1.0, 0.0),
            _ => (0.0, -1.0),
        }
    } else {
        let r = degrees.to_radians();
        (r.cos(), r.sin())
    }
}

impl Affine {
    /// Rotates by `degrees` (counter-clockwise on screen) and scales by `scale` about
    /// the centre of a `src`-sized image, whose centre then lands at the centre of a
    /// `out`-sized image shifted by `shift` pixels.
    pub fn about_centre(
        src: (u32, u32),
        out: (u32, u32),
        degrees: f64,
        scale: f64,
        shift: (f64, f64),
    ) -> Affine {
        let (c, s) = cos_sin(degrees);
        // Image y points down: a counter-clockwise turn on screen is [c, s; -s, c].
        let (a, b, d, e) = (scale * c, scale * s, -scale * s, scale * c);
        let (cx, cy) = (src.0 as f64 / 2.0, src.1 as f64 / 2.0);
        let (ox, oy) = (out.0 as f64 / 2.0 + shift.0, out.1 as f64 / 2.0 + shift.1);
        Affine {
            m: [[a, b, ox - a * cx - b * cy], [d, e, oy - d * cx - e * cy]],
        }
    }

    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let m = &self.m;
        (
            m[0][0] * x + m[0][1] * y + m[0][2],
            m[1][0] * x + m[1][1] * y + m[1][2],
        )
    }

    /// The inverse map, or None when the matrix is singular (scale 0).
    pub fn inverse(&self) -> Option<Affine> {
        let [[a, b, tx], [d, e, ty]] = self.m;
        let det = a * e - b * d;
        if det.abs() < 1e-12 {
            return None;
        }
        let (ia, ib, id, ie) = (e / det, -b / det, -d / det, a / det);
        Some(Affine {
            m: [
                [ia, ib, -(ia * tx + ib * ty)],
                [id, ie, -(id * tx + ie * ty)],
            ],
        })
    }
}

/// Warps `s` by `a` into an `out`-sized sample; instances left with fewer than
/// `min_area` pixels are dropped.
pub fn warp(s: &Sample, a: &Affine, out: (u32, u32), min_area: u64) -> Sample {
    let (ow, oh) = out;
    let (w, h) = s.image.dimensions();
    let mut image = RgbImage::from_pixel(ow, oh, Rgb([PAD_GREY; 3]));
    let Some(inv) = a.inverse() else {
        return Sample {
            image,
            instances: Vec::new(),
        };
    };
    // Source pixel of each output pixel for the masks (nearest), computed once.
    let mut nearest: Vec<Option<usize>> = vec![None; (ow * oh) as usize];
    let fill = [PAD_GREY as f64; 3];
    let px = |x: i64, y: i64| -> [f64; 3] {
        if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
            fill
        } else {
            s.image.get_pixel(x as u32, y as u32).0.map(f64::from)
        }
    };
    for v in 0..oh {
        for u in 0..ow {
            let (sx, sy) = inv.apply(u as f64 + 0.5, v as f64 + 0.5);
            let (nx, ny) = (sx.floor(), sy.floor());
            if nx >= 0.0 && ny >= 0.0 && nx < w as f64 && ny < h as f64 {
                nearest[(v * ow + u) as usize] = Some(ny as usize * w as usize + nx as usize);
            }
            // Bilinear between the four pixel centres around (sx, sy).
            let (bx, by) = (sx - 0.5, sy - 0.5);
            let (x0, y0) = (bx.floor(), by.floor());
            let (fx, fy) = (bx - x0, by - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            if x0 + 1 < 0 || y0 + 1 < 0 || x0 >= w as i64 || y0 >= h as i64 {
                continue;
            }
            let (p00, p10, p01, p11) = (
                px(x0, y0),
                px(x0 + 1, y0),
                px(x0, y0 + 1),
                px(x0 + 1, y0 + 1),
            );
            let mut c = [0u8; 3];
            for k in 0..3 {
                let top = p00[k] * (1.0 - fx) + p10[k] * fx;
                let bot = p01[k] * (1.0 - fx) + p11[k] * fx;
                c[k] = (top * (1.0 - fy) + bot * fy).round().clamp(0.0, 255.0) as u8;
            }
            image.put_pixel(u, v, Rgb(c));
        }
    }
    let instances = s
        .instances
        .iter()
        .filter_map(|inst| {
            let mut m = Mask::new(oh, ow);
            for (o, src) in m.data.iter_mut().zip(&nearest) {
                if let Some(i) = src {
                    *o = u8::from(inst.mask.data[*i] != 0);
                }
            }
            (m.area() >= min_area.max(1)).then_some(Instance {
                class: inst.class,
                mask: m,
            })
        })
        .collect();
    Sample { image, instances }
}

/// The pipeline's affine warp: rotation uniform in ±`degrees`, scale in `1 ± scale`,
/// shift in ±`translate` of the item's size per axis, each drawn from the second stream
/// only when on; after a mosaic it maps the canvas back to the item's size (so it runs
/// whenever `mosaic` is on, even with the three ranges 0).
pub struct RandomAffine {
    pub degrees: f64,
    pub scale: f64,
    pub translate: f64,
    /// Whether the warp can be other than the identity (`AugmentConfig::warps`).
    pub on: bool,
}

impl Augment for RandomAffine {
    fn name(&self) -> &'static str {
        "affine"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        if !self.on {
            return s;
        }
        let dims = s.image.dimensions();
        let (from, (w, h)) = st.canvas.unwrap_or((dims, dims));
        let degrees = if self.degrees > 0.0 {
            st.extra.random_range(-self.degrees..=self.degrees)
        } else {
            0.0
        };
        let scale = if self.scale > 0.0 {
            st.extra.random_range(1.0 - self.scale..=1.0 + self.scale)
        } else {
            1.0
        };
        let shift = if self.translate > 0.0 {
            (
                st.extra.random_range(-self.translate..=self.translate) * w as f64,
                st.extra.random_range(-self.translate..=self.translate) * h as f64,
            )
        } else {
            (0.0, 0.0)
        };
        let a = Affine::about_centre(from, (w, h), degrees, scale, shift);
        Cow::Owned(warp(&s, &a, (w, h), MIN_INSTANCE_PX))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn painted(w: u32, h: u32) -> Sample {
        let mut image = RgbImage::new(w, h);
        for (x, y, p) in image.enumerate_pixels_mut() {
            p.0 = [
                (x * 7 % 256) as u8,
                (y * 11 % 256) as u8,
                ((x + y) % 256) as u8,
            ];
        }
        let mut m = Mask::new(h, w);
        for y in 1..4 {
            for x in 2..6 {
                m.set(x, y, true);
            }
        }
        Sample {
            image,
            instances: vec![Instance { class: 0, mask: m }],
        }
    }

    #[test]
    fn quarter_turn_is_exact() {
        let s = painted(9, 9);
        let a = Affine::about_centre((9, 9), (9, 9), 90.0, 1.0, (0.0, 0.0));
        let r = warp(&s, &a, (9, 9), 1);
        // Counter-clockwise on screen: source (x, y) lands at (y, 8 - x).
        for y in 0..9 {
            for x in 0..9 {
                assert_eq!(r.image.get_pixel(y, 8 - x), s.image.get_pixel(x, y));
                assert_eq!(
                    r.instances[0].mask.get(y, 8 - x),
                    s.instances[0].mask.get(x, y)
                );
            }
        }
        // Four quarter turns are the identity, for the image and the masks.
        let mut t = s.clone();
        for _ in 0..4 {
            t = warp(&t, &a, (9, 9), 1);
        }
        assert_eq!(t.image, s.image);
        assert_eq!(t.instances, s.instances);
    }

    #[test]
    fn identity_and_inverse() {
        let s = painted(8, 6);
        let id = Affine::about_centre((8, 6), (8, 6), 0.0, 1.0, (0.0, 0.0));
        let r = warp(&s, &id, (8, 6), 1);
        assert_eq!(r.image, s.image);
        assert_eq!(r.instances, s.instances);
        let a = Affine::about_centre((8, 6), (10, 10), 33.0, 1.3, (1.5, -2.0));
        let inv = a.inverse().unwrap();
        let (x, y) = a.apply(3.25, 1.5);
        let (bx, by) = inv.apply(x, y);
        assert!((bx - 3.25).abs() < 1e-9 && (by - 1.5).abs() < 1e-9);
        assert!(Affine::about_centre((8, 6), (8, 6), 0.0, 0.0, (0.0, 0.0))
            .inverse()
            .is_none());
    }

    #[test]
    fn shifted_out_of_frame_fills_grey_and_drops_instances() {
        let s = painted(8, 8);
        let a = Affine::about_centre((8, 8), (8, 8), 0.0, 1.0, (20.0, 0.0));
        let r = warp(&s, &a, (8, 8), 1);
        assert!(r.instances.is_empty());
        assert!(r.image.pixels().all(|p| p.0 == [PAD_GREY; 3]));
        // An integer shift moves pixels and masks together, exactly.
        let a = Affine::about_centre((8, 8), (8, 8), 0.0, 1.0, (2.0, 1.0));
        let r = warp(&s, &a, (8, 8), 1);
        assert_eq!(r.image.get_pixel(4, 3), s.image.get_pixel(2, 2));
        assert!(r.instances[0].mask.get(4, 2) && !r.instances[0].mask.get(3, 2));
        assert_eq!(r.instances[0].mask.area(), 12);
        // The instance falls under `min_area` when shifted mostly out.
        let a = Affine::about_centre((8, 8), (8, 8), 0.0, 1.0, (5.0, 0.0));
        assert_eq!(warp(&s, &a, (8, 8), 1).instances[0].mask.area(), 3);
        assert!(warp(&s, &a, (8, 8), 4).instances.is_empty());
    }
}
