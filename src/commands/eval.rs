//! `chicktrain eval`: a checkpoint scored on a split, printed as the 12 COCO stats of
//! bbox and segm side by side (pycocotools' order and names), optionally as JSON, and
//! with `--save-json` its detections written as a COCO results file (what
//! ultralytics' `val save_json=True` writes), so another evaluator can score them.

use std::path::PathBuf;

use anyhow::Result;

use crate::annotations::coco::save_results;
use crate::config::DeviceKind;
use crate::eval::STAT_NAMES;
use crate::infer::validate::{score_checkpoint, SplitName};
use crate::train::run_files::StatsRecord;

/// `eval` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct EvalRequest {
    /// A best.bpk / last.bpk written by `train`.
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// Which split of the data to score: train, val or test.
    #[arg(long, value_enum, default_value = "val")]
    pub split: SplitName,
    /// Evaluate on the real data of this config instead of the checkpoint's own.
    #[arg(long, value_name = "CONFIG")]
    pub data: Option<String>,
    /// Letterbox the images to this square size (a multiple of 32) instead of the
    /// size the checkpoint was trained at.
    #[arg(long)]
    pub imgsz: Option<usize>,
    /// Print {"bbox": {"stats": [12]}, "segm": {"stats": [12]}}.
    #[arg(long)]
    pub json: bool,
    /// Also write the detections to this file as COCO results JSON (a list of
    /// {image_id, category_id, score, bbox, segmentation}; the image ids are the data's).
    #[arg(long, value_name = "FILE")]
    pub save_json: Option<PathBuf>,
    /// Test-time augmentation: score each image in its eight top-view symmetries
    /// (quarter turns, mirrored) and fuse the detections (8× the inference time).
    #[arg(long)]
    pub augment: bool,
    /// Override the checkpoint's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long)]
    pub device: Option<DeviceKind>,
}

impl EvalRequest {
    /// `checkpoint` on `split`, every other flag at its default.
    pub fn new(checkpoint: impl Into<PathBuf>, split: SplitName) -> EvalRequest {
        EvalRequest {
            checkpoint: checkpoint.into(),
            split,
            data: None,
            imgsz: None,
            json: false,
            save_json: None,
            augment: false,
            device: None,
        }
    }
}

/// The 12 COCO stats of bbox and segm as a table: one row per stat, pycocotools' order.
pub fn stats_table(bbox: &[f64; 12], segm: &[f64; 12]) -> String {
    let mut s = format!("{:<6} {:>7} {:>7}\n", "stat", "bbox", "segm");
    for (k, name) in STAT_NAMES.iter().enumerate() {
        s.push_str(&format!("{name:<6} {:>7.4} {:>7.4}\n", bbox[k], segm[k]));
    }
    s
}

/// `chicktrain eval --checkpoint X [--split val|test] [--data CONFIG] [--imgsz N] [--json]
/// [--save-json FILE] [--augment]`: scores the checkpoint's weights (see
/// [`score_checkpoint`]).
pub fn eval_cmd(r: &EvalRequest) -> Result<String> {
    let s = score_checkpoint(
        &r.checkpoint,
        r.split,
        r.data.as_deref(),
        r.device,
        r.imgsz,
        r.augment,
    )?;
    if let Some(p) = &r.save_json {
        save_results(p, &s.detections)?;
    }
    if r.json {
        return Ok(serde_json::to_string(&StatsRecord::from(&s.stats))?);
    }
    let saved = match &r.save_json {
        Some(p) => format!(
            "\n{} detections written to {}",
            s.detections.len(),
            p.display()
        ),
        None => String::new(),
    };
    Ok(format!(
        "{} (epoch {}) on the {:?} split of {}, {} images at {} px{}{}:\n{}{}{}",
        r.checkpoint.display(),
        s.epoch,
        r.split,
        s.origin,
        s.images,
        s.input,
        if r.augment {
            ", test-time augmentation (8 views)"
        } else {
            ""
        },
        if s.proxy {
            " [proxy-real renders, not real photos]"
        } else {
            ""
        },
        stats_table(&s.stats.bbox, &s.stats.segm),
        s.timing.line(),
        saved
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_has_every_stat_in_pycocotools_order() {
        let b: [f64; 12] = std::array::from_fn(|k| k as f64 / 100.0);
        let s: [f64; 12] = std::array::from_fn(|k| 1.0 - k as f64 / 100.0);
        let t = stats_table(&b, &s);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 13);
        assert_eq!(lines[1], "AP      0.0000  1.0000");
        assert_eq!(lines[12], "ARl     0.1100  0.8900");
    }
}
