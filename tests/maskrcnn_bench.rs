//! Mask R-CNN timing harness, ignored by default (it is a measurement, not a check):
//!
//! ```text
//! MRCNN_BENCH="50:512,50:640,101:512,101:640" MRCNN_RUNS=2 \
//!   cargo test --release --test maskrcnn_bench -- --ignored --nocapture
//! ```
//!
//! Compact preset (`MaskRcnnConfig::new(depth, 1)`; `p50:640` for `paper(50, 1)`) on flex, batch 1 inference and batch 2
//! training; prints params, GFLOPs and `MaskRcnnBench` rows.

use burn::tensor::Device;
use chicktrain::model::maskrcnn::bench::bench_maskrcnn;
use chicktrain::model::maskrcnn::MaskRcnnConfig;

#[test]
#[ignore = "benchmark: run with --ignored --nocapture"]
fn bench_compact() {
    let spec = std::env::var("MRCNN_BENCH").unwrap_or_else(|_| "50:512".into());
    let runs: usize = std::env::var("MRCNN_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2);
    let train_batch: usize = std::env::var("MRCNN_TRAIN_BATCH")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2);
    for item in spec.split(',') {
        let (d, s) = item
            .split_once(':')
            .expect("MRCNN_BENCH items are [p]depth:size");
        // A leading `p` selects the paper-sized preset (like-for-like with torchvision).
        let (preset, d) = match d.strip_prefix('p') {
            Some(d) => ("paper", d),
            None => ("compact", d),
        };
        let (d, s): (usize, usize) = (d.parse().unwrap(), s.parse().unwrap());
        let cfg = if preset == "paper" {
            MaskRcnnConfig::paper(d, 1)
        } else {
            MaskRcnnConfig::new(d, 1)
        }
        .with_input_size(s);
        let dev = Device::flex();
        let summary = cfg.init(&dev).summary(cfg.input_size);
        println!("r{d} {preset}: {summary}");
        println!("{}", bench_maskrcnn(&cfg, &dev, 1, train_batch, runs));
    }
}
