//! The 2×2 mosaic of ultralytics' `Mosaic` (YOLOv4, Bochkovskiy et al. 2020): four
//! samples placed around a random centre of a canvas twice their size, each cornered on
//! that centre, the rest grey 114. The trainer's affine warp then crops the canvas back
//! to the training size (ultralytics' `RandomPerspective` with `border = -size / 2`).
//!
//! Why: a crop of the canvas shows piles cut at arbitrary lines and more instances per
//! image, which is what a camera over a conveyor sees at the edge of its view.

use std::borrow::Cow;

use image::{Rgb, RgbImage};
use rand::Rng;

use super::augment::step::{Augment, AugmentState, MIN_INSTANCE_PX};
use super::dataset::{Instance, Sample};
use super::letterbox::PAD_GREY;
use crate::annotations::mask::Mask;

/// Places up to four `samples` (top-left, top-right, bottom-left, bottom-right) around
/// `centre` of a `2 × size` canvas; quadrants without a sample stay grey. Instances cut
/// below `min_area` pixels are dropped.
pub fn mosaic(samples: &[&Sample], size: (u32, u32), centre: (u32, u32), min_area: u64) -> Sample {
    let (cw, ch) = (2 * size.0, 2 * size.1);
    let (xc, yc) = (centre.0.min(cw) as i64, centre.1.min(ch) as i64);
    let mut image = RgbImage::from_pixel(cw, ch, Rgb([PAD_GREY; 3]));
    let mut instances = Vec::new();
    for (q, s) in samples.iter().take(4).enumerate() {
        let (w, h) = (s.image.width() as i64, s.image.height() as i64);
        // Top-left corner of the sample on the canvas: cornered on the centre.
        let (x0, y0) = match q {
            0 => (xc - w, yc - h),
            1 => (xc, yc - h),
            2 => (xc - w, yc),
            _ => (xc, yc),
        };
        // The visible window, in canvas coordinates.
        let (ax0, ay0) = (x0.max(0), y0.max(0));
        let (ax1, ay1) = ((x0 + w).min(cw as i64), (y0 + h).min(ch as i64));
        if ax0 >= ax1 || ay0 >= ay1 {
            continue;
        }
        for y in ay0..ay1 {
            for x in ax0..ax1 {
                let p = *s.image.get_pixel((x - x0) as u32, (y - y0) as u32);
                image.put_pixel(x as u32, y as u32, p);
            }
        }
        for inst in &s.instances {
            let mut m = Mask::new(ch, cw);
            for y in ay0..ay1 {
                let src = ((y - y0) * w - x0) as usize;
                let dst = (y * cw as i64) as usize;
                for x in ax0 as usize..ax1 as usize {
                    m.data[dst + x] = u8::from(inst.mask.data[src + x] != 0);
                }
            }
            if m.area() >= min_area.max(1) {
                instances.push(Instance {
                    class: inst.class,
                    mask: m,
                });
            }
        }
    }
    Sample { image, instances }
}

/// The pipeline's mosaic: with the item's three mosaic partners when it has them (drawn
/// with probability `mosaic` before loading), around a centre drawn from the second
/// stream; leaves the canvas size for the affine warp, which maps it back.
pub struct Mosaic;

impl Augment for Mosaic {
    fn name(&self) -> &'static str {
        "mosaic"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        let partners = st.partners;
        let Some(rest) = &partners.mosaic else {
            return s;
        };
        let (w, h) = s.image.dimensions();
        let centre = (
            st.extra.random_range(w / 2..=w + w / 2),
            st.extra.random_range(h / 2..=h + h / 2),
        );
        let mut tiles = vec![&*s];
        tiles.extend(rest.iter().copied());
        let tiled = mosaic(&tiles, (w, h), centre, MIN_INSTANCE_PX);
        st.canvas = Some(((2 * w, 2 * h), (w, h)));
        Cow::Owned(tiled)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w × h` sample of one colour with one instance (a `k × k` square at the top-left).
    fn solid(w: u32, h: u32, c: u8, k: u32) -> Sample {
        let image = RgbImage::from_pixel(w, h, Rgb([c, c, c]));
        let mut m = Mask::new(h, w);
        for y in 0..k {
            for x in 0..k {
                m.set(x, y, true);
            }
        }
        Sample {
            image,
            instances: vec![Instance {
                class: c as usize,
                mask: m,
            }],
        }
    }

    #[test]
    fn quadrants_corner_on_the_centre() {
        let s: Vec<Sample> = (0..4).map(|i| solid(4, 4, 10 + i, 2)).collect();
        let refs: Vec<&Sample> = s.iter().collect();
        let m = mosaic(&refs, (4, 4), (3, 5), 1);
        assert_eq!(m.image.dimensions(), (8, 8));
        // Top-left sample ends at (3, 5): its visible part is x 0..3, y 1..5.
        assert_eq!(m.image.get_pixel(2, 4).0, [10; 3]);
        assert_eq!(m.image.get_pixel(2, 0).0, [PAD_GREY; 3]);
        assert_eq!(m.image.get_pixel(3, 4).0, [11; 3]);
        assert_eq!(m.image.get_pixel(2, 5).0, [12; 3]);
        assert_eq!(m.image.get_pixel(3, 5).0, [13; 3]);
        assert_eq!(m.image.get_pixel(7, 7).0, [PAD_GREY; 3]);
        // Masks go with their pixels: every mask pixel has its sample's colour.
        assert_eq!(m.instances.len(), 4);
        for inst in &m.instances {
            for y in 0..8 {
                for x in 0..8 {
                    if inst.mask.get(x, y) {
                        assert_eq!(m.image.get_pixel(x, y).0, [inst.class as u8; 3]);
                    }
                }
            }
        }
        // The top-left sample's 2×2 instance starts one column left of the canvas.
        assert_eq!((m.instances[0].class, m.instances[0].mask.area()), (10, 2));
        assert_eq!((m.instances[1].class, m.instances[1].mask.area()), (11, 4));
        assert!(m.instances[1].mask.get(3, 1) && m.instances[1].mask.get(4, 2));
    }

    #[test]
    fn fewer_than_four_samples_leave_grey_quadrants() {
        let a = solid(4, 4, 50, 4);
        let m = mosaic(&[&a], (4, 4), (4, 4), 1);
        assert_eq!(m.instances.len(), 1);
        assert_eq!(m.instances[0].mask.area(), 16);
        assert_eq!(m.image.get_pixel(5, 5).0, [PAD_GREY; 3]);
        let e = mosaic(&[], (4, 4), (4, 4), 1);
        assert!(e.instances.is_empty() && e.image.pixels().all(|p| p.0 == [PAD_GREY; 3]));
    }
}
