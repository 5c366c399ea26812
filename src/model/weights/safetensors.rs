//! safetensors files (Hugging Face's format: a u64 little-endian header length, a JSON
//! header `{name: {dtype, shape, data_offsets}}`, then the raw bytes) as [`Snapshot`]s under
//! the file's key names, in the order of their data.

use anyhow::{bail, Context, Result};
use burn::tensor::DType;

use super::Snapshot;

fn dtype(s: &str) -> Option<DType> {
    Some(match s {
        "F64" => DType::F64,
        "F32" => DType::F32,
        "F16" => DType::F16,
        "BF16" => DType::BF16,
        "I64" => DType::I64,
        "I32" => DType::I32,
        "I16" => DType::I16,
        "I8" => DType::I8,
        "U8" | "BOOL" => DType::U8,
        _ => return None,
    })
}

/// Every tensor of a safetensors file. Errors say what is wrong without naming the file
/// (the caller adds it).
pub fn read(bytes: &[u8]) -> Result<Vec<Snapshot>> {
    let n = bytes
        .get(..8)
        .context("shorter than a safetensors header")?;
    let n = u64::from_le_bytes(n.try_into()?) as usize;
    let header = bytes
        .get(8..8usize.saturating_add(n))
        .context("safetensors header runs past the end of the file (truncated?)")?;
    let data = &bytes[8 + n..];
    let header: serde_json::Map<String, serde_json::Value> =
        serde_json::from_slice(header).context("safetensors header is not a JSON object")?;
    let mut out = Vec::new();
    for (name, v) in header {
        if name == "__metadata__" {
            continue;
        }
        let bad = |what: &str| anyhow::anyhow!("safetensors tensor {name}: {what}");
        let dt = v
            .get("dtype")
            .and_then(|d| d.as_str())
            .ok_or_else(|| bad("no dtype"))?;
        let dt = dtype(dt).ok_or_else(|| bad(&format!("unsupported dtype {dt}")))?;
        let shape: Vec<usize> = v
            .get("shape")
            .and_then(|s| s.as_array())
            .ok_or_else(|| bad("no shape"))?
            .iter()
            .map(|x| x.as_u64().map(|x| x as usize))
            .collect::<Option<_>>()
            .ok_or_else(|| bad("shape is not a list of sizes"))?;
        let off: Vec<usize> = v
            .get("data_offsets")
            .and_then(|s| s.as_array())
            .ok_or_else(|| bad("no data_offsets"))?
            .iter()
            .map(|x| x.as_u64().map(|x| x as usize))
            .collect::<Option<_>>()
            .ok_or_else(|| bad("data_offsets are not offsets"))?;
        let [a, b] = off[..] else {
            return Err(bad("data_offsets must be [begin, end]"));
        };
        let want = shape
            .iter()
            .try_fold(dt.size(), |a, &n| a.checked_mul(n))
            .ok_or_else(|| bad("shape overflows"))?;
        if b < a || b - a != want {
            return Err(bad(&format!(
                "data_offsets {a}..{b} do not hold {want} bytes of shape {shape:?}"
            )));
        }
        let raw = data
            .get(a..b)
            .ok_or_else(|| bad("data runs past the end of the file (truncated?)"))?;
        out.push((
            a,
            Snapshot::new(
                name.clone(),
                dt,
                shape,
                None,
                burn::tensor::Bytes::from_bytes_vec(raw.to_vec()),
            ),
        ));
    }
    if out.is_empty() {
        bail!("the safetensors file holds no tensors");
    }
    out.sort_by_key(|t| t.0);
    Ok(out.into_iter().map(|t| t.1).collect())
}

/// A safetensors file of f32 tensors (for tests and fixtures written from Rust).
pub fn write_f32(tensors: &[(String, Vec<usize>, Vec<f32>)]) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut off = 0usize;
    for (name, shape, v) in tensors {
        let n = v.len() * 4;
        header.insert(
            name.clone(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [off, off + n]}),
        );
        off += n;
    }
    let h = serde_json::to_vec(&header).expect("json");
    let mut out = (h.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&h);
    for (_, _, v) in tensors {
        for x in v {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let b = write_f32(&[
            ("a.weight".into(), vec![2, 2], vec![1.0, 2.0, 3.0, 4.0]),
            ("b".into(), vec![1], vec![5.0]),
        ]);
        assert_eq!(
            super::super::sniff(&b),
            Some(super::super::Format::Safetensors)
        );
        let t = read(&b).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t[0].name, "a.weight");
        let d = super::super::snapshot_data(t[0].clone()).unwrap();
        assert_eq!(d.try_to_vec::<f32>().unwrap(), vec![1.0, 2.0, 3.0, 4.0]);
        let e = format!("{:#}", read(&b[..b.len() - 3]).unwrap_err());
        assert!(e.contains("truncated"), "{e}");
    }
}
