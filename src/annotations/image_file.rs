//! Image files as training and prediction see them: any format and bit depth the
//! `image` crate decodes (gray, RGBA, 16-bit, …) becomes RGB8, and the EXIF orientation
//! is applied, as ultralytics does (OpenCV's `imread` rotates by EXIF, and labelme
//! annotates the rotated image), so masks drawn on a phone photo line up with its pixels.
//! Errors name the file.

use std::path::Path;

use anyhow::{bail, Context, Result};
use image::{DynamicImage, ImageDecoder, ImageReader, RgbImage};

/// Converts any decoded image (gray, RGBA, 16-bit, …) to RGB8.
pub fn to_rgb8(img: DynamicImage) -> RgbImage {
    match img {
        DynamicImage::ImageRgb8(i) => i,
        other => other.to_rgb8(),
    }
}

fn decoder(path: &Path) -> Result<impl ImageDecoder> {
    if !path.exists() {
        bail!("image file {} does not exist", path.display());
    }
    ImageReader::open(path)
        .with_context(|| format!("cannot open image {}", path.display()))?
        .with_guessed_format()
        .with_context(|| format!("cannot read image {}", path.display()))?
        .into_decoder()
        .with_context(|| {
            format!(
                "cannot decode image {} (corrupt or unsupported)",
                path.display()
            )
        })
}

fn orientation(d: &mut impl ImageDecoder, path: &Path) -> Result<image::metadata::Orientation> {
    d.orientation()
        .with_context(|| format!("cannot read the EXIF orientation of {}", path.display()))
}

/// Decodes an image file to RGB8 with its EXIF orientation applied.
pub fn read_image(path: &Path) -> Result<RgbImage> {
    let mut d = decoder(path)?;
    let o = orientation(&mut d, path)?;
    let mut img = DynamicImage::from_decoder(d).with_context(|| {
        format!(
            "cannot decode image {} (corrupt or unsupported)",
            path.display()
        )
    })?;
    img.apply_orientation(o);
    Ok(to_rgb8(img))
}

/// `(width, height)` of an image file after its EXIF orientation (headers only).
pub fn image_dimensions(path: &Path) -> Result<(u32, u32)> {
    let mut d = decoder(path)?;
    let (w, h) = d.dimensions();
    use image::metadata::Orientation::*;
    Ok(match orientation(&mut d, path)? {
        Rotate90 | Rotate270 | Rotate90FlipH | Rotate270FlipH => (h, w),
        _ => (w, h),
    })
}
