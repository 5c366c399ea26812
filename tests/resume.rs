//! Crash safety: `--resume` after a stop gives the same epoch as an uninterrupted run
//! (optimiser, schedule, EMA and data order restored), and `kill -9` at any moment leaves
//! checkpoints and metrics that load (every file is written through a temp file and a
//! rename, `util::write_atomic`).

mod common;

use std::path::Path;

use chicktrain::infer::checkpoint::Checkpoint;
use common::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Smoke sets with a learning rate that does not depend on `train.epochs` (linear
/// schedule with lrf 1: the factor is 1 every epoch), so a 1-epoch run resumed to 2
/// epochs must follow the 2-epoch run step for step.
const FLAT_LR: [&str; 2] = ["train.schedule=\"linear\"", "train.lrf=1.0"];

fn metrics(dir: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(dir.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn resumed_run_matches_the_uninterrupted_one() {
    let d = tmp("resume-eq");
    let (a, b) = (d.join("a"), d.join("b"));
    assert_success(&run(&smoke_args(
        &a,
        &[FLAT_LR[0], FLAT_LR[1], "train.epochs=2"],
    )));
    assert_success(&run(&smoke_args(
        &b,
        &[FLAT_LR[0], FLAT_LR[1], "train.epochs=1"],
    )));
    let mut resume = smoke_args(&b, &[FLAT_LR[0], FLAT_LR[1], "train.epochs=2"]);
    resume.push("--resume".into());
    assert_success(&run(&resume));
    let (ma, mb) = (metrics(&a), metrics(&b));
    assert_eq!((ma.len(), mb.len()), (2, 2));
    for e in 0..2 {
        assert_eq!(ma[e]["lr"], mb[e]["lr"], "epoch {}", e + 1);
        for t in ["box", "cls", "dfl", "seg"] {
            let (x, y) = (
                ma[e]["loss"][t].as_f64().unwrap(),
                mb[e]["loss"][t].as_f64().unwrap(),
            );
            assert!(
                (x - y).abs() <= 1e-5 * x.abs().max(1.0),
                "epoch {} {t} loss: uninterrupted {x}, resumed {y}",
                e + 1
            );
        }
        for iou in ["bbox", "segm"] {
            let sa = ma[e]["val"][iou]["stats"].as_array().unwrap();
            let sb = mb[e]["val"][iou]["stats"].as_array().unwrap();
            for (x, y) in sa.iter().zip(sb) {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                assert!(
                    (x - y).abs() < 1e-9,
                    "epoch {} val {iou}: {sa:?} vs {sb:?}",
                    e + 1
                );
            }
        }
    }
    // The EMA weights of the final checkpoints agree too.
    let dev = burn::tensor::Device::flex();
    let wa = Checkpoint::load(&a.join("last.bpk")).unwrap();
    let wb = Checkpoint::load(&b.join("last.bpk")).unwrap();
    assert_eq!(wa.header.ema_updates, wb.header.ema_updates);
    let (ea, eb) = (
        wa.model("ema", &dev).unwrap(),
        wb.model("ema", &dev).unwrap(),
    );
    let x = burn::tensor::Tensor::<4>::full([1, 3, 64, 64], 0.5, &dev);
    let logits = |m: &chicktrain::infer::detector::Detector, x| match m {
        chicktrain::infer::detector::Detector::Yolo(m) => m.forward(x).cls_logits,
        _ => panic!("quickstart trains a YOLO model"),
    };
    let (oa, ob) = (logits(&ea, x.clone()), logits(&eb, x));
    let diff = (oa - ob).abs().max().into_scalar::<f32>();
    assert!(diff < 1e-4, "EMA outputs differ by {diff}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// kill -9 at seeded random moments of a long smoke run (each epoch rewrites last.bpk,
/// best.bpk and metrics.jsonl); after every kill all three must load, and `--resume`
/// must continue.
#[cfg(unix)]
#[test]
fn kill_9_never_leaves_a_torn_checkpoint() {
    let d = tmp("kill9");
    let rd = d.join("run");
    let sets = ["train.epochs=1000", "data.synthetic=4"];
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let dev = burn::tensor::Device::flex();
    for round in 0..5 {
        let mut args = smoke_args(&rd, &sets);
        // --smoke caps epochs at 2: undo that with a plain run of the smoke sizes.
        args.retain(|a| a != "--smoke");
        for s in [
            "data.image_size=64",
            "data.crop=64",
            "data.real.count=9",
            "train.batch=4",
        ] {
            args.push("--set".into());
            args.push(s.into());
        }
        if round > 0 {
            args.push("--resume".into());
        }
        let mut child = bin()
            .args(&args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let t0 = std::time::Instant::now();
        while !rd.join("last.bpk").exists() {
            assert!(t0.elapsed().as_secs() < 120, "no checkpoint after 120 s");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        std::thread::sleep(std::time::Duration::from_millis(rng.random_range(50..1500)));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        for f in ["last.bpk", "best.bpk"] {
            let ck = Checkpoint::load(&rd.join(f))
                .unwrap_or_else(|e| panic!("round {round}: {f} torn: {e:#}"));
            ck.model("ema", &dev)
                .unwrap_or_else(|e| panic!("round {round}: {f} weights: {e:#}"));
        }
        let m = metrics(&rd);
        assert!(!m.is_empty(), "round {round}: metrics.jsonl empty");
    }
    std::fs::remove_dir_all(&d).unwrap();
}
