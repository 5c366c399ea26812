//! `torch.save` files (PyTorch ≥ 1.6 zip format) read without Python: the archive's
//! `data.pkl` through [`super::pickle`], tensor bytes from `data/<key>` entries. Yields the
//! state dict (`model.state_dict()`, or the `state_dict` / `model` entry of a dict around
//! it) as [`Snapshot`]s under the file's own key names.
//!
//! `torch.save` stores zip entries uncompressed; a compressed entry (an archive re-zipped
//! by another tool) is refused by name. The legacy pre-1.6 format is refused with the
//! one-line conversion.

use anyhow::{bail, Context, Result};
use burn::tensor::DType;
use burn::tensor::TensorData;

use super::pickle::{self, Value};
use super::Snapshot;

/// One stored entry of a zip archive.
struct Entry {
    name: String,
    data: std::ops::Range<usize>,
}

fn u16_at(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(i..i + 2)?.try_into().ok()?))
}
fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?))
}
fn u64_at(b: &[u8], i: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(i..i + 8)?.try_into().ok()?))
}

/// The entries of a zip archive (central directory, zip64 aware).
fn zip_entries(b: &[u8]) -> Result<Vec<Entry>> {
    const EOCD: u32 = 0x0605_4b50;
    let min = b.len().saturating_sub(22 + 65_535);
    let eocd = (min..=b.len().saturating_sub(22))
        .rev()
        .find(|&i| u32_at(b, i) == Some(EOCD))
        .context("no zip end-of-central-directory record (truncated file?)")?;
    let bad = || anyhow::anyhow!("corrupt zip central directory (truncated file?)");
    let mut count = u16_at(b, eocd + 10).ok_or_else(bad)? as u64;
    let mut cd = u32_at(b, eocd + 16).ok_or_else(bad)? as u64;
    if count == 0xffff || cd == 0xffff_ffff {
        // Zip64 locator just before the EOCD → zip64 EOCD record.
        let loc = eocd.checked_sub(20).ok_or_else(bad)?;
        if u32_at(b, loc) != Some(0x0706_4b50) {
            return Err(bad());
        }
        let z = u64_at(b, loc + 8).ok_or_else(bad)? as usize;
        if u32_at(b, z) != Some(0x0606_4b50) {
            return Err(bad());
        }
        count = u64_at(b, z + 32).ok_or_else(bad)?;
        cd = u64_at(b, z + 48).ok_or_else(bad)?;
    }
    let mut at = cd as usize;
    let mut out = Vec::new();
    for _ in 0..count {
        if u32_at(b, at) != Some(0x0201_4b50) {
            return Err(bad());
        }
        let method = u16_at(b, at + 10).ok_or_else(bad)?;
        let mut csize = u32_at(b, at + 20).ok_or_else(bad)? as u64;
        let mut usize_ = u32_at(b, at + 24).ok_or_else(bad)? as u64;
        let n = u16_at(b, at + 28).ok_or_else(bad)? as usize;
        let e = u16_at(b, at + 30).ok_or_else(bad)? as usize;
        let c = u16_at(b, at + 32).ok_or_else(bad)? as usize;
        let mut local = u32_at(b, at + 42).ok_or_else(bad)? as u64;
        let name = b.get(at + 46..at + 46 + n).ok_or_else(bad)?;
        let name = String::from_utf8_lossy(name).into_owned();
        // Zip64 extended information: the fields that were 0xffffffff, in order.
        let extra = b.get(at + 46 + n..at + 46 + n + e).ok_or_else(bad)?;
        let mut i = 0;
        while i + 4 <= extra.len() {
            let id = u16_at(extra, i).ok_or_else(bad)?;
            let len = u16_at(extra, i + 2).ok_or_else(bad)? as usize;
            if id == 1 {
                let mut j = i + 4;
                for f in [&mut usize_, &mut csize, &mut local] {
                    if *f == 0xffff_ffff {
                        *f = u64_at(extra, j).ok_or_else(bad)?;
                        j += 8;
                    }
                }
            }
            i += 4 + len;
        }
        if method != 0 {
            bail!(
                "zip entry {name} is compressed (method {method}); torch.save writes stored entries — load and re-save it with torch.save"
            );
        }
        let l = local as usize;
        if u32_at(b, l) != Some(0x0403_4b50) {
            return Err(bad());
        }
        let ln = u16_at(b, l + 26).ok_or_else(bad)? as usize;
        let le = u16_at(b, l + 28).ok_or_else(bad)? as usize;
        let start = l + 30 + ln + le;
        let end = start
            .checked_add(csize as usize)
            .filter(|&x| x <= b.len())
            .with_context(|| {
                format!("zip entry {name} runs past the end of the file (truncated?)")
            })?;
        out.push(Entry {
            name,
            data: start..end,
        });
        at += 46 + n + e + c;
    }
    Ok(out)
}

