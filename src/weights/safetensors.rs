//! safetensors files (huggingface/safetensors): a little-endian u64 header length, a JSON
//! header `{name: {dtype, shape, data_offsets}, "__metadata__": {str: str}}`, then the raw
//! little-endian tensor bytes. Read into [`HostTensor`]s; written atomically.
//!
//! Small enough to do by hand: the `safetensors` crate would come with burn-store's feature
//! set, which rebuilds all of Burn (see `pytorch.rs`).

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Map, Value};

use super::host::{HostData, HostTensor};

/// Largest header accepted (the format's own reference implementation caps it at 100 MB).
const MAX_HEADER: u64 = 100 << 20;

/// Whether `path` starts like a safetensors file (a plausible header length, then `{`).
pub fn looks_like(path: &Path) -> Result<bool> {
    let mut f =
        std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let len = f.metadata()?.len();
    let mut head = [0u8; 9];
    if len < 9 || f.read_exact(&mut head).is_err() {
        return Ok(false);
    }
    let n = u64::from_le_bytes(head[..8].try_into().unwrap());
    Ok(n <= MAX_HEADER && n <= len - 8 && head[8] == b'{')
}

/// Reads every tensor of a safetensors file (floats as f32, integers and bools as i64).
pub fn read(path: &Path) -> Result<BTreeMap<String, HostTensor>> {
    let shown = path.display();
    let b = std::fs::read(path).with_context(|| format!("cannot read {shown}"))?;
    let (tensors, _) =
        parse(&b).with_context(|| format!("{shown} is not a valid safetensors file"))?;
    Ok(tensors)
}

/// Parses a whole file: the tensors and the `__metadata__` strings.
pub fn parse(b: &[u8]) -> Result<(BTreeMap<String, HostTensor>, BTreeMap<String, String>)> {
    if b.len() < 8 {
        bail!("{} bytes, shorter than the 8-byte header length", b.len());
    }
    let n = u64::from_le_bytes(b[..8].try_into().unwrap());
    if n > MAX_HEADER || n > (b.len() - 8) as u64 {
        bail!(
            "header length {n} does not fit the file of {} bytes (truncated?)",
            b.len()
        );
    }
    let header: Map<String, Value> =
        serde_json::from_slice(&b[8..8 + n as usize]).context("the header is not a JSON object")?;
    let data = &b[8 + n as usize..];
    let mut out = BTreeMap::new();
    let mut meta = BTreeMap::new();
    for (name, v) in header {
        if name == "__metadata__" {
            if let Value::Object(m) = v {
                for (k, v) in m {
                    meta.insert(k, v.as_str().unwrap_or_default().to_string());
                }
            }
            continue;
        }
        let dtype = v["dtype"]
            .as_str()
            .with_context(|| format!("tensor {name}: no dtype"))?;
        let shape: Vec<usize> = v["shape"]
            .as_array()
            .with_context(|| format!("tensor {name}: no shape"))?
            .iter()
            .map(|x| x.as_u64().map(|x| x as usize))
            .collect::<Option<_>>()
            .with_context(|| format!("tensor {name}: shape is not a list of sizes"))?;
        let off: Vec<usize> = v["data_offsets"]
            .as_array()
            .filter(|a| a.len() == 2)
            .and_then(|a| a.iter().map(|x| x.as_u64().map(|x| x as usize)).collect())
            .with_context(|| format!("tensor {name}: no [begin, end] data_offsets"))?;
        let (size, source_dtype) = match dtype {
            "F16" => (2, "float16"),
            "BF16" => (2, "bfloat16"),
            "F32" => (4, "float32"),
            "F64" => (8, "float64"),
            "I64" => (8, "int64"),
            "I32" => (4, "int32"),
            "I16" => (2, "int16"),
            "I8" => (1, "int8"),
            "U8" => (1, "uint8"),
            "BOOL" => (1, "bool"),
            other => bail!("tensor {name}: dtype {other} is not supported"),
        };
        let bytes = shape
            .iter()
            .try_fold(size as usize, |a: usize, &d| a.checked_mul(d))
            .with_context(|| format!("tensor {name}: shape {shape:?} is too large"))?;
        if off[1] < off[0] || off[1] > data.len() || off[1] - off[0] != bytes {
            bail!(
                "tensor {name}: data_offsets {off:?} do not hold {shape:?} {dtype} values in {} data bytes (truncated?)",
                data.len()
            );
        }
        let data = decode(dtype, size, &data[off[0]..off[1]]);
        out.insert(
            name,
            HostTensor {
                shape,
                data,
                source_dtype,
            },
        );
    }
    Ok((out, meta))
}

