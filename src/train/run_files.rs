//! The run folder's file formats, owned in one place: `metrics.jsonl` (one
//! [`EpochRecord`] per line), `results.csv` (the same, one row per epoch), `test.json`
//! ([`TestRecord`]) and the resolved `config.toml`. The trainer writes them; `plot`,
//! `sweep`, `bench models` and `--resume` read them back through these types.
//!
//! The folder itself is chosen by [`super::run_folder`] (never overwritten: `-2`, `-3`,
//! …); its images are written by [`super::plot`] (`plots.png`), [`super::run_plots`]
//! (PR and F1 curves, confusion matrix) and [`super::batch_plots`] (batch mosaics).
//!
//! Field order is the files' key order (alphabetical, as the untyped `serde_json` maps
//! that wrote them before these types existed), so files stay byte-identical.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Deserializer, Serialize};

use crate::config::{Config, RealKind};
use crate::eval::STAT_NAMES;
use crate::util::write_atomic;

use crate::infer::checkpoint::Stats;

/// The 12 pycocotools numbers of one IoU type, as `{"stats": [...]}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IouStats {
    pub stats: [f64; 12],
}

/// Box and mask stats of one evaluation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatsRecord {
    pub bbox: IouStats,
    pub segm: IouStats,
}

impl From<&Stats> for StatsRecord {
    fn from(s: &Stats) -> Self {
        StatsRecord {
            bbox: IouStats { stats: s.bbox },
            segm: IouStats { stats: s.segm },
        }
    }
}

/// One line of `metrics.jsonl`: an epoch's mean losses per step, learning rate, times,
/// training throughput and validation stats.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// Seconds the training steps waited for the loader thread's next batch (rendering,
    /// decoding, augmenting): near 0 when the data side keeps up with the device.
    #[serde(default)]
    pub data_wait_s: f64,
    /// 1-based.
    pub epoch: usize,
    #[serde(default)]
    pub images_per_s: f64,
    /// Mean of each named loss term per step (`null` in the file reads as NaN).
    #[serde(deserialize_with = "nan_if_null")]
    pub loss: BTreeMap<String, f64>,
    /// f16 runs: the loss scale at the end of the epoch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_scale: Option<f32>,
    pub lr: f64,
    /// True when the "real" images are proxy-real renders.
    #[serde(default)]
    pub proxy: bool,
    /// f16 runs: steps of the epoch skipped for overflowed gradients (their loss is in
    /// the means; no optimiser step was taken).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub skipped_steps: usize,
    /// Optimiser steps of the epoch (0 in files written before it was recorded).
    #[serde(default)]
    pub steps: usize,
    /// Seconds for the epoch, validation included.
    pub time: f64,
    /// Seconds of training steps alone.
    #[serde(default)]
    pub train_time: f64,
    /// Validation stats; absent on epochs `train.val_every` skipped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub val: Option<StatsRecord>,
    /// Where the validation's time went; absent when the epoch was not validated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub val_time: Option<ValTime>,
}

/// Seconds of one epoch's validation: the whole of it (reading or fetching the images,
/// forward passes, postprocess, masks and RLE at the original size, COCO matching) and
/// the forward passes alone, so `total / forward` is what validation costs beyond the
/// network. Fields in alphabetical order, as every key of the file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValTime {
    /// The forward passes alone.
    pub forward: f64,
    /// The whole validation.
    pub total: f64,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<BTreeMap<String, f64>, D::Error> {
    let m = BTreeMap::<String, Option<f64>>::deserialize(d)?;
    Ok(m.into_iter()
        .map(|(k, v)| (k, v.unwrap_or(f64::NAN)))
        .collect())
}

/// `test.json`: the best checkpoint scored on the test split.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TestRecord {
    pub bbox: IouStats,
    /// File name of the scored checkpoint in the run folder (`best.bpk`).
    pub checkpoint: String,
    pub epoch: usize,
    pub images: usize,
    pub proxy: bool,
    pub segm: IouStats,
    pub split: String,
}

impl TestRecord {
    pub fn stats(&self) -> Stats {
        Stats {
            bbox: self.bbox.stats,
            segm: self.segm.stats,
        }
    }
}

fn json<T: Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).expect("plain data serialises")
}

