//! Weights from elsewhere, one code path for every source: a reader turns a file into
//! [`Snapshot`]s (burn-store's `TensorSnapshot`: a name, dtype, shape and bytes) keyed by
//! chicktrain's own module paths — exactly the names [`collect`] gives, `backbone.l0.conv.weight`
//! — and [`apply`] loads them into a model, checking every shape.
//!
//! Readers: [`read_file`] (`torch.save` zip files and safetensors, through
//! `util::{pytorch, safetensors}`, the readers the ultralytics importer uses too); a
//! chicktrain checkpoint goes through [`collect`] on the model it holds. Key mapping from another framework's names
//! lives beside the model it describes (`maskrcnn::torchvision`). [`sniff`] tells the
//! formats apart by their first bytes, never by the extension.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use anyhow::{bail, Result};
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{DType, Tensor, TensorData};

use crate::weights::host::HostData;
use crate::weights::state_dict::read_state_dict;

/// One named tensor: burn-store's `TensorSnapshot` (`burn_pack::Tensor`), so a store from
/// burn-store can feed [`apply`] unchanged.
pub type Snapshot = burn_pack::Tensor;

/// What a weights file is, from its first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// A chicktrain checkpoint (`CHICKTRAIN-CKPT1\n`).
    Chicktrain,
    /// `torch.save` since PyTorch 1.6: a zip archive (`PK\x03\x04`).
    TorchZip,
    /// `torch.save(..., _use_new_zipfile_serialization=False)`: a bare pickle (`\x80\x02`).
    TorchLegacy,
    /// safetensors: a little-endian u64 header length, then a JSON object.
    Safetensors,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Chicktrain => "chicktrain checkpoint",
            Format::TorchZip => "PyTorch zip file",
            Format::TorchLegacy => "legacy PyTorch pickle",
            Format::Safetensors => "safetensors file",
        }
    }
}

/// The magic line of a chicktrain checkpoint (`infer::checkpoint` writes it).
pub const CHICKTRAIN_MAGIC: &[u8] = b"CHICKTRAIN-CKPT1\n";

/// The format of `bytes`, or `None` if it is none of the four.
pub fn sniff(bytes: &[u8]) -> Option<Format> {
    sniff_head(bytes, bytes.len() as u64)
}

/// Bytes [`sniff_file`] reads: the longest magic, the checkpoint's line.
const HEAD: usize = 17;

/// The format of the file at `path` from its first bytes and its length, without
/// reading the rest (a torchvision `.pth` is 100–200 MB, and its reader opens it anyway);
/// also the first bytes, for messages.
pub fn sniff_file(path: &Path) -> std::io::Result<(Option<Format>, Vec<u8>)> {
    use std::io::Read;
    let f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    let mut head = Vec::with_capacity(HEAD);
    f.take(HEAD as u64).read_to_end(&mut head)?;
    Ok((sniff_head(&head, len), head))
}

/// [`sniff`] of a file whose first bytes are `bytes` and whose length is `len`.
fn sniff_head(bytes: &[u8], len: u64) -> Option<Format> {
    if bytes.starts_with(CHICKTRAIN_MAGIC) {
        return Some(Format::Chicktrain);
    }
    if bytes.starts_with(b"PK\x03\x04") {
        return Some(Format::TorchZip);
    }
    // Pickle protocol 2+ starts with PROTO (0x80) and the protocol number.
    if bytes.len() >= 2 && bytes[0] == 0x80 && (2..=5).contains(&bytes[1]) {
        return Some(Format::TorchLegacy);
    }
    if bytes.len() >= 9 {
        let n = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
        if n >= 2 && n <= len - 8 && bytes[8] == b'{' {
            return Some(Format::Safetensors);
        }
    }
    None
}

