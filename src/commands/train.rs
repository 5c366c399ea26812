//! The `train` and `predict` commands as library functions returning the text the
//! binary prints (`eval` is [`super::eval`]; `predict`'s flags are [`super::predict`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use burn::tensor::{Tensor, TensorData};
use image::RgbImage;
use serde_json::json;

use crate::annotations::coco::{save_results, Detection};
use crate::config::{self, DeviceKind};
use crate::data::dataset::read_image;
use crate::data::letterbox::Letterbox;
use crate::eval::overlay::{draw_box, tint};
use crate::render::export::instance_color;
use crate::train::checkpoint::Checkpoint;
use crate::train::device::device_of;
pub use crate::train::evaluate::SplitName;
use crate::train::evaluate::{augmented, fused_to_coco, inference_size, push_planes, to_coco};
use crate::train::trainer::{train, TrainOptions, TrainSummary};

use super::predict::{yolo_txt, PredictOptions};

/// `chicktrain train` / `chicktrain --config X`.
pub fn train_cmd(config_name: &str, overrides: &[String], opts: &TrainOptions) -> Result<String> {
    let cfg = config::load(config_name, overrides)?;
    crate::train::interrupt::install();
    let s: TrainSummary = train(cfg, opts)?;
    Ok(format!(
        "trained {} epochs ({} optimiser steps) in {:.1} s ({:.2} train img/s); best epoch {}; run files in {}\n\
         test split ({} images{}), best.bpk:\n{}",
        s.epochs,
        s.steps,
        s.seconds,
        s.train_images_per_s,
        s.best_epoch,
        s.run_dir.display(),
        s.test_images,
        if s.proxy {
            ", proxy-real renders standing in for real photos"
        } else {
            ""
        },
        super::eval::stats_table(&s.test.bbox, &s.test.segm).trim_end()
    ))
}

fn list_images(input: &Path) -> Result<Vec<PathBuf>> {
    if !input.exists() {
        bail!("--input {} does not exist", input.display());
    }
    if input.is_file() {
        return Ok(vec![input.to_path_buf()]);
    }
    let mut v: Vec<PathBuf> = std::fs::read_dir(input)
        .with_context(|| format!("cannot read folder {}", input.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
        })
        .collect();
    v.sort();
    if v.is_empty() {
        bail!("no .jpg/.jpeg/.png images in {}", input.display());
    }
    Ok(v)
}

/// Draws masks (tinted), boxes and a score bar (length ∝ score, above each box; the
/// overlay has no text, the scores are in `results.json`) with [`crate::eval::overlay`].
fn overlay(img: &RgbImage, dets: &[Detection]) -> Result<RgbImage> {
    let mut out = img.clone();
    let (w, h) = out.dimensions();
    for (k, d) in dets.iter().enumerate() {
        let c = instance_color(k as u16 + 1);
        if let Some(seg) = &d.segmentation {
            tint(&mut out, &seg.to_rle(h, w)?.decode(), c);
        }
        if let Some(b) = d.bbox {
            draw_box(&mut out, b, c, Some(d.score));
        }
    }
    Ok(out)
}

/// `chicktrain predict --checkpoint X --input IMG_OR_DIR --out DIR`.
pub fn predict_cmd(
    checkpoint: &Path,
    input: &Path,
    out_dir: &Path,
    opts: &PredictOptions,
    device: Option<DeviceKind>,
    imgsz: Option<usize>,
) -> Result<String> {
    let ck = Checkpoint::load(checkpoint)?;
    let size = inference_size(ck.header.model.input_size(), imgsz)?;
    let dev = device_of(device.unwrap_or(ck.header.config.device))?;
    let model = ck
        .model("ema", &dev)
        .with_context(|| format!("in checkpoint {}", checkpoint.display()))?;
    let classes = PredictClasses {
        category_ids: ck.header.category_ids.clone(),
        names: ck.header.class_names.clone(),
    };
    predict_images(input, out_dir, size as u32, &classes, opts, &mut |px| {
        let x = Tensor::<4>::from_data(TensorData::new(px, [1, 3, size, size]), &dev);
        Ok(model
            .predict_nms(x, opts.conf, opts.iou, opts.max_det)
            .swap_remove(0))
    })
}

