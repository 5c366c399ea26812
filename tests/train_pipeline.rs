//! The training pipeline end to end on tiny data: a smoke run through every stage (render,
//! mix, train, per-epoch eval, checkpoints, test eval) whose run files parse and whose
//! `best.bpk` reproduces `test.json` through `eval`; `--resume` continuing it; the same
//! steps on ndarray; a non-finite loss stopping with a clean error.

use std::path::{Path, PathBuf};

use chicktrain::commands::train::{eval_cmd, predict_cmd, SplitName};
use chicktrain::config::{self, Config, DeviceKind};
use chicktrain::train::trainer::{train, TrainOptions};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ct-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// quickstart.toml shrunk by `--smoke`, cache in `dir`.
fn tiny(dir: &Path, extra: &[&str]) -> Config {
    let mut ov = vec![format!("data.cache=\"{}\"", dir.join("cache").display())];
    ov.extend(extra.iter().map(|s| s.to_string()));
    config::load("quickstart.toml", &ov).unwrap()
}

fn opts(dir: &Path) -> TrainOptions {
    TrainOptions {
        run_dir: Some(dir.join("run")),
        smoke: true,
        quiet: true,
        ..Default::default()
    }
}

#[test]
fn smoke_run_writes_every_file_and_eval_reproduces_it() {
    let dir = tmp("smoke");
    let s = train(tiny(&dir, &[]), &opts(&dir)).unwrap();
    let run = dir.join("run");
    for f in [
        "config.toml",
        "split.json",
        "metrics.jsonl",
        "results.csv",
        "best.bpk",
        "last.bpk",
        "test.json",
        "plots.png",
    ] {
        assert!(run.join(f).is_file(), "{f} missing");
    }
    // The resolved config loads back as a config.
    config::load(run.join("config.toml").to_str().unwrap(), &[]).unwrap();
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    for (i, m) in lines.iter().enumerate() {
        assert_eq!(m["epoch"], i + 1);
        assert!(m["lr"].as_f64().unwrap() > 0.0);
        assert!(m["time"].as_f64().unwrap() > 0.0);
        for k in ["box", "cls", "dfl", "seg"] {
            assert!(m["loss"][k].as_f64().unwrap().is_finite(), "loss.{k}");
        }
        for t in ["bbox", "segm"] {
            assert_eq!(
                m["val"][t]["stats"].as_array().unwrap().len(),
                12,
                "val.{t}.stats"
            );
        }
    }
    let csv = std::fs::read_to_string(run.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3);
    assert_eq!(csv.lines().next().unwrap().split(',').count(), 3 + 4 + 24);
    let test: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("test.json")).unwrap()).unwrap();
    assert_eq!(test["proxy"], true);
    assert_eq!(test["segm"]["stats"].as_array().unwrap().len(), 12);
    assert_eq!(test["bbox"]["stats"], serde_json::json!(s.test.bbox));

    // eval of best.bpk reproduces test.json from the checkpoint alone.
    let out = eval_cmd(&run.join("best.bpk"), SplitName::Test, None, None, true).unwrap();
    let ev: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(ev["bbox"]["stats"], test["bbox"]["stats"]);
    assert_eq!(ev["segm"]["stats"], test["segm"]["stats"]);
    // --data with the run's own resolved config rebuilds the same data and split.
    let own = run.join("config.toml");
    let out = eval_cmd(
        &run.join("best.bpk"),
        SplitName::Test,
        Some(own.to_str().unwrap()),
        None,
        true,
    )
    .unwrap();
    let ev2: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(ev2["segm"]["stats"], test["segm"]["stats"]);
    // ... and the logged validation stats of its epoch.
    let best_epoch = test["epoch"].as_u64().unwrap() as usize;
    let out = eval_cmd(&run.join("best.bpk"), SplitName::Val, None, None, true).unwrap();
    let ev: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        ev["segm"]["stats"],
        lines[best_epoch - 1]["val"]["segm"]["stats"]
    );

    // predict writes overlays and a results file.
    let img_dir = dir.join("imgs");
    std::fs::create_dir_all(&img_dir).unwrap();
    image::RgbImage::from_pixel(80, 60, image::Rgb([200, 180, 150]))
        .save(img_dir.join("a.png"))
        .unwrap();
    predict_cmd(&run.join("best.bpk"), &img_dir, &dir.join("pred"), None).unwrap();
    assert!(dir.join("pred/a.png").is_file());
    chicktrain::annotations::coco::load_results(&dir.join("pred/results.json")).unwrap();

    // --resume continues from last.bpk to a third epoch.
    let mut o = opts(&dir);
    o.resume = true;
    let cfg = tiny(&dir, &["train.epochs=3"]);
    // smoke caps epochs at 2, so resume without smoke on the smoke-shrunk config.
    let mut shrunk = cfg.clone();
    chicktrain::train::smoke::smoke_config(&mut shrunk);
    shrunk.train.epochs = 3;
    o.smoke = false;
    train(shrunk, &o).unwrap();
    let n = std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(n, 3, "resume appends epoch 3 only");
    // Resuming a finished run says so.
    let mut again = cfg;
    chicktrain::train::smoke::smoke_config(&mut again);
    again.train.epochs = 3;
    let e = format!("{:#}", train(again, &o).unwrap_err());
    assert!(e.contains("already completed 3 of 3"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_steps_run_on_ndarray() {
    let dir = tmp("ndarray");
    let mut o = opts(&dir);
    o.device = Some(DeviceKind::Ndarray);
    let cfg = tiny(&dir, &["train.epochs=1", "data.synthetic=0"]);
    let s = train(cfg, &o).unwrap();
    assert!(s.test.segm.iter().all(|v| v.is_finite()));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn non_finite_loss_stops_with_a_clean_error() {
    let dir = tmp("nan");
    // An absurd learning rate blows the weights up within a few steps.
    let cfg = tiny(
        &dir,
        &[
            "train.lr=1e30",
            "train.warmup_epochs=0",
            "train.grad_clip=1e30",
            "train.epochs=2",
            "train.batch=1",
        ],
    );
    let e = format!("{:#}", train(cfg, &opts(&dir)).unwrap_err());
    assert!(e.contains("non-finite"), "{e}");
    assert!(e.contains("epoch") && e.contains("step"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// CI's check of every shipped config: `--smoke` goes through every stage.
#[test]
fn every_shipped_config_runs_in_smoke_mode() {
    let dir = tmp("shipped");
    for (name, _) in config::SHIPPED {
        let ov = [format!("data.cache=\"{}\"", dir.join("cache").display())];
        let cfg = config::load(name, &ov).unwrap();
        let o = TrainOptions {
            run_dir: Some(dir.join(name)),
            smoke: true,
            quiet: true,
            ..Default::default()
        };
        let s = train(cfg, &o).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        assert!(s.run_dir.join("test.json").is_file(), "{name}");
        assert!(s.test.segm.iter().all(|v| v.is_finite()), "{name}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
