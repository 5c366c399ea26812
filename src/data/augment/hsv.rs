//! ultralytics' HSV colour jitter (`augment_hsv`): gains drawn uniformly in `1 ± hsv[k]`
//! from the main stream for every item (also when all three are 0, so the stream stays
//! where the paper's pipeline left it); hue rotated, saturation and value scaled.

use std::borrow::Cow;

use image::RgbImage;
use rand::Rng;

use super::step::{Augment, AugmentState};
use crate::data::dataset::Sample;

/// Colour jitter with gain ranges `gains` (hue, saturation, value).
pub struct Hsv {
    pub gains: [f64; 3],
}

impl Augment for Hsv {
    fn name(&self) -> &'static str {
        "hsv"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        let g = self.gains;
        let drawn = [
            1.0 + g[0] * st.rng.random_range(-1.0..=1.0),
            1.0 + g[1] * st.rng.random_range(-1.0..=1.0),
            1.0 + g[2] * st.rng.random_range(-1.0..=1.0),
        ];
        if g.iter().any(|&x| x > 0.0) {
            let mut s = s.into_owned();
            hsv_jitter(&mut s.image, drawn);
            Cow::Owned(s)
        } else {
            s
        }
    }
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
