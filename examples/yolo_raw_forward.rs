//! Raw YOLO head outputs of a checkpoint on a given input, for cross-checks against another
//! framework (`bench/ultralytics_weights_check.py` compares them with ultralytics' forward of
//! the exported safetensors):
//!
//! `target/release/examples/yolo_raw_forward CKPT.bpk INPUT.safetensors OUT.safetensors`
//! `target/release/examples/yolo_raw_forward yolo11n-seg.pt INPUT OUT n 1.0 80`
//!
//! The second form reads ultralytics weights (`.pt` or safetensors) through
//! `read_ultralytics` into a model of scale, width multiplier and class count given after
//! OUT, strictly (every tensor must fit). INPUT holds `images` `[B, 3, H, W]` (f32, 0–1, H and W multiples of 32); OUT gets the
//! eval-mode `boxes` `[B, 64, A]`, `scores` `[B, nc, A]`, `mask_coefficient` `[B, nm, A]` and
//! `proto` `[B, nm, H/4, W/4]` of the checkpoint's `ema` weights, f32. Built by
//! `cargo test --release` like every example.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::infer::checkpoint::Checkpoint;
use chicktrain::infer::detector::Detector;
use chicktrain::model::yolo::ultralytics::{apply_all, read_ultralytics};
use chicktrain::model::yolo::{Scale, YoloSegConfig};
use chicktrain::util::tensor::to_host;
use chicktrain::weights::host::HostTensor;
use chicktrain::weights::safetensors;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: yolo_raw_forward CKPT.bpk|WEIGHTS.pt INPUT.safetensors OUT.safetensors [SCALE WIDTH_MULT NC]";
    let (ckpt, input, out) = match args.as_slice() {
        [c, i, o] | [c, i, o, _, _, _] => (c, i, o),
        _ => bail!("{usage}"),
    };
    let dev = Device::flex();
    let model = if let [_, _, _, scale, width, nc] = args.as_slice() {
        let scale: Scale = scale.parse().map_err(anyhow::Error::msg)?;
        let cfg = YoloSegConfig::new(scale, nc.parse().context("NC")?)
            .with_width_mult(width.parse().context("WIDTH_MULT")?);
        let w = read_ultralytics(Path::new(ckpt), &cfg)?;
        for n in &w.notes {
            eprintln!("{n}");
        }
        apply_all(cfg.init(&dev), &w)?
    } else {
        let Detector::Yolo(m) = Checkpoint::load(Path::new(ckpt))?.model("ema", &dev)? else {
            bail!("{ckpt} is not a YOLO checkpoint");
        };
        m
    };
    let inputs = safetensors::read(Path::new(input))?;
    let img = inputs
        .get("images")
        .with_context(|| format!("{input} has no `images` tensor"))?;
    let [b, c, h, w] = img.shape[..] else {
        bail!("{input}: images must be [B, 3, H, W], got {:?}", img.shape);
    };
    let x = Tensor::<4>::from_data(TensorData::new(img.to_f32(), [b, c, h, w]), &dev);
    let o = model.forward(x);
    let mut t = Vec::new();
    for (name, dims, v) in [
        ("boxes", o.box_dist.dims().to_vec(), to_host(o.box_dist)),
        (
            "scores",
            o.cls_logits.dims().to_vec(),
            to_host(o.cls_logits),
        ),
        (
            "mask_coefficient",
            o.mask_coef.dims().to_vec(),
            to_host(o.mask_coef),
        ),
        ("proto", o.proto.dims().to_vec(), to_host(o.proto)),
    ] {
        t.push((name.to_string(), HostTensor::f32(dims, v)));
    }
    safetensors::write(Path::new(out), &t, &BTreeMap::new())?;
    println!("wrote {out}");
    Ok(())
}
