//! `chicktrain export --checkpoint X.bpk --format onnx|safetensors [--out PATH]`: a
//! checkpoint's weights in a format other tools read. Each format lives in its own file
//! ([`crate::export::onnx`], [`crate::export::safetensors`]); this file only picks one and
//! the default output path. Both write atomically: a failed export leaves no partial file.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use crate::export::onnx::{export_onnx, OnnxExport};
use crate::infer::checkpoint::Checkpoint;

/// The formats `export` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// The inference graph: ultralytics' ONNX layout (YOLO-seg), or Mask R-CNN's
    /// backbone + RPN head, box head and mask head graphs.
    Onnx,
    /// The state dict under ultralytics' / torchvision's key names.
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

/// What `export` was asked for.
#[derive(Debug, Clone, clap::Args)]
pub struct ExportRequest {
    /// A best.bpk / last.bpk written by `train`.
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// onnx or safetensors.
    #[arg(long, value_enum)]
    pub format: ExportFormat,
    /// Output file (default: the checkpoint's path with .onnx / .safetensors, as
    /// ultralytics writes `best.onnx` beside `best.pt`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// ONNX: batch size of a static graph (and of the reference input).
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// ONNX: a symbolic batch dimension instead of a fixed one.
    #[arg(long)]
    pub dynamic: bool,
    /// ONNX: also write <out>.reference.safetensors (a seeded input and chicktrain's
    /// outputs for it; `bench/onnx_check.py` compares ONNX Runtime against them).
    #[arg(long)]
    pub reference: bool,
}

/// Output path of an export.
pub fn out_path(checkpoint: &Path, format: ExportFormat, out: Option<&Path>) -> PathBuf {
    out.map(Path::to_path_buf)
        .unwrap_or_else(|| checkpoint.with_extension(format.extension()))
}

pub fn export_cmd(r: &ExportRequest) -> Result<String> {
    let out = out_path(&r.checkpoint, r.format, r.out.as_deref());
    if out == r.checkpoint {
        bail!("--out {} would overwrite the checkpoint", out.display());
    }
    if r.format == ExportFormat::Safetensors && (r.dynamic || r.reference || r.batch != 1) {
        bail!(
            "--dynamic, --batch and --reference are ONNX options; --format safetensors writes the weights only"
        );
    }
    match r.format {
        ExportFormat::Onnx => export_onnx(&OnnxExport {
            checkpoint: r.checkpoint.clone(),
            out,
            batch: r.batch,
            dynamic: r.dynamic,
            reference: r.reference,
        }),
        ExportFormat::Safetensors => {
            let ckpt = Checkpoint::load(&r.checkpoint)?;
            crate::export::safetensors::export(&ckpt, &r.checkpoint, &out)
        }
    }
}
