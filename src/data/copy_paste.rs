//! Copy-Paste (Ghiasi et al. 2021, "Simple Copy-Paste is a Strong Data Augmentation
//! Method for Instance Segmentation"; ultralytics' `CopyPaste`): instances of another
//! sample pasted, pixels and masks, on top of this one. Pasted instances occlude the
//! ones beneath: their visible masks shrink, and those left under `min_area` pixels are
//! dropped.
//!
//! Why: a pile is instances occluding instances; pasting a carcass from another image
//! makes new occlusion boundaries whose masks are exact by construction.

use std::borrow::Cow;

use image::RgbImage;
use rand::Rng;

use super::augment::step::{Augment, AugmentState, MIN_INSTANCE_PX};
use super::dataset::{Instance, Sample};
use crate::annotations::mask::Mask;

/// Pastes a random non-empty subset of `src`'s instances (each kept with probability
/// 1/2, at least one; the source mirrored left-right with probability 1/2, as in
/// ultralytics' flip mode) onto `dst` at the same place. Samples of different sizes
/// paste over their common top-left window. A `src` without instances returns `dst`.
pub fn copy_paste<R: Rng>(dst: &Sample, src: &Sample, rng: &mut R, min_area: u64) -> Sample {
    if src.instances.is_empty() {
        return dst.clone();
    }
    let mut chosen: Vec<usize> = (0..src.instances.len())
        .filter(|_| rng.random::<bool>())
        .collect();
    if chosen.is_empty() {
        chosen.push(rng.random_range(0..src.instances.len()));
    }
    let flip = rng.random::<bool>();
    let (w, h) = dst.image.dimensions();
    let (sw, sh) = src.image.dimensions();
    let (ww, wh) = (w.min(sw), h.min(sh));
    // Source x of destination x inside the common window.
    let sx = |x: u32| if flip { sw - 1 - x } else { x };
    let mut image: RgbImage = dst.image.clone();
    let mut union = vec![false; (w * h) as usize];
    let mut pasted = Vec::new();
    for &i in &chosen {
        let inst = &src.instances[i];
        let mut m = Mask::new(h, w);
        for y in 0..wh {
            for x in 0..ww {
                if inst.mask.get(sx(x), y) {
                    m.data[(y * w + x) as usize] = 1;
                }
            }
        }
        // Too small to be a target: not pasted at all, so no unlabelled pixels appear.
        if m.area() < min_area.max(1) {
            continue;
        }
        for y in 0..wh {
            for x in 0..ww {
                let k = (y * w + x) as usize;
                if m.data[k] != 0 {
                    union[k] = true;
                    image.put_pixel(x, y, *src.image.get_pixel(sx(x), y));
                }
            }
        }
        pasted.push(Instance {
            class: inst.class,
            mask: m,
        });
    }
    let mut instances: Vec<Instance> = dst
        .instances
        .iter()
        .filter_map(|inst| {
            let mut m = inst.mask.clone();
            for (v, &covered) in m.data.iter_mut().zip(&union) {
                if covered {
                    *v = 0;
                }
            }
            (m.area() >= min_area.max(1)).then_some(Instance {
                class: inst.class,
                mask: m,
            })
        })
        .collect();
    instances.extend(pasted);
    Sample { image, instances }
}

/// The pipeline's copy-paste: pastes from the item's copy-paste partner when it has one
/// (drawn with probability `copy_paste` before loading), from the second stream.
pub struct CopyPaste;

