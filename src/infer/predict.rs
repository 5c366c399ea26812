//! `predict`: a trained model on image files — each image letterboxed to the model's
//! size, detections above a confidence threshold (after NMS, at most `max_det`) mapped
//! back to it (or, with test-time augmentation, the eight views fused), overlay PNGs,
//! `results.json` (COCO results), `images.json` (the image ids) and with `--save-txt`
//! YOLO-seg label lines in ultralytics' format (`class x1 y1 … xn yn conf`, polygons
//! normalised to the image, `%g`; one `labels/<image stem>.txt` per image with
//! detections, as ultralytics' `save_txt=True, save_conf=True` writes them). The options
//! every engine shares are [`PredictOptions`]. Any engine plugs in as a closure from an
//! image's planes to detections: a checkpoint's weights here, the ONNX graph through
//! tract in [`super::onnx`].

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use burn::tensor::{Tensor, TensorData};
use image::RgbImage;
use serde_json::json;

use crate::annotations::coco::{save_results, Detection};
use crate::annotations::polygon::mask_to_polygons;
use crate::annotations::yolo_export::{fmt_g, polygon_line};
use crate::config::DeviceKind;
use crate::data::dataset::read_image;
use crate::data::letterbox::Letterbox;
use crate::eval::overlay::{draw_box, tint};
use crate::render::export::instance_color;

use super::checkpoint::Checkpoint;
use super::device::device_of;
use super::validate::{augmented, fused_to_coco, inference_size, push_planes, to_coco};

/// Default confidence threshold of `predict` (ultralytics' predict default).
pub const PREDICT_CONF: f32 = 0.25;
/// Default NMS IoU of `predict` (ultralytics' predict default, and the validation one).
pub const PREDICT_IOU: f32 = 0.7;
/// Default cap on detections per image (ultralytics' `max_det`).
pub const PREDICT_MAX_DET: usize = 300;

/// What every engine of `predict` is asked for.
#[derive(Clone, Debug, clap::Args)]
pub struct PredictOptions {
    /// Keep detections scoring above this.
    #[arg(long, default_value_t = PREDICT_CONF)]
    pub conf: f32,
    /// IoU above which NMS suppresses the lower-scoring of two same-class boxes (YOLO's
    /// postprocess runs at it; Mask R-CNN's and Mask2Former's outputs go through a
    /// class-wise NMS at it after their own).
    #[arg(long, default_value_t = PREDICT_IOU)]
    pub iou: f32,
    /// At most this many detections per image, highest scores first.
    #[arg(long, default_value_t = PREDICT_MAX_DET)]
    pub max_det: usize,
    /// Test-time augmentation: predict on each image's eight top-view symmetries
    /// (quarter turns, mirrored) and fuse the detections (8× the inference time; a
    /// fused score is the views' mean, so `--conf` applies to that mean too).
    #[arg(long)]
    pub augment: bool,
    /// Also write labels/<image stem>.txt under --out: one line per detection,
    /// `class x1 y1 … xn yn conf` with the polygon normalised to the image (ultralytics'
    /// save_txt + save_conf format).
    #[arg(long)]
    pub save_txt: bool,
}

impl Default for PredictOptions {
    fn default() -> PredictOptions {
        PredictOptions {
            conf: PREDICT_CONF,
            iou: PREDICT_IOU,
            max_det: PREDICT_MAX_DET,
            augment: false,
            save_txt: false,
        }
    }
}

impl PredictOptions {
    /// Refuses thresholds outside [0, 1] (a typo such as `--iou 70` would keep everything).
    pub fn check(&self) -> Result<()> {
        for (flag, v) in [("--conf", self.conf), ("--iou", self.iou)] {
            if !(0.0..=1.0).contains(&v) {
                bail!("{flag} {v}: must lie in [0, 1]");
            }
        }
        Ok(())
    }
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

/// Predicts with a checkpoint's `ema` weights on `input` (a file or folder) into `out_dir`
/// (see [`predict_images`]); the device defaults to the checkpoint's, the size to the one
/// it was trained at.
pub fn predict_checkpoint(
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

/// The `--save-txt` lines of one image of `(width, height)`: each detection's mask traced
/// into polygons, class = index of its category in `category_ids`. A detection without
/// a mask (or with an empty one) has no line.
pub fn yolo_txt(dets: &[Detection], category_ids: &[u64], (w, h): (u32, u32)) -> Result<String> {
    let mut text = String::new();
    for d in dets {
        let Some(seg) = &d.segmentation else {
            continue;
        };
        let polys = mask_to_polygons(&seg.to_rle(h, w)?.decode());
        let cls = category_ids
            .iter()
            .position(|&c| c == d.category_id)
            .unwrap_or(0);
        if let Some(line) = polygon_line(cls, &polys, (w as f64, h as f64)) {
            text.push_str(&line);
            text.push(' ');
            text.push_str(&fmt_g(d.score));
            text.push('\n');
        }
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotations::coco::Segmentation;
    use crate::annotations::mask::Mask;
    use crate::annotations::rle::Rle;

    #[test]
    fn txt_lines_are_ultralytics_normalised_polygons_with_conf() {
        // A 4×2 block of pixels at (2, 1) in a 10×5 image: its outline runs through
        // pixel corners, x 2..6 and y 1..3.
        let mut m = Mask::new(5, 10);
        for y in 1..3 {
            for x in 2..6 {
                m.set(x, y, true);
            }
        }
        let d = Detection {
            image_id: 1,
            category_id: 7,
            score: 0.875,
            bbox: Some([2.0, 1.0, 4.0, 2.0]),
            segmentation: Some(Segmentation::Uncompressed(Rle::encode(&m))),
        };
        let t = yolo_txt(&[d], &[3, 7], (10, 5)).unwrap();
        assert_eq!(t.lines().count(), 1);
        let f: Vec<&str> = t.split_whitespace().collect();
        assert_eq!(f[0], "1", "class = index of category 7");
        assert_eq!(*f.last().unwrap(), "0.875");
        let xy: Vec<f64> = f[1..f.len() - 1]
            .iter()
            .map(|v| v.parse().unwrap())
            .collect();
        assert!(xy.len() >= 8 && xy.len() % 2 == 0, "{t}");
        let (xs, ys): (Vec<f64>, Vec<f64>) = (
            xy.iter().step_by(2).copied().collect(),
            xy.iter().skip(1).step_by(2).copied().collect(),
        );
        let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        let max = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert_eq!((min(&xs), max(&xs)), (0.2, 0.6), "{t}");
        assert_eq!((min(&ys), max(&ys)), (0.2, 0.6), "{t}");
        let none = Detection {
            image_id: 1,
            category_id: 3,
            score: 0.5,
            bbox: Some([0.0, 0.0, 1.0, 1.0]),
            segmentation: None,
        };
        assert_eq!(
            yolo_txt(&[none], &[3], (10, 5)).unwrap(),
            "",
            "no mask, no line"
        );
    }

    #[test]
    fn thresholds_outside_0_1_are_refused() {
        let o = PredictOptions {
            iou: 70.0,
            ..PredictOptions::default()
        };
        assert!(o.check().unwrap_err().to_string().contains("--iou 70"));
        assert!(PredictOptions::default().check().is_ok());
    }
}
