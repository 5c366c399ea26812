//! PyTorch `.pt` / `.pth` files as `torch.save` writes them since torch 1.6: a zip archive
//! (`<root>/data.pkl`, one stored entry per tensor storage under `<root>/data/`), read without
//! Python.
//!
//! The pickle machine below runs the opcodes `torch.save` emits (protocol 2) and the rest of
//! protocols 0–5 a checkpoint's metadata can hold. Nothing is imported or executed: a class
//! reference is just its name, and a call of anything but the few constructors torch uses to
//! rebuild tensors and dicts becomes a generic [`Object`] that keeps its arguments and state.
//! That is enough to walk a pickled `nn.Module` (ultralytics saves the whole model object):
//! its `__dict__` holds `_parameters`, `_buffers` and `_modules`, which
//! [`module_state_dict`] follows to the names `state_dict()` would give.
//!
//! Burn's own reader (burn-store's `pytorch` feature, the pytorch-reader crate) walks
//! modules too, but its zip 9 dependency turns on features of crates all of Burn is built
//! on, which rebuilds Burn (~20 min here); this reader needs only `zip` 0.6 without
//! features (stored entries: `torch.save` does not compress).

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::Path;
use std::rc::Rc;

use anyhow::{anyhow, bail, Context, Result};

use super::state_dict::{HostData, HostTensor};

/// Element type of a torch storage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageType {
    F16,
    BF16,
    F32,
    F64,
    I64,
    I32,
    I16,
    I8,
    U8,
    Bool,
}

impl StorageType {
    fn from_class(name: &str) -> Option<Self> {
        Some(match name {
            "HalfStorage" | "float16" | "half" => Self::F16,
            "BFloat16Storage" | "bfloat16" => Self::BF16,
            "FloatStorage" | "float32" | "float" => Self::F32,
            "DoubleStorage" | "float64" | "double" => Self::F64,
            "LongStorage" | "int64" | "long" => Self::I64,
            "IntStorage" | "int32" | "int" => Self::I32,
            "ShortStorage" | "int16" | "short" => Self::I16,
            "CharStorage" | "int8" => Self::I8,
            "ByteStorage" | "uint8" => Self::U8,
            "BoolStorage" | "bool" => Self::Bool,
            _ => return None,
        })
    }

    pub fn size(self) -> usize {
        match self {
            Self::F16 | Self::BF16 | Self::I16 => 2,
            Self::F32 | Self::I32 => 4,
            Self::F64 | Self::I64 => 8,
            Self::I8 | Self::U8 | Self::Bool => 1,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::F16 => "float16",
            Self::BF16 => "bfloat16",
            Self::F32 => "float32",
            Self::F64 => "float64",
            Self::I64 => "int64",
            Self::I32 => "int32",
            Self::I16 => "int16",
            Self::I8 => "int8",
            Self::U8 => "uint8",
            Self::Bool => "bool",
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Self::F16 | Self::BF16 | Self::F32 | Self::F64)
    }
}

/// A storage reference from `persistent_load`: the archive entry `data/<key>`.
#[derive(Debug)]
pub struct Storage {
    pub key: String,
    pub dtype: StorageType,
    pub numel: usize,
}

