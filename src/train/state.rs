//! The state a training run carries from epoch to epoch — weights, EMA, optimiser, how
//! far it got and its records — built fresh or restored from `last.bpk`, and the one place
//! a `last.bpk` is assembled from it.

use std::path::Path;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::tensor::{Device, FloatDType};

use crate::config::Config;

use super::ema::Ema;
use super::init::load_init;
use super::loss_scale::LossScaler;
use super::optim;
use super::run_files::{self, EpochRecord};
use crate::infer::checkpoint::{module_bytes, optim_bytes, Checkpoint, Header};
use crate::infer::detector::{Detector, DetectorConfig};
use crate::infer::precision::cast_module;
use crate::model::freeze::freeze;

/// A new model of `mcfg` on `device` whose weights are drawn on the CPU (`flex`) from
/// `seed`: a config and seed start from the same weights on every backend (as PyTorch
/// draws them on the CPU before `.to(device)`), so a `wgpu` or `cuda` run is the same
/// experiment as a `flex` one; each backend's own generator would draw other weights.
/// The device's generator still advances as if it had drawn them (the model is first built
/// there), so on `flex` the weights and later draws are what they were before this existed.
pub fn seeded_init(mcfg: &DetectorConfig, seed: u64, device: &Device) -> Result<Detector> {
    let model = mcfg.init(device);
    let cpu = Device::flex();
    cpu.seed(seed);
    let drawn = mcfg.init(&cpu).into_record();
    model
        .try_load_record(drawn)
        .map_err(|e| anyhow::anyhow!("cannot move the initial weights to {device:?}: {e}"))
}

/// Weights, EMA and optimiser of a run, and how far it got.
pub struct TrainState {
    pub model: Detector,
    pub ema: Ema<Detector>,
    pub optim: ModuleOptimizer,
    /// f16 runs: dynamic loss scaling.
    pub scaler: Option<LossScaler>,
    /// Epochs completed.
    pub epoch: usize,
    pub best_fitness: f64,
    pub best_epoch: usize,
    pub records: Vec<EpochRecord>,
}

impl TrainState {
    /// A new model of `mcfg` on the autodiff device `ad` (started from `model.init` if
    /// set), or the state of `resume` (which ignores `model.init`); `train.freeze` applied
    /// to either. `say` prints what was loaded.
    pub fn new(
        cfg: &Config,
        mcfg: &DetectorConfig,
        resume: Option<&Checkpoint>,
        run_dir: &Path,
        ad: &Device,
        base: &Device,
        say: &dyn Fn(String),
    ) -> Result<TrainState> {
        let optim = optim::build(&cfg.train);
        let frozen = mcfg.frozen_prefixes(cfg.train.freeze)?;
        if !frozen.is_empty() {
            say(format!(
                "train.freeze = {}: frozen (no gradients, BatchNorm in eval mode): {}",
                cfg.train.freeze,
                frozen.join(", ")
            ));
        }
        let f16 = cfg.train.precision == crate::config::Precision::F16;
        let Some(ck) = resume else {
            // f32 master weights whatever the run's precision (`precision`).
            let mut model = cast_module(seeded_init(mcfg, cfg.seed, ad)?, FloatDType::F32);
            if let Some(p) = cfg.model.init() {
                let (m, note) = load_init(model, &mcfg, Path::new(p), base)?;
                say(note);
                model = cast_module(m, FloatDType::F32);
            }
            let model = freeze(model, &frozen);
            let ema = Ema::new(&model, 0).with_frozen(frozen);
            return Ok(TrainState {
                model,
                ema,
                optim,
                scaler: f16.then(LossScaler::default),
                epoch: 0,
                best_fitness: f64::NEG_INFINITY,
                best_epoch: 0,
                records: Vec::new(),
            });
        };
        let last = run_dir.join("last.bpk");
        if let Some(why) = mcfg.mismatch(&ck.header.model) {
            bail!("--resume: cannot continue from {}: {why}", last.display());
        }
        if let Some(p) = cfg.model.init() {
            say(format!(
                "model.init = {p} is not used: --resume continues from {}",
                last.display()
            ));
        }
        let in_last = || format!("--resume: in {}", last.display());
        let model = freeze(ck.model_f32("model", ad).with_context(in_last)?, &frozen);
        let ema = Ema {
            model: ck.model_f32("ema", base).with_context(in_last)?,
            updates: ck.header.ema_updates,
            frozen,
        };
        let optim = ck.optimizer(optim).with_context(in_last)?;
        let records = run_files::read_metrics(run_dir, ck.header.epoch)?;
        Ok(TrainState {
            model,
            ema,
            optim,
            scaler: f16.then(|| ck.header.loss_scale.unwrap_or_default()),
            epoch: ck.header.epoch,
            best_fitness: ck.header.best_fitness,
            best_epoch: run_files::best_epoch(&records),
            records,
        })
    }

    /// The weights evaluated and shipped: the EMA copy, or the model with EMA off (both
    /// f32 weights; BatchNorm statistics in the run's type until a checkpoint casts them).
    pub fn eval_model(&self, ema: bool) -> Detector {
        if ema {
            self.ema.model.clone()
        } else {
            self.model.valid()
        }
    }

    /// `last.bpk`: the evaluated weights as `ema`, plus the raw weights and optimiser
    /// state for `--resume`.
    pub fn last_checkpoint(&self, header: Header, eval_bytes: Vec<u8>) -> Result<Checkpoint> {
        Ok(Checkpoint {
            header,
            sections: vec![
                ("ema".into(), eval_bytes),
                ("model".into(), module_bytes(&self.model)?),
                ("optim".into(), optim_bytes(&self.optim)?),
            ],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::yolo::{Scale, YoloSegConfig};
    use crate::util::tensor::to_host;
    use burn::tensor::{Tensor, TensorData};

    /// The YOLO prototypes and box logits of `m` for a fixed 32 px input, on the host.
    fn outputs(m: Detector, dev: &Device) -> Vec<f32> {
        let Detector::Yolo(m) = m else { unreachable!() };
        let px: Vec<f32> = (0..3 * 32 * 32).map(|i| (i % 7) as f32 / 7.0).collect();
        let o = m.forward(Tensor::<4>::from_data(
            TensorData::new(px, [1, 3, 32, 32]),
            dev,
        ));
        let mut v = to_host(o.box_dist);
        v.extend(to_host(o.proto));
        v
    }

    #[test]
    #[allow(deprecated)] // Device::ndarray: a second backend with its own generator.
    fn initial_weights_follow_the_seed_not_the_backend() {
        let mcfg = DetectorConfig::Yolo(
            YoloSegConfig::new(Scale::N, 1)
                .with_input_size(32)
                .with_width_mult(0.25)
                .with_num_masks(4),
        );
        let out = |seed, dev: &Device| outputs(seeded_init(&mcfg, seed, dev).unwrap(), dev);
        let flex = Device::flex();
        let on_flex = out(7, &flex);
        let close = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .all(|(x, y)| (x - y).abs() <= 1e-5 * (1.0 + x.abs()))
        };
        assert!(close(&on_flex, &out(7, &Device::ndarray())));
        // On the training (autodiff) device, in eval mode (BatchNorm's running statistics).
        let trained = seeded_init(&mcfg, 7, &flex.clone().autodiff()).unwrap();
        assert!(close(&on_flex, &outputs(trained.valid(), &flex)));
        assert!(!close(&on_flex, &out(8, &flex)));
    }
}
