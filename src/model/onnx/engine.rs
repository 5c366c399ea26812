//! Runs an ONNX file with tract (pure Rust): the check that an exported model computes
//! what chicktrain computes, and the `predict --onnx` engine.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{anyhow, ensure, Context, Result};
use tract_onnx::pb::ModelProto;
use tract_onnx::prelude::*;

use super::graph;

/// One output tensor: shape and row-major values.
#[derive(Debug, Clone)]
pub struct HostTensor {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// An optimised tract plan of one ONNX file with one float input.
pub struct TractEngine {
    plan: Arc<TypedRunnableModel>,
    /// Input shape as declared by the file; `None` for a symbolic dimension.
    pub input_shape: Vec<Option<usize>>,
    /// The file's protobuf (metadata, declared shapes).
    pub proto: ModelProto,
    pub path: PathBuf,
}

/// Uses `threads` threads for tract's matrix products (process-wide; 1 = tract's default).
pub fn set_threads(threads: usize) {
    if threads > 1 {
        tract_linalg::multithread::set_default_executor(
            tract_linalg::multithread::Executor::multithread(threads),
        );
    }
}

impl TractEngine {
    /// Loads and optimises `path`. A symbolic batch stays symbolic unless `batch` fixes it
    /// (a fixed batch lets tract plan every shape ahead).
    pub fn load(path: &Path, batch: Option<usize>) -> Result<Self> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        Self::from_bytes(&bytes, path, batch)
    }

    /// [`TractEngine::load`] of ONNX `bytes` (`path` names them in messages).
    pub fn from_bytes(bytes: &[u8], path: &Path, batch: Option<usize>) -> Result<Self> {
        let proto = graph::decode(&bytes, path)?;
        let g = proto
            .graph
            .as_ref()
            .ok_or_else(|| anyhow!("{} has no graph", path.display()))?;
        ensure!(
            g.input.len() == 1,
            "{}: expected one input (images), found {}",
            path.display(),
            g.input.len()
        );
        let input_shape: Vec<Option<usize>> = declared_shape(&g.input[0]);
        let mut model = tract_onnx::onnx()
            .model_for_read(&mut &bytes[..])
            .map_err(|e| anyhow!("tract cannot read {}: {e:#}", path.display()))?;
        if let Some(b) = batch {
            let mut dims: Vec<usize> = input_shape.iter().map(|d| d.unwrap_or(b)).collect();
            if let Some(d0) = dims.first_mut() {
                *d0 = b;
            }
            model = model
                .with_input_fact(0, f32::fact(&dims).into())
                .map_err(|e| anyhow!("{}: input shape {dims:?}: {e:#}", path.display()))?;
        }
        let plan = model
            .into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(|e| anyhow!("tract cannot plan {}: {e:#}", path.display()))?;
        Ok(Self {
            plan,
            input_shape,
            proto,
            path: path.to_path_buf(),
        })
    }

    /// Runs the model on one `shape` input; returns every graph output in order.
    pub fn run(&self, shape: &[usize], data: &[f32]) -> Result<Vec<HostTensor>> {
        ensure!(
            shape.iter().product::<usize>() == data.len(),
            "input shape {shape:?} does not hold {} values",
            data.len()
        );
        ensure!(
            shape.len() == self.input_shape.len()
                && shape
                    .iter()
                    .zip(&self.input_shape)
                    .all(|(s, d)| d.is_none_or(|d| d == *s)),
            "{}: input of shape {shape:?} does not fit the declared {:?}",
            self.path.display(),
            self.input_shape
        );
        let x = Tensor::from_shape(shape, data)?;
        let out = self
            .plan
            .run(tvec!(x.into()))
            .map_err(|e| anyhow!("tract failed running {}: {e:#}", self.path.display()))?;
        out.iter()
            .map(|t| {
                let v = t.to_plain_array_view::<f32>()?;
                Ok(HostTensor {
                    shape: v.shape().to_vec(),
                    data: v.iter().copied().collect(),
                })
            })
            .collect()
    }

    /// The file's metadata entry `key`.
    pub fn metadata(&self, key: &str) -> Option<&str> {
        graph::metadata(&self.proto, key)
    }
}

/// Declared dimensions of a graph input (`None`: symbolic or missing).
fn declared_shape(v: &tract_onnx::pb::ValueInfoProto) -> Vec<Option<usize>> {
    use tract_onnx::pb::{tensor_shape_proto::dimension::Value, type_proto};
    match v.r#type.as_ref().and_then(|t| t.value.as_ref()) {
        Some(type_proto::Value::TensorType(t)) => t
            .shape
            .as_ref()
            .map(|s| {
                s.dim
                    .iter()
                    .map(|d| match d.value {
                        Some(Value::DimValue(n)) if n > 0 => Some(n as usize),
                        _ => None,
                    })
                    .collect()
            })
            .unwrap_or_default(),
        _ => Vec::new(),
    }
}
