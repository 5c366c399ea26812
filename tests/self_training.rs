//! Self-training on unlabeled photos (issue 38, part 3): a tiny run with an unlabeled
//! folder labels it with the EMA teacher, trains on the pseudo-labels at the configured
//! share without adding steps, relabels on schedule, and is deterministic; bad
//! `[data.unlabeled]` / `[train.self_training]` settings are clear errors.

use std::path::{Path, PathBuf};

use chicktrain::config::{self, Config};
use chicktrain::train::run_files::read_metrics;
use chicktrain::train::self_training::read_records;
use chicktrain::train::trainer::{train, TrainOptions};

mod common;

/// Three "photos" of different shapes (letterboxed like real ones): bright blobs on a
/// dark belt, and a label file beside them that must be ignored.
fn unlabeled_folder(dir: &Path) -> PathBuf {
    let d = dir.join("unlabeled");
    std::fs::create_dir_all(d.join("line2")).unwrap();
    for (k, (w, h)) in [(80u32, 60u32), (64, 64), (50, 70)].into_iter().enumerate() {
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let (cx, cy) = (w as f32 * (0.3 + 0.2 * k as f32), h as f32 * 0.5);
            let r2 = (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2) * 1.8;
            if r2 < (w.min(h) as f32 * 0.3).powi(2) {
                image::Rgb([230, 190, 160])
            } else {
                image::Rgb([40, 45, 50 + (x % 7) as u8])
            }
        });
        let p = if k == 2 {
            d.join("line2").join("c.jpg")
        } else {
            d.join(format!("{k}.png"))
        };
        img.save(&p).unwrap();
    }
    std::fs::write(d.join("0.txt"), "0 0.1 0.1 0.5 0.1 0.5 0.5").unwrap();
    d
}

/// quickstart at 64 px, 4 proxy images + 3 renders, 3 epochs of 2 steps of 4; `extra`
/// overrides after those.
fn tiny(dir: &Path, extra: &[String]) -> Config {
    let mut ov: Vec<String> = vec![
        format!("data.cache=\"{}\"", dir.join("cache").display()),
        "data.image_size=64".into(),
        "data.crop=64".into(),
        "data.real.count=4".into(),
        "data.synthetic=3".into(),
        "train.epochs=3".into(),
        "train.batch=4".into(),
        "train.steps_per_epoch=2".into(),
        "train.val_every=3".into(),
    ];
    ov.extend(extra.iter().cloned());
    config::load("quickstart.toml", &ov).unwrap()
}

fn self_training(dir: &Path, unl: &Path) -> Vec<String> {
    vec![
        format!("data.unlabeled.images=\"{}\"", unl.display()),
        // An untrained teacher scores low: keep nearly everything so labels exist.
        "train.self_training.score_threshold=0.0001".into(),
        "train.self_training.final_threshold=0.00005".into(),
        "train.self_training.start_epoch=1".into(),
        "train.self_training.refresh_every=1".into(),
        "train.self_training.share=0.5".into(),
        format!("name=\"st-{}\"", dir.file_name().unwrap().to_string_lossy()),
    ]
}

fn run(cfg: Config, run_dir: PathBuf) -> chicktrain::train::trainer::TrainSummary {
    let opts = TrainOptions {
        run_dir: Some(run_dir),
        quiet: true,
        ..Default::default()
    };
    train(cfg, &opts).unwrap()
}

