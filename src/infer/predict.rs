//! `predict`: a trained model on image files — each image letterboxed to the model's
//! size, detections above a confidence threshold mapped back to it (or, with test-time
//! augmentation, the eight views fused), overlay PNGs, `results.json` (COCO results) and
//! `images.json` (the image ids). Any engine plugs in as a closure from an image's
//! planes to detections: a checkpoint's weights here, the ONNX graph through tract in
//! [`super::onnx`].

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use burn::tensor::{Tensor, TensorData};
use image::{Rgb, RgbImage};
use serde_json::json;

use crate::annotations::coco::{save_results, Detection};
use crate::config::DeviceKind;
use crate::data::dataset::read_image;
use crate::data::letterbox::Letterbox;
use crate::render::export::instance_color;

use super::checkpoint::Checkpoint;
use super::device::device_of;
use super::validate::{augmented, fused_to_coco, inference_size, push_planes, to_coco};

/// Default confidence threshold of `predict` (ultralytics' predict default).
pub const PREDICT_CONF: f32 = 0.25;

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

/// Draws masks (tinted), boxes and a score bar (length ∝ score, above each box; no font
/// is embedded, the scores are in `results.json`).
fn overlay(img: &RgbImage, dets: &[Detection]) -> Result<RgbImage> {
    let mut out = img.clone();
    let (w, h) = out.dimensions();
    for (k, d) in dets.iter().enumerate() {
        let c = instance_color(k as u16 + 1);
        if let Some(seg) = &d.segmentation {
            let m = seg.to_rle(h, w)?.decode();
            for y in 0..h {
                for x in 0..w {
                    if m.get(x, y) {
                        let p = out.get_pixel_mut(x, y);
                        for i in 0..3 {
                            p.0[i] = ((p.0[i] as u16 + c[i] as u16) / 2) as u8;
                        }
                    }
                }
            }
        }
        if let Some([bx, by, bw, bh]) = d.bbox {
            let (x0, y0) = (bx.max(0.0) as u32, by.max(0.0) as u32);
            let x1 = ((bx + bw) as u32).min(w.saturating_sub(1));
            let y1 = ((by + bh) as u32).min(h.saturating_sub(1));
            for x in x0..=x1 {
                out.put_pixel(x, y0.min(h - 1), Rgb(c));
                out.put_pixel(x, y1, Rgb(c));
            }
            for y in y0..=y1 {
                out.put_pixel(x0.min(w - 1), y, Rgb(c));
                out.put_pixel(x1, y, Rgb(c));
            }
            let len = ((x1.saturating_sub(x0)) as f64 * d.score) as u32;
            for yy in y0.saturating_sub(4)..y0.saturating_sub(1) {
                for x in x0..(x0 + len).min(w) {
                    out.put_pixel(x, yy, Rgb(c));
                }
            }
        }
    }
    Ok(out)
}

/// Predicts with a checkpoint's `ema` weights on `input` (a file or folder) into `out_dir`
/// (see [`predict_images`]); the device defaults to the checkpoint's, the size to the one
/// it was trained at.
pub fn predict_checkpoint(
    checkpoint: &Path,
    input: &Path,
    out_dir: &Path,
    conf: f32,
    device: Option<DeviceKind>,
    imgsz: Option<usize>,
    augment: bool,
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
    predict_images(
        input,
        out_dir,
        size as u32,
        &classes,
        conf,
        augment,
        &mut |px| {
            let x = Tensor::<4>::from_data(TensorData::new(px, [1, 3, size, size]), &dev);
            Ok(model.predict(x, conf).swap_remove(0))
        },
    )
}

/// Category ids and names of a model's classes (index = class).
pub struct PredictClasses {
    pub category_ids: Vec<u64>,
    pub names: Vec<String>,
}

/// The body of `predict` for any engine: letterboxes each image of `input` to
/// `size × size`, hands its `[1, 3, size, size]` planes to `infer` (detections with score
/// > `conf` at the input size), maps them back to the image and writes the overlays,
/// `results.json` and `images.json` into `out_dir`. With `augment`, every image is seen
/// in eight views ([`augmented`]) and the fused detections scoring above `conf` are kept.
pub fn predict_images(
    input: &Path,
    out_dir: &Path,
    size: u32,
    classes: &PredictClasses,
    conf: f32,
    augment: bool,
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
        let dets: Vec<Detection> = if augment {
            augmented(&img, size, infer)
                .with_context(|| format!("on {}", f.display()))?
                .iter()
                .filter(|d| d.score > conf)
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
        images.push(json!({"id": id, "file_name": f.display().to_string(), "width": w, "height": h, "detections": dets.len()}));
        all.extend(dets);
    }
    save_results(&out_dir.join("results.json"), &all)?;
    crate::util::write_atomic(
        &out_dir.join("images.json"),
        serde_json::to_string_pretty(&json!({"images": images, "categories": classes.category_ids.iter().zip(&classes.names).map(|(i, n)| json!({"id": i, "name": n})).collect::<Vec<_>>()}))?.as_bytes(),
    )?;
    Ok(format!(
        "{} images, {} detections (score > {conf}); overlays, results.json (COCO results) and images.json (image ids) in {}",
        files.len(),
        all.len(),
        out_dir.display()
    ))
}
