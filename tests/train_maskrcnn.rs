//! Mask R-CNN through the shared trainer: a `--smoke` run of a shipped R50 config writes
//! every run file with the Mask R-CNN loss terms, `eval` of `best.bpk` reproduces
//! `test.json` and the logged validation stats, `predict` works, `--resume` continues,
//! checkpoints of the other model kind are refused with a clear message, and the same
//! steps run on ndarray.

use std::path::{Path, PathBuf};

use chicktrain::commands::train::{eval_cmd, predict_cmd, SplitName};
use chicktrain::config::{self, Config, DeviceKind};
use chicktrain::train::smoke::smoke_config;
use chicktrain::train::trainer::{train, TrainOptions};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ct-mrcnn-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A shipped Mask R-CNN config, render cache in `dir`.
fn shipped(name: &str, dir: &Path, extra: &[&str]) -> Config {
    let mut ov = vec![format!("data.cache=\"{}\"", dir.join("cache").display())];
    ov.extend(extra.iter().map(|s| s.to_string()));
    config::load(name, &ov).unwrap()
}

fn opts(dir: &Path) -> TrainOptions {
    TrainOptions {
        run_dir: Some(dir.join("run")),
        smoke: true,
        quiet: true,
        ..Default::default()
    }
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn smoke_run_evaluates_reloads_and_resumes() {
    let dir = tmp("smoke");
    let s = train(shipped("maskrcnn_r50_syn250.toml", &dir, &[]), &opts(&dir)).unwrap();
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
    let resolved = config::load(run.join("config.toml").to_str().unwrap(), &[]).unwrap();
    let config::ModelConfig::Maskrcnn(m) = &resolved.model else {
        panic!("resolved config is not a Mask R-CNN: {:?}", resolved.model)
    };
    assert_eq!(m.depth, 50);
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    for m in &lines {
        let loss = m["loss"].as_object().unwrap();
        let mut keys: Vec<&str> = loss.keys().map(|k| k.as_str()).collect();
        keys.sort_unstable();
        assert_eq!(keys, ["box", "cls", "mask", "rpn_box", "rpn_cls"]);
        for (k, v) in loss {
            assert!(v.as_f64().unwrap().is_finite(), "loss.{k}");
        }
        assert_eq!(m["val"]["segm"]["stats"].as_array().unwrap().len(), 12);
    }
    let csv = std::fs::read_to_string(run.join("results.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(header.contains("train/rpn_cls_loss") && header.contains("train/mask_loss"));
    assert_eq!(header.split(',').count(), 3 + 5 + 24);
    for row in csv.lines().skip(1) {
        assert_eq!(row.split(',').count(), 3 + 5 + 24, "{row}");
    }

    // eval of best.bpk reproduces test.json, and the logged val stats of its epoch.
    let test = json(&run.join("test.json"));
    assert_eq!(test["segm"]["stats"], serde_json::json!(s.test.segm));
    let ev: serde_json::Value = serde_json::from_str(
        &eval_cmd(&run.join("best.bpk"), SplitName::Test, None, None, true).unwrap(),
    )
    .unwrap();
    assert_eq!(ev["bbox"]["stats"], test["bbox"]["stats"]);
    assert_eq!(ev["segm"]["stats"], test["segm"]["stats"]);
    let best_epoch = test["epoch"].as_u64().unwrap() as usize;
    let ev: serde_json::Value = serde_json::from_str(
        &eval_cmd(&run.join("best.bpk"), SplitName::Val, None, None, true).unwrap(),
    )
    .unwrap();
    assert_eq!(
        ev["segm"]["stats"],
        lines[best_epoch - 1]["val"]["segm"]["stats"]
    );

    // predict reads the model kind from the checkpoint.
    let img_dir = dir.join("imgs");
    std::fs::create_dir_all(&img_dir).unwrap();
    image::RgbImage::from_pixel(80, 60, image::Rgb([200, 180, 150]))
        .save(img_dir.join("a.png"))
        .unwrap();
    predict_cmd(&run.join("best.bpk"), &img_dir, &dir.join("pred"), None).unwrap();
    assert!(dir.join("pred/a.png").is_file());
    chicktrain::annotations::coco::load_results(&dir.join("pred/results.json")).unwrap();

    // --resume continues from last.bpk to a third epoch (without --smoke, which caps
    // epochs at 2, on the smoke-shrunk config).
    let mut o = opts(&dir);
    o.resume = true;
    o.smoke = false;
    let mut shrunk = shipped("maskrcnn_r50_syn250.toml", &dir, &[]);
    smoke_config(&mut shrunk);
    shrunk.train.epochs = 3;
    train(shrunk.clone(), &o).unwrap();
    let n = std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(n, 3, "resume appends epoch 3 only");

    // A checkpoint of the other kind, or of another depth, is refused by name.
    let mut yolo = shipped("quickstart.toml", &dir, &[]);
    smoke_config(&mut yolo);
    yolo.train.epochs = 4;
    let e = format!("{:#}", train(yolo, &o).unwrap_err());
    assert!(
        e.contains("model.kind = \"maskrcnn\"") && e.contains("model.kind = \"yolo\""),
        "{e}"
    );
    let mut deeper = shrunk;
    if let config::ModelConfig::Maskrcnn(m) = &mut deeper.model {
        m.depth = 101;
    }
    deeper.train.epochs = 4;
    let e = format!("{:#}", train(deeper, &o).unwrap_err());
    assert!(
        e.contains("cannot continue from") && e.contains("depth: 50"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_steps_run_on_ndarray() {
    let dir = tmp("ndarray");
    let mut o = opts(&dir);
    o.device = Some(DeviceKind::Ndarray);
    let cfg = shipped("maskrcnn_r50_real_baseline.toml", &dir, &["train.epochs=1"]);
    let s = train(cfg, &o).unwrap();
    assert!(s.test.segm.iter().all(|v| v.is_finite()));
    let m: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(dir.join("run/metrics.jsonl"))
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    assert!(m["loss"]["mask"].as_f64().unwrap().is_finite());
    std::fs::remove_dir_all(&dir).unwrap();
}
