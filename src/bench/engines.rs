//! Batch-1 inference latency of one YOLO-seg under the two engines chicktrain has, in
//! one process on the same weights and input: Burn's flex backend (the fused model,
//! timed as `bench models` times it: forward until the raw outputs are on the host) and
//! tract running the ONNX export of that model (forward plus the DFL decode and sigmoid
//! that the export's `output0` includes; outputs on the host). Both exclude NMS and
//! masks. The two outputs are also compared, so a fast but wrong engine shows.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};

use super::variant::Variant;
use crate::data::ellipses::ellipse_batch;
use crate::infer::detector::DetectorConfig;
use crate::model::onnx::engine::{set_threads, TractEngine};
use crate::model::onnx::graph::encode;
use crate::model::yolo::onnx::{export_yolo, ultralytics_output0, OnnxExportOptions};
use crate::util::stats::percentile;
use crate::util::tensor::to_host;
use crate::util::write_atomic;

/// One (variant, size): latencies in ms as (median, p10, p90).
#[derive(Debug, Clone)]
pub struct EngineRow {
    pub variant: String,
    pub size: usize,
    pub flex_ms: [f64; 3],
    pub tract_ms: [f64; 3],
    /// Max |tract − flex| over output0 and output1.
    pub max_abs_diff: f32,
}

fn stats(v: &[f64]) -> [f64; 3] {
    [
        percentile(v, 50.0),
        percentile(v, 10.0),
        percentile(v, 90.0),
    ]
}

/// Times `variant` at `size`: `warmup` untimed and `repeats` timed runs per engine.
/// With `save`, the exported file is also written there as `<variant>_<size>.onnx`
/// (for timing other runtimes on the same weights, `bench/onnx_latency.py`).
pub fn time_engines(
    variant: &Variant,
    size: usize,
    warmup: usize,
    repeats: usize,
    save: Option<&Path>,
) -> Result<EngineRow> {
    let DetectorConfig::Yolo(cfg) = variant.config(size) else {
        bail!("bench engines: {variant} is not a YOLO variant (only YOLO-seg exports to ONNX)");
    };
    if size < 32 || size % 32 != 0 || repeats == 0 {
        bail!("bench engines: size {size} must be a multiple of 32 and --repeats ≥ 1");
    }
    let dev = Device::flex();
    dev.seed(0);
    let model = cfg.init(&dev);
    let fused = model.clone().fuse();
    let (px, _) = ellipse_batch(1, size, 6, 1);
    let x = Tensor::<4>::from_data(TensorData::new(px.clone(), [1, 3, size, size]), &dev);
    let mut flex = Vec::new();
    let mut last = None;
    for r in 0..warmup + repeats {
        let t = Instant::now();
        let out = fused.forward(x.clone());
        let y = (to_host(out.cls_logits.clone()), to_host(out.proto.clone()));
        if r >= warmup {
            flex.push(t.elapsed().as_secs_f64() * 1e3);
        }
        drop(y);
        last = Some(out);
    }
    let out = last.expect("at least one run");
    let (ref0, _) = ultralytics_output0(&out);
    let ref1 = to_host(out.proto);

    let opts = OnnxExportOptions {
        batch: 1,
        dynamic: false,
        names: vec!["carcass".into()],
        category_ids: vec![1],
    };
    let bytes = encode(&export_yolo(&model, [size, size], &opts)?);
    if let Some(dir) = save {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        write_atomic(&dir.join(format!("{variant}_{size}.onnx")), &bytes)?;
    }
    let eng = TractEngine::from_bytes(
        &bytes,
        Path::new(&format!("{variant}@{size}.onnx")),
        Some(1),
    )?;
    let mut tract = Vec::new();
    let mut got = Vec::new();
    for r in 0..warmup + repeats {
        let t = Instant::now();
        let o = eng.run(&[1, 3, size, size], &px)?;
        if r >= warmup {
            tract.push(t.elapsed().as_secs_f64() * 1e3);
        }
        got = o;
    }
    let diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max)
    };
    Ok(EngineRow {
        variant: variant.to_string(),
        size,
        flex_ms: stats(&flex),
        tract_ms: stats(&tract),
        max_abs_diff: diff(&got[0].data, &ref0).max(diff(&got[1].data, &ref1)),
    })
}

/// `chicktrain bench engines`: every variant × size, a markdown table.
pub fn bench_engines(
    variants: &[Variant],
    sizes: &[usize],
    warmup: usize,
    repeats: usize,
    threads: usize,
    save: Option<&Path>,
) -> Result<String> {
    set_threads(threads);
    let mut s = format!(
        "batch-1 latency, ms (median, p10–p90 of {repeats} runs after {warmup} warm-up); flex: fused Burn model, rayon over all cores; tract: ONNX export, {threads} thread(s)\n\n\
         | variant | size | flex | tract | tract / flex | max abs diff |\n|---|---|---|---|---|---|\n"
    );
    for v in variants {
        for &size in sizes {
            let r = time_engines(v, size, warmup, repeats, save)?;
            s.push_str(&format!(
                "| {} | {} | {:.1} ({:.1}–{:.1}) | {:.1} ({:.1}–{:.1}) | {:.2} | {:.1e} |\n",
                r.variant,
                r.size,
                r.flex_ms[0],
                r.flex_ms[1],
                r.flex_ms[2],
                r.tract_ms[0],
                r.tract_ms[1],
                r.tract_ms[2],
                r.tract_ms[0] / r.flex_ms[0],
                r.max_abs_diff
            ));
        }
    }
    Ok(s)
}
