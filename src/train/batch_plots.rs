//! The batch mosaics ultralytics writes into a run folder: `train_batch0.jpg` …
//! `train_batch2.jpg`, the first three training batches exactly as the model receives
//! them (augmented, letterboxed, collated) with their target masks and boxes drawn, the
//! one check that augmentation and labels agree; and `val_batch0_labels.jpg` /
//! `val_batch0_pred.jpg`, the first validation images with their ground truth and with
//! `best.bpk`'s detections above 0.25.
//!
//! The training batches are rebuilt through the run's own loader from the first
//! epoch's plan: the loader draws each item from (seed, epoch, position), so these are
//! the batches the first steps train on.

use std::path::Path;

use anyhow::Result;
use image::{Rgb, RgbImage};

use crate::annotations::coco::{CocoDataset, Detection};
use crate::annotations::mask::Mask;
use crate::config::Config;
use crate::data::batch::Batch;
use crate::data::dataset::RealSet;
use crate::eval::mosaic::{mosaic, write_jpeg, MAX_TILES};
use crate::eval::overlay::{draw_box, tint};
use crate::render::export::instance_color;

use super::loader::{epoch_batches, Loader, Mix};

/// Training batches drawn into the run folder.
pub const TRAIN_BATCHES: usize = 3;
/// Mosaic cell side in pixels.
const CELL: u32 = 320;
/// Detections drawn in `val_batch0_pred.jpg` score above this (ultralytics' plot conf).
pub const PLOT_CONF: f64 = 0.25;

/// Image `i` of `batch` with its targets drawn.
pub fn batch_tile(batch: &Batch, i: usize) -> RgbImage {
    let [_, _, h, w] = batch.dims;
    let plane = h * w;
    let base = i * 3 * plane;
    let mut img = RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let p = y as usize * w + x as usize;
        let c =
            |k: usize| (batch.pixels[base + k * plane + p].clamp(0.0, 1.0) * 255.0).round() as u8;
        Rgb([c(0), c(1), c(2)])
    });
    if let Some(t) = batch.targets.images.get(i) {
        for (k, (b, m)) in t.boxes.iter().zip(&t.masks).enumerate() {
            let c = instance_color(k as u16 + 1);
            if let Some(mask) = Mask::from_row_major(h as u32, w as u32, m.clone()) {
                tint(&mut img, &mask, c);
            }
            let xywh = [
                b[0] as f64,
                b[1] as f64,
                (b[2] - b[0]) as f64,
                (b[3] - b[1]) as f64,
            ];
            draw_box(&mut img, xywh, c, None);
        }
    }
    img
}

/// Writes `train_batch0.jpg` … of the first epoch's first [`TRAIN_BATCHES`] batches.
pub fn write_train_batches(
    dir: &Path,
    cfg: &Config,
    loader: &Loader,
    train_ids: &[u64],
) -> Result<()> {
    let bsz = cfg.train.batch;
    let m = Mix::of(&cfg.train);
    let plan = epoch_batches(train_ids, cfg.data.synthetic, cfg.seed, 0, bsz, m)?;
    for b in 0..TRAIN_BATCHES {
        let first = b * bsz;
        if first >= plan.len() {
            break;
        }
        let batch = loader.batch(&plan, first, bsz.min(plan.len() - first), 0)?;
        let tiles: Vec<RgbImage> = (0..batch.dims[0].min(MAX_TILES))
            .map(|i| batch_tile(&batch, i))
            .collect();
        write_jpeg(
            &dir.join(format!("train_batch{b}.jpg")),
            &mosaic(&tiles, CELL),
        )?;
    }
    Ok(())
}

/// `img` with COCO instances drawn (masks and boxes; `scores`: bars too).
fn draw_coco(mut img: RgbImage, inst: &[(Option<Mask>, [f64; 4], Option<f64>)]) -> RgbImage {
    for (k, (m, b, s)) in inst.iter().enumerate() {
        let c = instance_color(k as u16 + 1);
        if let Some(m) = m {
            tint(&mut img, m, c);
        }
        draw_box(&mut img, *b, c, *s);
    }
    img
}

/// Writes `val_batch0_labels.jpg` and `val_batch0_pred.jpg`: the first validation images
/// (`ids`, at most [`MAX_TILES`]) with `gt`'s instances, and with `dets` above
/// [`PLOT_CONF`].
pub fn write_val_batches(
    dir: &Path,
    real: &RealSet,
    gt: &CocoDataset,
    ids: &[u64],
    dets: &[Detection],
) -> Result<()> {
    let (mut labels, mut preds) = (Vec::new(), Vec::new());
    for &id in ids.iter().take(MAX_TILES) {
        let img = real.original(id)?;
        let (w, h) = img.dimensions();
        let mut g = Vec::new();
        for a in gt
            .annotations
            .iter()
            .filter(|a| a.image_id == id && a.iscrowd == 0)
        {
            g.push((Some(a.segmentation.to_rle(h, w)?.decode()), a.bbox, None));
        }
        let mut p = Vec::new();
        for d in dets
            .iter()
            .filter(|d| d.image_id == id && d.score > PLOT_CONF)
        {
            let m = match &d.segmentation {
                Some(s) => Some(s.to_rle(h, w)?.decode()),
                None => None,
            };
            let b = d.bbox.unwrap_or_default();
            p.push((m, b, Some(d.score)));
        }
        labels.push(draw_coco(img.clone(), &g));
        preds.push(draw_coco(img, &p));
    }
    write_jpeg(&dir.join("val_batch0_labels.jpg"), &mosaic(&labels, CELL))?;
    write_jpeg(&dir.join("val_batch0_pred.jpg"), &mosaic(&preds, CELL))
}
