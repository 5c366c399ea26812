//! Checkpoint files (`best.bpk`, `last.bpk`): one self-contained file that `eval` and
//! `predict` can use with no other file from the run.
//!
//! Layout: the magic line `CHICKTRAIN-CKPT1\n`, a little-endian u64 length and a JSON
//! [`Header`] (model config, class names, the resolved run config, the split, epoch,
//! validation stats), then named sections, each a u64 name length, the name, a u64 byte
//! length and the bytes. Sections are Burn burnpack records: `ema` (the weights evaluated
//! and used for inference — the EMA copy, or the model itself with EMA off), and in
//! `last.bpk` also `model` (raw training weights) and `optim` (optimiser state) for
//! `--resume`. Files are written atomically (temp + rename).

use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device, FloatDType};
use serde::{Deserialize, Serialize};

use crate::annotations::split::Split;
use crate::config::Config;

use super::detector::{Detector, DetectorConfig};
use super::precision::{all_in, f32_copy};

use crate::model::weights::CHICKTRAIN_MAGIC as MAGIC;
/// Header format: 2 added the model kind (`model.kind`).
pub const FORMAT: u32 = 2;

/// Validation (or test) COCO stats of a model, pycocotools order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    pub bbox: [f64; 12],
    pub segm: [f64; 12],
}

/// Everything but the weights.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Header {
    pub format: u32,
    pub chicktrain: String,
    /// The model kind (`model.kind`) and its full config.
    pub model: DetectorConfig,
    /// COCO category ids in class-index order, and their names.
    pub category_ids: Vec<u64>,
    pub class_names: Vec<String>,
    /// The resolved run config (data config included), so eval can rebuild the data.
    pub config: Config,
    pub split: Split,
    /// True when the "real" images are proxy-real renders.
    pub proxy: bool,
    /// Epochs completed (1-based).
    pub epoch: usize,
    pub ema_updates: u64,
    /// Best validation segm AP so far.
    pub best_fitness: f64,
    /// Validation stats of the `ema` weights after `epoch`.
    pub val: Option<Stats>,
    /// f16 runs: the loss scaler's state, so `--resume` continues with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loss_scale: Option<LossScaleState>,
}

/// f16 runs: the dynamic loss scale's state as saved. The trainer's rule that updates it
/// (`train::loss_scale`, where this type is `LossScaler`) lives with the trainer; the
/// type lives here so that the checkpoint format does not import the training loop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossScaleState {
    pub scale: f32,
    /// Good steps since the last change of scale.
    pub good_steps: u32,
    /// Steps skipped over the run.
    pub skipped: u64,
}

/// A checkpoint in memory.
pub struct Checkpoint {
    pub header: Header,
    pub sections: Vec<(String, Vec<u8>)>,
}

/// Serialises a module's weights (burnpack), always in f32: a checkpoint loads on any
/// device and precision (an f16 / bf16 module is cast on a copy; f32 is written as is).
pub fn module_bytes<M: Module>(m: &M) -> Result<Vec<u8>> {
    let rec = if all_in(m, FloatDType::F32) {
        m.clone().into_record()
    } else {
        f32_copy(m).into_record()
    };
    let b = rec
        .into_bytes()
        .map_err(|e| anyhow::anyhow!("cannot serialise weights: {e}"))?;
    Ok(b.to_vec())
}

/// Serialises optimiser state (burnpack).
pub fn optim_bytes(o: &ModuleOptimizer) -> Result<Vec<u8>> {
    let b = o
        .into_bytes()
        .map_err(|e| anyhow::anyhow!("cannot serialise optimiser state: {e}"))?;
    Ok(b.to_vec())
}

impl std::fmt::Debug for Checkpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Checkpoint")
            .field("header", &self.header)
            .field(
                "sections",
                &self
                    .sections
                    .iter()
                    .map(|s| (&s.0, s.1.len()))
                    .collect::<Vec<_>>(),
            )
            .finish()
    }
}

