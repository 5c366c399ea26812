//! A grid of images as one JPEG, as ultralytics' `plot_images` lays out
//! `train_batch*.jpg` and `val_batch*_{labels,pred}.jpg`: up to 16 tiles, a square-ish
//! grid in batch order, each tile scaled to fill its cell, a white border between cells.

use std::path::Path;

use anyhow::{Context, Result};
use image::{imageops, Rgb, RgbImage};

/// At most this many images per mosaic (ultralytics' `max_subplots`).
pub const MAX_TILES: usize = 16;

/// `tiles` (the first [`MAX_TILES`]) in a grid of cells `cell × cell` pixels.
pub fn mosaic(tiles: &[RgbImage], cell: u32) -> RgbImage {
    let n = tiles.len().clamp(1, MAX_TILES);
    let cols = (n as f64).sqrt().ceil() as u32;
    let rows = (n as u32).div_ceil(cols);
    let border = 2;
    let mut out = RgbImage::from_pixel(cols * cell, rows * cell, Rgb([255, 255, 255]));
    for (k, t) in tiles.iter().take(MAX_TILES).enumerate() {
        let (tw, th) = t.dimensions();
        if tw == 0 || th == 0 {
            continue;
        }
        let inner = cell.saturating_sub(2 * border).max(1);
        // Scaled to fill the cell, up or down (a 64 px smoke batch is shown as large as a
        // 640 px one).
        let s = inner as f64 / tw.max(th) as f64;
        let (nw, nh) = (
            ((tw as f64 * s) as u32).max(1),
            ((th as f64 * s) as u32).max(1),
        );
        let small = imageops::resize(t, nw, nh, imageops::FilterType::Triangle);
        let (cx, cy) = ((k as u32 % cols) * cell, (k as u32 / cols) * cell);
        imageops::replace(&mut out, &small, (cx + border) as i64, (cy + border) as i64);
    }
    out
}

/// Writes `img` as a JPEG (quality 90) to `path`, atomically.
pub fn write_jpeg(path: &Path, img: &RgbImage) -> Result<()> {
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
        .encode_image(img)
        .with_context(|| format!("encoding {}", path.display()))?;
    crate::util::write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_fill_a_square_grid_in_order() {
        let tiles: Vec<RgbImage> = (0..5)
            .map(|k| RgbImage::from_pixel(40, 20, Rgb([k * 50, 0, 0])))
            .collect();
        let m = mosaic(&tiles, 64);
        assert_eq!(
            m.dimensions(),
            (3 * 64, 2 * 64),
            "5 tiles: 3 columns, 2 rows"
        );
        assert_eq!(m.get_pixel(10, 10).0, [0, 0, 0], "tile 0 top left");
        assert_eq!(
            m.get_pixel(64 + 10, 10).0,
            [50, 0, 0],
            "tile 1 to its right"
        );
        assert_eq!(
            m.get_pixel(64 + 10, 64 + 10).0,
            [200, 0, 0],
            "tile 4: row 2, col 2"
        );
        assert_eq!(
            m.get_pixel(2 * 64 + 10, 64 + 10).0,
            [255, 255, 255],
            "empty cell"
        );
    }
}
