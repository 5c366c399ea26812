//! A state dict on the host: named tensors read from a PyTorch `.pt` / `.pth` file
//! ([`super::pytorch`]) or a safetensors file ([`super::safetensors`]), floats as f32 and
//! integers as i64, with no model attached. The model layer maps the names.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};

use super::pytorch::{module_state_dict, tensor_dict, PtFile, Value};

/// Elements of a host tensor, row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum HostData {
    F32(Vec<f32>),
    I64(Vec<i64>),
}

/// One tensor of a state dict.
#[derive(Debug, Clone, PartialEq)]
pub struct HostTensor {
    pub shape: Vec<usize>,
    pub data: HostData,
    /// The element type in the file (`float16`, `float32`, `int64`, …).
    pub source_dtype: &'static str,
}

impl HostTensor {
    pub fn f32(shape: Vec<usize>, v: Vec<f32>) -> Self {
        Self {
            shape,
            data: HostData::F32(v),
            source_dtype: "float32",
        }
    }

    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }

    /// The elements as f32 (integers converted).
    pub fn to_f32(&self) -> Vec<f32> {
        match &self.data {
            HostData::F32(v) => v.clone(),
            HostData::I64(v) => v.iter().map(|&x| x as f32).collect(),
        }
    }
}

/// The tensors of a weights file and which object of the file they came from.
#[derive(Debug, Clone)]
pub struct StateDict {
    pub tensors: BTreeMap<String, HostTensor>,
    /// `"ema"` / `"model"` (the checkpoint entry that was read), `"state dict"`, `"module"`
    /// (a whole pickled model) or `"safetensors"`.
    pub origin: String,
}

/// Reads the weights of `path`: safetensors (by its header), or a `torch.save` zip holding a
/// state dict, a pickled module, or a checkpoint dict. In a checkpoint dict the first of
/// `prefer` that holds a module or a tensor dict is taken (ultralytics: `["ema", "model"]`,
/// its `attempt_load_one_weight` order), then a `state_dict` entry.
pub fn read_state_dict(path: &Path, prefer: &[&str]) -> Result<StateDict> {
    if !path.exists() {
        bail!("weights file {} does not exist", path.display());
    }
    if super::safetensors::looks_like(path)? {
        return Ok(StateDict {
            tensors: super::safetensors::read(path)?,
            origin: "safetensors".into(),
        });
    }
    let pt = PtFile::open(path)?;
    let (entries, origin) =
        pick(&pt.root, prefer).with_context(|| format!("{}: no weights found", path.display()))?;
    Ok(StateDict {
        tensors: pt.read_all(&entries)?,
        origin,
    })
}

type Entries = Vec<(String, std::rc::Rc<super::pytorch::TensorRef>)>;

fn pick(root: &Value, prefer: &[&str]) -> Result<(Entries, String)> {
    if root.is_module() {
        return Ok((module_state_dict(root)?, "module".into()));
    }
    if let Some(t) = tensor_dict(root) {
        return Ok((t, "state dict".into()));
    }
    let Value::Dict(_) = root else {
        bail!(
            "the pickle holds a {}, not a state dict, a module or a checkpoint dict",
            root.type_name()
        );
    };
    for key in prefer.iter().copied().chain(["state_dict"]) {
        match root.get(key) {
            Some(v) if v.is_module() => return Ok((module_state_dict(&v)?, key.to_string())),
            Some(v) => {
                if let Some(t) = tensor_dict(&v) {
                    return Ok((t, key.to_string()));
                }
            }
            None => {}
        }
    }
    let keys: Vec<String> = match root {
        Value::Dict(d) => d
            .borrow()
            .iter()
            .map(|(k, v)| format!("{}: {}", k.as_str().unwrap_or("?"), v.type_name()))
            .collect(),
        _ => Vec::new(),
    };
    bail!(
        "a checkpoint dict without a module or tensor dict under {:?} (its entries: {})",
        prefer.iter().chain(&["state_dict"]).collect::<Vec<_>>(),
        keys.join(", ")
    )
}
