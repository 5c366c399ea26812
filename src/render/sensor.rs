//! The camera's sensor and image pipeline: exposure (auto-exposure plus a random offset),
//! white balance error, vignetting, optical blur, shot + read noise, a soft tone curve,
//! sRGB encoding, and the file encoders (JPEG at a chosen quality, PNG with fast
//! compression: default PNG compression costs ~160 ms per 640² image, `notes/crates.md`).

use glam::Vec3;
use image::RgbImage;

use rayon::prelude::*;

use crate::util::hash::hash;

#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

const LUT_N: usize = 8192;

/// Linear [0, 1] → 8-bit sRGB, tabulated (a powf per channel per pixel is slow).
fn srgb_lut() -> &'static [u8; LUT_N] {
    static LUT: std::sync::OnceLock<[u8; LUT_N]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| {
        let mut t = [0u8; LUT_N];
        for (i, v) in t.iter_mut().enumerate() {
            *v = (linear_to_srgb(i as f32 / (LUT_N - 1) as f32) * 255.0 + 0.5) as u8;
        }
        t
    })
}

/// Sensor settings for one image.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// Exposure offset from auto-exposure, in stops.
    pub exposure_ev: f32,
    /// Auto-exposure target for the mean luminance (linear).
    pub target: f32,
    /// Per-channel white-balance gains (camera's error, not the light's colour).
    pub wb: Vec3,
    pub vignette: f32,
    /// Gaussian blur sigma in pixels (lens softness / slight defocus).
    pub blur: f32,
    /// Shot-noise and read-noise standard deviations (linear, at signal 1).
    pub shot: f32,
    pub read: f32,
    /// Share of the noise common to all three channels (0 = independent per channel,
    /// pure colour noise, the base look; 1 = grey noise only).
    pub mono_noise: f32,
    /// Motion blur: the image-space displacement (pixels) during the exposure, a box
    /// filter along it; zero = none. Masks stay the sharp object footprint.
    pub motion: [f32; 2],
    /// Highlight protection of the auto-exposure: the gain is capped so the 90th
    /// percentile of luminance lands at or below 0.8 (before the exposure offset), by at
    /// most 1.3 stops. Off in
    /// the base look; the `scene` and `lighting` groups turn it on, since their dark
    /// surfaces and wide exposure range would otherwise blow the carcasses out to white.
    pub highlight_guard: bool,
    pub seed: u64,
}

fn blur_rows(src: &[Vec3], w: usize, _h: usize, k: &[f32], out: &mut [Vec3]) {
    let r = (k.len() / 2) as isize;
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut s = Vec3::ZERO;
            for (i, &kv) in k.iter().enumerate() {
                let xx = (x as isize + i as isize - r).clamp(0, w as isize - 1) as usize;
                s += src[y * w + xx] * kv;
            }
            *o = s;
        }
    });
}

fn blur_cols(src: &[Vec3], w: usize, h: usize, k: &[f32], out: &mut [Vec3]) {
    let r = (k.len() / 2) as isize;
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut s = Vec3::ZERO;
            for (i, &kv) in k.iter().enumerate() {
                let yy = (y as isize + i as isize - r).clamp(0, h as isize - 1) as usize;
                s += src[yy * w + x] * kv;
            }
            *o = s;
        }
    });
}

