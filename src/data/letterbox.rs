//! Letterboxing: an image of any shape into the network's square input without
//! distorting it (scale the long side to the input, pad the short side with grey 114,
//! centred, as ultralytics does), and the inverse that maps boxes predicted on the square
//! input back to the original image (masks are decoded at the original size from the
//! model's soft output: `model::instance_mask`).
//!
//! Why not stretch: users' line photos are 4:3 or 16:9; stretching them to a square makes
//! carcasses look thinner or fatter than any synthetic render, a domain gap the synthetic
//! data cannot close. For square images (every render) letterboxing *is* the plain resize,
//! pixel for pixel, so rendered data is unaffected.

use image::{imageops::FilterType, Rgb, RgbImage};

use crate::annotations::mask::{resize_mask, Mask};

/// The padding grey of ultralytics' `LetterBox`.
pub const PAD_GREY: u8 = 114;

/// Where an `orig`-sized image sits inside the `size × size` input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Letterbox {
    /// Original image (width, height).
    pub orig: (u32, u32),
    /// Side of the square network input.
    pub size: u32,
    /// Size of the resized image inside the input (width, height).
    pub inner: (u32, u32),
    /// Offset of the resized image (left, top).
    pub pad: (u32, u32),
}

impl Letterbox {
    pub fn new(orig: (u32, u32), size: u32) -> Letterbox {
        let (w, h) = (orig.0.max(1), orig.1.max(1));
        let scale = size as f64 / w.max(h) as f64;
        // Python's round (ties to even), as ultralytics' LetterBox and scale_boxes.
        let iw = ((w as f64 * scale).round_ties_even() as u32).clamp(1, size);
        let ih = ((h as f64 * scale).round_ties_even() as u32).clamp(1, size);
        Letterbox {
            orig: (w, h),
            size,
            inner: (iw, ih),
            pad: ((size - iw) / 2, (size - ih) / 2),
        }
    }

    /// The image at the network input.
    pub fn image(&self, img: &RgbImage) -> RgbImage {
        let (iw, ih) = self.inner;
        let resized = if img.dimensions() == (iw, ih) {
            img.clone()
        } else {
            image::imageops::resize(img, iw, ih, FilterType::Triangle)
        };
        if (iw, ih) == (self.size, self.size) {
            return resized;
        }
        let mut out = RgbImage::from_pixel(self.size, self.size, Rgb([PAD_GREY; 3]));
        image::imageops::replace(&mut out, &resized, self.pad.0 as i64, self.pad.1 as i64);
        out
    }

    /// A mask of the original image at the network input (nearest neighbour).
    pub fn mask(&self, m: &Mask) -> Mask {
        let (iw, ih) = self.inner;
        let inner = resize_mask(m, iw, ih);
        if (iw, ih) == (self.size, self.size) {
            return inner;
        }
        let mut out = Mask::new(self.size, self.size);
        for y in 0..ih {
            let src = (y * iw) as usize;
            let dst = ((y + self.pad.1) * self.size + self.pad.0) as usize;
            out.data[dst..dst + iw as usize].copy_from_slice(&inner.data[src..src + iw as usize]);
        }
        out
    }

    /// A box `[x1, y1, x2, y2]` at the network input → `[x, y, w, h]` in the original
    /// image, clipped to it.
    pub fn unbox(&self, b: [f64; 4]) -> [f64; 4] {
        let ([x1, y1, x2, y2], sx, sy) = self.clip_inner(b);
        [x1 * sx, y1 * sy, (x2 - x1) * sx, (y2 - y1) * sy]
    }

    /// [`Self::unbox`] as `[x1, y1, x2, y2]` (ultralytics' `scale_boxes`: the padding
    /// subtracted, scaled by the gain of each axis, clipped to the image).
    pub fn unbox_xyxy(&self, b: [f64; 4]) -> [f64; 4] {
        let ([x1, y1, x2, y2], sx, sy) = self.clip_inner(b);
        [x1 * sx, y1 * sy, x2 * sx, y2 * sy]
    }