/// `results.csv` header for a model with loss terms `loss_names`.
pub fn csv_header(loss_names: &[&str]) -> String {
    let mut h = vec!["epoch".to_string(), "lr".into(), "time".into()];
    h.extend(loss_names.iter().map(|s| format!("train/{s}_loss")));
    for t in ["bbox", "segm"] {
        h.extend(STAT_NAMES.iter().map(|n| format!("val/{t}_{n}")));
    }
    h.join(",")
}

/// One `results.csv` row; a loss term the record lacks, and every val column of an
/// epoch that was not validated, is `null`.
pub fn csv_row(r: &EpochRecord, loss_names: &[&str]) -> String {
    let mut row = vec![json(&r.epoch), json(&r.lr), json(&r.time)];
    for k in loss_names {
        row.push(r.loss.get(*k).map_or("null".into(), json));
    }
    match &r.val {
        Some(v) => {
            for s in [&v.bbox.stats, &v.segm.stats] {
                row.extend(s.iter().map(json));
            }
        }
        None => row.extend(std::iter::repeat_n("null".to_string(), 24)),
    }
    row.join(",")
}

/// Writes `metrics.jsonl` and `results.csv` from the per-epoch records.
pub fn write_metrics(dir: &Path, records: &[EpochRecord], loss_names: &[&str]) -> Result<()> {
    let mut jl = String::new();
    let mut csv = csv_header(loss_names) + "\n";
    for r in records {
        jl.push_str(&json(r));
        jl.push('\n');
        csv.push_str(&csv_row(r, loss_names));
        csv.push('\n');
    }
    write_atomic(&dir.join("metrics.jsonl"), jl.as_bytes())?;
    write_atomic(&dir.join("results.csv"), csv.as_bytes())?;
    Ok(())
}

/// The records of `<dir>/metrics.jsonl` up to epoch `upto_epoch` (none if the file is
/// missing); a line that is not a record is an error naming the file and line.
pub fn read_metrics(dir: &Path, upto_epoch: usize) -> Result<Vec<EpochRecord>> {
    let p = dir.join("metrics.jsonl");
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for (i, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let r: EpochRecord = serde_json::from_str(line)
            .with_context(|| format!("{} line {} is not an epoch record", p.display(), i + 1))?;
        if r.epoch <= upto_epoch {
            out.push(r);
        }
    }
    Ok(out)
}

/// The epoch of the best validation segm AP among the validated `records` (0 when there
/// are none).
pub fn best_epoch(records: &[EpochRecord]) -> usize {
    records
        .iter()
        .filter_map(|r| Some((r.epoch, r.val.as_ref()?.segm.stats[0])))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(e, _)| e)
}

/// Writes `<dir>/test.json`.
pub fn write_test(dir: &Path, t: &TestRecord) -> Result<()> {
    write_atomic(
        &dir.join("test.json"),
        serde_json::to_string_pretty(t)?.as_bytes(),
    )
}

/// Reads `<dir>/test.json`.
pub fn read_test(dir: &Path) -> Result<TestRecord> {
    let p = dir.join("test.json");
    let text =
        std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not a test record", p.display()))
}

/// Optimiser steps of all epochs in `<dir>/metrics.jsonl` (0 when the file is missing).
pub fn total_steps(dir: &Path) -> Result<usize> {
    Ok(read_metrics(dir, usize::MAX)?.iter().map(|r| r.steps).sum())
}

/// Seconds of all epochs in `<dir>/metrics.jsonl` (0 when the file is missing).
pub fn train_seconds(dir: &Path) -> Result<f64> {
    Ok(read_metrics(dir, usize::MAX)?.iter().map(|r| r.time).sum())
}

