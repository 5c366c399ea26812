//! Mask2Former through the shared trainer: a `--smoke` run of a shipped config writes every
//! run file with the Mask2Former loss terms, `eval` of `best.bpk` reproduces `test.json`
//! and the logged validation stats, `predict` works, `--resume` continues (the shared
//! scenario, `common::smoke`), and a checkpoint of another model kind is refused by name.

use chicktrain::config;
use chicktrain::train::run_files::read_metrics;
use chicktrain::train::smoke::smoke_config;
use chicktrain::train::trainer::train;

mod common;
use common::smoke::{shipped, smoke_scenario};

#[test]
fn smoke_run_evaluates_reloads_and_resumes() {
    let dir = common::tmp("m2f-smoke");
    let r = smoke_scenario(&dir, "mask2former_syn250.toml", &["cls", "mask", "dice"]);
    let config::ModelConfig::Mask2former(m) = &r.resolved.model else {
        panic!(
            "resolved config is not a Mask2Former: {:?}",
            r.resolved.model
        )
    };
    assert_eq!((m.depth, m.queries, m.dec_layers), (50, Some(10), Some(3)));
    assert_eq!(r.resolved.train.backbone_lr_mult, 0.1);
    for rec in read_metrics(&r.run, usize::MAX).unwrap() {
        let keys: Vec<&str> = rec.loss.keys().map(String::as_str).collect();
        assert_eq!(keys, ["cls", "dice", "mask"], "epoch {}", rec.epoch);
    }
    let mut yolo = shipped("quickstart.toml", &dir, &[]);
    smoke_config(&mut yolo);
    yolo.train.epochs = 4;
    let e = format!("{:#}", train(yolo, &r.resume).unwrap_err());
    assert!(
        e.contains("model.kind = \"mask2former\"") && e.contains("model.kind = \"yolo\""),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
