//! `chicktrain predict`'s flags and its YOLO-seg text output: which engine runs (a
//! checkpoint, or an ONNX export through tract), the options every engine shares
//! ([`PredictOptions`]: confidence, NMS IoU, detection cap, test-time augmentation,
//! `--save-txt`), and the label lines `--save-txt` writes in ultralytics' format
//! (`class x1 y1 … xn yn conf`, polygons normalised to the image, `%g`), one
//! `labels/<image stem>.txt` per image with detections, as ultralytics' `save_txt=True,
//! save_conf=True` writes them.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use crate::annotations::coco::Detection;
use crate::annotations::polygon::mask_to_polygons;
use crate::annotations::yolo_export::{fmt_g, polygon_line};
use crate::config::DeviceKind;

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

/// `predict` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct PredictRequest {
    /// A best.bpk / last.bpk written by `train`.
    #[arg(long, required_unless_present = "onnx", conflicts_with = "onnx")]
    pub checkpoint: Option<PathBuf>,
    /// An ONNX file written by `export --format onnx`, run through tract.
    #[arg(long)]
    pub onnx: Option<PathBuf>,
    /// An image file or a folder of .jpg/.png images.
    #[arg(long)]
    pub input: PathBuf,
    /// Output folder: overlay PNGs, results.json (COCO results), images.json, labels/.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub opts: PredictOptions,
    /// Threads of the tract engine (`--onnx`; default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Override the checkpoint's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long, conflicts_with = "onnx")]
    pub device: Option<DeviceKind>,
    /// Letterbox the images to this square size (a multiple of 32) instead of the
    /// size the checkpoint was trained at (`--checkpoint`; an ONNX graph has its own).
    #[arg(long, conflicts_with = "onnx")]
    pub imgsz: Option<usize>,
}

impl PredictRequest {
    /// `checkpoint` on `input` into `out`, every other flag at its default.
    pub fn new(checkpoint: &Path, input: &Path, out: &Path) -> PredictRequest {
        PredictRequest {
            checkpoint: Some(checkpoint.to_path_buf()),
            onnx: None,
            input: input.to_path_buf(),
            out: out.to_path_buf(),
            opts: PredictOptions::default(),
            threads: None,
            device: None,
            imgsz: None,
        }
    }
}

/// `chicktrain predict`: through the checkpoint, or through the ONNX file.
pub fn predict(r: &PredictRequest) -> Result<String> {
    r.opts.check()?;
    match (&r.checkpoint, &r.onnx) {
        (_, Some(onnx)) => super::onnx::predict_onnx(onnx, &r.input, &r.out, &r.opts, r.threads),
        (Some(c), None) => {
            super::train::predict_cmd(c, &r.input, &r.out, &r.opts, r.device, r.imgsz)
        }
        (None, None) => bail!("predict needs --checkpoint or --onnx"),
    }
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