/// Float data as f32: checkpoints may hold fp16 / bf16 / f64 (ultralytics saves fp16);
/// the models compute in f32.
pub fn snapshot_data(s: Snapshot) -> Result<TensorData> {
    let name = s.name.clone();
    let (_, dtype, shape, _, bytes) = s
        .into_parts()
        .map_err(|e| anyhow::anyhow!("tensor {name}: unreadable data: {e}"))?;
    let data = TensorData::try_from_bytes(bytes, shape, dtype)
        .map_err(|e| anyhow::anyhow!("tensor {name}: {e}"))?;
    Ok(match dtype {
        DType::F32 => data,
        DType::F16 | DType::BF16 | DType::F64 => data.convert::<f32>(),
        d => bail!("tensor {name}: dtype {d:?} is not a float type"),
    })
}

/// The tensors of a PyTorch (`torch.save`) or safetensors file under the file's own key
/// names, floats as f32 and integers (BatchNorm `num_batches_tracked`) as i64. In a
/// checkpoint dict the first entry of `prefer` that holds weights is read (see
/// [`read_state_dict`]).
pub fn read_file(path: &Path, prefer: &[&str]) -> Result<Vec<Snapshot>> {
    let sd = read_state_dict(path, prefer)?;
    Ok(sd
        .tensors
        .into_iter()
        .map(|(name, t)| match t.data {
            HostData::F32(v) => snapshot_f32(name, v, t.shape),
            HostData::I64(v) => {
                let (bytes, shape, dtype) = TensorData::new(v, t.shape).into_parts();
                Snapshot::new(name, dtype, shape, None, bytes)
            }
        })
        .collect())
}

/// A snapshot of f32 host values.
pub fn snapshot_f32(name: impl Into<String>, values: Vec<f32>, shape: Vec<usize>) -> Snapshot {
    let (bytes, shape, dtype) = TensorData::new(values, shape).into_parts();
    Snapshot::new(name.into(), dtype, shape, None, bytes)
}

/// Every float tensor of `module` (weights, biases, BatchNorm running statistics), named
/// by its path, in visiting order. The names are burn-store's `ModuleSnapshot::collect`
/// names (enter-module names joined by `.`).
pub fn collect<M: Module>(module: &M) -> Vec<Snapshot> {
    struct C {
        path: Vec<String>,
        out: Vec<Snapshot>,
    }
    impl ModuleVisitor for C {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            let (bytes, shape, dtype) = p.val().into_data().into_parts();
            self.out.push(Snapshot::new(
                self.path.join("."),
                dtype,
                shape,
                None,
                bytes,
            ));
        }
    }
    let mut c = C {
        path: Vec::new(),
        out: Vec::new(),
    };
    module.visit(&mut c);
    c.out
}

/// Paths and shapes of every float tensor of `module`, in visiting order.
pub fn shapes<M: Module>(module: &M) -> Vec<(String, Vec<usize>)> {
    struct S {
        path: Vec<String>,
        out: Vec<(String, Vec<usize>)>,
    }
    impl ModuleVisitor for S {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.out
                .push((self.path.join("."), p.lazy_shape().to_vec()));
        }
    }
    let mut s = S {
        path: Vec::new(),
        out: Vec::new(),
    };
    module.visit(&mut s);
    s.out
}

/// What [`apply`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Applied {
    /// Tensors loaded from the source.
    pub loaded: usize,
    /// Class-dependent tensors kept at their fresh initialisation (missing from the
    /// source, or of another shape there because the class count differs).
    pub reinitialised: Vec<String>,
}

/// Loads `snapshots` into `module` by path. Every tensor of the module must be in the
/// source with its shape, and every source tensor must be used; the exception is a
/// tensor for which `class_dependent(path)` holds (a classifier sized by the class count):
/// missing or of another shape, it keeps its fresh initialisation and is listed in
/// [`Applied::reinitialised`]. Errors name `origin` and the first key (in the module's
/// order) that does not fit, with the expected and found shapes. Float data of any
/// precision is loaded as f32; parameter ids and gradient settings stay the module's.
pub fn apply<M: Module>(
    module: M,
    snapshots: Vec<Snapshot>,
    class_dependent: &dyn Fn(&str) -> bool,
    origin: &str,
) -> Result<(M, Applied)> {
    apply_named(module, snapshots, class_dependent, origin, &HashMap::new())
}

