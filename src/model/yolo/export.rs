//! YOLO-seg's export formats (its `Family::ONNX` and `Family::SAFETENSORS`): the ONNX
//! file in ultralytics' layout ([`super::onnx`] builds the graph), optionally with the
//! reference input and outputs; the safetensors state dict under ultralytics' key names
//! ([`super::ultralytics`]), whose `__metadata__` says how to build that model in
//! ultralytics (scale row, nc, nm, names).

use std::collections::BTreeMap;

use anyhow::{Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::model::family::ExportRequest;
use crate::model::onnx::graph::encode;
use crate::model::onnx::reference::{reference_file, reference_path, REFERENCE_SEED};
use crate::util::tensor::to_host;
use crate::util::write_atomic;
use crate::weights::safetensors;

use super::onnx::{export_yolo, ultralytics_output0, OnnxExportOptions};
use super::scale::Scaler;
use super::ultralytics::ultralytics_state_dict;
use super::{YoloSeg, YoloSegConfig};

/// `export --format onnx`: one graph, `images` → `output0` (boxes, class scores, mask
/// coefficients) and `output1` (prototypes).
pub fn onnx(m: &YoloSeg, cfg: &YoloSegConfig, r: &ExportRequest) -> Result<String> {
    let dev = Device::flex();
    let size = cfg.input_size;
    let opts = OnnxExportOptions {
        batch: r.batch,
        dynamic: r.dynamic,
        names: r.class_names.to_vec(),
        category_ids: r.category_ids.to_vec(),
    };
    let proto = export_yolo(m, [size, size], &opts)
        .with_context(|| format!("exporting {}", r.checkpoint.display()))?;
    let bytes = encode(&proto);
    write_atomic(&r.out, &bytes)?;
    let mut msg = format!(
        "{} → {} ({:.1} MB, opset 17, input images [{}, 3, {size}, {size}], outputs output0 [B, {}, A] and output1 (prototypes))",
        r.checkpoint.display(),
        r.out.display(),
        bytes.len() as f64 / 1e6,
        if r.dynamic { "batch".to_string() } else { r.batch.to_string() },
        4 + m.num_classes() + m.head.num_masks,
    );
    if r.reference {
        let b = r.batch;
        let mut rng = ChaCha8Rng::seed_from_u64(REFERENCE_SEED);
        let x: Vec<f32> = (0..b * 3 * size * size)
            .map(|_| rng.random::<f32>())
            .collect();
        let out = m.forward(Tensor::<4>::from_data(
            TensorData::new(x.clone(), [b, 3, size, size]),
            &dev,
        ));
        let (y0, s0) = ultralytics_output0(&out);
        let s1 = out.proto.dims();
        let y1 = to_host(out.proto);
        let path = reference_path(&r.out);
        let file = reference_file(vec![
            ("images".into(), vec![b, 3, size, size], x),
            ("output0".into(), s0.to_vec(), y0),
            ("output1".into(), s1.to_vec(), y1),
        ])?;
        write_atomic(&path, &file)?;
        msg.push_str(&format!(
            "\nreference input (seed {REFERENCE_SEED}) and chicktrain's outputs: {}",
            path.display()
        ));
    }
    Ok(msg)
}

/// `export --format safetensors`: the EMA weights under ultralytics' keys (BatchNorm
/// statistics, `num_batches_tracked` and the fixed DFL conv included).
pub fn safetensors(m: &YoloSeg, cfg: &YoloSegConfig, r: &ExportRequest) -> Result<String> {
    let sd = ultralytics_state_dict(m, cfg)?;
    let sc = Scaler::new(cfg.scale, cfg.width_mult);
    let names: BTreeMap<String, &String> = r
        .class_names
        .iter()
        .enumerate()
        .map(|(i, n)| (i.to_string(), n))
        .collect();
    let meta = BTreeMap::from([
        ("format".to_string(), "pt".to_string()),
        (
            "producer".into(),
            format!("chicktrain {}", env!("CARGO_PKG_VERSION")),
        ),
        ("architecture".into(), "yolo11-seg.yaml".into()),
        (
            "ultralytics_scale".into(),
            serde_json::json!([sc.depth, sc.width, sc.max_channels]).to_string(),
        ),
        ("nc".into(), cfg.num_classes.to_string()),
        ("nm".into(), cfg.num_masks.to_string()),
        ("imgsz".into(), cfg.input_size.to_string()),
        ("names".into(), serde_json::to_string(&names)?),
        ("epoch".into(), r.epoch.to_string()),
    ]);
    safetensors::write(r.out, &sd, &meta)?;
    Ok(format!(
        "wrote {} ({} tensors, ultralytics yolo11-seg names; scale [{}, {}, {}], nc {}, nm {})",
        r.out.display(),
        sd.len(),
        sc.depth,
        sc.width,
        sc.max_channels,
        cfg.num_classes,
        cfg.num_masks
    ))
}
