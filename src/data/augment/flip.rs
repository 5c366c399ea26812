//! The two mirror augmentations: [`FlipLr`] (probability `fliplr`, drawn from the main
//! stream for every item, as the paper's pipeline always did) and [`FlipUd`] (probability
//! `flipud`, from the second stream, drawn only when it is on).

use std::borrow::Cow;

use rand::Rng;

use super::step::{Augment, AugmentState};
use crate::data::dataset::Sample;

/// Horizontal flip with probability `p`.
pub struct FlipLr {
    pub p: f64,
}

impl Augment for FlipLr {
    fn name(&self) -> &'static str {
        "fliplr"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        if st.rng.random::<f64>() < self.p {
            let mut s = s.into_owned();
            flip_horizontal(&mut s);
            Cow::Owned(s)
        } else {
            s
        }
    }
}

/// Vertical flip with probability `p` (nothing drawn at 0).
pub struct FlipUd {
    pub p: f64,
}

impl Augment for FlipUd {
    fn name(&self) -> &'static str {
        "flipud"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        if self.p > 0.0 && st.extra.random::<f64>() < self.p {
            let mut s = s.into_owned();
            flip_vertical(&mut s);
            Cow::Owned(s)
        } else {
            s
        }
    }
}

/// Mirrors a sample left to right, image and masks.
pub fn flip_horizontal(s: &mut Sample) {
    image::imageops::flip_horizontal_in_place(&mut s.image);
    for inst in &mut s.instances {
        let w = inst.mask.width as usize;
        if w > 0 {
            for row in inst.mask.data.chunks_exact_mut(w) {
                row.reverse();
            }
        }
    }
}

/// Mirrors a sample top to bottom, image and masks.
pub fn flip_vertical(s: &mut Sample) {
    image::imageops::flip_vertical_in_place(&mut s.image);
    for inst in &mut s.instances {
        let w = inst.mask.width as usize;
        let h = inst.mask.height as usize;
        for y in 0..h / 2 {
            let (top, bottom) = inst.mask.data.split_at_mut((h - 1 - y) * w);
            top[y * w..(y + 1) * w].swap_with_slice(&mut bottom[..w]);
        }
    }
}
