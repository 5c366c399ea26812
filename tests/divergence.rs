//! Divergence detection end to end (`src/train/divergence.rs`): learning rate 10 stops the
//! run naming the epoch, step and loss term, exits 2, and leaves the last good
//! checkpoint untouched and loadable; learning rate 1e-9 trains without NaN.

mod common;

use chicktrain::infer::checkpoint::Checkpoint;
use common::*;

#[test]
fn lr_10_is_detected_and_the_last_good_checkpoint_survives() {
    let d = tmp("diverge");
    // From scratch (the command): AdamW at lr 10 explodes on its first update.
    let rd = d.join("scratch");
    let out = run(&smoke_args(&rd, &["train.lr=10"]));
    assert_clean_error(
        &out,
        &[
            "training diverged",
            "loss exploded at epoch 1, step 2",
            "no checkpoint was written yet",
        ],
    );
    assert!(!rd.join("last.bpk").exists() && !rd.join("best.bpk").exists());

    // One good epoch, then resume at lr 10 without warmup: epoch 2 diverges.
    let rd = d.join("resumed");
    assert_success(&run(&smoke_args(&rd, &["train.epochs=1"])));
    let last = rd.join("last.bpk");
    let before = std::fs::read(&last).unwrap();
    let mut a = smoke_args(
        &rd,
        &["train.epochs=2", "train.lr=10", "train.warmup_epochs=0"],
    );
    a.push("--resume".into());
    let out = run(&a);
    assert_clean_error(
        &out,
        &[
            "training diverged",
            "at epoch 2, step",
            "last.bpk still holds epoch 1",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        ["box", "cls", "dfl", "seg", "total"]
            .iter()
            .any(|t| err.contains(&format!("{t} loss"))),
        "names the term: {err}"
    );
    assert_eq!(
        std::fs::read(&last).unwrap(),
        before,
        "last.bpk was rewritten"
    );
    let ck = Checkpoint::load(&last).unwrap();
    assert_eq!(ck.header.epoch, 1);
    let dev = burn::tensor::Device::flex();
    ck.model("ema", &dev).unwrap();
    ck.model("model", &dev).unwrap();
    let out = run(&["eval", "--checkpoint", last.to_str().unwrap(), "--json"]);
    assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["segm"]["stats"].as_array().unwrap().len(), 12);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn lr_1e9_trains_a_smoke_without_nan() {
    let d = tmp("tiny-lr");
    let rd = d.join("run");
    assert_success(&run(&smoke_args(&rd, &["train.lr=1e-9"])));
    let text = std::fs::read_to_string(rd.join("metrics.jsonl")).unwrap();
    assert_eq!(text.lines().count(), 2);
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        for t in ["box", "cls", "dfl", "seg"] {
            let x = v["loss"][t].as_f64().expect("a number, not null (NaN)");
            assert!(x.is_finite() && x >= 0.0, "{t} = {x}");
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}
