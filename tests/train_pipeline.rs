//! The training pipeline end to end on tiny data: a smoke run through every stage (render,
//! mix, train, per-epoch eval, checkpoints, test eval) whose run files parse and whose
//! `best.bpk` reproduces `test.json` through `eval`, and `--resume` continuing it (the
//! shared scenario, `common::smoke`); the same steps on ndarray; a non-finite loss
//! stopping with a clean error.

use chicktrain::commands::eval::{eval_cmd, EvalRequest};
use chicktrain::commands::train::SplitName;
use chicktrain::config::{self, DeviceKind};
use chicktrain::infer::checkpoint::Checkpoint;
use chicktrain::train::run_files::{read_test, StatsRecord};
use chicktrain::train::trainer::{train, TrainOptions};

mod common;
use common::smoke::{eval_stats, shipped, smoke_opts, smoke_scenario};

/// `eval --split test` of `best` with these flags.
fn eval_test(
    best: &std::path::Path,
    device: Option<DeviceKind>,
    imgsz: Option<usize>,
    json: bool,
    augment: bool,
) -> anyhow::Result<String> {
    eval_cmd(&EvalRequest {
        device,
        imgsz,
        json,
        augment,
        ..EvalRequest::new(best, SplitName::Test)
    })
}

#[test]
fn smoke_run_writes_every_file_and_eval_reproduces_it() {
    let dir = common::tmp("train-smoke");
    let r = smoke_scenario(&dir, "quickstart.toml", &["box", "cls", "dfl", "seg"]);
    assert!(
        r.summary.proxy,
        "quickstart's real images are proxy renders"
    );

    // --data with the run's own resolved config rebuilds the same data and split.
    let own = r.run.join("config.toml");
    let ev = eval_stats(
        &r.run.join("best.bpk"),
        SplitName::Test,
        Some(own.to_str().unwrap()),
    );
    assert_eq!(ev.segm, read_test(&r.run).unwrap().segm);

    // Checkpoints do not depend on the device: the flex-trained best.bpk scores the same
    // on ndarray (on the CPU backends bit for bit; a GPU backend rounds differently).
    let on_ndarray: StatsRecord = serde_json::from_str(
        &eval_test(
            &r.run.join("best.bpk"),
            Some(DeviceKind::Ndarray),
            None,
            true,
            false,
        )
        .unwrap(),
    )
    .unwrap();
    let t = read_test(&r.run).unwrap();
    assert_eq!((&on_ndarray.bbox, &on_ndarray.segm), (&t.bbox, &t.segm));

    // `--imgsz`: the trained size given explicitly is the default; another multiple of 32
    // letterboxes to it (other pixels, so other detections, still a valid COCO score);
    // a size the network cannot take is refused before any work, naming the flag.
    let best = r.run.join("best.bpk");
    let trained = Checkpoint::load(&best).unwrap().header.model.input_size();
    let at = |s: Option<usize>| eval_test(&best, None, s, true, false);
    let same: StatsRecord = serde_json::from_str(&at(Some(trained)).unwrap()).unwrap();
    assert_eq!((same.bbox, same.segm), (t.bbox, t.segm));
    let larger: StatsRecord = serde_json::from_str(&at(Some(trained + 32)).unwrap()).unwrap();
    assert!(larger
        .segm
        .stats
        .iter()
        .all(|&v| v == -1.0 || (0.0..=1.0).contains(&v)));
    let text = eval_test(&best, None, Some(trained + 32), false, false).unwrap();
    assert!(text.contains(&format!("at {} px", trained + 32)), "{text}");
    // The text report is the 12-row table of both IoU types, AP first, ARl last.
    assert!(text.contains("stat      bbox    segm\nAP "), "{text}");
    assert!(text.contains("\nARl "), "{text}");
    // `--save-json`: the scored detections as a COCO results file that scores the same.
    let saved = r.run.join("eval_dets.json");
    let json = eval_cmd(&EvalRequest {
        save_json: Some(saved.clone()),
        json: true,
        ..EvalRequest::new(&best, SplitName::Test)
    })
    .unwrap();
    let stats: StatsRecord = serde_json::from_str(&json).unwrap();
    let dets = chicktrain::annotations::coco::load_results(&saved).unwrap();
    let split = Checkpoint::load(&best).unwrap().header.split;
    assert!(dets.iter().all(|d| split.test.contains(&d.image_id)));
    let real = chicktrain::data::dataset::RealSet::load(&r.resolved.data, r.resolved.seed).unwrap();
    let gt = chicktrain::infer::validate::gt_subset(&real.gt, &split.test);
    let again = chicktrain::eval::evaluate(&gt, &dets, chicktrain::eval::IouType::Segm).unwrap();
    assert_eq!(again.stats, stats.segm.stats);
    // `--augment` (test-time augmentation) scores the same images in eight views: a valid
    // COCO score, and the report says how it was made.
    let tta = eval_test(&best, None, None, false, true).unwrap();
    assert!(tta.contains("test-time augmentation (8 views)"), "{tta}");
    let tta: StatsRecord =
        serde_json::from_str(&eval_test(&best, None, None, true, true).unwrap()).unwrap();
    assert!(tta
        .segm
        .stats
        .iter()
        .chain(&tta.bbox.stats)
        .all(|&v| v == -1.0 || (0.0..=1.0).contains(&v)));
    for bad in [trained + 1, 32, 4096] {
        let e = format!("{:#}", at(Some(bad)).unwrap_err());
        assert!(
            e.contains(&format!("--imgsz {bad}")) && e.contains("multiple of 32"),
            "{e}"
        );
    }

    // Resuming a finished run says so.
    let e = format!("{:#}", train(r.resumed, &r.resume).unwrap_err());
    assert!(e.contains("already completed 3 of 3"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_steps_run_on_ndarray() {
    let dir = common::tmp("train-ndarray");
    let mut o = smoke_opts(&dir);
    o.device = Some(DeviceKind::Ndarray);
    let cfg = shipped(
        "quickstart.toml",
        &dir,
        &["train.epochs=1", "data.synthetic=0"],
    );
    let s = train(cfg, &o).unwrap();
    assert!(s.test.segm.iter().all(|v| v.is_finite()));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn non_finite_loss_stops_with_a_clean_error() {
    let dir = common::tmp("train-nan");
    // An absurd learning rate blows the weights up within a few steps.
    let cfg = shipped(
        "quickstart.toml",
        &dir,
        &[
            "train.lr=1e30",
            "train.warmup_epochs=0",
            "train.grad_clip=1e30",
            "train.epochs=2",
            "train.batch=1",
        ],
    );
    let e = format!("{:#}", train(cfg, &smoke_opts(&dir)).unwrap_err());
    assert!(e.contains("non-finite"), "{e}");
    assert!(e.contains("epoch") && e.contains("step"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// CI's check of every shipped config: `--smoke` goes through every stage.
#[test]
fn every_shipped_config_runs_in_smoke_mode() {
    let dir = common::tmp("train-shipped");
    for (name, _) in config::SHIPPED {
        let cfg = shipped(name, &dir, &[]);
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
