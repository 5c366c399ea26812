//! A pickled `torch.nn.Module` or a pickled dict of tensors, walked to the names
//! `state_dict()` would give (parameters, persistent buffers, then children, dotted).
//! Tensor views are returned unread; [`super::pytorch::PtFile`] reads them.

use std::rc::Rc;

use anyhow::{bail, Context, Result};

use super::pickle_value::Value;
use super::torch_storage::TensorRef;

fn dict_key(v: &Value) -> Result<String> {
    match v {
        Value::Str(s) => Ok(s.to_string()),
        Value::Int(i) => Ok(i.to_string()),
        other => bail!(
            "dict key of type {} where a name was expected",
            other.type_name()
        ),
    }
}

/// Module nesting deeper than this is refused (a hostile file could nest without end).
const MAX_DEPTH: usize = 256;

/// The `state_dict()` of a pickled module: parameters, persistent buffers, then children,
/// dotted names, `None` entries skipped. Values are tensor views, not yet read.
pub fn module_state_dict(module: &Value) -> Result<Vec<(String, Rc<TensorRef>)>> {
    let mut out = Vec::new();
    walk_module(module, "", 0, &mut out)?;
    Ok(out)
}

fn walk_module(
    module: &Value,
    prefix: &str,
    depth: usize,
    out: &mut Vec<(String, Rc<TensorRef>)>,
) -> Result<()> {
    if depth > MAX_DEPTH {
        bail!("modules nested more than {MAX_DEPTH} deep at {prefix}");
    }
    let Value::Object(o) = module else {
        bail!("{prefix}: expected a module, found {}", module.type_name());
    };
    let o = o.borrow();
    let state = o
        .state
        .as_ref()
        .with_context(|| format!("module {prefix} ({}) has no state", o.class))?;
    let table = |name: &str| -> Result<Vec<(Value, Value)>> {
        match state.get(name) {
            Some(Value::Dict(d)) => Ok(d.borrow().clone()),
            _ => bail!("module {prefix} ({}) has no {name} table", o.class),
        }
    };
    let non_persistent: Vec<String> = match state.get("_non_persistent_buffers_set") {
        Some(v) => v
            .elements()
            .unwrap_or_default()
            .iter()
            .filter_map(|s| s.as_str().map(str::to_string))
            .collect(),
        None => Vec::new(),
    };
    for (t, skip) in [("_parameters", false), ("_buffers", true)] {
        for (k, v) in table(t)? {
            let k = dict_key(&k)?;
            if skip && non_persistent.contains(&k) {
                continue;
            }
            match v {
                Value::None => {}
                Value::Tensor(tr) => out.push((format!("{prefix}{k}"), tr)),
                other => bail!(
                    "{prefix}{k} in {t} is a {}, not a tensor",
                    other.type_name()
                ),
            }
        }
    }
    for (k, v) in table("_modules")? {
        let k = dict_key(&k)?;
        if matches!(v, Value::None) {
            continue;
        }
        walk_module(&v, &format!("{prefix}{k}."), depth + 1, out)?;
    }
    Ok(())
}

/// A dict of tensors (a plain `state_dict()` save), or `None` if some value is not a tensor.
pub fn tensor_dict(v: &Value) -> Option<Vec<(String, Rc<TensorRef>)>> {
    let Value::Dict(d) = v else { return None };
    let d = d.borrow();
    let mut out = Vec::with_capacity(d.len());
    for (k, v) in d.iter() {
        match (dict_key(k), v) {
            (Ok(k), Value::Tensor(t)) => out.push((k, t.clone())),
            _ => return None,
        }
    }
    (!out.is_empty()).then_some(out)
}