impl Checkpoint {
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let header = serde_json::to_vec(&self.header)?;
        let mut b = Vec::with_capacity(
            header.len() + self.sections.iter().map(|s| s.1.len() + 64).sum::<usize>(),
        );
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&(header.len() as u64).to_le_bytes());
        b.extend_from_slice(&header);
        b.extend_from_slice(&(self.sections.len() as u64).to_le_bytes());
        for (name, data) in &self.sections {
            b.extend_from_slice(&(name.len() as u64).to_le_bytes());
            b.extend_from_slice(name.as_bytes());
            b.extend_from_slice(&(data.len() as u64).to_le_bytes());
            b.extend_from_slice(data);
        }
        Ok(b)
    }

    pub fn save(&self, path: &Path) -> Result<()> {
        crate::util::write_atomic(path, &self.to_bytes()?)
    }

    pub fn from_bytes(b: &[u8], origin: &Path) -> Result<Checkpoint> {
        let bad = |what: &str| {
            anyhow::anyhow!(
                "{} is not a chicktrain checkpoint ({what})",
                origin.display()
            )
        };
        if !b.starts_with(MAGIC) {
            return Err(bad("wrong magic"));
        }
        let mut r = Reader { b, at: MAGIC.len() };
        let n = r.len().ok_or_else(|| bad("truncated"))?;
        let header: Header = serde_json::from_slice(r.take(n).ok_or_else(|| bad("truncated"))?)
            .with_context(|| {
                format!(
                    "{}: unreadable checkpoint header (written by an older chicktrain? header format {FORMAT} is needed)",
                    origin.display()
                )
            })?;
        let count = r.len().ok_or_else(|| bad("truncated"))?;
        if count > 64 {
            return Err(bad("too many sections"));
        }
        let mut sections = Vec::new();
        for _ in 0..count {
            let n = r.len().ok_or_else(|| bad("truncated"))?;
            let name = r.take(n).ok_or_else(|| bad("truncated"))?;
            let name = String::from_utf8(name.to_vec()).map_err(|_| bad("section name"))?;
            let n = r.len().ok_or_else(|| bad("truncated"))?;
            sections.push((name, r.take(n).ok_or_else(|| bad("truncated"))?.to_vec()));
        }
        Ok(Checkpoint { header, sections })
    }

    pub fn load(path: &Path) -> Result<Checkpoint> {
        if !path.exists() {
            bail!("checkpoint {} does not exist", path.display());
        }
        let b = std::fs::read(path)
            .with_context(|| format!("cannot read checkpoint {}", path.display()))?;
        Self::from_bytes(&b, path)
    }

    pub fn section(&self, name: &str) -> Option<&[u8]> {
        self.sections
            .iter()
            .find(|s| s.0 == name)
            .map(|s| s.1.as_slice())
    }

    /// Builds the model of the header on `device` and loads section `name` into it, in
    /// the device's float type (the f32 weights are cast on load on an f16 / bf16 device).
    pub fn model(&self, name: &str, device: &Device) -> Result<Detector> {
        self.load_model(
            name,
            device,
            device.settings().float_dtype != FloatDType::F32,
        )
    }

    /// [`Self::model`] in the file's type, f32, whatever the device's: the EMA copy of a
    /// reduced-precision run, which stays f32.
    pub fn model_f32(&self, name: &str, device: &Device) -> Result<Detector> {
        self.load_model(name, device, false)
    }

    fn load_model(&self, name: &str, device: &Device, cast: bool) -> Result<Detector> {
        let data = self
            .section(name)
            .with_context(|| format!("checkpoint has no {name:?} weights"))?;
        let model = self.header.model.init(device);
        let mut rec = ModuleRecord::from_bytes(Bytes::from_bytes_vec(data.to_vec()))
            .map_err(|e| anyhow::anyhow!("corrupt {name:?} weights in checkpoint: {e}"))?;
        if cast {
            rec = rec.cast_to_module_dtype();
        }
        model.try_load_record(rec).map_err(|e| {
            anyhow::anyhow!("{name:?} weights do not fit the model of the header: {e}")
        })
    }

    /// Loads the optimiser state into `optim`.
    pub fn optimizer(&self, optim: ModuleOptimizer) -> Result<ModuleOptimizer> {
        let data = self
            .section("optim")
            .context("checkpoint has no optimiser state (only last.bpk has)")?;
        optim
            .from_bytes(Bytes::from_bytes_vec(data.to_vec()))
            .map_err(|e| anyhow::anyhow!("corrupt optimiser state in checkpoint: {e}"))
    }
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.b.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn len(&mut self) -> Option<usize> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?) as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotations::split::Split;
    use crate::infer::precision::cast_module;
    use crate::model::yolo::{Scale, YoloSegConfig};
    use burn::tensor::{Tensor, TensorData};

    /// A quarter-width YOLO-seg n at 32 px.
    fn tiny() -> YoloSegConfig {
        YoloSegConfig::new(Scale::N, 1)
            .with_input_size(32)
            .with_width_mult(0.25)
            .with_num_masks(4)
    }

    #[test]
    fn round_trip_gives_the_same_outputs_and_bad_files_are_named() {
        let dev = Device::flex();
        let mcfg = tiny();
        let model = mcfg.init(&dev);
        let mcfg = DetectorConfig::Yolo(mcfg);
        let cfg = crate::config::parse(crate::config::SHIPPED[0].1, "q", &[]).unwrap();
        let ck = Checkpoint {
            header: Header {
                format: FORMAT,
                chicktrain: "test".into(),
                model: mcfg.clone(),
                category_ids: vec![1],
                class_names: vec!["carcass".into()],
                config: cfg,
                split: Split::new(&[1, 2, 3], [0.34, 0.33], 0).unwrap(),
                proxy: true,
                epoch: 4,
                ema_updates: 9,
                best_fitness: 0.5,
                val: None,
                loss_scale: None,
            },
            sections: vec![(
                "ema".into(),
                module_bytes(&Detector::Yolo(model.clone())).unwrap(),
            )],
        };
        let dir = std::env::temp_dir().join(format!("ct-ckpt-{}", std::process::id()));
        let p = dir.join("best.bpk");
        ck.save(&p).unwrap();
        let back = Checkpoint::load(&p).unwrap();
        assert_eq!(back.header.epoch, 4);
        assert_eq!(back.header.model, mcfg);
        let loaded = back.model("ema", &dev).unwrap();
        let x = Tensor::<4>::from_data(
            TensorData::new(
                (0..3 * 32 * 32)
                    .map(|i| (i % 7) as f32 / 7.0)
                    .collect::<Vec<_>>(),
                [1, 3, 32, 32],
            ),
            &dev,
        );
        let a = model.forward(x.clone()).cls_logits.into_data();
        let Detector::Yolo(loaded) = loaded else {
            panic!("a YOLO checkpoint loads as YOLO")
        };
        let b = loaded.forward(x).cls_logits.into_data();
        assert_eq!(a, b);
        assert!(format!("{:#}", back.model("model", &dev).unwrap_err()).contains("no \"model\""));

        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
        let e = format!("{:#}", Checkpoint::load(&p).unwrap_err());
        assert!(e.contains("best.bpk") && e.contains("truncated"), "{e}");
        std::fs::write(&p, b"hello").unwrap();
        assert!(format!("{:#}", Checkpoint::load(&p).unwrap_err())
            .contains("not a chicktrain checkpoint"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn casts_round_trip_and_the_f32_path_is_untouched() {
        // Here rather than beside the casts: module_bytes is the byte-exact comparison.
        let m = tiny().init(&Device::flex());
        assert!(all_in(&m, FloatDType::F32));
        let before = module_bytes(&m).unwrap();
        let same = f32_copy(&m);
        assert_eq!(module_bytes(&same).unwrap(), before);
        let b = cast_module(m.valid(), FloatDType::BF16);
        assert!(all_in(&b, FloatDType::BF16) && !all_in(&b, FloatDType::F32));
        // bf16 → f32 is exact, so a second round trip changes nothing.
        let back = f32_copy(&b);
        assert!(all_in(&back, FloatDType::F32));
        let again = f32_copy(&cast_module(back.valid(), FloatDType::BF16));
        assert_eq!(module_bytes(&back).unwrap(), module_bytes(&again).unwrap());
        // The source keeps its type (its running statistics were not cast in place).
        assert!(all_in(&m, FloatDType::F32));
        assert_eq!(module_bytes(&m).unwrap(), before);
    }
}
