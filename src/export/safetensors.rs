//! `chicktrain export --format safetensors`: a checkpoint's EMA weights as the state dict
//! of the Python model it mirrors, so that `model.load_state_dict(safetensors.torch.load_file(PATH))`
//! takes it, through its family's exporter (`Family::SAFETENSORS`: ultralytics' keys for
//! YOLO-seg, torchvision's for Mask R-CNN); a family without one is refused by name
//! before its weights load.

use std::path::Path;

use anyhow::{bail, Result};
use burn::tensor::Device;

use super::refusal;
use crate::infer::checkpoint::Checkpoint;
use crate::model::family::{ExportFormat, ExportRequest};

/// `chicktrain export --checkpoint X.bpk --format safetensors`: the family's state dict
/// (refused before the weights load when the family has none).
pub fn export(ckpt: &Checkpoint, from: &Path, out: &Path) -> Result<String> {
    let h = &ckpt.header;
    if !h.model.exports(ExportFormat::Safetensors) {
        bail!(refusal(from, &h.model, ExportFormat::Safetensors));
    }
    let model = ckpt.model("ema", &Device::flex())?;
    let request = ExportRequest {
        checkpoint: from,
        out,
        class_names: &h.class_names,
        category_ids: &h.category_ids,
        epoch: h.epoch,
        batch: 1,
        dynamic: false,
        reference: false,
    };
    match model.export(&h.model, ExportFormat::Safetensors, &request) {
        Some(done) => done,
        None => bail!(refusal(from, &h.model, ExportFormat::Safetensors)),
    }
}
