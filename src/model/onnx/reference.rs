//! The reference file beside an exported ONNX graph: a seeded input and chicktrain's own
//! outputs for it, as float32 safetensors, which `bench/onnx_check.py` and
//! `bench/maskrcnn_export_check.py` compare against ONNX Runtime.

use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::weights::host::HostTensor;
use crate::weights::safetensors::to_bytes;

/// Seed of the reference input (uniform [0, 1] pixels).
pub const REFERENCE_SEED: u64 = 0;

/// Path of the reference file next to an exported `model.onnx`.
pub fn reference_path(onnx: &Path) -> PathBuf {
    onnx.with_extension("reference.safetensors")
}

/// The reference file: float32 tensors in the given order, no metadata — the one format
/// both Rust and NumPy read without a pickle.
pub fn reference_file(named: Vec<(String, Vec<usize>, Vec<f32>)>) -> Result<Vec<u8>> {
    let tensors: Vec<(String, HostTensor)> = named
        .into_iter()
        .map(|(k, shape, v)| (k, HostTensor::f32(shape, v)))
        .collect();
    to_bytes(&tensors, &Default::default())
}
