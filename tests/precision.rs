//! `train.precision`: bf16 and f16 `--smoke` runs of the binary (a device's float type is
//! fixed per process, so each run is its own process), their f32 checkpoints evaluated in
//! this (f32) process, f16 loss scaling as recorded, and the refusals.

use std::path::Path;

use burn::tensor::{Device, FloatDType};
use chicktrain::commands::train::SplitName;
use chicktrain::config::Precision;
use chicktrain::infer::checkpoint::Checkpoint;
use chicktrain::infer::precision::all_in;
use chicktrain::train::loss_scale::MAX_SCALE;
use chicktrain::train::run_files::{read_metrics, EpochRecord};

mod common;
use common::smoke::eval_stats;
use common::{assert_clean_error, run, tmp};

/// `train --smoke` of shipped `config` into `<dir>/<run>` with `--set`s `extra`.
fn smoke(dir: &Path, config: &str, run_name: &str, extra: &[&str]) -> std::process::Output {
    let cache = format!("data.cache=\"{}\"", dir.join("cache").display());
    let run_dir = dir.join(run_name);
    let mut args = vec![
        "train",
        "--config",
        config,
        "--smoke",
        "--run-dir",
        run_dir.to_str().unwrap(),
        "--set",
        &cache,
    ];
    for e in extra {
        args.extend(["--set", e]);
    }
    run(&args)
}

/// The run trained two epochs with finite losses; its checkpoints hold f32 weights that
/// evaluate in this f32 process. Returns the records.
fn check_run(
    dir: &Path,
    run_name: &str,
    out: &std::process::Output,
    p: Precision,
) -> Vec<EpochRecord> {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{run_name}: {err}");
    assert!(
        err.contains(&format!(
            " in {} (f32 master weights, EMA and checkpoints",
            p.name()
        )),
        "{err}"
    );
    let run = dir.join(run_name);
    let recs = read_metrics(&run, usize::MAX).unwrap();
    assert_eq!(recs.len(), 2, "{run_name}");
    for r in &recs {
        for (k, v) in &r.loss {
            assert!(
                v.is_finite() && *v > 0.0,
                "{run_name} epoch {}: {k} = {v}",
                r.epoch
            );
        }
        assert!(
            r.data_wait_s >= 0.0 && r.data_wait_s <= r.train_time,
            "{r:?}"
        );
    }
    let dev = Device::flex();
    for f in ["best.bpk", "last.bpk"] {
        let ck = Checkpoint::load(&run.join(f)).unwrap();
        assert_eq!(ck.header.config.train.precision, p);
        // Loaded in the file's own type: the weights were written in f32.
        let m = ck.model_f32("ema", &dev).unwrap();
        assert!(all_in(&m, FloatDType::F32), "{run_name}/{f}: ema not f32");
        if f == "last.bpk" {
            let m = ck.model_f32("model", &dev).unwrap();
            assert!(all_in(&m, FloatDType::F32), "{run_name}/{f}: model not f32");
        }
    }
    let ev = eval_stats(&run.join("best.bpk"), SplitName::Test, None);
    for s in ev.bbox.stats.iter().chain(&ev.segm.stats) {
        assert!((-1.0..=1.0).contains(s), "{run_name}: eval stat {s}");
    }
    recs
}

#[test]
fn bf16_smokes_of_every_family_train_and_their_checkpoints_evaluate_in_f32() {
    let dir = tmp("prec-bf16");
    for config in [
        "quickstart.toml",
        "maskrcnn_r50_syn250.toml",
        "mask2former_syn500.toml",
    ] {
        let name = config.trim_end_matches(".toml");
        let out = smoke(&dir, config, name, &["train.precision=bf16"]);
        let recs = check_run(&dir, name, &out, Precision::Bf16);
        assert!(recs
            .iter()
            .all(|r| r.loss_scale.is_none() && r.skipped_steps == 0));
    }
    // A resume must not switch the float type of the optimiser state it continues
    // (checked before the epoch count, which --smoke caps at the 2 already done).
    let resumed = run(&[
        "train",
        "--config",
        "quickstart.toml",
        "--smoke",
        "--resume",
        "--run-dir",
        dir.join("quickstart").to_str().unwrap(),
        "--set",
        &format!("data.cache=\"{}\"", dir.join("cache").display()),
    ]);
    assert_clean_error(
        &resumed,
        &[
            "--resume",
            "train.precision = \"bf16\"",
            "asks for \"f32\"",
            "--set train.precision=bf16",
        ],
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn f16_smoke_scales_the_loss_and_records_every_skipped_step() {
    let dir = tmp("prec-f16");
    let out = smoke(&dir, "quickstart.toml", "q", &["train.precision=f16"]);
    let recs = check_run(&dir, "q", &out, Precision::F16);
    // No growth in 4 steps: the scale halved once per skipped step, from 2^15.
    let mut skipped = 0;
    for r in &recs {
        skipped += r.skipped_steps;
        assert!(r.skipped_steps <= r.steps, "{r:?}");
        let want = MAX_SCALE / 2f32.powi(skipped as i32);
        assert_eq!(r.loss_scale, Some(want), "epoch {}", r.epoch);
    }
    let last = Checkpoint::load(&dir.join("q/last.bpk")).unwrap();
    let s = last
        .header
        .loss_scale
        .expect("an f16 last.bpk keeps the scaler");
    assert_eq!(
        (s.scale, s.skipped),
        (recs[1].loss_scale.unwrap(), skipped as u64)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_precision_values_and_devices_without_it_are_clean_errors() {
    let dir = tmp("prec-bad");
    let out = smoke(&dir, "quickstart.toml", "q", &["train.precision=fp16"]);
    assert_clean_error(&out, &["train", "fp16", "`f32`, `f16`, `bf16`"]);
    let cache = format!("data.cache=\"{}\"", dir.join("cache").display());
    let out = run(&[
        "train",
        "--config",
        "quickstart.toml",
        "--smoke",
        "--device",
        "ndarray",
        "--run-dir",
        dir.join("nd").to_str().unwrap(),
        "--set",
        &cache,
        "--set",
        "train.precision=bf16",
    ]);
    assert_clean_error(
        &out,
        &[
            "train.precision = \"bf16\"",
            "no BF16 support",
            "--device flex",
        ],
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_divergence_guard_still_stops_a_bf16_run() {
    // As in f32 (README): lr 10 explodes the loss at the second step.
    let dir = tmp("prec-div");
    let out = smoke(
        &dir,
        "quickstart.toml",
        "q",
        &["train.precision=bf16", "train.lr=10"],
    );
    assert_clean_error(
        &out,
        &[
            "training diverged",
            "epoch 1, step 2",
            "no checkpoint was written yet",
        ],
    );
    assert!(!dir.join("q/last.bpk").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
