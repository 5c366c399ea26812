//! Mask R-CNN through the shared trainer: a `--smoke` run of a shipped R50 config writes
//! every run file with the Mask R-CNN loss terms, `eval` of `best.bpk` reproduces
//! `test.json` and the logged validation stats, `predict` works, `--resume` continues
//! (the shared scenario, `common::smoke`), checkpoints of the other model kind or depth
//! are refused with a clear message, and the same steps run on ndarray.

use chicktrain::config::{self, DeviceKind};
use chicktrain::train::run_files::read_metrics;
use chicktrain::train::smoke::smoke_config;
use chicktrain::train::trainer::train;

mod common;
use common::smoke::{shipped, smoke_opts, smoke_scenario};

#[test]
fn smoke_run_evaluates_reloads_and_resumes() {
    let dir = common::tmp("mrcnn-smoke");
    let r = smoke_scenario(
        &dir,
        "maskrcnn_r50_syn250.toml",
        &["rpn_cls", "rpn_box", "cls", "box", "mask"],
    );
    let config::ModelConfig::Maskrcnn(m) = &r.resolved.model else {
        panic!(
            "resolved config is not a Mask R-CNN: {:?}",
            r.resolved.model
        )
    };
    assert_eq!(m.depth, 50);
    for rec in read_metrics(&r.run, usize::MAX).unwrap() {
        let keys: Vec<&str> = rec.loss.keys().map(String::as_str).collect();
        assert_eq!(
            keys,
            ["box", "cls", "mask", "rpn_box", "rpn_cls"],
            "epoch {}",
            rec.epoch
        );
    }

    // A checkpoint of the other kind, or of another depth, is refused by name.
    let mut yolo = shipped("quickstart.toml", &dir, &[]);
    smoke_config(&mut yolo);
    yolo.train.epochs = 4;
    let e = format!("{:#}", train(yolo, &r.resume).unwrap_err());
    assert!(
        e.contains("model.kind = \"maskrcnn\"") && e.contains("model.kind = \"yolo\""),
        "{e}"
    );
    let mut deeper = r.resumed;
    if let config::ModelConfig::Maskrcnn(m) = &mut deeper.model {
        m.depth = 101;
    }
    deeper.train.epochs = 4;
    let e = format!("{:#}", train(deeper, &r.resume).unwrap_err());
    assert!(
        e.contains("cannot continue from") && e.contains("depth: 50"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_steps_run_on_ndarray() {
    let dir = common::tmp("mrcnn-ndarray");
    let mut o = smoke_opts(&dir);
    o.device = Some(DeviceKind::Ndarray);
    let cfg = shipped("maskrcnn_r50_real_baseline.toml", &dir, &["train.epochs=1"]);
    let s = train(cfg, &o).unwrap();
    assert!(s.test.segm.iter().all(|v| v.is_finite()));
    let m = &read_metrics(&dir.join("run"), usize::MAX).unwrap()[0];
    assert!(m.loss["mask"].is_finite());
    std::fs::remove_dir_all(&dir).unwrap();
}
