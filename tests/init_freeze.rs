//! `model.init` from a chicktrain checkpoint and `train.freeze` (issue 15 §1, issue 14 §3):
//! a `--smoke` run started from another run's `best.bpk` loads every tensor; with
//! `train.freeze = 3` the tensors of ultralytics layers 0–2 (weights, biases and BatchNorm
//! running statistics) are bit-identical to the start after training steps, in the raw
//! weights and in the EMA, also across `--resume`, while the rest trains; a model with
//! another class count re-initialises exactly the class branch and says so; another family,
//! a PyTorch file for YOLO and a garbage file are clean errors naming the file. For Mask
//! R-CNN, `train.freeze = 2` keeps the stem and res2 across an epoch and `--resume`, and a
//! torchvision file given through the config ends up, frozen, exactly in those stages.

mod common;

use std::collections::HashMap;
use std::path::Path;

use burn::tensor::Device;
use chicktrain::infer::checkpoint::Checkpoint;
use chicktrain::infer::detector::{Detector, DetectorConfig};
use chicktrain::model::weights::{collect, snapshot_data};
use chicktrain::model::yolo::YoloSegConfig;
use chicktrain::train::init::load_init;
use chicktrain::train::trainer::{train, TrainOptions};
use common::smoke::{shipped, smoke_opts};
use common::*;

/// Every float tensor of section `section` of a checkpoint, by module path.
fn tensors(ck: &Path, section: &str) -> HashMap<String, Vec<f32>> {
    let ck = Checkpoint::load(ck).unwrap();
    let m = ck.model(section, &Device::flex()).unwrap();
    let snaps = match m {
        Detector::Yolo(m) => collect(&m),
        Detector::MaskRcnn(m) => collect(&m),
        Detector::Mask2Former(m) => collect(&m),
    };
    snaps
        .into_iter()
        .map(|s| {
            (
                s.name.clone(),
                snapshot_data(s).unwrap().try_to_vec::<f32>().unwrap(),
            )
        })
        .collect()
}

/// The error of `model.init` from `path` into `model` (a model of `config`).
fn init_error(model: Detector, config: &DetectorConfig, path: &Path, dev: &Device) -> String {
    format!("{:#}", load_init(model, config, path, dev).unwrap_err())
}

fn frozen(path: &str) -> bool {
    ["backbone.l0.", "backbone.l1.", "backbone.l2."]
        .iter()
        .any(|p| path.starts_with(p))
}

