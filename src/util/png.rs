//! PNG encoding in one place: fast compression for images written in bulk (renders,
//! predictions), best compression for the few plots a run writes.

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder, RgbImage};

/// PNG bytes of an RGB8 buffer `width × height` at `compression`.
pub fn encode_rgb8(
    rgb: &[u8],
    width: u32,
    height: u32,
    compression: CompressionType,
) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, compression, FilterType::Adaptive).write_image(
        rgb,
        width,
        height,
        ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}

/// PNG bytes with fast compression.
pub fn encode_png(img: &RgbImage) -> anyhow::Result<Vec<u8>> {
    encode_rgb8(
        img.as_raw(),
        img.width(),
        img.height(),
        CompressionType::Fast,
    )
}