/// Category ids and names of a model's classes (index = class).
pub struct PredictClasses {
    pub category_ids: Vec<u64>,
    pub names: Vec<String>,
}

/// The body of `predict` for any engine: letterboxes each image of `input` to
/// `size × size`, hands its `[1, 3, size, size]` planes to `infer` (detections with score
/// > `conf` at the input size, after NMS at `iou`, at most `max_det`), maps them back to
/// the image and writes the overlays, `results.json`, `images.json` and with `save_txt`
/// `labels/<stem>.txt` into `out_dir`. With `augment`, every image is seen in eight views
/// ([`augmented`]) and the fused detections scoring above `conf` are kept (at most
/// `max_det`).
pub fn predict_images(
    input: &Path,
    out_dir: &Path,
    size: u32,
    classes: &PredictClasses,
    opts: &PredictOptions,
    infer: &mut dyn FnMut(Vec<f32>) -> Result<Vec<crate::model::detection::Detection>>,
) -> Result<String> {
    let files = list_images(input)?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let mut all = Vec::new();
    let mut images = Vec::new();
    for (k, f) in files.iter().enumerate() {
        let img = read_image(f)?;
        let (w, h) = img.dimensions();
        let id = k as u64 + 1;
        let dets: Vec<Detection> = if opts.augment {
            let mut fused =
                augmented(&img, size, infer).with_context(|| format!("on {}", f.display()))?;
            fused.retain(|d| d.score > opts.conf);
            fused.sort_by(|a, b| b.score.total_cmp(&a.score));
            fused.truncate(opts.max_det);
            fused
                .iter()
                .map(|d| fused_to_coco(d, id, &classes.category_ids))
                .collect()
        } else {
            let small = Letterbox::new((w, h), size).image(&img);
            let mut px = Vec::new();
            push_planes(&small, &mut px);
            let raw = infer(px).with_context(|| format!("on {}", f.display()))?;
            raw.iter()
                .map(|d| to_coco(d, id, &classes.category_ids, size, (w, h)))
                .collect()
        };
        let ov = overlay(&img, &dets)?;
        let stem = f
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or(format!("{id}"));
        let png = crate::util::png::encode_png(&ov)?;
        crate::util::write_atomic(&out_dir.join(format!("{stem}.png")), &png)?;
        if opts.save_txt && !dets.is_empty() {
            let labels = out_dir.join("labels");
            std::fs::create_dir_all(&labels)
                .with_context(|| format!("cannot create {}", labels.display()))?;
            let txt = yolo_txt(&dets, &classes.category_ids, (w, h))?;
            crate::util::write_atomic(&labels.join(format!("{stem}.txt")), txt.as_bytes())?;
        }
        images.push(json!({"id": id, "file_name": f.display().to_string(), "width": w, "height": h, "detections": dets.len()}));
        all.extend(dets);
    }
    save_results(&out_dir.join("results.json"), &all)?;
    crate::util::write_atomic(
        &out_dir.join("images.json"),
        serde_json::to_string_pretty(&json!({"images": images, "categories": classes.category_ids.iter().zip(&classes.names).map(|(i, n)| json!({"id": i, "name": n})).collect::<Vec<_>>()}))?.as_bytes(),
    )?;
    Ok(format!(
        "{} images, {} detections (score > {}); overlays, results.json (COCO results){} and images.json (image ids) in {}",
        files.len(),
        all.len(),
        opts.conf,
        if opts.save_txt { ", labels/ (YOLO-seg txt)" } else { "" },
        out_dir.display()
    ))
}
