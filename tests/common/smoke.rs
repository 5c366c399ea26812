//! The end-to-end `--smoke` scenario of the `train_*` tests, for any shipped config: the
//! run writes every run file, the resolved config loads back, `metrics.jsonl` holds two
//! records with finite losses named as the model logs them, `results.csv` matches it,
//! `test.json` equals the summary, `eval` of `best.bpk` reproduces `test.json` and the
//! logged validation stats of its epoch, `predict` writes an overlay and `results.json`,
//! and `--resume` to epoch 3 appends exactly one record.

use std::path::{Path, PathBuf};

use chicktrain::commands::eval::{eval_cmd, EvalRequest};
use chicktrain::commands::predict::{predict, PredictRequest};
use chicktrain::commands::train::SplitName;
use chicktrain::config::{self, Config};
use chicktrain::train::run_files::{read_metrics, read_test, EpochRecord, StatsRecord};
use chicktrain::train::smoke::smoke_config;
use chicktrain::train::trainer::{train, TrainOptions, TrainSummary};

/// Shipped config `name` with its render cache in `<dir>/cache`, plus `--set`s `extra`.
pub fn shipped(name: &str, dir: &Path, extra: &[&str]) -> Config {
    let mut ov = vec![format!("data.cache=\"{}\"", dir.join("cache").display())];
    ov.extend(extra.iter().map(|s| s.to_string()));
    config::load(name, &ov).unwrap()
}

/// `--smoke`, quiet, into `<dir>/run`.
pub fn smoke_opts(dir: &Path) -> TrainOptions {
    TrainOptions {
        run_dir: Some(dir.join("run")),
        smoke: true,
        quiet: true,
        ..Default::default()
    }
}

/// `eval --json` of `checkpoint` on `split` (`data`: `--data`).
pub fn eval_stats(checkpoint: &Path, split: SplitName, data: Option<&str>) -> StatsRecord {
    let r = EvalRequest {
        data: data.map(str::to_string),
        json: true,
        ..EvalRequest::new(checkpoint, split)
    };
    serde_json::from_str(&eval_cmd(&r).unwrap()).unwrap()
}

/// What [`smoke_scenario`] leaves for a test's own checks.
pub struct SmokeRun {
    /// `<dir>/run`, resumed to epoch 3.
    pub run: PathBuf,
    /// The summary of the 2-epoch `--smoke` run.
    pub summary: TrainSummary,
    /// Its resolved `config.toml`, loaded back.
    pub resolved: Config,
    /// Its 2 records of `metrics.jsonl`.
    pub records: Vec<EpochRecord>,
    /// The smoke-shrunk config at 3 epochs that the resume ran.
    pub resumed: Config,
    /// The resume's options: `--resume` without `--smoke` (which caps epochs at 2).
    pub resume: TrainOptions,
}

fn check_losses(r: &EpochRecord, loss_names: &[&str]) {
    let mut want = loss_names.to_vec();
    want.sort_unstable();
    let keys: Vec<&str> = r.loss.keys().map(String::as_str).collect();
    assert_eq!(keys, want, "epoch {}: loss terms", r.epoch);
    for (k, v) in &r.loss {
        assert!(v.is_finite(), "epoch {}: loss.{k} = {v}", r.epoch);
    }
}

