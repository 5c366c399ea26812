//! Times a YOLO-seg model: inference ms/image and SGD train-step ms/image (split into
//! forward, loss, backward, optimiser), until `chicktrain bench` calls the same helper.
//!
//! Usage: `cargo run --release --example yolo_bench -- [n|s] [size ...]`
//! (defaults: scale n, sizes 320 640; inference batch 1, train batch 8, nc 1, median of 3).

use burn::tensor::Device;
use chicktrain::model::yolo::bench::bench_yolo;
use chicktrain::model::yolo::{Scale, YoloSegConfig};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scale: Scale = args
        .first()
        .map_or(Ok(Scale::N), |s| s.parse())
        .unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(2)
        });
    let mut sizes: Vec<usize> = args.iter().skip(1).filter_map(|s| s.parse().ok()).collect();
    if sizes.is_empty() {
        sizes = vec![320, 640];
    }
    let device = Device::flex();
    for size in sizes {
        let cfg = YoloSegConfig::new(scale, 1).with_input_size(size);
        let summary = cfg.init(&device).summary(size);
        println!("yolo11{}-seg nc 1: {summary}", scale.name());
        let r = bench_yolo(&cfg, &device, 1, 8, 3);
        println!("{r}");
    }
}