/// Element type of a `torch.*Storage` global.
fn storage_dtype(name: &str) -> Option<DType> {
    Some(match name {
        "FloatStorage" => DType::F32,
        "HalfStorage" => DType::F16,
        "BFloat16Storage" => DType::BF16,
        "DoubleStorage" => DType::F64,
        "LongStorage" => DType::I64,
        "IntStorage" => DType::I32,
        "ShortStorage" => DType::I16,
        "CharStorage" => DType::I8,
        "ByteStorage" => DType::U8,
        "BoolStorage" => DType::U8,
        _ => return None,
    })
}

/// The entries of a dict, an `OrderedDict(...)` call filled by `SETITEMS`, or either with a
/// `BUILD` state (`_metadata`) on top.
fn dict_entries(v: &Value) -> Option<&[(Value, Value)]> {
    match v {
        Value::Dict(e) => Some(e),
        Value::Build(o, s) => dict_entries(o).or_else(|| dict_entries(s)),
        _ => None,
    }
}

struct Archive<'a> {
    bytes: &'a [u8],
    entries: Vec<Entry>,
    prefix: String,
}

impl Archive<'_> {
    fn storage(&self, key: &str) -> Result<&[u8]> {
        let want = format!("{}data/{key}", self.prefix);
        let e = self
            .entries
            .iter()
            .find(|e| e.name == want)
            .with_context(|| format!("storage {want} is missing from the archive"))?;
        Ok(&self.bytes[e.data.clone()])
    }

    /// A tensor from `_rebuild_tensor_v2(storage, offset, size, stride, ...)` (or a
    /// `Parameter` around one), or `None` if `v` is not a tensor.
    fn tensor(&self, name: &str, v: &Value) -> Result<Option<Snapshot>> {
        let Value::Call(f, args) = v else {
            return Ok(None);
        };
        let f = f.global_name().unwrap_or_default();
        let args = args.as_seq().unwrap_or(&[]);
        if f == "torch._utils._rebuild_parameter"
            || f == "torch._utils._rebuild_parameter_with_state"
        {
            return match args.first() {
                Some(d) => self.tensor(name, d),
                None => bail!("tensor {name}: empty _rebuild_parameter"),
            };
        }
        if f != "torch._utils._rebuild_tensor_v2" && f != "torch._utils._rebuild_tensor" {
            return Ok(None);
        }
        let bad = |what: &str| anyhow::anyhow!("tensor {name}: {what}");
        let [storage, offset, size, stride, ..] = args else {
            return Err(bad("_rebuild_tensor_v2 has too few arguments"));
        };
        let Value::PersId(pid) = storage else {
            return Err(bad("storage is not a persistent id"));
        };
        let pid = pid
            .as_seq()
            .ok_or_else(|| bad("storage id is not a tuple"))?;
        let (Some(ty), Some(key)) = (pid.get(1), pid.get(2).and_then(|k| k.as_str())) else {
            return Err(bad("storage id lacks a type or key"));
        };
        let ty_name = match ty {
            Value::Global(_, n) => n.clone(),
            _ => return Err(bad("storage type is not a global")),
        };
        let dtype = storage_dtype(&ty_name)
            .ok_or_else(|| bad(&format!("unsupported storage type {ty_name}")))?;
        let esize = dtype.size();
        let offset = offset
            .as_int()
            .ok_or_else(|| bad("offset is not an integer"))? as usize;
        let ints = |v: &Value, what: &str| -> Result<Vec<usize>> {
            v.as_seq()
                .ok_or_else(|| bad(&format!("{what} is not a tuple")))?
                .iter()
                .map(|x| {
                    x.as_int()
                        .filter(|&i| i >= 0)
                        .map(|i| i as usize)
                        .ok_or_else(|| bad(&format!("{what} has a non-integer entry")))
                })
                .collect()
        };
        let shape = ints(size, "size")?;
        let stride = ints(stride, "stride")?;
        if stride.len() != shape.len() {
            return Err(bad("size and stride differ in length"));
        }
        let raw = self.storage(key)?;
        // Checked: sizes come from the file, and a corrupt one must be an error, not a
        // wrapped product that passes the bounds check.
        let too_big = || bad("size overflows (corrupt file?)");
        let numel = shape
            .iter()
            .try_fold(1usize, |a, &n| a.checked_mul(n))
            .ok_or_else(too_big)?;
        // Row-major gather (a contiguous tensor is one slice).
        let mut contiguous = vec![0usize; shape.len()];
        let mut acc = 1;
        for i in (0..shape.len()).rev() {
            contiguous[i] = acc;
            acc *= shape[i];
        }
        let span = if numel == 0 {
            0
        } else {
            shape
                .iter()
                .zip(&stride)
                .try_fold(1usize, |a, (&n, &s)| a.checked_add((n - 1).checked_mul(s)?))
                .ok_or_else(too_big)?
        };
        let need = offset
            .checked_add(if stride == contiguous || numel <= 1 {
                numel
            } else {
                span
            })
            .and_then(|e| e.checked_mul(esize))
            .ok_or_else(too_big)?;
        if need > raw.len() {
            return Err(bad(&format!(
                "storage {key} holds {} bytes, the tensor needs {need} (truncated file?)",
                raw.len()
            )));
        }
        let bytes = if stride == contiguous || numel <= 1 {
            raw[offset * esize..(offset + numel) * esize].to_vec()
        } else {
            let mut out = Vec::with_capacity(numel * esize);
            let mut idx = vec![0usize; shape.len()];
            for _ in 0..numel {
                let at = offset + idx.iter().zip(&stride).map(|(i, s)| i * s).sum::<usize>();
                out.extend_from_slice(&raw[at * esize..(at + 1) * esize]);
                for d in (0..shape.len()).rev() {
                    idx[d] += 1;
                    if idx[d] < shape[d] {
                        break;
                    }
                    idx[d] = 0;
                }
            }
            out
        };
        let data = TensorData::from_bytes_vec(bytes, shape, dtype);
        let (bytes, shape, dtype) = data.into_parts();
        Ok(Some(Snapshot::new(
            name.to_string(),
            dtype,
            shape,
            None,
            bytes,
        )))
    }
}

