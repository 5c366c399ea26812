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
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;
use std::rc::Rc;

use anyhow::{anyhow, bail, Context, Result};

use super::host::{HostData, HostTensor};
use super::pickle::unpickle;
use super::pickle_value::Value;
use super::torch_storage::{StorageType, TensorRef};

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
        let root = unpickle(&bytes).with_context(|| format!("{shown}: cannot unpickle {pkl}"))?;
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
        let offsets = self.view_offsets(name, t, numel)?;
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

    /// The element offsets of view `t` (`numel` elements) into its storage, in row-major
    /// order; an offset past the storage is an error naming the tensor.
    fn view_offsets(&self, name: &str, t: &TensorRef, numel: usize) -> Result<Vec<usize>> {
        let mut offsets = Vec::with_capacity(numel);
        if numel > 0 {
            let mut idx = vec![0usize; t.shape.len()];
            loop {
                let off = idx
                    .iter()
                    .zip(&t.stride)
                    .try_fold(t.offset, |a, (i, s)| a.checked_add(i.checked_mul(*s)?))
                    .unwrap_or(usize::MAX);
                if off >= t.storage.numel {
                    bail!(
                        "{}: tensor {name} (shape {:?}, stride {:?}, offset {}) reaches past its storage of {} elements",
                        self.path, t.shape, t.stride, t.offset, t.storage.numel
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
        Ok(offsets)
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
