//! A value of the pickle machine: Python's scalars and containers, class references and
//! instances of classes the reader does not interpret ([`Object`]), and the torch storages
//! and tensor views it rebuilds. Containers are shared (`Rc`), as Python objects are.

use std::cell::RefCell;
use std::rc::Rc;

use super::torch_storage::{Storage, TensorRef};

/// An instance of a class the reader does not interpret (an `nn.Module`, a namespace, …).
#[derive(Debug, Default)]
pub struct Object {
    /// `module.Class`.
    pub class: String,
    /// The constructor arguments (`NEWOBJ` / `REDUCE`).
    pub args: Vec<Value>,
    /// The `BUILD` state: for plain objects and modules, their `__dict__`.
    pub state: Option<Value>,
    /// Items set on a dict or list subclass.
    pub items: Vec<(Value, Value)>,
    pub elements: Vec<Value>,
}

/// A pickled value. Containers are shared (`Rc`), as in Python: the memo hands out the same
/// object, and a later `BUILD` / `SETITEMS` is seen through every reference.
#[derive(Debug, Clone)]
pub enum Value {
    None,
    Bool(bool),
    Int(i64),
    /// An integer wider than 64 bits (little-endian two's complement bytes).
    BigInt(Rc<[u8]>),
    Float(f64),
    Str(Rc<str>),
    Bytes(Rc<[u8]>),
    Tuple(Rc<Vec<Value>>),
    List(Rc<RefCell<Vec<Value>>>),
    Dict(Rc<RefCell<Vec<(Value, Value)>>>),
    /// A `GLOBAL` reference: `(module, name)`.
    Class(Rc<(String, String)>),
    Object(Rc<RefCell<Object>>),
    Storage(Rc<Storage>),
    Tensor(Rc<TensorRef>),
}

impl Value {
    pub fn type_name(&self) -> String {
        match self {
            Value::None => "None".into(),
            Value::Bool(_) => "bool".into(),
            Value::Int(_) | Value::BigInt(_) => "int".into(),
            Value::Float(_) => "float".into(),
            Value::Str(_) => "str".into(),
            Value::Bytes(_) => "bytes".into(),
            Value::Tuple(_) => "tuple".into(),
            Value::List(_) => "list".into(),
            Value::Dict(_) => "dict".into(),
            Value::Class(c) => format!("class {}.{}", c.0, c.1),
            Value::Object(o) => o.borrow().class.clone(),
            Value::Storage(_) => "storage".into(),
            Value::Tensor(_) => "tensor".into(),
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    pub(super) fn as_usize(&self) -> Option<usize> {
        match self {
            Value::Int(i) => usize::try_from(*i).ok(),
            Value::Bool(b) => Some(*b as usize),
            _ => None,
        }
    }

    /// Items of a tuple or list.
    pub(super) fn elements(&self) -> Option<Vec<Value>> {
        match self {
            Value::Tuple(t) => Some(t.as_ref().clone()),
            Value::List(l) => Some(l.borrow().clone()),
            _ => None,
        }
    }

    /// The value under string key `key` of a dict (the last one set, as in Python).
    pub fn get(&self, key: &str) -> Option<Value> {
        match self {
            Value::Dict(d) => d
                .borrow()
                .iter()
                .rev()
                .find(|(k, _)| k.as_str() == Some(key))
                .map(|(_, v)| v.clone()),
            _ => None,
        }
    }

    /// Whether this is a pickled `torch.nn.Module` (an object whose `__dict__` has the three
    /// module tables). The class is not looked at: a model pickles under its own name.
    pub fn is_module(&self) -> bool {
        let Value::Object(o) = self else { return false };
        let o = o.borrow();
        let Some(state) = &o.state else { return false };
        ["_parameters", "_buffers", "_modules"]
            .iter()
            .all(|t| matches!(state.get(t), Some(Value::Dict(_))))
    }
}

pub(super) fn class_name(v: &Value) -> String {
    match v {
        Value::Class(c) => format!("{}.{}", c.0, c.1),
        other => other.type_name(),
    }
}

pub(super) fn new_object(cls: &Value, args: Vec<Value>) -> Value {
    Value::Object(Rc::new(RefCell::new(Object {
        class: class_name(cls),
        args,
        ..Object::default()
    })))
}