/// The tensors of a state dict among `entries`, or `None` if some value is not a tensor.
fn state_dict(a: &Archive, entries: &[(Value, Value)]) -> Result<Option<Vec<Snapshot>>> {
    let mut out = Vec::with_capacity(entries.len());
    for (k, v) in entries {
        let Some(k) = k.as_str() else { return Ok(None) };
        match a.tensor(k, v)? {
            Some(t) => out.push(t),
            None => return Ok(None),
        }
    }
    Ok(Some(out))
}

/// The state dict of a `torch.save` zip file, key names as in the file. Errors say what is
/// wrong without naming the file (the caller adds it).
pub fn read(bytes: &[u8]) -> Result<Vec<Snapshot>> {
    if super::sniff(bytes) == Some(super::Format::TorchLegacy) {
        bail!("legacy (pre-1.6) PyTorch format; convert it with: python -c \"import torch; torch.save(torch.load('IN', weights_only=True), 'OUT')\"");
    }
    let entries = zip_entries(bytes)?;
    let pkl = entries
        .iter()
        .find(|e| e.name.ends_with("data.pkl") && e.name.matches('/').count() <= 1)
        .context("no data.pkl in the archive (not a torch.save file)")?;
    let prefix = pkl.name[..pkl.name.len() - "data.pkl".len()].to_string();
    if let Some(bo) = entries
        .iter()
        .find(|e| e.name == format!("{prefix}byteorder"))
    {
        let order = &bytes[bo.data.clone()];
        if order != b"little" {
            bail!(
                "byte order {:?} is not supported (only little-endian)",
                String::from_utf8_lossy(order)
            );
        }
    }
    let root = pickle::load(&bytes[pkl.data.clone()]).context("cannot unpickle data.pkl")?;
    let a = Archive {
        bytes,
        entries,
        prefix,
    };
    let top =
        dict_entries(&root).context("data.pkl does not hold a dict (expected a state_dict)")?;
    if let Some(sd) = state_dict(&a, top)? {
        return Ok(sd);
    }
    for key in ["state_dict", "model_state_dict", "model"] {
        let inner = top
            .iter()
            .find(|(k, _)| k.as_str() == Some(key))
            .and_then(|(_, v)| dict_entries(v));
        if let Some(inner) = inner {
            if let Some(sd) = state_dict(&a, inner)? {
                return Ok(sd);
            }
        }
    }
    let keys: Vec<&str> = top.iter().filter_map(|(k, _)| k.as_str()).take(6).collect();
    bail!(
        "no state dict of tensors in data.pkl (top-level keys {keys:?}); save one with torch.save(model.state_dict(), PATH)"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn garbage_and_truncation_are_errors() {
        let e = format!("{:#}", read(b"PK\x03\x04 not really a zip").unwrap_err());
        assert!(e.contains("end-of-central-directory"), "{e}");
        let e = format!("{:#}", read(b"\x80\x02}q\x00.").unwrap_err());
        assert!(e.contains("legacy"), "{e}");
    }
}
