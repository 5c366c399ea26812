//! `chicktrain predict`'s flags: which engine runs (a checkpoint, or an ONNX export
//! through tract) and the options every engine shares ([`PredictOptions`], with the
//! predicting itself, in `infer::predict`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use crate::config::DeviceKind;
use crate::infer::predict::predict_checkpoint;
pub use crate::infer::predict::{PredictOptions, PREDICT_CONF, PREDICT_IOU, PREDICT_MAX_DET};

/// `predict` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct PredictRequest {
    /// A best.bpk / last.bpk written by `train`.
    #[arg(long, required_unless_present = "onnx", conflicts_with = "onnx")]
    pub checkpoint: Option<PathBuf>,
    /// An ONNX file written by `export --format onnx`, run through tract.
    #[arg(long)]
    pub onnx: Option<PathBuf>,
    /// An image file or a folder of .jpg/.png images.
    #[arg(long)]
    pub input: PathBuf,
    /// Output folder: overlay PNGs, results.json (COCO results), images.json, labels/.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub opts: PredictOptions,
    /// Threads of the tract engine (`--onnx`; default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Override the checkpoint's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long, conflicts_with = "onnx")]
    pub device: Option<DeviceKind>,
    /// Letterbox the images to this square size (a multiple of 32) instead of the
    /// size the checkpoint was trained at (`--checkpoint`; an ONNX graph has its own).
    #[arg(long, conflicts_with = "onnx")]
    pub imgsz: Option<usize>,
}

impl PredictRequest {
    /// `checkpoint` on `input` into `out`, every other flag at its default.
    pub fn new(checkpoint: &Path, input: &Path, out: &Path) -> PredictRequest {
        PredictRequest {
            checkpoint: Some(checkpoint.to_path_buf()),
            onnx: None,
            input: input.to_path_buf(),
            out: out.to_path_buf(),
            opts: PredictOptions::default(),
            threads: None,
            device: None,
            imgsz: None,
        }
    }
}

/// `chicktrain predict`: through the checkpoint, or through the ONNX file.
pub fn predict(r: &PredictRequest) -> Result<String> {
    r.opts.check()?;
    match (&r.checkpoint, &r.onnx) {
        (_, Some(onnx)) => {
            crate::infer::onnx::predict_onnx(onnx, &r.input, &r.out, &r.opts, r.threads)
        }
        (Some(c), None) => predict_checkpoint(c, &r.input, &r.out, &r.opts, r.device, r.imgsz),
        (None, None) => bail!("predict needs --checkpoint or --onnx"),
    }
}
