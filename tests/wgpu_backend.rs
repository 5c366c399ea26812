//! The `wgpu` feature end to end (built only with `--features wgpu`; CI runs it on Mesa's
//! software Vulkan driver, lavapipe, so the GPU path is exercised without a GPU):
//! the same `--smoke` run trained on `wgpu` and on `flex` logs close losses, and each
//! run's checkpoint means the same network on either device — raw YOLO outputs within a
//! stated float tolerance, and the same COCO stats when scored on `wgpu` and on `flex`.
#![cfg(feature = "wgpu")]

mod common;

use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::config::DeviceKind;
use chicktrain::data::ellipses::ellipse_batch;
use chicktrain::infer::checkpoint::Checkpoint;
use chicktrain::infer::detector::Detector;
use chicktrain::infer::device::device_of;
use chicktrain::infer::validate::{score_checkpoint, SplitName};
use chicktrain::train::run_files::read_metrics;
use chicktrain::train::trainer::{train, TrainOptions};
use chicktrain::util::tensor::to_host;

use common::smoke::shipped;

/// Largest `|a − b| / (1 + |a|)` over two outputs of one network.
fn max_rel(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / (1.0 + x.abs()))
        .fold(0.0, f32::max)
}

/// The YOLO outputs (box logits, class logits, mask coefficients, prototypes) of
/// `checkpoint`'s EMA weights on `dev` for a fixed batch of 64 px images.
fn outputs(ck: &Checkpoint, dev: &Device) -> [Vec<f32>; 4] {
    let Detector::Yolo(m) = ck.model("ema", dev).unwrap() else {
        panic!("quickstart is a YOLO config")
    };
    let (px, _) = ellipse_batch(2, 64, 2, 7);
    let o = m.forward(Tensor::<4>::from_data(
        TensorData::new(px, [2, 3, 64, 64]),
        dev,
    ));
    [
        to_host(o.box_dist),
        to_host(o.cls_logits),
        to_host(o.mask_coef),
        to_host(o.proto),
    ]
}

/// A `--smoke` quickstart on `device` into `<root>/<name>` (renders cached in
/// `<root>/cache`, shared): 64 px, 9 real and 4 synthetic images, 2 epochs.
fn smoke_run(root: &std::path::Path, name: &str, device: DeviceKind) -> std::path::PathBuf {
    let cfg = shipped("quickstart.toml", root, &[]);
    let opts = TrainOptions {
        run_dir: Some(root.join(name)),
        smoke: true,
        quiet: true,
        device: Some(device),
        ..Default::default()
    };
    train(cfg, &opts).unwrap();
    root.join(name)
}

/// Bound on the outputs' relative difference between devices: f32 kernels that sum in
/// another order (measured on lavapipe: ≤ 7.2e-7 over the four outputs of both runs).
const OUTPUT_TOL: f32 = 1e-4;

#[test]
fn wgpu_and_flex_train_alike_and_read_each_others_checkpoints() {
    let wgpu = device_of(DeviceKind::Wgpu).unwrap_or_else(|e| {
        panic!("{e:#}\n(this test needs a Vulkan driver: on Debian `apt-get install mesa-vulkan-drivers` gives lavapipe)")
    });
    let flex = device_of(DeviceKind::Flex).unwrap();
    let root = std::env::temp_dir().join(format!("ct-wgpu-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let on_wgpu = smoke_run(&root, "wgpu", DeviceKind::Wgpu);
    let on_flex = smoke_run(&root, "flex", DeviceKind::Flex);

    // Same initial weights (drawn on the CPU from the seed, whatever the device), data and
    // steps: the first epoch's mean losses agree closely (they part slowly as rounding
    // differences compound through the updates). Before the weights were drawn on the CPU,
    // each backend's generator gave its own, and this held only by chance.
    let (a, b) = (
        read_metrics(&on_wgpu, 1).unwrap(),
        read_metrics(&on_flex, 1).unwrap(),
    );
    for (k, x) in &a[0].loss {
        let y = b[0].loss[k];
        assert!(x.is_finite() && y.is_finite(), "{k}: {x} vs {y}");
        assert!(
            (x - y).abs() <= 0.05 * (1.0 + y.abs()),
            "epoch 1 loss {k}: wgpu {x} vs flex {y}"
        );
    }

    for run in [&on_wgpu, &on_flex] {
        let best = run.join("best.bpk");
        let ck = Checkpoint::load(&best).unwrap();
        let (g, f) = (outputs(&ck, &wgpu), outputs(&ck, &flex));
        let rel: Vec<f32> = g.iter().zip(&f).map(|(g, f)| max_rel(f, g)).collect();
        eprintln!(
            "{}: wgpu vs flex outputs, max relative difference {rel:?}",
            run.display()
        );
        assert!(
            rel.iter().all(|r| *r <= OUTPUT_TOL),
            "{}: outputs differ by {rel:?} (bound {OUTPUT_TOL})",
            run.display()
        );
        // The same checkpoint on each device, one view.
        let score = |device| {
            score_checkpoint(&best, SplitName::Test, None, Some(device), None, false).unwrap()
        };
        let (sg, sf) = (score(DeviceKind::Wgpu), score(DeviceKind::Flex));
        for (x, y) in sg
            .stats
            .bbox
            .iter()
            .chain(&sg.stats.segm)
            .zip(sf.stats.bbox.iter().chain(&sf.stats.segm))
        {
            assert!(
                (x - y).abs() <= 0.01,
                "{}: stats {:?} vs {:?}",
                run.display(),
                sg.stats,
                sf.stats
            );
        }
    }
    std::fs::remove_dir_all(&root).unwrap();
}