#[test]
fn pseudo_labels_are_made_used_refreshed_and_deterministic() {
    let dir = common::tmp("self-training");
    let unl = unlabeled_folder(&dir);
    let cfg = tiny(&dir, &self_training(&dir, &unl));
    let a = run(cfg.clone(), dir.join("a"));
    // Equal steps: self-training does not add optimiser steps.
    assert_eq!(a.steps, 6);
    let recs = read_records(&dir.join("a")).unwrap();
    assert_eq!(recs.len(), 3, "{recs:?}");
    // Epoch 1 is the warm-up: no labels, no pseudo-labelled items.
    assert!(!recs[0].labelled && recs[0].items == 0 && recs[0].threshold.is_none());
    // Labelled before epochs 2 and 3 (refresh_every = 1), the curriculum lowering the
    // threshold from 1e-4 to 5e-5 over them.
    assert!(recs[1].labelled && recs[2].labelled, "{recs:?}");
    assert_eq!(recs[1].threshold, Some(0.0001));
    assert_eq!(recs[2].threshold, Some(0.00005));
    for r in &recs[1..] {
        assert!(r.instances > 0 && r.pool > 0, "no pseudo-labels: {r:?}");
        // Used: 2 of every batch of 4, 2 steps.
        assert_eq!(r.items, 4, "{r:?}");
        assert!(r.pool <= 3);
    }
    // Deterministic from the seed: a second run trains the same losses and labels.
    let b = run(cfg, dir.join("b"));
    assert_eq!(b.steps, 6);
    let again = read_records(&dir.join("b")).unwrap();
    for (x, y) in recs.iter().zip(&again) {
        assert_eq!(
            (x.labelled, x.threshold, x.pool, x.instances, x.items),
            (y.labelled, y.threshold, y.pool, y.instances, y.items)
        );
    }
    let (ma, mb) = (
        read_metrics(&dir.join("a"), 9).unwrap(),
        read_metrics(&dir.join("b"), 9).unwrap(),
    );
    for (x, y) in ma.iter().zip(&mb) {
        assert_eq!(x.loss, y.loss, "epoch {}", x.epoch);
    }
    assert_eq!(a.test.segm, b.test.segm);
    // The same run without the unlabeled folder trains other batches in the same steps.
    let plain = run(tiny(&dir, &[]), dir.join("plain"));
    assert_eq!(plain.steps, 6);
    let mp = read_metrics(&dir.join("plain"), 9).unwrap();
    assert_eq!(
        mp[0].loss, ma[0].loss,
        "the warm-up epoch is the plain run's"
    );
    assert_ne!(mp[1].loss, ma[1].loss, "pseudo-labels changed nothing");
    assert!(read_records(&dir.join("plain")).unwrap().is_empty());

    // (Here, not in the errors test: training runs of one test binary must not overlap,
    // Burn's seeded generator is shared, and the runs above are compared bit for bit.)
    // A folder without images, or with a broken one, stops the run before step 1 and
    // names it.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(empty.join("labels.txt"), "carcass").unwrap();
    let cfg = tiny(
        &dir,
        &[format!("data.unlabeled.images=\"{}\"", empty.display())],
    );
    let opts = TrainOptions {
        run_dir: Some(dir.join("run-empty")),
        quiet: true,
        ..Default::default()
    };
    let e = format!("{:#}", train(cfg.clone(), &opts).unwrap_err());
    assert!(e.contains("holds no .jpg/.jpeg/.png image"), "{e}");
    std::fs::write(empty.join("torn.png"), b"\x89PNG\r\n\x1a\n not really").unwrap();
    let e = format!("{:#}", train(cfg, &opts).unwrap_err());
    assert!(e.contains("torn.png"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn parse_err(dir: &Path, extra: &[String]) -> String {
    let mut ov: Vec<String> = vec![format!("data.cache=\"{}\"", dir.display())];
    ov.extend(extra.iter().cloned());
    format!("{:#}", config::load("quickstart.toml", &ov).unwrap_err())
}

#[test]
fn bad_self_training_settings_are_clear_errors() {
    let dir = common::tmp("self-training-errors");
    let unl = unlabeled_folder(&dir);
    let images = format!("data.unlabeled.images=\"{}\"", unl.display());
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["data.unlabeled.images=\"no/such/folder\"".into()],
            "data.unlabeled.images = \"no/such/folder\" is not a folder",
        ),
        (
            vec!["train.self_training.share=0.5".into()],
            "there is no [data.unlabeled]",
        ),
        (
            vec![images.clone(), "train.self_training.share=1.5".into()],
            "train.self_training.share = 1.5 must be in (0, 1)",
        ),
        (
            vec![images.clone(), "train.self_training.shares=0.5".into()],
            "unknown field `shares`",
        ),
        (
            vec![images.clone(), "data.unlabeled.labels=\"x\"".into()],
            "unknown field `labels`",
        ),
        (
            vec![images.clone(), "train.self_training.start_epoch=50".into()],
            "start_epoch = 50 must be less than train.epochs = 50",
        ),
        (
            vec![
                images.clone(),
                "train.self_training.teacher=\"missing.bpk\"".into(),
            ],
            "neither \"ema\" nor an existing checkpoint",
        ),
    ];
    for (ov, want) in cases {
        let e = parse_err(&dir, &ov);
        assert!(e.contains(want), "{ov:?}: {e}");
    }
    // The table alone turns self-training on with its defaults.
    let cfg = config::load("quickstart.toml", &[images]).unwrap();
    assert!(cfg.data.unlabeled.is_some() && cfg.train.self_training.is_none());

    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_committed_crossdomain_split_loads() {
    // bench/crossdomain/selftrain: ids 1-60 unlabeled (links into the set), 61-120 test.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let unl = chicktrain::data::unlabeled::UnlabeledSet::scan(
        &root.join("bench/crossdomain/selftrain/unlabeled"),
    )
    .unwrap();
    assert_eq!(unl.len(), 60);
    assert!(unl.paths[0].ends_with("xd_00000.jpg") && unl.paths[59].ends_with("xd_00059.jpg"));
    assert!(unl.sizes.iter().all(|&s| s == (320, 320)));
    let test = chicktrain::annotations::coco::CocoDataset::load(
        &root.join("bench/crossdomain/selftrain/test.json"),
    )
    .unwrap();
    let ids: Vec<u64> = test.images.iter().map(|i| i.id).collect();
    assert_eq!(ids, (61..=120).collect::<Vec<u64>>());
    assert!(test.annotations.iter().all(|a| a.image_id > 60));
    // The configs parse from the repository root (cargo runs tests there), as their
    // headers run them.
    let cfg = config::load("bench/crossdomain/selftrain/selftrain.toml", &[]).unwrap();
    assert_eq!(cfg.train.epochs, 25);
    assert!(cfg.data.unlabeled.is_some());
    config::load("bench/crossdomain/selftrain/test.toml", &[]).unwrap();
}
