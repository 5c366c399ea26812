//! `chicktrain export --checkpoint X.bpk --format onnx|safetensors [--out PATH]`: a trained
//! model in a format other tools read. One file per format: [`super::export_safetensors`]
//! (the state dict under ultralytics' names); ONNX is built in its own branch.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use crate::train::checkpoint::Checkpoint;

/// Output format of `chicktrain export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// The inference graph (ONNX Runtime, OpenVINO, TensorRT).
    Onnx,
    /// The weights under ultralytics' state_dict names (`model.load_state_dict`).
    Safetensors,
}

impl ExportFormat {
    pub fn extension(self) -> &'static str {
        match self {
            ExportFormat::Onnx => "onnx",
            ExportFormat::Safetensors => "safetensors",
        }
    }
}

/// Exports `checkpoint` to `out` (default: beside the checkpoint, `best.bpk` →
/// `best.safetensors`, as ultralytics names `best.onnx` after `best.pt`). The file is written
/// atomically: a failed export leaves no partial file.
pub fn export_cmd(checkpoint: &Path, format: ExportFormat, out: Option<&Path>) -> Result<String> {
    let out: PathBuf = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| checkpoint.with_extension(format.extension()));
    if out == checkpoint {
        bail!("--out {} would overwrite the checkpoint", out.display());
    }
    let ckpt = Checkpoint::load(checkpoint)?;
    match format {
        ExportFormat::Safetensors => super::export_safetensors::export(&ckpt, checkpoint, &out),
        ExportFormat::Onnx => bail!(
            "ONNX export is not built in this branch (it comes with the `onnx` branch); \
             `--format safetensors` is"
        ),
    }
}
