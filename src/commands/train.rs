//! The `train`, `eval` and `predict` commands as library functions returning the text
//! the binary prints; predicting itself lives in `infer::predict`.

use std::path::Path;

use anyhow::Result;

use crate::config::{self, DeviceKind};
pub use crate::infer::onnx::predict_onnx;
/// `chicktrain predict --checkpoint X --input IMG_OR_DIR --out DIR`.
pub use crate::infer::predict::predict_checkpoint as predict_cmd;
pub use crate::infer::predict::PREDICT_CONF;
use crate::infer::validate::score_checkpoint;
pub use crate::infer::validate::SplitName;
use crate::train::run_files::StatsRecord;
use crate::train::trainer::{train, TrainOptions, TrainSummary};

/// One line per COCO stat block, pycocotools names.
pub fn stats_line(kind: &str, s: &[f64; 12]) -> String {
    format!(
        "{kind}: AP {:.4}  AP50 {:.4}  AP75 {:.4}  APs {:.4}  APm {:.4}  APl {:.4}  AR1 {:.4}  AR10 {:.4}  AR100 {:.4}",
        s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8]
    )
}

/// `chicktrain train` / `chicktrain --config X`.
pub fn train_cmd(config_name: &str, overrides: &[String], opts: &TrainOptions) -> Result<String> {
    let cfg = config::load(config_name, overrides)?;
    crate::train::interrupt::install();
    let s: TrainSummary = train(cfg, opts)?;
    Ok(format!(
        "trained {} epochs ({} optimiser steps) in {:.1} s ({:.2} train img/s); best epoch {}; run files in {}\n\
         test split ({} images{}), best.bpk:\n{}\n{}",
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
        stats_line("bbox", &s.test.bbox),
        stats_line("segm", &s.test.segm)
    ))
}

/// `chicktrain eval --checkpoint X [--split val|test] [--data CONFIG] [--imgsz N] [--json]
/// [--augment]`:
/// scores the checkpoint's weights (see [`score_checkpoint`]).
pub fn eval_cmd(
    checkpoint: &Path,
    split: SplitName,
    data: Option<&str>,
    device: Option<DeviceKind>,
    imgsz: Option<usize>,
    json_out: bool,
    augment: bool,
) -> Result<String> {
    let s = score_checkpoint(checkpoint, split, data, device, imgsz, augment)?;
    if json_out {
        return Ok(serde_json::to_string(&StatsRecord::from(&s.stats))?);
    }
    Ok(format!(
        "{} (epoch {}) on the {:?} split of {}, {} images at {} px{}{}:\n{}\n{}\n{}",
        checkpoint.display(),
        s.epoch,
        split,
        s.origin,
        s.images,
        s.input,
        if augment {
            ", test-time augmentation (8 views)"
        } else {
            ""
        },
        if s.proxy {
            " [proxy-real renders, not real photos]"
        } else {
            ""
        },
        stats_line("bbox", &s.stats.bbox),
        stats_line("segm", &s.stats.segm),
        s.timing.line()
    ))
}