/// A tensor view of a storage (`torch._utils._rebuild_tensor_v2`).
#[derive(Debug)]
pub struct TensorRef {
    pub storage: Rc<Storage>,
    pub offset: usize,
    pub shape: Vec<usize>,
    pub stride: Vec<usize>,
}

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

    fn as_usize(&self) -> Option<usize> {
        match self {
            Value::Int(i) => usize::try_from(*i).ok(),
            Value::Bool(b) => Some(*b as usize),
            _ => None,
        }
    }

    /// Items of a tuple or list.
    fn elements(&self) -> Option<Vec<Value>> {
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

/// An open `.pt` file: the unpickled root object and the archive its storages live in.
pub struct PtFile {
    pub root: Value,
    archive: RefCell<zip::ZipArchive<std::fs::File>>,
    prefix: String,
    path: String,
    file_len: u64,
}

/// Largest tensor view read (elements): a view may repeat its storage (stride 0), so the
/// file does not bound it; 2^31 f32 is 8 GiB, far above any YOLO or Mask R-CNN tensor.
const MAX_VIEW_ELEMENTS: usize = 1 << 31;

/// Magic of the pre-1.6 (non-zip) `torch.save` format: a pickled long 0x1950a86a20f9469cfc6c.
const LEGACY_MAGIC: [u8; 10] = [0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19];

impl PtFile {
    /// Opens `path` and unpickles its `data.pkl` (tensor bytes are read on demand).
    pub fn open(path: &Path) -> Result<Self> {
        let shown = path.display().to_string();
        let mut head = [0u8; 16];
        let n = std::fs::File::open(path)
            .with_context(|| format!("cannot open {shown}"))?
            .read(&mut head)
            .with_context(|| format!("cannot read {shown}"))?;
        let head = &head[..n];
        if !head.starts_with(b"PK\x03\x04") {
            if head.len() >= 13 && head[0] == 0x80 && head[3..13] == LEGACY_MAGIC {
                bail!(
                    "{shown} is in the legacy (torch < 1.6) torch.save format, which is not read; \
                     re-save it with a current torch: python -c \"import torch; torch.save(torch.load('{shown}', weights_only=False), 'new.pt')\""
                );
            }
            bail!("{shown} is not a PyTorch checkpoint (a .pt file is a zip archive; this one starts with {head:02x?})");
        }
        let file = std::fs::File::open(path).with_context(|| format!("cannot open {shown}"))?;
        let file_len = file.metadata().map(|m| m.len()).unwrap_or(0);
        let mut archive = zip::ZipArchive::new(file).map_err(|e| {
            anyhow!("{shown} is not a readable PyTorch zip archive (truncated or damaged?): {e}")
        })?;
        let pkl = archive
            .file_names()
            .filter(|n| *n == "data.pkl" || n.ends_with("/data.pkl"))
            .min_by_key(|n| n.len())
            .map(str::to_string)
            .with_context(|| {
                format!("{shown}: the zip archive has no data.pkl (not a torch.save file)")
            })?;
        let prefix = pkl[..pkl.len() - "data.pkl".len()].to_string();
        let bytes = {
            let mut e = archive
                .by_name(&pkl)
                .map_err(|e| anyhow!("{shown}: cannot read {pkl}: {e}"))?;
            // The entry's size comes from the (possibly damaged) zip header: do not trust it
            // beyond the file's own length.
            let mut b = Vec::with_capacity(e.size().min(file_len) as usize);
            e.read_to_end(&mut b)
                .with_context(|| format!("{shown}: cannot read {pkl} (truncated?)"))?;
            b
        };
        let root = Unpickler::new(&bytes)
            .run()
            .with_context(|| format!("{shown}: cannot unpickle {pkl}"))?;
        Ok(Self {
            root,
            archive: RefCell::new(archive),
            prefix,
            path: shown,
            file_len,
        })
    }

    /// Reads the elements of a tensor view (any strides) as f32 (floats) or i64 (integers).
    pub fn read(&self, name: &str, t: &TensorRef) -> Result<HostTensor> {
        let st = &t.storage;
        let entry = format!("{}data/{}", self.prefix, st.key);
        let need = st
            .numel
            .checked_mul(st.dtype.size())
            .with_context(|| format!("{}: storage {} too large", self.path, st.key))?;
        let mut bytes = Vec::new();
        {
            let mut ar = self.archive.borrow_mut();
            let mut e = ar.by_name(&entry).map_err(|e| {
                anyhow!(
                    "{}: tensor {name}: cannot read archive entry {entry}: {e}",
                    self.path
                )
            })?;
            if (e.size() as usize) < need || need as u64 > self.file_len {
                bail!(
                    "{}: tensor {name}: storage {entry} holds {} bytes, {need} needed",
                    self.path,
                    e.size()
                );
            }
            bytes.reserve(need);
            e.read_to_end(&mut bytes).with_context(|| {
                format!(
                    "{}: tensor {name}: cannot read {entry} (truncated?)",
                    self.path
                )
            })?;
        }
        let numel = t
            .shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .filter(|&n| n <= MAX_VIEW_ELEMENTS)
            .with_context(|| {
                format!(
                    "{}: tensor {name} of shape {:?} is too large",
                    self.path, t.shape
                )
            })?;
        if t.shape.len() != t.stride.len() {
            bail!(
                "{}: tensor {name}: {} sizes but {} strides",
                self.path,
                t.shape.len(),
                t.stride.len()
            );
        }
        // Element offsets of the view in row-major order.
        let mut offsets = Vec::with_capacity(numel);
        if numel > 0 {
            let mut idx = vec![0usize; t.shape.len()];
            loop {
                let off = idx
                    .iter()
                    .zip(&t.stride)
                    .try_fold(t.offset, |a, (i, s)| a.checked_add(i.checked_mul(*s)?))
                    .unwrap_or(usize::MAX);
                if off >= st.numel {
                    bail!(
                        "{}: tensor {name} (shape {:?}, stride {:?}, offset {}) reaches past its storage of {} elements",
                        self.path, t.shape, t.stride, t.offset, st.numel
                    );
                }
                offsets.push(off);
                let mut d = t.shape.len();
                loop {
                    if d == 0 {
                        break;
                    }
                    d -= 1;
                    idx[d] += 1;
                    if idx[d] < t.shape[d] {
                        break;
                    }
                    idx[d] = 0;
                }
                if idx.iter().all(|&i| i == 0) {
                    break;
                }
            }
        }
        let sz = st.dtype.size();
        let at = |o: usize| &bytes[o * sz..o * sz + sz];
        let data = if st.dtype.is_float() {
            HostData::F32(
                offsets
                    .iter()
                    .map(|&o| {
                        let b = at(o);
                        match st.dtype {
                            StorageType::F16 => half::f16::from_le_bytes([b[0], b[1]]).to_f32(),
                            StorageType::BF16 => half::bf16::from_le_bytes([b[0], b[1]]).to_f32(),
                            StorageType::F32 => f32::from_le_bytes(b.try_into().unwrap()),
                            _ => f64::from_le_bytes(b.try_into().unwrap()) as f32,
                        }
                    })
                    .collect(),
            )
        } else {
            HostData::I64(
                offsets
                    .iter()
                    .map(|&o| {
                        let b = at(o);
                        match st.dtype {
                            StorageType::I64 => i64::from_le_bytes(b.try_into().unwrap()),
                            StorageType::I32 => i32::from_le_bytes(b.try_into().unwrap()) as i64,
                            StorageType::I16 => i16::from_le_bytes([b[0], b[1]]) as i64,
                            StorageType::I8 => b[0] as i8 as i64,
                            _ => b[0] as i64,
                        }
                    })
                    .collect(),
            )
        };
        Ok(HostTensor {
            shape: t.shape.clone(),
            data,
            source_dtype: st.dtype.name(),
        })
    }

    /// Reads every tensor of `entries`, keeping their order.
    pub fn read_all(
        &self,
        entries: &[(String, Rc<TensorRef>)],
    ) -> Result<BTreeMap<String, HostTensor>> {
        let mut out = BTreeMap::new();
        for (k, t) in entries {
            out.insert(k.clone(), self.read(k, t)?);
        }
        Ok(out)
    }
}

/// Unpickles `bytes` (a `data.pkl`): the root value, persistent ids resolved to storage
/// references. For fuzzing and for files that are a bare pickle.
pub fn unpickle(bytes: &[u8]) -> Result<Value> {
    Unpickler::new(bytes).run()
}

/// The pickle virtual machine (protocols 0–5, no extension registry, no out-of-band buffers).
struct Unpickler<'a> {
    b: &'a [u8],
    at: usize,
    stack: Vec<Value>,
    marks: Vec<usize>,
    memo: HashMap<u32, Value>,
    /// Nesting depth of each container built so far, by address: a hostile pickle could nest
    /// deep enough to overflow the stack when the values are dropped or walked.
    depth: HashMap<usize, u32>,
}

