//! `export --format onnx`: a checkpoint's model through its family's ONNX exporter
//! (`Family::ONNX`: YOLO-seg as one graph in ultralytics' layout, Mask R-CNN as three
//! graphs), optionally with a reference input and chicktrain's own outputs for it
//! (`model::onnx::reference`), which `bench/onnx_check.py` and
//! `bench/maskrcnn_export_check.py` compare against ONNX Runtime; a family without one is
//! refused by name. Running such a file is `infer::onnx` (`predict --onnx`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use burn::tensor::Device;

use super::refusal;
use crate::infer::checkpoint::Checkpoint;
use crate::model::family::{ExportFormat, ExportRequest};

/// Options of `export --format onnx`.
#[derive(Debug, Clone)]
pub struct OnnxExport {
    pub checkpoint: PathBuf,
    pub out: PathBuf,
    pub batch: usize,
    pub dynamic: bool,
    /// Also write `<out>.reference.safetensors`: a seeded input and chicktrain's outputs.
    pub reference: bool,
}

/// `chicktrain export --checkpoint X.bpk --format onnx [--out Y.onnx]`.
pub fn export_onnx(r: &OnnxExport) -> Result<String> {
    let ck = Checkpoint::load(&r.checkpoint)?;
    let dev = Device::flex();
    let model = ck
        .model("ema", &dev)
        .with_context(|| format!("in checkpoint {}", r.checkpoint.display()))?;
    let h = &ck.header;
    let request = ExportRequest {
        checkpoint: &r.checkpoint,
        out: &r.out,
        class_names: &h.class_names,
        category_ids: &h.category_ids,
        epoch: h.epoch,
        batch: r.batch,
        dynamic: r.dynamic,
        reference: r.reference,
    };
    match model.export(&h.model, ExportFormat::Onnx, &request) {
        Some(done) => done,
        None => bail!(refusal(&r.checkpoint, &h.model, ExportFormat::Onnx)),
    }
}
