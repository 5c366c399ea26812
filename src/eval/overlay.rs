//! Instances drawn onto an image: the mask tinted half-way to the instance's colour, the
//! box outlined, and a bar above the box whose length is the score (no text: the
//! numbers are in the results files). What `predict` writes as overlays, and what the
//! run folder's batch mosaics (`train_batch*.jpg`, `val_batch0_*.jpg`) are drawn with.

use image::{Rgb, RgbImage};

use crate::annotations::mask::Mask;

/// Tints the pixels of `mask` (the image's size) half-way towards `c`.
pub fn tint(img: &mut RgbImage, mask: &Mask, c: [u8; 3]) {
    let (w, h) = img.dimensions();
    for y in 0..h.min(mask.height) {
        for x in 0..w.min(mask.width) {
            if mask.get(x, y) {
                let p = img.get_pixel_mut(x, y);
                for i in 0..3 {
                    p.0[i] = ((p.0[i] as u16 + c[i] as u16) / 2) as u8;
                }
            }
        }
    }
}

/// Outlines the `[x, y, w, h]` box (clipped to the image) in `c`; with `score`, draws
/// a 3-pixel bar above it, `score` × the box width long.
pub fn draw_box(img: &mut RgbImage, [bx, by, bw, bh]: [f64; 4], c: [u8; 3], score: Option<f64>) {
    let (w, h) = img.dimensions();
    if w == 0 || h == 0 {
        return;
    }
    let (x0, y0) = (bx.max(0.0) as u32, by.max(0.0) as u32);
    let x1 = ((bx + bw) as u32).min(w - 1);
    let y1 = ((by + bh) as u32).min(h - 1);
    for x in x0..=x1 {
        img.put_pixel(x, y0.min(h - 1), Rgb(c));
        img.put_pixel(x, y1, Rgb(c));
    }
    for y in y0..=y1 {
        img.put_pixel(x0.min(w - 1), y, Rgb(c));
        img.put_pixel(x1, y, Rgb(c));
    }
    if let Some(s) = score {
        let len = ((x1.saturating_sub(x0)) as f64 * s) as u32;
        for yy in y0.saturating_sub(4)..y0.saturating_sub(1) {
            for x in x0..(x0 + len).min(w) {
                img.put_pixel(x, yy, Rgb(c));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_outline_tint_and_score_bar() {
        let mut img = RgbImage::from_pixel(20, 20, Rgb([0, 0, 0]));
        let mut m = Mask::new(20, 20);
        m.set(5, 10, true);
        tint(&mut img, &m, [200, 100, 50]);
        assert_eq!(img.get_pixel(5, 10).0, [100, 50, 25]);
        assert_eq!(img.get_pixel(6, 10).0, [0, 0, 0]);
        draw_box(&mut img, [4.0, 8.0, 10.0, 6.0], [255, 0, 0], Some(0.5));
        assert_eq!(img.get_pixel(4, 8).0, [255, 0, 0]);
        assert_eq!(img.get_pixel(14, 14).0, [255, 0, 0]);
        assert_eq!(
            img.get_pixel(8, 5).0,
            [255, 0, 0],
            "bar: half of the 10 px width"
        );
        assert_eq!(img.get_pixel(10, 5).0, [0, 0, 0]);
        // Boxes beyond the image are clipped, never a panic.
        draw_box(&mut img, [-5.0, -5.0, 100.0, 100.0], [0, 255, 0], Some(1.0));
        assert_eq!(img.get_pixel(19, 19).0, [0, 255, 0]);
    }
}