/// [`apply`], with errors also naming the file's own key of each chicktrain key
/// (`file_keys`: chicktrain path → key in the file), for importers that rename.
pub fn apply_named<M: Module>(
    module: M,
    snapshots: Vec<Snapshot>,
    class_dependent: &dyn Fn(&str) -> bool,
    origin: &str,
    file_keys: &HashMap<String, String>,
) -> Result<(M, Applied)> {
    let named = |k: &str| match file_keys.get(k) {
        Some(f) => format!("{k} (file key {f})"),
        None => k.to_string(),
    };
    let mut src: HashMap<String, Snapshot> = HashMap::new();
    let mut order = Vec::new();
    for s in snapshots {
        if src.contains_key(&s.name) {
            bail!("{origin}: key {} appears twice", named(&s.name));
        }
        order.push(s.name.clone());
        src.insert(s.name.clone(), s);
    }
    let targets = shapes(&module);
    let wanted: HashSet<&str> = targets.iter().map(|t| t.0.as_str()).collect();
    if let Some(extra) = order.iter().find(|k| !wanted.contains(k.as_str())) {
        bail!(
            "{origin}: key {} has no place in this model (a checkpoint of another architecture? the model's first key is {})",
            named(extra),
            targets.first().map(|t| t.0.as_str()).unwrap_or("none")
        );
    }
    let mut load: HashMap<String, TensorData> = HashMap::new();
    let mut reinitialised = Vec::new();
    for (path, shape) in &targets {
        let Some(s) = src.remove(path) else {
            if class_dependent(path) {
                reinitialised.push(path.clone());
                continue;
            }
            bail!("{origin}: key {} (shape {shape:?}) is missing", named(path));
        };
        let found: Vec<usize> = s.shape.to_vec();
        if &found != shape {
            if class_dependent(path) {
                reinitialised.push(path.clone());
                continue;
            }
            bail!(
                "{origin}: key {} does not fit: the model expects shape {shape:?}, the file has {found:?}",
                named(path)
            );
        }
        let data = snapshot_data(s).map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
        load.insert(path.clone(), data);
    }
    let loaded = load.len();
    struct Load {
        path: Vec<String>,
        data: HashMap<String, TensorData>,
    }
    impl ModuleMapper for Load {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
            match self.data.remove(&self.path.join(".")) {
                Some(d) => {
                    let device = p.lazy_device();
                    let id = p.id;
                    p.transform_for_load(Tensor::from_data(d, &device), id)
                }
                None => p,
            }
        }
    }
    let module = module.map(&mut Load {
        path: Vec::new(),
        data: load,
    });
    Ok((
        module,
        Applied {
            loaded,
            reinitialised,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::yolo::{Scale, YoloSegConfig};
    use burn::tensor::Device;

    fn tiny(nc: usize) -> crate::model::yolo::YoloSeg {
        YoloSegConfig::new(Scale::N, nc)
            .with_input_size(32)
            .with_width_mult(0.25)
            .with_num_masks(4)
            .init(&Device::flex())
    }

    #[test]
    fn sniff_tells_the_formats_apart() {
        assert_eq!(sniff(b"CHICKTRAIN-CKPT1\nxx"), Some(Format::Chicktrain));
        assert_eq!(sniff(b"PK\x03\x04rest"), Some(Format::TorchZip));
        assert_eq!(sniff(b"\x80\x02\x8a\x0alegacy"), Some(Format::TorchLegacy));
        let mut st = 2u64.to_le_bytes().to_vec();
        st.extend_from_slice(b"{}");
        assert_eq!(sniff(&st), Some(Format::Safetensors));
        // A header length past the end of the file is not safetensors.
        let mut bad = 99u64.to_le_bytes().to_vec();
        bad.extend_from_slice(b"{}");
        assert_eq!(sniff(&bad), None);
        assert_eq!(sniff(b"hello world"), None);
        assert_eq!(sniff(b""), None);
    }

    #[test]
    fn collect_then_apply_copies_every_tensor() {
        let a = tiny(1);
        let b = tiny(1);
        let snaps = collect(&a);
        assert!(
            snaps.iter().any(|s| s.name == "backbone.l0.conv.weight"),
            "{:?}",
            snaps[0].name
        );
        assert!(snaps.iter().any(|s| s.name.ends_with("bn.running_var")));
        // Enum variants are path segments, as in burn-store's `collect(None, None, false)`:
        // the names an importer must produce.
        assert!(
            snaps
                .iter()
                .any(|s| s.name.starts_with("backbone.l2.m.0.Bottleneck.")),
            "{:?}",
            snaps.iter().map(|s| &s.name).collect::<Vec<_>>()
        );
        let n = snaps.len();
        let (b, r) = apply(b, snaps, &|_| false, "a").unwrap();
        assert_eq!(
            r,
            Applied {
                loaded: n,
                reinitialised: vec![]
            }
        );
        let va: Vec<Vec<f32>> = collect(&a)
            .into_iter()
            .map(|s| snapshot_data(s).unwrap().try_to_vec::<f32>().unwrap())
            .collect();
        let vb: Vec<Vec<f32>> = collect(&b)
            .into_iter()
            .map(|s| snapshot_data(s).unwrap().try_to_vec::<f32>().unwrap())
            .collect();
        assert_eq!(va, vb);
    }

    #[test]
    fn mismatches_name_the_first_key_and_class_tensors_are_reinitialised() {
        let (_, r) = apply(
            tiny(3),
            collect(&tiny(1)),
            &|p| p.starts_with("head.cls."),
            "one.bpk",
        )
        .unwrap();
        assert!(!r.reinitialised.is_empty());
        assert!(
            r.reinitialised.iter().all(|p| p.starts_with("head.cls.")),
            "{:?}",
            r.reinitialised
        );
        assert!(r.reinitialised.iter().any(|p| p.ends_with("out.weight")));
        let e = format!(
            "{:#}",
            apply(tiny(3), collect(&tiny(1)), &|_| false, "one.bpk").unwrap_err()
        );
        assert!(
            e.contains("one.bpk") && e.contains("head.cls.") && e.contains("expects shape"),
            "{e}"
        );
        let wide = YoloSegConfig::new(Scale::N, 1)
            .with_input_size(32)
            .with_width_mult(0.5)
            .with_num_masks(4)
            .init(&Device::flex());
        let e = format!(
            "{:#}",
            apply(tiny(1), collect(&wide), &|_| false, "w.bpk").unwrap_err()
        );
        // The first key in the model's order whose shape differs, expected and found.
        assert!(
            e.contains("w.bpk: key backbone.l1.conv.weight does not fit"),
            "{e}"
        );
        assert!(
            e.contains("expects shape [8, 8, 3, 3], the file has [16, 8, 3, 3]"),
            "{e}"
        );
        let mut snaps = collect(&tiny(1));
        snaps.retain(|s| s.name != "backbone.l1.bn.gamma");
        let e = format!("{:#}", apply(tiny(1), snaps, &|_| false, "m").unwrap_err());
        assert!(
            e.contains("key backbone.l1.bn.gamma") && e.contains("missing"),
            "{e}"
        );
        let mut snaps = collect(&tiny(1));
        snaps.push(snapshot_f32("extra.weight", vec![0.0], vec![1]));
        let e = format!("{:#}", apply(tiny(1), snaps, &|_| false, "x").unwrap_err());
        assert!(e.contains("key extra.weight has no place"), "{e}");
    }

    #[test]
    fn half_precision_loads_as_f32() {
        let a = tiny(1);
        let snaps: Vec<Snapshot> = collect(&a)
            .into_iter()
            .map(|s| {
                let name = s.name.clone();
                let d = snapshot_data(s).unwrap().convert::<burn::tensor::f16>();
                let (bytes, shape, dtype) = d.into_parts();
                Snapshot::new(name, dtype, shape, None, bytes)
            })
            .collect();
        assert_eq!(snaps[0].dtype, DType::F16);
        let (b, _) = apply(tiny(1), snaps, &|_| false, "h").unwrap();
        for s in collect(&b) {
            assert_eq!(s.dtype, DType::F32, "{}", s.name);
        }
    }
}
