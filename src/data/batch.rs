//! Batching: samples of one size → the model's `[B, 3, H, W]` input (values in [0, 1],
//! channel planes) and [`Targets`] (boxes xyxy in pixels from the masks, classes,
//! masks at input resolution).
//!
//! Instances whose box is under 2 px wide or high are dropped, as ultralytics'
//! `box_candidates` does after augmentation: they are slivers cut by the crop.

use anyhow::{bail, Result};

use crate::annotations::targets::{ImageTargets, Targets};

use super::dataset::Sample;
use crate::annotations::mask::Mask;

/// A batch ready for the device.
#[derive(Clone, Debug)]
pub struct Batch {
    /// `[B, 3, H, W]` row-major.
    pub pixels: Vec<f32>,
    pub dims: [usize; 4],
    pub targets: Targets,
}

/// Tight xyxy box of a mask (exclusive max), or None if empty.
pub fn mask_box(m: &Mask) -> Option<[f32; 4]> {
    let (w, h) = (m.width as usize, m.height as usize);
    let (mut x1, mut y1, mut x2, mut y2) = (usize::MAX, usize::MAX, 0, 0);
    for y in 0..h {
        let row = &m.data[y * w..(y + 1) * w];
        if let (Some(a), Some(b)) = (
            row.iter().position(|&v| v != 0),
            row.iter().rposition(|&v| v != 0),
        ) {
            x1 = x1.min(a);
            x2 = x2.max(b + 1);
            y1 = y1.min(y);
            y2 = y + 1;
        }
    }
    (x1 != usize::MAX).then(|| [x1 as f32, y1 as f32, x2 as f32, y2 as f32])
}

/// Stacks samples (all the same size) into a batch.
pub fn collate(samples: &[Sample]) -> Result<Batch> {
    let Some(first) = samples.first() else {
        bail!("cannot build an empty batch");
    };
    let (w, h) = first.image.dimensions();
    let (w, h) = (w as usize, h as usize);
    let b = samples.len();
    let plane = w * h;
    let mut pixels = vec![0f32; b * 3 * plane];
    let mut images = Vec::with_capacity(b);
    for (i, s) in samples.iter().enumerate() {
        if s.image.dimensions() != (w as u32, h as u32) {
            bail!(
                "batch mixes image sizes {:?} and {w}x{h}",
                s.image.dimensions()
            );
        }
        let base = i * 3 * plane;
        for (p, px) in s.image.pixels().enumerate() {
            for c in 0..3 {
                pixels[base + c * plane + p] = px.0[c] as f32 / 255.0;
            }
        }
        let mut t = ImageTargets::default();
        for inst in &s.instances {
            let Some(bx) = mask_box(&inst.mask) else {
                continue;
            };
            if bx[2] - bx[0] < 2.0 || bx[3] - bx[1] < 2.0 {
                continue;
            }
            t.boxes.push(bx);
            t.classes.push(inst.class);
            t.masks
                .push(inst.mask.data.iter().map(|&v| u8::from(v != 0)).collect());
        }
        images.push(t);
    }
    Ok(Batch {
        pixels,
        dims: [b, 3, h, w],
        targets: Targets { images },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::dataset::Instance;
    use image::RgbImage;

    #[test]
    fn collate_layout_boxes_and_slivers() {
        let mut image = RgbImage::new(4, 3);
        image.put_pixel(1, 2, image::Rgb([255, 0, 51]));
        let mut m = Mask::new(3, 4);
        for (x, y) in [(1, 1), (2, 1), (2, 2)] {
            m.set(x, y, true);
        }
        let mut sliver = Mask::new(3, 4);
        sliver.set(3, 0, true);
        sliver.set(3, 1, true);
        let s = Sample {
            image,
            instances: vec![
                Instance { class: 0, mask: m },
                Instance {
                    class: 0,
                    mask: sliver,
                },
            ],
        };
        let b = collate(&[s.clone(), s]).unwrap();
        assert_eq!(b.dims, [2, 3, 3, 4]);
        let plane = 12;
        assert_eq!(b.pixels[2 * 4 + 1], 1.0);
        assert!((b.pixels[2 * plane + 2 * 4 + 1] - 0.2).abs() < 1e-6);
        assert_eq!(
            b.pixels[3 * plane + 2 * 4 + 1],
            1.0,
            "second image starts at 3 planes"
        );
        let t = &b.targets.images[1];
        assert_eq!(
            t.boxes,
            vec![[1.0, 1.0, 3.0, 3.0]],
            "the 1-px-wide sliver is dropped"
        );
        assert_eq!(t.masks[0].len(), 12);
        assert!(collate(&[]).is_err());
    }
}