/// Writes the resolved `<dir>/config.toml`, with a first line saying when the "real"
/// images are proxy renders.
pub fn write_config(dir: &Path, cfg: &Config) -> Result<()> {
    let text = format!(
        "# chicktrain resolved config (schema 1){}\n{}",
        if cfg.data.real.kind == RealKind::Proxy {
            "; data.real is the proxy-real render preset, a stand-in for real photos"
        } else {
            ""
        },
        toml::to_string(cfg)?
    );
    write_atomic(&dir.join("config.toml"), text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(epoch: usize, segm_ap: f64) -> EpochRecord {
        let mut segm = [0.25; 12];
        segm[0] = segm_ap;
        EpochRecord {
            data_wait_s: 0.25,
            epoch,
            images_per_s: 6.5,
            loss: [("box".to_string(), 1.5), ("seg".to_string(), 0.1)].into(),
            loss_scale: None,
            lr: 0.01,
            proxy: true,
            skipped_steps: 0,
            steps: 7,
            time: 12.0,
            train_time: 10.0,
            val: Some(StatsRecord {
                bbox: IouStats { stats: [-1.0; 12] },
                segm: IouStats { stats: segm },
            }),
            val_time: Some(ValTime {
                total: 2.5,
                forward: 2.0,
            }),
        }
    }

    #[test]
    fn metrics_lines_keep_the_untyped_key_order() {
        let r = record(3, 0.5);
        // What `serde_json::json!` (sorted keys) wrote before the typed record (plus
        // `data_wait_s`, which sorts first).
        let v = r.val.as_ref().unwrap();
        let (bbox, segm) = (v.bbox.stats, v.segm.stats);
        let untyped = serde_json::json!({
            "data_wait_s": 0.25, "epoch": 3, "lr": 0.01, "time": 12.0, "train_time": 10.0, "images_per_s": 6.5,
            "loss": {"seg": 0.1, "box": 1.5}, "proxy": true, "steps": 7,
            "val": {"bbox": {"stats": bbox}, "segm": {"stats": segm}},
            "val_time": {"total": 2.5, "forward": 2.0},
        });
        assert_eq!(json(&r), serde_json::to_string(&untyped).unwrap());
        let t = TestRecord {
            bbox: IouStats { stats: [0.5; 12] },
            checkpoint: "best.bpk".into(),
            epoch: 2,
            images: 36,
            proxy: true,
            segm: IouStats { stats: [0.25; 12] },
            split: "test".into(),
        };
        let (bbox, segm) = ([0.5; 12], [0.25; 12]);
        let untyped = serde_json::json!({
            "checkpoint": "best.bpk", "epoch": 2, "split": "test", "images": 36,
            "proxy": true, "bbox": {"stats": bbox}, "segm": {"stats": segm},
        });
        assert_eq!(
            serde_json::to_string_pretty(&t).unwrap(),
            serde_json::to_string_pretty(&untyped).unwrap()
        );
    }

    #[test]
    fn metrics_round_trip_and_resume_reads_up_to_an_epoch() {
        let dir = std::env::temp_dir().join(format!("ct-runfiles-{}", std::process::id()));
        let recs = vec![record(1, 0.2), record(2, 0.6), record(3, 0.4)];
        write_metrics(&dir, &recs, &["box", "seg", "dfl"]).unwrap();
        assert_eq!(read_metrics(&dir, 2).unwrap(), recs[..2]);
        assert_eq!(best_epoch(&recs), 2);
        assert_eq!(best_epoch(&[]), 0);
        assert_eq!(train_seconds(&dir).unwrap(), 36.0);
        assert_eq!(total_steps(&dir).unwrap(), 21);
        let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert!(lines[0].starts_with(
            "epoch,lr,time,train/box_loss,train/seg_loss,train/dfl_loss,val/bbox_AP,"
        ));
        assert!(
            lines[1].starts_with("1,0.01,12.0,1.5,0.1,null,-1.0,"),
            "{}",
            lines[1]
        );
        assert_eq!(lines[1].split(',').count(), 3 + 3 + 24);
        // A NaN loss is written as null and read back as NaN.
        let mut nan = record(4, 0.1);
        nan.loss.insert("box".into(), f64::NAN);
        write_metrics(&dir, &[nan], &["box"]).unwrap();
        assert!(read_metrics(&dir, 9).unwrap()[0].loss["box"].is_nan());
        // An epoch without validation: no `val` key, `null` val cells, never the best.
        let mut skipped = record(5, 0.9);
        skipped.val = None;
        skipped.val_time = None;
        let line = json(&skipped);
        assert!(!line.contains("val"), "{line}");
        write_metrics(&dir, &[recs[0].clone(), skipped.clone()], &["box"]).unwrap();
        let back = read_metrics(&dir, 9).unwrap();
        assert_eq!(back[1], skipped);
        assert_eq!(best_epoch(&back), 1);
        let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
        let row: Vec<&str> = csv.lines().nth(2).unwrap().split(',').collect();
        assert_eq!(row.len(), 3 + 1 + 24);
        assert!(row[4..].iter().all(|c| *c == "null"), "{row:?}");
        std::fs::write(dir.join("metrics.jsonl"), "{\"epoch\": 1}\n").unwrap();
        let e = format!("{:#}", read_metrics(&dir, 9).unwrap_err());
        assert!(e.contains("metrics.jsonl line 1"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
