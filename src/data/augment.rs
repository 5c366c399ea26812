//! Training augmentation, as in the paper plus ultralytics' colour jitter: a random
//! `crop × crop` window, horizontal flip with probability `fliplr`, and HSV gains drawn
//! uniformly in `1 ± hsv[k]` (hue rotated, saturation and value scaled, like
//! ultralytics' `augment_hsv`). Everything is drawn from the caller's RNG, so a run is
//! reproducible given its seed. Instances that leave the crop are dropped.

use image::RgbImage;
use rand::Rng;

use super::dataset::{Instance, Sample};
use crate::annotations::mask::Mask;

/// What to apply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AugmentConfig {
    pub crop: u32,
    pub fliplr: f64,
    pub hsv: [f64; 3],
}

/// Crop, flip and colour-jitter one sample.
pub fn augment<R: Rng>(s: &Sample, cfg: &AugmentConfig, rng: &mut R) -> Sample {
    let (w, h) = s.image.dimensions();
    let cw = cfg.crop.min(w);
    let ch = cfg.crop.min(h);
    let x0 = rng.random_range(0..=w - cw);
    let y0 = rng.random_range(0..=h - ch);
    let flip = rng.random::<f64>() < cfg.fliplr;
    let gains = [
        1.0 + cfg.hsv[0] * rng.random_range(-1.0..=1.0),
        1.0 + cfg.hsv[1] * rng.random_range(-1.0..=1.0),
        1.0 + cfg.hsv[2] * rng.random_range(-1.0..=1.0),
    ];
    let src_x = |x: u32| if flip { x0 + cw - 1 - x } else { x0 + x };
    let mut image = RgbImage::new(cw, ch);
    for y in 0..ch {
        for x in 0..cw {
            image.put_pixel(x, y, *s.image.get_pixel(src_x(x), y0 + y));
        }
    }
    if cfg.hsv.iter().any(|&g| g > 0.0) {
        hsv_jitter(&mut image, gains);
    }
    let instances = s
        .instances
        .iter()
        .filter_map(|inst| {
            let mut m = Mask::new(ch, cw);
            for y in 0..ch {
                let row = ((y0 + y) * inst.mask.width) as usize;
                for x in 0..cw {
                    m.data[(y * cw + x) as usize] = inst.mask.data[row + src_x(x) as usize];
                }
            }
            (m.area() > 0).then_some(Instance {
                class: inst.class,
                mask: m,
            })
        })
        .collect();
    Sample { image, instances }
}

/// Multiplies hue (as a rotation on the 0..1 circle, like OpenCV's 0..180 LUT), saturation
/// and value by `gains`, clipping saturation and value to [0, 1].
pub fn hsv_jitter(img: &mut RgbImage, gains: [f64; 3]) {
    let [gh, gs, gv] = gains.map(|g| g as f32);
    for p in img.pixels_mut() {
        let [r, g, b] = p.0.map(|c| c as f32 / 255.0);
        let (h, s, v) = rgb_to_hsv(r, g, b);
        let h = (h * gh).rem_euclid(1.0);
        let s = (s * gs).clamp(0.0, 1.0);
        let v = (v * gv).clamp(0.0, 1.0);
        let (r, g, b) = hsv_to_rgb(h, s, v);
        p.0 = [r, g, b].map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8);
    }
}

/// RGB in [0, 1] → (hue in [0, 1), saturation, value).
pub fn rgb_to_hsv(r: f32, g: f32, b: f32) -> (f32, f32, f32) {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let h = if d <= 0.0 {
        0.0
    } else if max == r {
        ((g - b) / d).rem_euclid(6.0) / 6.0
    } else if max == g {
        ((b - r) / d + 2.0) / 6.0
    } else {
        ((r - g) / d + 4.0) / 6.0
    };
    let s = if max <= 0.0 { 0.0 } else { d / max };
    (h, s, max)
}

pub fn hsv_to_rgb(h: f32, s: f32, v: f32) -> (f32, f32, f32) {
    let h6 = (h * 6.0).rem_euclid(6.0);
    let i = h6.floor();
    let f = h6 - i;
    let p = v * (1.0 - s);
    let q = v * (1.0 - s * f);
    let t = v * (1.0 - s * (1.0 - f));
    match i as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn sample() -> Sample {
        let mut image = RgbImage::new(8, 8);
        for (x, y, p) in image.enumerate_pixels_mut() {
            p.0 = [(x * 30) as u8, (y * 30) as u8, 100];
        }
        let mut m = Mask::new(8, 8);
        m.set(0, 0, true);
        m.set(1, 0, true);
        let mut far = Mask::new(8, 8);
        far.set(7, 7, true);
        Sample {
            image,
            instances: vec![
                Instance { class: 0, mask: m },
                Instance {
                    class: 1,
                    mask: far,
                },
            ],
        }
    }

    #[test]
    fn hsv_round_trip() {
        for rgb in [
            [0.2f32, 0.5, 0.9],
            [1.0, 0.0, 0.0],
            [0.3, 0.3, 0.3],
            [0.9, 0.8, 0.1],
        ] {
            let (h, s, v) = rgb_to_hsv(rgb[0], rgb[1], rgb[2]);
            let (r, g, b) = hsv_to_rgb(h, s, v);
            assert!(
                (r - rgb[0]).abs() < 1e-5 && (g - rgb[1]).abs() < 1e-5 && (b - rgb[2]).abs() < 1e-5
            );
        }
    }

    #[test]
    fn flip_only_mirrors_image_and_masks() {
        let s = sample();
        let cfg = AugmentConfig {
            crop: 8,
            fliplr: 1.0,
            hsv: [0.0; 3],
        };
        let a = augment(&s, &cfg, &mut ChaCha8Rng::seed_from_u64(1));
        assert_eq!(a.image.get_pixel(7, 3), s.image.get_pixel(0, 3));
        assert!(a.instances[0].mask.get(7, 0) && a.instances[0].mask.get(6, 0));
        assert_eq!(a.instances[0].mask.area(), 2);
    }

    #[test]
    fn crop_drops_instances_outside_and_is_seeded() {
        let s = sample();
        let cfg = AugmentConfig {
            crop: 4,
            fliplr: 0.0,
            hsv: [0.015, 0.7, 0.4],
        };
        let mut kept = [0usize; 3];
        for seed in 0..40 {
            let a = augment(&s, &cfg, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!(a.image.dimensions(), (4, 4));
            kept[a.instances.len()] += 1;
            let b = augment(&s, &cfg, &mut ChaCha8Rng::seed_from_u64(seed));
            assert_eq!(a.image, b.image);
            for i in &a.instances {
                assert_eq!((i.mask.width, i.mask.height), (4, 4));
            }
        }
        // The two instances sit in opposite corners of 8×8: a 4×4 crop never holds both.
        assert_eq!(kept[2], 0);
        assert!(kept[1] > 0 && kept[0] > 0, "{kept:?}");
    }
}