/// Containers nested deeper than this are refused (real checkpoints nest a few dozen deep).
const MAX_NESTING: u32 = 1000;

fn address(v: &Value) -> Option<usize> {
    Some(match v {
        Value::Tuple(r) => Rc::as_ptr(r) as *const () as usize,
        Value::List(r) => Rc::as_ptr(r) as *const () as usize,
        Value::Dict(r) => Rc::as_ptr(r) as *const () as usize,
        Value::Object(r) => Rc::as_ptr(r) as *const () as usize,
        _ => return None,
    })
}

impl<'a> Unpickler<'a> {
    fn new(b: &'a [u8]) -> Self {
        Self {
            b,
            at: 0,
            stack: Vec::new(),
            marks: Vec::new(),
            memo: HashMap::new(),
            depth: HashMap::new(),
        }
    }

    fn depth_of(&self, v: &Value) -> u32 {
        address(v)
            .and_then(|a| self.depth.get(&a).copied())
            .unwrap_or(0)
    }

    fn max_depth(&self, items: &[Value]) -> u32 {
        items.iter().map(|v| self.depth_of(v)).max().unwrap_or(0)
    }

    /// Records that the container on top of the stack holds values `inner` deep.
    fn nest_top(&mut self, inner: u32) -> Result<()> {
        let Some(a) = self.stack.last().and_then(address) else {
            return Ok(());
        };
        let d = self.depth.entry(a).or_insert(0);
        *d = (*d).max(inner + 1);
        if *d > MAX_NESTING {
            bail!(
                "pickle nests containers more than {MAX_NESTING} deep (byte {})",
                self.at
            );
        }
        Ok(())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| anyhow!("pickle ends early at byte {} (wanted {n} more)", self.at))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2)?.try_into()?))
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into()?))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into()?))
    }
    fn len(&mut self, n: u64) -> Result<usize> {
        let n = usize::try_from(n)?;
        if n > self.b.len() - self.at {
            bail!(
                "pickle declares {n} bytes at byte {}, only {} left",
                self.at,
                self.b.len() - self.at
            );
        }
        Ok(n)
    }
    fn line(&mut self) -> Result<&'a str> {
        let rest = &self.b[self.at..];
        let end = rest
            .iter()
            .position(|&c| c == b'\n')
            .ok_or_else(|| anyhow!("pickle ends inside a text line at byte {}", self.at))?;
        self.at += end + 1;
        std::str::from_utf8(&rest[..end]).map_err(|_| anyhow!("non-UTF-8 text line in pickle"))
    }

    fn pop(&mut self) -> Result<Value> {
        if self.marks.last().is_some_and(|&m| m >= self.stack.len()) {
            bail!("pickle pops past a mark at byte {}", self.at);
        }
        self.stack
            .pop()
            .ok_or_else(|| anyhow!("pickle stack underflow at byte {}", self.at))
    }

    fn pop_mark(&mut self) -> Result<Vec<Value>> {
        let m = self
            .marks
            .pop()
            .ok_or_else(|| anyhow!("pickle has no mark to pop at byte {}", self.at))?;
        if m > self.stack.len() {
            bail!("corrupt pickle mark at byte {}", self.at);
        }
        Ok(self.stack.split_off(m))
    }

    fn top(&self) -> Result<&Value> {
        self.stack
            .last()
            .ok_or_else(|| anyhow!("pickle stack empty at byte {}", self.at))
    }

    fn memo_get(&self, i: u32) -> Result<Value> {
        self.memo
            .get(&i)
            .cloned()
            .ok_or_else(|| anyhow!("pickle refers to memo entry {i} that was never stored"))
    }

    fn run(mut self) -> Result<Value> {
        loop {
            let pos = self.at;
            let op = self.u8()?;
            match op {
                0x80 => {
                    let p = self.u8()?;
                    if p > 5 {
                        bail!("pickle protocol {p} is not supported (0–5)");
                    }
                }
                0x95 => {
                    self.u64()?; // FRAME: a length hint only
                }
                b'.' => return self.pop(),
                b'(' => self.marks.push(self.stack.len()),
                b'0' => {
                    self.pop()?;
                }
                b'1' => {
                    self.pop_mark()?;
                }
                b'2' => {
                    let v = self.top()?.clone();
                    self.stack.push(v);
                }
                b'N' => self.stack.push(Value::None),
                0x88 => self.stack.push(Value::Bool(true)),
                0x89 => self.stack.push(Value::Bool(false)),
                b'I' => {
                    let l = self.line()?;
                    let v = match l {
                        "00" => Value::Bool(false),
                        "01" => Value::Bool(true),
                        _ => Value::Int(l.trim().parse().map_err(|_| anyhow!("bad INT {l:?}"))?),
                    };
                    self.stack.push(v);
                }
                b'J' => {
                    let v = i32::from_le_bytes(self.take(4)?.try_into()?);
                    self.stack.push(Value::Int(v as i64));
                }
                b'K' => {
                    let v = self.u8()?;
                    self.stack.push(Value::Int(v as i64));
                }
                b'M' => {
                    let v = self.u16()?;
                    self.stack.push(Value::Int(v as i64));
                }
                b'L' => {
                    let l = self.line()?.trim_end_matches('L');
                    let v = l
                        .parse::<i64>()
                        .map(Value::Int)
                        .unwrap_or_else(|_| Value::BigInt(l.as_bytes().into()));
                    self.stack.push(v);
                }
                0x8a | 0x8b => {
                    let n = if op == 0x8a {
                        self.u8()? as u64
                    } else {
                        self.u32()? as u64
                    };
                    let n = self.len(n)?;
                    let b = self.take(n)?;
                    let v = if n <= 8 {
                        let fill = if b.last().is_some_and(|&x| x & 0x80 != 0) {
                            0xff
                        } else {
                            0
                        };
                        let mut full = [fill; 8];
                        full[..n].copy_from_slice(b);
                        Value::Int(i64::from_le_bytes(full))
                    } else {
                        Value::BigInt(b.into())
                    };
                    self.stack.push(v);
                }
                b'F' => {
                    let l = self.line()?;
                    self.stack.push(Value::Float(
                        l.trim().parse().map_err(|_| anyhow!("bad FLOAT {l:?}"))?,
                    ));
                }
                b'G' => {
                    let v = f64::from_be_bytes(self.take(8)?.try_into()?);
                    self.stack.push(Value::Float(v));
                }
                b'S' => {
                    let l = self.line()?;
                    let s = l.trim().trim_matches(|c| c == '\'' || c == '"');
                    self.stack.push(Value::Str(s.into()));
                }
                b'T' | b'U' | b'X' | 0x8c | 0x8d | b'B' | b'C' | 0x8e | 0x96 => {
                    let n = match op {
                        b'U' | 0x8c | b'C' => self.u8()? as u64,
                        b'T' | b'X' | b'B' => self.u32()? as u64,
                        _ => self.u64()?,
                    };
                    let n = self.len(n)?;
                    let b = self.take(n)?;
                    let v = match op {
                        b'B' | b'C' | 0x8e | 0x96 => Value::Bytes(b.into()),
                        _ => Value::Str(String::from_utf8_lossy(b).into()),
                    };
                    self.stack.push(v);
                }
                b'V' => {
                    let l = self.line()?;
                    self.stack.push(Value::Str(l.into()));
                }
                b')' => self.stack.push(Value::Tuple(Rc::new(Vec::new()))),
                b't' => {
                    let items = self.pop_mark()?;
                    let d = self.max_depth(&items);
                    self.stack.push(Value::Tuple(Rc::new(items)));
                    self.nest_top(d)?;
                }
                0x85..=0x87 => {
                    let n = (op - 0x84) as usize;
                    if self.stack.len() < n {
                        bail!("pickle stack underflow at byte {pos}");
                    }
                    let items = self.stack.split_off(self.stack.len() - n);
                    let d = self.max_depth(&items);
                    self.stack.push(Value::Tuple(Rc::new(items)));
                    self.nest_top(d)?;
                }
                b']' => self.stack.push(Value::List(Rc::default())),
                b'l' => {
                    let items = self.pop_mark()?;
                    let d = self.max_depth(&items);
                    self.stack.push(Value::List(Rc::new(RefCell::new(items))));
                    self.nest_top(d)?;
                }
                b'a' => {
                    let v = self.pop()?;
                    self.extend_list(vec![v])?;
                }
                b'e' => {
                    let items = self.pop_mark()?;
                    self.extend_list(items)?;
                }
                b'}' => self.stack.push(Value::Dict(Rc::default())),
                b'd' => {
                    let items = self.pop_mark()?;
                    let d = Value::Dict(Rc::default());
                    self.stack.push(d);
                    self.set_items(items)?;
                }
                b's' => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    self.set_items(vec![k, v])?;
                }
                b'u' => {
                    let items = self.pop_mark()?;
                    self.set_items(items)?;
                }
                0x8f => self.stack.push(Value::List(Rc::default())),
                0x90 => {
                    let items = self.pop_mark()?;
                    self.extend_list(items)?;
                }
                0x91 => {
                    let items = self.pop_mark()?;
                    let d = self.max_depth(&items);
                    self.stack.push(Value::List(Rc::new(RefCell::new(items))));
                    self.nest_top(d)?;
                }
                b'c' => {
                    let module = self.line()?.to_string();
                    let name = self.line()?.to_string();
                    self.stack.push(Value::Class(Rc::new((module, name))));
                }
                0x93 => {
                    let name = self.pop()?;
                    let module = self.pop()?;
                    match (module.as_str(), name.as_str()) {
                        (Some(m), Some(n)) => self
                            .stack
                            .push(Value::Class(Rc::new((m.to_string(), n.to_string())))),
                        _ => bail!("STACK_GLOBAL needs two strings at byte {pos}"),
                    }
                }
                b'R' => {
                    let args = self.pop()?;
                    let callable = self.pop()?;
                    let d = self.depth_of(&args);
                    let v = reduce(callable, args)?;
                    self.stack.push(v);
                    self.nest_top(d)?;
                }
                0x81 => {
                    let args = self.pop()?;
                    let cls = self.pop()?;
                    let d = self.depth_of(&args);
                    self.stack
                        .push(new_object(&cls, args.elements().unwrap_or_default()));
                    self.nest_top(d)?;
                }
                0x92 => {
                    let _kwargs = self.pop()?;
                    let args = self.pop()?;
                    let cls = self.pop()?;
                    let d = self.depth_of(&args);
                    self.stack
                        .push(new_object(&cls, args.elements().unwrap_or_default()));
                    self.nest_top(d)?;
                }
                b'i' => {
                    let module = self.line()?.to_string();
                    let name = self.line()?.to_string();
                    let args = self.pop_mark()?;
                    let cls = Value::Class(Rc::new((module, name)));
                    self.stack.push(new_object(&cls, args));
                }
                b'o' => {
                    let mut items = self.pop_mark()?;
                    if items.is_empty() {
                        bail!("OBJ without a class at byte {pos}");
                    }
                    let cls = items.remove(0);
                    self.stack.push(new_object(&cls, items));
                }
                b'b' => {
                    let state = self.pop()?;
                    let obj = self.top()?.clone();
                    let d = self.depth_of(&state);
                    build(&obj, state)?;
                    self.nest_top(d)?;
                }
                b'p' => {
                    let i: u32 = self.line()?.trim().parse()?;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                b'q' => {
                    let i = self.u8()? as u32;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                b'r' => {
                    let i = self.u32()?;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                0x94 => {
                    let i = self.memo.len() as u32;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                b'g' => {
                    let i: u32 = self.line()?.trim().parse()?;
                    let v = self.memo_get(i)?;
                    self.stack.push(v);
                }
                b'h' => {
                    let i = self.u8()? as u32;
                    let v = self.memo_get(i)?;
                    self.stack.push(v);
                }
                b'j' => {
                    let i = self.u32()?;
                    let v = self.memo_get(i)?;
                    self.stack.push(v);
                }
                b'Q' => {
                    let pid = self.pop()?;
                    self.stack.push(persistent_load(pid)?);
                }
                b'P' => {
                    bail!("text persistent ids (PERSID) are not used by torch.save; byte {pos}")
                }
                other => bail!("unsupported pickle opcode 0x{other:02x} at byte {pos}"),
            }
        }
    }

    fn extend_list(&mut self, items: Vec<Value>) -> Result<()> {
        let d = self.max_depth(&items);
        self.nest_top(d)?;
        match self.top()? {
            Value::List(l) => l.borrow_mut().extend(items),
            Value::Object(o) => o.borrow_mut().elements.extend(items),
            other => bail!("APPEND to a {} at byte {}", other.type_name(), self.at),
        }
        Ok(())
    }

    fn set_items(&mut self, items: Vec<Value>) -> Result<()> {
        if items.len() % 2 != 0 {
            bail!("SETITEMS with an odd number of values at byte {}", self.at);
        }
        let d = self.max_depth(&items);
        self.nest_top(d)?;
        let mut pairs = Vec::with_capacity(items.len() / 2);
        let mut it = items.into_iter();
        while let (Some(k), Some(v)) = (it.next(), it.next()) {
            pairs.push((k, v));
        }
        match self.top()? {
            Value::Dict(d) => d.borrow_mut().extend(pairs),
            Value::Object(o) => o.borrow_mut().items.extend(pairs),
            other => bail!("SETITEM on a {} at byte {}", other.type_name(), self.at),
        }
        Ok(())
    }
}

fn class_name(v: &Value) -> String {
    match v {
        Value::Class(c) => format!("{}.{}", c.0, c.1),
        other => other.type_name(),
    }
}

fn new_object(cls: &Value, args: Vec<Value>) -> Value {
    Value::Object(Rc::new(RefCell::new(Object {
        class: class_name(cls),
        args,
        ..Object::default()
    })))
}

/// `BUILD`: a dict state updates a dict; anything else becomes an object's state.
fn build(obj: &Value, state: Value) -> Result<()> {
    match obj {
        Value::Object(o) => {
            let mut o = o.borrow_mut();
            // `(dict_state, slots_state)` tuples: keep the dict part.
            let state = match &state {
                Value::Tuple(t) if t.len() == 2 && matches!(t[0], Value::Dict(_) | Value::None) => {
                    t[0].clone()
                }
                _ => state,
            };
            o.state = Some(state);
        }
        Value::Dict(d) => {
            if let Value::Dict(s) = &state {
                let add = s.borrow().clone();
                d.borrow_mut().extend(add);
            }
        }
        // Tensors and other values rebuilt by reduce ignore their state (hooks, metadata).
        _ => {}
    }
    Ok(())
}

fn persistent_load(pid: Value) -> Result<Value> {
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
fn reduce(callable: Value, args: Value) -> Result<Value> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn run(b: &[u8]) -> Result<Value> {
        Unpickler::new(b).run()
    }

    #[test]
    fn reads_basic_protocol2_values() {
        // pickle.dumps({'a': [1, -2, 3.5], 'b': (True, None)}, protocol=2)
        let b = b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01]q\x02(K\x01J\xfe\xff\xff\xffG@\x0c\x00\x00\x00\x00\x00\x00eX\x01\x00\x00\x00bq\x03\x88N\x86q\x04u.";
        let v = run(b).unwrap();
        let a = v.get("a").unwrap().elements().unwrap();
        assert!(matches!(a[0], Value::Int(1)) && matches!(a[1], Value::Int(-2)));
        assert!(matches!(a[2], Value::Float(x) if x == 3.5));
        let t = v.get("b").unwrap().elements().unwrap();
        assert!(matches!(t[0], Value::Bool(true)) && matches!(t[1], Value::None));
    }

    #[test]
    fn memo_shares_built_objects() {
        // An object built after it was memoized is seen built through the memo (as in Python).
        // c__main__\nA\n)\x81q\x00}X\x01\x00\x00\x00xK\x05sb h\x00 .  → the same object twice in a tuple
        let mut b =
            b"\x80\x02c__main__\nA\nq\x00)\x81q\x01}q\x02X\x01\x00\x00\x00xK\x05sbh\x01\x86."
                .to_vec();
        // (obj, obj) after BUILD
        let v = run(&b).unwrap();
        let t = v.elements().unwrap();
        let Value::Object(o) = &t[1] else { panic!() };
        assert_eq!(o.borrow().class, "__main__.A");
        assert!(matches!(
            o.borrow().state.as_ref().unwrap().get("x"),
            Some(Value::Int(5))
        ));
        b.truncate(5);
        assert!(run(&b).unwrap_err().to_string().contains("ends"));
    }

    #[test]
    fn refuses_deep_nesting_and_survives_damage() {
        // 5000 nested 1-tuples: refused with a message, not a stack overflow.
        let mut b = b"\x80\x02N".to_vec();
        b.extend(std::iter::repeat_n(0x85u8, 5000));
        b.push(b'.');
        let e = run(&b).unwrap_err().to_string();
        assert!(e.contains("more than 1000 deep"), "{e}");
        // Every prefix and every single-byte change of a real torch pickle: an error or a
        // value, never a panic.
        let f = std::fs::File::open(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fixtures/ultralytics/reader/stripped.pt"),
        )
        .unwrap();
        let mut ar = zip::ZipArchive::new(f).unwrap();
        let mut pkl = Vec::new();
        ar.by_name("stripped/data.pkl")
            .unwrap()
            .read_to_end(&mut pkl)
            .unwrap();
        let root = run(&pkl).unwrap();
        assert!(root.get("model").unwrap().is_module());
        for n in 0..pkl.len() {
            let _ = run(&pkl[..n]);
            for x in [0x00u8, 0xff, b'(', b't', b'h'] {
                let mut c = pkl.clone();
                c[n] = x;
                let _ = run(&c);
            }
        }
    }

    #[test]
    fn rejects_unknown_opcode_and_underflow() {
        let e = run(b"\x80\x02\xff.").unwrap_err().to_string();
        assert!(
            e.contains("unsupported pickle opcode 0xff at byte 2"),
            "{e}"
        );
        let e = run(b"\x80\x02t.").unwrap_err().to_string();
        assert!(e.contains("mark"), "{e}");
        let e = run(b"\x80\x02h\x07.").unwrap_err().to_string();
        assert!(e.contains("memo entry 7"), "{e}");
    }
}
