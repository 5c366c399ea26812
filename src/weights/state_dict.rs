//! A state dict on the host: named tensors read from a PyTorch `.pt` / `.pth` file
//! ([`super::pytorch`]) or a safetensors file ([`super::safetensors`]), by the file's
//! first bytes, with no model attached. The model layer maps the names.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};

use super::host::HostTensor;
use super::pickle_value::Value;
use super::pytorch::PtFile;
use super::torch_module::{module_state_dict, tensor_dict};
use super::torch_storage::TensorRef;

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

type Entries = Vec<(String, std::rc::Rc<TensorRef>)>;

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