#[test]
fn init_from_a_checkpoint_and_frozen_stages_stay_bit_identical() {
    let d = tmp("init-freeze");
    let (a, b) = (d.join("a"), d.join("b"));
    train(
        shipped("quickstart", &a, &["train.epochs=1"]),
        &smoke_opts(&a),
    )
    .unwrap();
    let start = a.join("run/best.bpk");
    let init = format!("model.init=\"{}\"", start.display());
    let sets = [init.as_str(), "train.freeze=3", "train.epochs=1"];
    train(shipped("quickstart", &b, &sets), &smoke_opts(&b)).unwrap();

    let t0 = tensors(&start, "ema");
    let n_frozen = t0.keys().filter(|k| frozen(k)).count();
    assert!(n_frozen > 20, "layers 0–2 hold {n_frozen} tensors");
    assert!(t0.keys().any(|k| frozen(k) && k.ends_with("running_mean")));
    let check = |ck: &Path, section: &str| {
        let t = tensors(ck, section);
        assert_eq!(t.len(), t0.len());
        let mut moved = 0;
        for (k, v) in &t {
            if frozen(k) {
                assert!(v == &t0[k], "{section} {k} changed although frozen");
            } else if v != &t0[k] {
                moved += 1;
            }
        }
        assert!(
            moved > 20,
            "{section}: only {moved} unfrozen tensors changed"
        );
    };
    check(&b.join("run/last.bpk"), "model");
    check(&b.join("run/last.bpk"), "ema");

    // --resume keeps them frozen (and ignores model.init: it is not reloaded).
    let more = [init.as_str(), "train.freeze=3", "train.epochs=2"];
    let opts = TrainOptions {
        run_dir: Some(b.join("run")),
        smoke: true,
        resume: true,
        quiet: true,
        ..Default::default()
    };
    train(shipped("quickstart", &b, &more), &opts).unwrap();
    assert_eq!(
        Checkpoint::load(&b.join("run/last.bpk"))
            .unwrap()
            .header
            .epoch,
        2
    );
    check(&b.join("run/last.bpk"), "model");
    check(&b.join("run/last.bpk"), "ema");

    // Another class count: the class branch (and only it) starts fresh, and says so.
    let dev = Device::flex();
    let ck = Checkpoint::load(&start).unwrap();
    let DetectorConfig::Yolo(c) = &ck.header.model else {
        panic!()
    };
    let c3 = YoloSegConfig {
        num_classes: 3,
        ..c.clone()
    };
    let (_, note) = load_init(
        Detector::Yolo(c3.init(&dev)),
        &DetectorConfig::Yolo(c3.clone()),
        &start,
        &dev,
    )
    .unwrap();
    assert!(note.contains("keep their fresh initialisation"), "{note}");
    let listed = note.lines().nth(1).unwrap().split(": ").last().unwrap();
    assert!(
        listed.split(", ").all(|m| m.starts_with("head.cls.")),
        "{note}"
    );

    // Another family, a PyTorch file for YOLO, garbage: clean errors naming the file.
    let mcfg = chicktrain::model::maskrcnn::MaskRcnnConfig::new(18, 1).with_width_mult(0.25);
    let e = init_error(
        Detector::MaskRcnn(mcfg.init(&dev)),
        &DetectorConfig::Maskrcnn(mcfg.clone()),
        &start,
        &dev,
    );
    assert!(
        e.contains("best.bpk") && e.contains("cannot start the other"),
        "{e}"
    );
    let pth =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/torchvision/resnet18_w8.pth");
    let e = init_error(
        Detector::Yolo(c.init(&dev)),
        &DetectorConfig::Yolo(c.clone()),
        &pth,
        &dev,
    );
    assert!(
        e.contains("resnet18_w8.pth") && e.contains("no ultralytics weights fit it"),
        "{e}"
    );
    let g = d.join("garbage.bpk");
    std::fs::write(&g, b"CHICKTRAIN-CKPT1\n\x05").unwrap();
    let out = run(&smoke_args(
        &d.join("c"),
        &[&format!("model.init=\"{}\"", g.display())],
    ));
    assert_clean_error(&out, &["garbage.bpk", "truncated"]);
    let out = run(&smoke_args(&d.join("c"), &["train.freeze=24"]));
    assert_clean_error(&out, &["train.freeze = 24 must be at most 23"]);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Mask R-CNN, `train.freeze = 2` (detectron2's default `FREEZE_AT`): the stem and res2
/// (weights and BatchNorm statistics) do not change over an epoch of steps (epoch 1 →
/// epoch 2 through `--resume`), res3 onwards does.
#[test]
fn maskrcnn_freeze_at_2_keeps_stem_and_res2() {
    let d = tmp("freeze-mrcnn");
    let sets = ["train.freeze=2", "train.epochs=1"];
    train(shipped("maskrcnn_r50_syn250", &d, &sets), &smoke_opts(&d)).unwrap();
    let last = d.join("run/last.bpk");
    let (m1, e1) = (tensors(&last, "model"), tensors(&last, "ema"));
    let opts = TrainOptions {
        run_dir: Some(d.join("run")),
        smoke: true,
        resume: true,
        quiet: true,
        ..Default::default()
    };
    train(
        shipped(
            "maskrcnn_r50_syn250",
            &d,
            &["train.freeze=2", "train.epochs=2"],
        ),
        &opts,
    )
    .unwrap();
    let (m2, e2) = (tensors(&last, "model"), tensors(&last, "ema"));
    let frozen = |k: &str| k.starts_with("backbone.stem.") || k.starts_with("backbone.stages.0.");
    for (before, after, what) in [(&m1, &m2, "model"), (&e1, &e2, "ema")] {
        let mut moved = 0;
        for (k, v) in after {
            if frozen(k) {
                assert!(v == &before[k], "{what} {k} changed although frozen");
            } else if v != &before[k] {
                moved += 1;
            }
        }
        assert!(moved > 20, "{what}: only {moved} unfrozen tensors changed");
    }
    assert!(m1
        .keys()
        .any(|k| frozen(k) && k.ends_with("bn.running_var")));
    std::fs::remove_dir_all(&d).unwrap();
}

/// The user path for torchvision weights, through the config: `--set model.init=X.pth`
/// with `train.freeze = 2` on a Mask R-CNN shaped like the fixture (paper preset at width
/// ×0.125, 16-wide FPN): after an epoch the frozen stem and res2 hold exactly the file's
/// values (fp16 widened to f32, BatchNorm statistics included), everything else loaded
/// from it has trained away from them.
#[test]
fn torchvision_weights_through_the_config_and_frozen_stages_keep_them() {
    use chicktrain::model::maskrcnn::torchvision::map_state_dict;
    use chicktrain::model::weights::read_file;
    let d = tmp("tv-config");
    let pth = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/torchvision/maskrcnn_r50_w8.pth");
    let init = format!("model.init=\"{}\"", pth.display());
    let sets = [
        init.as_str(),
        "train.freeze=2",
        "data.image_size=64",
        "data.crop=64",
        "data.real.count=9",
        "data.real.limit=9",
        "data.synthetic=4",
        "train.epochs=1",
        "train.batch=4",
        "train.warmup_iters=2",
        "model.preset=\"paper\"",
        "model.width_mult=0.125",
        "model.fpn_channels=16",
        "model.box_fc_dim=32",
        "model.mask_conv_dim=16",
    ];
    let opts = TrainOptions {
        run_dir: Some(d.join("run")),
        quiet: true,
        ..Default::default()
    };
    train(shipped("maskrcnn_r50_syn250", &d, &sets), &opts).unwrap();
    let file: HashMap<String, Vec<f32>> = map_state_dict(read_file(&pth, &[]).unwrap(), 1)
        .unwrap()
        .snapshots
        .into_iter()
        .map(|s| {
            (
                s.name.clone(),
                snapshot_data(s).unwrap().try_to_vec::<f32>().unwrap(),
            )
        })
        .collect();
    let trained = tensors(&d.join("run/last.bpk"), "model");
    let frozen = |k: &str| k.starts_with("backbone.stem.") || k.starts_with("backbone.stages.0.");
    let (mut same, mut moved) = (0, 0);
    for (k, v) in &file {
        if frozen(k) {
            assert!(v == &trained[k], "{k}: frozen, yet not the file's value");
            same += 1;
        } else if v != &trained[k] {
            moved += 1;
        }
    }
    assert!(
        same > 40 && moved > 100,
        "{same} frozen kept, {moved} trained"
    );
    std::fs::remove_dir_all(&d).unwrap();
}
