//! `plots.png`: per-epoch curves drawn with the `image` crate alone (no font, no plotting
//! dependency). Left panel: the training losses, each scaled to its own maximum, in the
//! model's loss order (YOLO: box red, cls green, dfl blue, seg orange; Mask R-CNN: rpn_cls,
//! rpn_box, cls, box, mask in red, green, blue, orange, purple). Right panel: validation AP (0–1 axis) —
//! bbox AP dark blue, bbox AP50 light blue, segm AP dark red, segm AP50 light red.
//! Grid lines every 0.25 of the axis. The numbers themselves are in `results.csv`.

use std::path::Path;

use anyhow::Result;
use image::{Rgb, RgbImage};

const W: u32 = 400;
const H: u32 = 300;
const PAD: u32 = 20;

fn line(img: &mut RgbImage, (x0, y0): (f64, f64), (x1, y1): (f64, f64), c: Rgb<u8>) {
    let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
        for (dx, dy) in [(0i64, 0i64), (1, 0), (0, 1)] {
            let (px, py) = (x as i64 + dx, y as i64 + dy);
            if px >= 0 && py >= 0 && (px as u32) < img.width() && (py as u32) < img.height() {
                img.put_pixel(px as u32, py as u32, c);
            }
        }
    }
}

fn panel(img: &mut RgbImage, ox: u32, series: &[(Vec<f64>, Rgb<u8>)], normalise: bool) {
    let (x0, x1) = ((ox + PAD) as f64, (ox + W - PAD) as f64);
    let (y0, y1) = ((H - PAD) as f64, PAD as f64);
    for k in 0..=4 {
        let y = y0 + (y1 - y0) * k as f64 / 4.0;
        line(img, (x0, y), (x1, y), Rgb([225, 225, 225]));
    }
    line(img, (x0, y0), (x1, y0), Rgb([0, 0, 0]));
    line(img, (x0, y0), (x0, y1), Rgb([0, 0, 0]));
    for (vals, c) in series {
        let max = if normalise {
            vals.iter()
                .cloned()
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max)
                .max(1e-12)
        } else {
            1.0
        };
        let n = vals.len();
        let at = |i: usize| {
            let x = if n > 1 {
                x0 + (x1 - x0) * i as f64 / (n - 1) as f64
            } else {
                x0
            };
            let v = (vals[i] / max).clamp(0.0, 1.0);
            (x, y0 + (y1 - y0) * v)
        };
        if n == 1 {
            line(img, at(0), (at(0).0 + 3.0, at(0).1), *c);
        }
        for i in 1..n {
            line(img, at(i - 1), at(i), *c);
        }
    }
}

/// Colours of the loss curves, in loss order.
const LOSS_COLOURS: [[u8; 3]; 6] = [
    [220, 40, 40],
    [40, 160, 40],
    [40, 40, 220],
    [240, 150, 0],
    [150, 40, 180],
    [90, 90, 90],
];

/// Writes `<dir>/plots.png` from the per-epoch metric records (`loss.<name>` for each of
/// `loss_names`).
pub fn write_plots(dir: &Path, records: &[serde_json::Value], loss_names: &[&str]) -> Result<()> {
    let get = |f: &dyn Fn(&serde_json::Value) -> Option<f64>| -> Vec<f64> {
        records.iter().map(|r| f(r).unwrap_or(0.0)).collect()
    };
    let loss = |k: &str| get(&|r: &serde_json::Value| r["loss"][k].as_f64());
    let stat = |t: &'static str, i: usize| get(&move |r| r["val"][t]["stats"][i].as_f64());
    let mut img = RgbImage::from_pixel(2 * W, H, Rgb([255, 255, 255]));
    panel(
        &mut img,
        0,
        &loss_names
            .iter()
            .zip(LOSS_COLOURS.iter().cycle())
            .map(|(k, c)| (loss(k), Rgb(*c)))
            .collect::<Vec<_>>(),
        true,
    );
    panel(
        &mut img,
        W,
        &[
            (stat("bbox", 0), Rgb([20, 40, 140])),
            (stat("bbox", 1), Rgb([110, 160, 240])),
            (stat("segm", 0), Rgb([150, 20, 20])),
            (stat("segm", 1), Rgb([240, 120, 120])),
        ],
        false,
    );
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut png,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::Rgb8,
    )?;
    crate::util::write_atomic(&dir.join("plots.png"), &png)
}

use image::ImageEncoder;