    /// An input box relative to the resized image and clipped to it, and the scales of
    /// the two axes back to the original.
    fn clip_inner(&self, b: [f64; 4]) -> ([f64; 4], f64, f64) {
        let (w, h) = (self.orig.0 as f64, self.orig.1 as f64);
        let sx = w / self.inner.0 as f64;
        let sy = h / self.inner.1 as f64;
        let (px, py) = (self.pad.0 as f64, self.pad.1 as f64);
        let (iw, ih) = (self.inner.0 as f64, self.inner.1 as f64);
        let x1 = (b[0] - px).clamp(0.0, iw);
        let y1 = (b[1] - py).clamp(0.0, ih);
        let x2 = (b[2] - px).clamp(0.0, iw);
        let y2 = (b[3] - py).clamp(0.0, ih);
        ([x1, y1, x2, y2], sx, sy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_images_are_a_plain_resize() {
        let lb = Letterbox::new((100, 100), 64);
        assert_eq!(lb.inner, (64, 64));
        assert_eq!(lb.pad, (0, 0));
        let img = RgbImage::from_fn(100, 100, |x, y| Rgb([x as u8, y as u8, (x ^ y) as u8]));
        let plain = image::imageops::resize(&img, 64, 64, FilterType::Triangle);
        assert_eq!(lb.image(&img), plain);
        let mut m = Mask::new(100, 100);
        m.data[55 * 100 + 30] = 1;
        assert_eq!(lb.mask(&m), resize_mask(&m, 64, 64));
        let b = lb.unbox([16.0, 8.0, 48.0, 64.0]);
        let s = 100.0 / 64.0;
        assert_eq!(b, [16.0 * s, 8.0 * s, 32.0 * s, 56.0 * s]);
    }

    #[test]
    fn wide_images_are_padded_top_and_bottom_and_map_back() {
        // 200 × 100 into 64: scale 0.32, inner 64 × 32, 16 px of grey above and below.
        let lb = Letterbox::new((200, 100), 64);
        assert_eq!(lb.inner, (64, 32));
        assert_eq!(lb.pad, (0, 16));
        let img = RgbImage::from_pixel(200, 100, Rgb([10, 200, 30]));
        let out = lb.image(&img);
        assert_eq!(out.dimensions(), (64, 64));
        assert_eq!(out.get_pixel(5, 3).0, [PAD_GREY; 3]);
        assert_eq!(out.get_pixel(5, 60).0, [PAD_GREY; 3]);
        assert_eq!(out.get_pixel(5, 30).0, [10, 200, 30]);
        // A rectangle mask keeps its aspect: 100 × 50 px at (50, 25) → 32 × 16 at (16, 24).
        let mut m = Mask::new(100, 200);
        for y in 25..75 {
            for x in 50..150 {
                m.data[y * 200 + x] = 1;
            }
        }
        let small = lb.mask(&m);
        assert_eq!((small.width, small.height), (64, 64));
        assert_eq!(small.area(), 32 * 16);
        assert!(small.get(16, 24) && small.get(47, 39) && !small.get(15, 24) && !small.get(16, 40));
        // The box around it maps back to the original box.
        let b = lb.unbox([16.0, 16.0 + 8.0, 48.0, 16.0 + 24.0]);
        for (got, want) in b.iter().zip([50.0, 25.0, 100.0, 50.0]) {
            assert!((got - want).abs() < 1e-9, "{b:?}");
        }
        // Boxes reaching into the padding are clipped to the image.
        assert_eq!(lb.unbox([-5.0, 0.0, 70.0, 64.0]), [0.0, 0.0, 200.0, 100.0]);
    }

    #[test]
    fn sizes_round_half_to_even_as_ultralytics() {
        // 333 × 0.5 = 166.5: Python's round (ultralytics' LetterBox) gives 166, not 167.
        let lb = Letterbox::new((333, 512), 256);
        assert_eq!((lb.inner, lb.pad), ((166, 256), (45, 0)));
        assert_eq!(Letterbox::new((335, 512), 256).inner, (168, 256));
    }

    #[test]
    fn tall_and_tiny_images() {
        let lb = Letterbox::new((30, 90), 64);
        assert_eq!(lb.inner, (21, 64));
        assert_eq!(lb.pad, (21, 0));
        let lb = Letterbox::new((1, 1000), 64);
        assert_eq!(lb.inner, (1, 64));
        let m = Mask::new(1000, 1);
        assert_eq!(lb.mask(&m).data.len(), 64 * 64);
        assert_eq!(lb.unbox([0.0, 0.0, 64.0, 64.0]), [0.0, 0.0, 1.0, 1000.0]);
    }
}