/// Normalised Gaussian kernel for `sigma` pixels (radius 2 sigma, at least 1).
pub fn gaussian_kernel(sigma: f32) -> Vec<f32> {
    let r = (2.0 * sigma).ceil().max(1.0) as i32;
    let k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

impl Sensor {
    /// Develops a linear radiance buffer into an 8-bit sRGB image.
    pub fn develop(&self, linear: &[Vec3], w: u32, h: u32) -> RgbImage {
        let (wu, hu) = (w as usize, h as usize);
        let lum = |c: Vec3| c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
        // Auto-exposure on the median luminance (of every 7th pixel): a mirrored lamp
        // on the steel must not darken the carcasses, as a log-average would.
        let mut sample: Vec<f32> = linear.iter().step_by(7).map(|c| lum(*c)).collect();
        let mid = sample.len() / 2;
        let median = if sample.is_empty() {
            1.0
        } else {
            *sample.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
        };
        let mut gain = self.target / median.max(1e-6);
        if self.highlight_guard && !sample.is_empty() {
            // The 90th percentile, not the maximum: a lamp mirrored in the steel may clip
            // (as in a real camera) without darkening the whole image; and at most 1.3
            // stops below the median exposure.
            let k = (sample.len() * 9 / 10).min(sample.len() - 1);
            let p90 = *sample.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
            gain = gain.min(0.8 / p90.max(1e-6)).max(gain * 0.4);
        }
        let gain = gain * 2f32.powf(self.exposure_ev);
        let mut buf: Vec<Vec3> = linear.iter().map(|c| *c * gain * self.wb).collect();
        if self.motion[0].hypot(self.motion[1]) > 0.5 {
            buf = motion_blur(&buf, wu, hu, self.motion);
        }
        if self.blur > 0.05 {
            let k = gaussian_kernel(self.blur);
            let mut tmp = vec![Vec3::ZERO; buf.len()];
            blur_rows(&buf, wu, hu, &k, &mut tmp);
            blur_cols(&tmp, wu, hu, &k, &mut buf);
        }
        let (cx, cy) = (w as f32 * 0.5, h as f32 * 0.5);
        let rmax2 = cx * cx + cy * cy;
        let lut = srgb_lut();
        let mut img = RgbImage::new(w, h);
        let raw: &mut [u8] = &mut img;
        raw.par_chunks_mut(3).enumerate().for_each(|(i, px)| {
            let (x, y) = ((i % wu) as f32 + 0.5, (i / wu) as f32 + 0.5);
            let r2 = ((x - cx).powi(2) + (y - cy).powi(2)) / rmax2;
            let v = 1.0 - self.vignette * r2;
            let mut c = buf[i] * v;
            // Noise: near-Gaussian per channel as the sum of four 16-bit uniforms from one
            // hash (Irwin-Hall, variance 1/3, rescaled): no ln/cos per pixel.
            let gauss = |ch: u64| {
                let hsh = hash(self.seed, i as u64, ch, 0x5E45);
                let sum: f32 = (0..4)
                    .map(|k| ((hsh >> (16 * k)) & 0xFFFF) as f32 / 65535.0)
                    .sum();
                (sum - 2.0) * 3f32.sqrt()
            };
            let shared = if self.mono_noise > 0.0 { gauss(3) } else { 0.0 };
            for ch in 0..3 {
                let mut g = gauss(ch);
                if self.mono_noise > 0.0 {
                    g = g * (1.0 - self.mono_noise).sqrt() + shared * self.mono_noise.sqrt();
                }
                let s = (self.shot * self.shot * c[ch as usize].max(0.0) + self.read * self.read)
                    .sqrt();
                c[ch as usize] += g * s;
            }
            // Soft shoulder so highlights roll off instead of clipping hard.
            let t = c.max(Vec3::ZERO);
            let t = t / (Vec3::ONE + t * 0.18) * 1.18;
            let q = |x: f32| lut[((x.min(1.0) * (LUT_N - 1) as f32) + 0.5) as usize];
            px.copy_from_slice(&[q(t.x), q(t.y), q(t.z)]);
        });
        img
    }
}

/// Box filter along the displacement `m` (pixels), taps one pixel apart, bilinear.
fn motion_blur(src: &[Vec3], w: usize, h: usize, m: [f32; 2]) -> Vec<Vec3> {
    let len = m[0].hypot(m[1]);
    let taps = len.ceil() as usize + 1;
    let mut out = vec![Vec3::ZERO; src.len()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut s = Vec3::ZERO;
            for t in 0..taps {
                let f = t as f32 / (taps - 1) as f32 - 0.5;
                let (sx, sy) = (x as f32 + m[0] * f, y as f32 + m[1] * f);
                let (x0, y0) = (sx.floor(), sy.floor());
                let (tx, ty) = (sx - x0, sy - y0);
                let at = |xx: f32, yy: f32| {
                    let xi = (xx as isize).clamp(0, w as isize - 1) as usize;
                    let yi = (yy as isize).clamp(0, h as isize - 1) as usize;
                    src[yi * w + xi]
                };
                let top = at(x0, y0).lerp(at(x0 + 1.0, y0), tx);
                let bot = at(x0, y0 + 1.0).lerp(at(x0 + 1.0, y0 + 1.0), tx);
                s += top.lerp(bot, ty);
            }
            *o = s / taps as f32;
        }
    });
    out
}

