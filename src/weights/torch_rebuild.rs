//! The calls a pickle makes to rebuild torch objects: `persistent_load` of a storage id
//! (the archive entry `data/<key>`), `torch._utils._rebuild_tensor_v2` and its relatives
//! (a view of a storage), `_rebuild_parameter`, `OrderedDict`, sets and
//! `copyreg._reconstructor`. Every other call becomes a generic [`Object`] that keeps its
//! arguments: nothing is imported or executed.
//!
//! [`Object`]: super::pickle_value::Object

use std::cell::RefCell;
use std::rc::Rc;

use anyhow::{anyhow, bail, Result};

use super::pickle_value::{new_object, Value};
use super::torch_storage::{Storage, StorageType, TensorRef};

pub(super) fn persistent_load(pid: Value) -> Result<Value> {
    let f = pid
        .elements()
        .ok_or_else(|| anyhow!("persistent id is a {}, not a tuple", pid.type_name()))?;
    if f.first().and_then(Value::as_str) != Some("storage") || f.len() < 5 {
        let kinds: Vec<String> = f.iter().map(Value::type_name).collect();
        bail!(
            "unsupported persistent id ({}) (only torch storages are read)",
            kinds.join(", ")
        );
    }
    let dtype = match &f[1] {
        Value::Class(c) => StorageType::from_class(&c.1),
        Value::Str(s) => StorageType::from_class(s),
        _ => None,
    }
    .ok_or_else(|| anyhow!("unsupported storage type {}", f[1].type_name()))?;
    let key = match &f[2] {
        Value::Str(s) => s.to_string(),
        Value::Int(i) => i.to_string(),
        other => bail!("storage key is a {}", other.type_name()),
    };
    let numel = f[4]
        .as_usize()
        .ok_or_else(|| anyhow!("storage {key}: element count is not a size"))?;
    Ok(Value::Storage(Rc::new(Storage { key, dtype, numel })))
}

fn sizes(v: &Value, what: &str) -> Result<Vec<usize>> {
    v.elements()
        .ok_or_else(|| anyhow!("tensor {what} is a {}, not a tuple", v.type_name()))?
        .iter()
        .map(|x| {
            x.as_usize()
                .ok_or_else(|| anyhow!("tensor {what} holds a non-size"))
        })
        .collect()
}

/// `REDUCE`: the calls torch uses to rebuild tensors, parameters and ordered dicts are
/// interpreted; every other call becomes a generic [`Object`].
pub(super) fn reduce(callable: Value, args: Value) -> Result<Value> {
    let Value::Class(c) = &callable else {
        return Ok(new_object(&callable, args.elements().unwrap_or_default()));
    };
    let a = args.elements().unwrap_or_default();
    Ok(match (c.0.as_str(), c.1.as_str()) {
        ("torch._utils", "_rebuild_tensor_v2" | "_rebuild_tensor" | "_rebuild_tensor_v3") => {
            if a.len() < 4 {
                bail!("{} with {} arguments", c.1, a.len());
            }
            let Value::Storage(s) = &a[0] else {
                bail!("{} of a {}, not a storage", c.1, a[0].type_name());
            };
            let mut storage = s.clone();
            if c.1 == "_rebuild_tensor_v3" {
                // v3 carries the dtype separately (an untyped storage counts bytes).
                if let Some(Value::Class(d)) = a.get(6) {
                    let dtype = StorageType::from_class(&d.1)
                        .ok_or_else(|| anyhow!("unsupported tensor dtype {}", d.1))?;
                    storage = Rc::new(Storage {
                        key: s.key.clone(),
                        dtype,
                        numel: s.numel.saturating_mul(s.dtype.size()) / dtype.size(),
                    });
                }
            }
            Value::Tensor(Rc::new(TensorRef {
                storage,
                offset: a[1]
                    .as_usize()
                    .ok_or_else(|| anyhow!("bad storage offset"))?,
                shape: sizes(&a[2], "size")?,
                stride: sizes(&a[3], "stride")?,
            }))
        }
        ("torch._utils", "_rebuild_parameter" | "_rebuild_parameter_with_state") => a
            .into_iter()
            .next()
            .ok_or_else(|| anyhow!("_rebuild_parameter without data"))?,
        ("torch._tensor", "_rebuild_from_type_v2") => {
            if a.len() < 3 {
                bail!("_rebuild_from_type_v2 with {} arguments", a.len());
            }
            reduce(a[0].clone(), a[2].clone())?
        }
        ("collections", "OrderedDict") => {
            let d = Value::Dict(Rc::default());
            if let Some(items) = a.first().and_then(Value::elements) {
                let Value::Dict(dd) = &d else { unreachable!() };
                for it in items {
                    match it.elements().as_deref() {
                        Some([k, v]) => dd.borrow_mut().push((k.clone(), v.clone())),
                        _ => bail!("OrderedDict item is not a pair"),
                    }
                }
            }
            d
        }
        ("builtins" | "__builtin__", "set" | "frozenset" | "list") => Value::List(Rc::new(
            RefCell::new(a.first().and_then(Value::elements).unwrap_or_default()),
        )),
        ("copyreg", "_reconstructor") => new_object(a.first().unwrap_or(&Value::None), Vec::new()),
        _ => new_object(&callable, a),
    })
}
