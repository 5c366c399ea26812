//! Export: a checkpoint's weights in formats other tools read, one module per format —
//! [`onnx`] and [`safetensors`]. Each loads the checkpoint and hands the model to its
//! family's exporter (`Family::ONNX`, `Family::SAFETENSORS`, written in
//! `model/<family>/export.rs`: YOLO-seg in ultralytics' layout and key names, Mask R-CNN
//! as three graphs and under torchvision's key names), or refuses, naming the family and
//! those that export. The `export` command (`commands::export`) picks the format; running
//! an export back is `infer::onnx`.
//!
//! It sits above `infer` (it loads checkpoints) and below the commands; nothing but the
//! commands and benches imports it.

pub mod onnx;
pub mod safetensors;

use std::path::Path;

use crate::infer::detector::DetectorConfig;
use crate::model::family::ExportFormat;

/// Why `checkpoint` (a model of family `model`) has no `format` export, naming the
/// families that have one.
fn refusal(checkpoint: &Path, model: &DetectorConfig, format: ExportFormat) -> String {
    format!(
        "{}: {} export of {} is not implemented ({} export)",
        checkpoint.display(),
        format.name(),
        model.family_name(),
        DetectorConfig::exporters(format).join(" and ")
    )
}
