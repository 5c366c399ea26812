//! The `train` command as a library function returning the text the binary prints
//! (`eval` is [`super::eval`], `predict` [`super::predict`]; predicting itself lives in
//! `infer::predict`).

use anyhow::Result;

use crate::config;
pub use crate::infer::validate::SplitName;
use crate::train::trainer::{train, TrainOptions, TrainSummary};

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