/// JPEG bytes at `quality` (1-100).
pub fn encode_jpeg(img: &RgbImage, quality: u8) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100));
    img.write_with_encoder(enc)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::png::encode_png;

    #[test]
    fn srgb_roundtrip_and_develop_is_deterministic() {
        for i in 0..=10 {
            let c = i as f32 / 10.0;
            assert!((srgb_to_linear(linear_to_srgb(c)) - c).abs() < 1e-5);
        }
        let s = Sensor {
            exposure_ev: 0.0,
            target: 0.18,
            wb: Vec3::ONE,
            vignette: 0.2,
            blur: 0.7,
            shot: 0.02,
            read: 0.004,
            mono_noise: 0.0,
            motion: [0.0; 2],
            highlight_guard: false,
            seed: 9,
        };
        let buf: Vec<Vec3> = (0..64 * 64)
            .map(|i| Vec3::splat((i % 64) as f32 / 64.0))
            .collect();
        let a = s.develop(&buf, 64, 64);
        assert_eq!(a, s.develop(&buf, 64, 64));
        // Brighter input columns stay brighter after the pipeline.
        let mean_col = |x: u32| (0..64).map(|y| a.get_pixel(x, y)[1] as f32).sum::<f32>();
        assert!(mean_col(50) > mean_col(10));
        let j = encode_jpeg(&a, 90).unwrap();
        assert_eq!(&j[..2], &[0xFF, 0xD8]);
        let p = encode_png(&a).unwrap();
        assert_eq!(&p[1..4], b"PNG");
    }

    #[test]
    fn motion_blur_smears_along_its_direction_and_mono_noise_is_grey() {
        let base = Sensor {
            exposure_ev: 0.0,
            target: 0.18,
            wb: Vec3::ONE,
            vignette: 0.0,
            blur: 0.0,
            shot: 0.0,
            read: 0.0,
            mono_noise: 0.0,
            motion: [0.0; 2],
            highlight_guard: false,
            seed: 3,
        };
        // A bright dot on grey: horizontal motion spreads it along x, not along y.
        let mut buf = vec![Vec3::splat(0.1); 32 * 32];
        buf[16 * 32 + 16] = Vec3::splat(5.0);
        let s = Sensor {
            motion: [8.0, 0.0],
            ..base.clone()
        };
        let img = s.develop(&buf, 32, 32);
        let sharp = base.develop(&buf, 32, 32);
        assert!(img.get_pixel(20, 16)[0] > sharp.get_pixel(20, 16)[0] + 10);
        assert_eq!(img.get_pixel(16, 20), sharp.get_pixel(16, 20));
        // Grey noise only: the three channels move together.
        let flat = vec![Vec3::splat(0.2); 32 * 32];
        let noisy = Sensor {
            read: 0.05,
            mono_noise: 1.0,
            ..base.clone()
        };
        let img = noisy.develop(&flat, 32, 32);
        let spread = |im: &RgbImage| {
            im.pixels()
                .map(|p| (p[0] as i32 - p[2] as i32).abs())
                .max()
                .unwrap()
        };
        assert!(spread(&img) <= 1, "mono noise is coloured");
        let colour = Sensor {
            mono_noise: 0.0,
            ..noisy
        };
        assert!(spread(&colour.develop(&flat, 32, 32)) > 5);
    }
}
