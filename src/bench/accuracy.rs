//! Test accuracy of trained models for the bench reports: a checkpoint scored on its own
//! test split, or a finished run folder's `test.json`, with what its training took. Both
//! go through the library's evaluation and run-folder records, so a bench row's AP is
//! the same number `chicktrain eval --split test` prints.

use std::path::Path;

use anyhow::Result;

use crate::config::DeviceKind;
use crate::infer::validate::SplitName;
use crate::train::run_files;

/// Test accuracy of a trained model and what its training took.
#[derive(Clone, Debug, PartialEq)]
pub struct Accuracy {
    pub bbox: [f64; 12],
    pub segm: [f64; 12],
    /// Sum of the epoch times of its run (`metrics.jsonl` next to the checkpoint).
    pub train_seconds: f64,
    /// Where the numbers come from (checkpoint or run folder).
    pub source: String,
}

/// Test AP of a checkpoint on its own test split.
pub fn checkpoint_accuracy(ck: &Path, device: Option<DeviceKind>) -> Result<Accuracy> {
    let score =
        crate::infer::validate::score_checkpoint(ck, SplitName::Test, None, device, None, false)?;
    Ok(Accuracy {
        bbox: score.stats.bbox,
        segm: score.stats.segm,
        train_seconds: run_files::train_seconds(ck.parent().unwrap_or(Path::new(".")))?,
        source: ck.display().to_string(),
    })
}

/// Test AP of a finished run folder (its `test.json`).
pub fn run_accuracy(dir: &Path) -> Result<Accuracy> {
    let t = run_files::read_test(dir)?;
    Ok(Accuracy {
        bbox: t.bbox.stats,
        segm: t.segm.stats,
        train_seconds: run_files::train_seconds(dir)?,
        source: dir.display().to_string(),
    })
}