/// A tensor's little-endian values of `dtype` (`size` bytes each, checked by the caller):
/// floats widened or narrowed to f32, integers and bools to i64.
fn decode(dtype: &str, size: usize, raw: &[u8]) -> HostData {
    let chunks = raw.chunks_exact(size);
    match dtype {
        "F16" => HostData::F32(
            chunks
                .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
                .collect(),
        ),
        "BF16" => HostData::F32(
            chunks
                .map(|c| half::bf16::from_le_bytes([c[0], c[1]]).to_f32())
                .collect(),
        ),
        "F32" => HostData::F32(
            chunks
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect(),
        ),
        "F64" => HostData::F32(
            chunks
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()) as f32)
                .collect(),
        ),
        "I64" => HostData::I64(
            chunks
                .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
                .collect(),
        ),
        "I32" => HostData::I64(
            chunks
                .map(|c| i32::from_le_bytes(c.try_into().unwrap()) as i64)
                .collect(),
        ),
        "I16" => HostData::I64(
            chunks
                .map(|c| i16::from_le_bytes([c[0], c[1]]) as i64)
                .collect(),
        ),
        "I8" => HostData::I64(chunks.map(|c| c[0] as i8 as i64).collect()),
        _ => HostData::I64(chunks.map(|c| c[0] as i64).collect()),
    }
}

/// The bytes of a safetensors file holding `tensors` (f32 → `F32`, i64 → `I64`) in the given
/// order, with `metadata` as `__metadata__`. The header is padded to a multiple of 8 bytes.
pub fn to_bytes(
    tensors: &[(String, HostTensor)],
    metadata: &BTreeMap<String, String>,
) -> Result<Vec<u8>> {
    let mut header = Map::new();
    if !metadata.is_empty() {
        header.insert("__metadata__".into(), json!(metadata));
    }
    let mut at = 0usize;
    for (name, t) in tensors {
        if header.contains_key(name) {
            bail!("tensor name {name} appears twice");
        }
        let (dtype, bytes) = match &t.data {
            HostData::F32(v) => ("F32", 4 * v.len()),
            HostData::I64(v) => ("I64", 8 * v.len()),
        };
        if bytes / if dtype == "F32" { 4 } else { 8 } != t.numel() {
            bail!(
                "tensor {name}: shape {:?} does not match its {} elements",
                t.shape,
                bytes
            );
        }
        header.insert(
            name.clone(),
            json!({"dtype": dtype, "shape": t.shape, "data_offsets": [at, at + bytes]}),
        );
        at += bytes;
    }
    let mut h = serde_json::to_vec(&Value::Object(header))?;
    while h.len() % 8 != 0 {
        h.push(b' ');
    }
    let mut out = Vec::with_capacity(8 + h.len() + at);
    out.extend_from_slice(&(h.len() as u64).to_le_bytes());
    out.extend_from_slice(&h);
    for (_, t) in tensors {
        match &t.data {
            HostData::F32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            HostData::I64(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        }
    }
    Ok(out)
}

/// Writes a safetensors file atomically (temp + rename).
pub fn write(
    path: &Path,
    tensors: &[(String, HostTensor)],
    metadata: &BTreeMap<String, String>,
) -> Result<()> {
    crate::util::write_atomic(path, &to_bytes(tensors, metadata)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_rejects_truncation() {
        let t = vec![
            (
                "a.w".to_string(),
                HostTensor::f32(vec![2, 2], vec![1.0, -2.0, 3.5, 0.25]),
            ),
            (
                "n".to_string(),
                HostTensor {
                    shape: vec![],
                    data: HostData::I64(vec![7]),
                    source_dtype: "int64",
                },
            ),
        ];
        let meta = BTreeMap::from([("format".to_string(), "pt".to_string())]);
        let b = to_bytes(&t, &meta).unwrap();
        assert_eq!(u64::from_le_bytes(b[..8].try_into().unwrap()) % 8, 0);
        let (back, m) = parse(&b).unwrap();
        assert_eq!(m, meta);
        assert_eq!(back["a.w"].data, t[0].1.data);
        assert_eq!(back["n"].data, HostData::I64(vec![7]));
        let e = parse(&b[..b.len() - 3]).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
    }
}