impl Augment for CopyPaste {
    fn name(&self) -> &'static str {
        "copy_paste"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        match st.partners.copy_paste {
            Some(src) => Cow::Owned(copy_paste(&s, src, &mut st.extra, MIN_INSTANCE_PX)),
            None => s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// An 8×8 sample of background `bg` with rectangles `(x0, y0, x1, y1, colour)`,
    /// each an instance painted in its own colour (class = colour).
    fn rects(bg: u8, r: &[(u32, u32, u32, u32, u8)]) -> Sample {
        let mut image = RgbImage::from_pixel(8, 8, Rgb([bg; 3]));
        let mut instances = Vec::new();
        for &(x0, y0, x1, y1, c) in r {
            let mut m = Mask::new(8, 8);
            for y in y0..y1 {
                for x in x0..x1 {
                    m.set(x, y, true);
                    image.put_pixel(x, y, Rgb([c; 3]));
                }
            }
            instances.push(Instance {
                class: c as usize,
                mask: m,
            });
        }
        Sample { image, instances }
    }

    #[test]
    fn pasted_instances_occlude_and_stay_aligned() {
        let dst = rects(0, &[(0, 0, 8, 4, 10), (0, 6, 2, 8, 11)]);
        let src = rects(1, &[(2, 2, 6, 6, 20), (7, 7, 8, 8, 21)]);
        for seed in 0..32 {
            let out = copy_paste(&dst, &src, &mut ChaCha8Rng::seed_from_u64(seed), 2);
            // Every instance's mask is exactly the pixels of its colour.
            for inst in &out.instances {
                for y in 0..8 {
                    for x in 0..8 {
                        let c = out.image.get_pixel(x, y).0[0] as usize;
                        assert_eq!(
                            inst.mask.get(x, y),
                            c == inst.class,
                            "seed {seed} ({x},{y})"
                        );
                    }
                }
            }
            let top = out.instances.iter().find(|i| i.class == 10).unwrap();
            if out.instances.iter().any(|i| i.class == 20) {
                // The 4×4 square covers rows 2..4 of the top band: 32 - 8 pixels left.
                assert_eq!(top.mask.area(), 24);
            } else {
                assert_eq!(top.mask.area(), 32);
            }
            // The 1-px instance is below min_area and never pasted.
            assert!(out.instances.iter().all(|i| i.class != 21));
            let b = copy_paste(&dst, &src, &mut ChaCha8Rng::seed_from_u64(seed), 2);
            assert_eq!((b.image, b.instances), (out.image, out.instances));
        }
        // The square is symmetric; an asymmetric source shows both orientations drawn.
        let asym = rects(1, &[(0, 0, 3, 3, 30)]);
        let mut sides = [0usize; 2];
        for seed in 0..32 {
            let out = copy_paste(&dst, &asym, &mut ChaCha8Rng::seed_from_u64(seed), 1);
            let p = out.instances.last().unwrap();
            assert_eq!(p.class, 30);
            sides[p.mask.get(7, 0) as usize] += 1;
            assert_eq!(
                out.image
                    .get_pixel(if p.mask.get(7, 0) { 7 } else { 0 }, 0)
                    .0,
                [30; 3]
            );
        }
        assert!(sides[0] > 0 && sides[1] > 0, "{sides:?}");
    }

    #[test]
    fn nothing_to_paste_or_everything_covered() {
        let dst = rects(0, &[(0, 0, 4, 4, 10)]);
        let empty = rects(1, &[]);
        let out = copy_paste(&dst, &empty, &mut ChaCha8Rng::seed_from_u64(0), 1);
        assert_eq!(
            (out.image, out.instances),
            (dst.image.clone(), dst.instances.clone())
        );
        // A source instance covering the whole image hides every destination instance.
        let all = rects(1, &[(0, 0, 8, 8, 40)]);
        let out = copy_paste(&dst, &all, &mut ChaCha8Rng::seed_from_u64(0), 1);
        assert_eq!(out.instances.len(), 1);
        assert_eq!(out.instances[0].class, 40);
        assert_eq!(out.instances[0].mask.area(), 64);
        // An empty destination gets the pasted instance.
        let none = rects(0, &[]);
        let out = copy_paste(&none, &dst, &mut ChaCha8Rng::seed_from_u64(0), 1);
        assert_eq!(out.instances.len(), 1);
    }
}