/// Runs the scenario on shipped config `config` in `dir` (render cache and run folder);
/// `loss_names` are the model's loss terms in the order it logs them.
pub fn smoke_scenario(dir: &Path, config: &str, loss_names: &[&str]) -> SmokeRun {
    let s = train(shipped(config, dir, &[]), &smoke_opts(dir)).unwrap();
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
    // What ultralytics users look for first (issue 39): curves, confusion matrix, and
    // the batch mosaics, each a decodable image of the size it is drawn at.
    for (f, size) in [
        ("BoxPR_curve.png", Some((640, 480))),
        ("MaskPR_curve.png", Some((640, 480))),
        ("BoxF1_curve.png", Some((640, 480))),
        ("MaskF1_curve.png", Some((640, 480))),
        ("confusion_matrix.png", Some((1120, 520))),
        ("train_batch0.jpg", None),
        ("val_batch0_labels.jpg", None),
        ("val_batch0_pred.jpg", None),
    ] {
        let img = image::open(run.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        if let Some(wh) = size {
            assert_eq!((img.width(), img.height()), wh, "{f}");
        }
    }
    let resolved = config::load(run.join("config.toml").to_str().unwrap(), &[]).unwrap();

    // Typed records: a missing field, or val stats that are not 12 per IoU type, fail here.
    let records = read_metrics(&run, usize::MAX).unwrap();
    assert_eq!(records.len(), 2);
    for (i, r) in records.iter().enumerate() {
        assert_eq!(r.epoch, i + 1);
        assert!(r.lr > 0.0, "epoch {}: lr {}", r.epoch, r.lr);
        assert!(r.time > 0.0, "epoch {}: time {}", r.epoch, r.time);
        check_losses(r, loss_names);
    }
    let csv = std::fs::read_to_string(run.join("results.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + records.len(), "{csv}");
    let header: Vec<&str> = lines[0].split(',').collect();
    let loss_cols: Vec<String> = loss_names
        .iter()
        .map(|n| format!("train/{n}_loss"))
        .collect();
    assert_eq!(header[3..3 + loss_names.len()], loss_cols, "{}", lines[0]);
    for l in &lines {
        assert_eq!(l.split(',').count(), 3 + loss_names.len() + 24, "{l}");
    }

    // test.json is the summary's test evaluation.
    let test = read_test(&run).unwrap();
    assert_eq!(test.stats(), s.test);
    assert_eq!(test.epoch, s.best_epoch);
    assert_eq!(test.images, s.test_images);
    assert_eq!(test.proxy, s.proxy);
    assert_eq!(
        (test.checkpoint.as_str(), test.split.as_str()),
        ("best.bpk", "test")
    );

    // eval of best.bpk reproduces test.json from the checkpoint alone, and the logged
    // validation stats of its epoch.
    let best = run.join("best.bpk");
    let ev = eval_stats(&best, SplitName::Test, None);
    assert_eq!(ev.bbox, test.bbox);
    assert_eq!(ev.segm, test.segm);
    let ev = eval_stats(&best, SplitName::Val, None);
    assert_eq!(ev.segm, records[test.epoch - 1].val.as_ref().unwrap().segm);

    // predict reads the model kind from the checkpoint, writes overlays and a results file.
    let img_dir = dir.join("imgs");
    std::fs::create_dir_all(&img_dir).unwrap();
    image::RgbImage::from_pixel(80, 60, image::Rgb([200, 180, 150]))
        .save(img_dir.join("a.png"))
        .unwrap();
    predict(&PredictRequest::new(&best, &img_dir, &dir.join("pred"))).unwrap();
    assert!(dir.join("pred/a.png").is_file());
    chicktrain::annotations::coco::load_results(&dir.join("pred/results.json")).unwrap();
    // At another inference size (`--imgsz`, the model is convolutional) the boxes still
    // map back into the 80 × 60 image.
    predict(&PredictRequest {
        imgsz: Some(128),
        ..PredictRequest::new(&best, &img_dir, &dir.join("pred128"))
    })
    .unwrap();
    let dets =
        chicktrain::annotations::coco::load_results(&dir.join("pred128/results.json")).unwrap();
    for d in dets.iter().filter_map(|d| d.bbox) {
        assert!(
            d[0] >= 0.0 && d[1] >= 0.0 && d[0] + d[2] <= 80.01 && d[1] + d[3] <= 60.01,
            "{d:?}"
        );
    }
    // `--augment`: the eight views of the 80 × 60 image (four of them 60 × 80) fused
    // back into it: boxes inside it, masks of its size, scores above --conf.
    let conf = 0.01;
    let mut tta = PredictRequest::new(&best, &img_dir, &dir.join("tta"));
    tta.opts.conf = conf;
    tta.opts.augment = true;
    predict(&tta).unwrap();
    let dets = chicktrain::annotations::coco::load_results(&dir.join("tta/results.json")).unwrap();
    for d in &dets {
        let b = d.bbox.unwrap();
        assert!(
            b[0] >= 0.0 && b[1] >= 0.0 && b[0] + b[2] <= 80.01 && b[1] + b[3] <= 60.01,
            "{b:?}"
        );
        assert!(d.score > conf as f64 && d.score <= 1.0, "{}", d.score);
        let rle = d.segmentation.as_ref().unwrap().to_rle(60, 80).unwrap();
        assert_eq!((rle.width, rle.height), (80, 60));
    }

    // --resume continues from last.bpk to a third epoch (without --smoke, which caps
    // epochs at 2, on the smoke-shrunk config).
    let mut resumed = shipped(config, dir, &[]);
    smoke_config(&mut resumed);
    resumed.train.epochs = 3;
    let resume = TrainOptions {
        resume: true,
        smoke: false,
        ..smoke_opts(dir)
    };
    train(resumed.clone(), &resume).unwrap();
    let after = read_metrics(&run, usize::MAX).unwrap();
    let epochs: Vec<usize> = after.iter().map(|r| r.epoch).collect();
    assert_eq!(epochs, [1, 2, 3], "resume appends epoch 3 only");
    assert_eq!(
        after[..2],
        records[..],
        "resume keeps epochs 1 and 2 as logged"
    );
    check_losses(&after[2], loss_names);

    SmokeRun {
        run,
        summary: s,
        resolved,
        records,
        resumed,
        resume,
    }
}
