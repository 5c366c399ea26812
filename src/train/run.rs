//! What a run keeps fixed across epochs ([`Run`]: the config, the data, the model config
//! and the checkpoint header they make) and what it writes from them: the end of an epoch
//! (weight checks, validation, the epoch's record, `best.bpk` and `last.bpk`), the save on
//! Ctrl-C, and the test evaluation of the best checkpoint (`test.json`, the val plots).

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use burn::module::Module;

use crate::annotations::split::Split;
use crate::config::Config;
use crate::data::dataset::RealSet;
use crate::infer::checkpoint::{module_bytes, Checkpoint, Header, Stats, FORMAT};
use crate::infer::detector::DetectorConfig;
use crate::infer::precision::{copy_in, float_dtype};
use crate::infer::validate::{evaluate_ids, gt_subset, InputCache};
use burn::tensor::Device;

use super::divergence::check_weights;
use super::epoch::EpochSteps;
use super::run_files::{self, EpochRecord, StatsRecord, TestRecord, ValTime};
use super::state::TrainState;

/// What a run keeps fixed across epochs: the config, the data and the model config, and
/// the checkpoint header they make.
pub struct Run<'a> {
    pub cfg: &'a Config,
    pub run_dir: &'a Path,
    pub real: &'a RealSet,
    pub split: &'a Split,
    pub mcfg: &'a DetectorConfig,
    pub class_names: Vec<String>,
    /// The plain (no autodiff) device that evaluates.
    pub base: &'a Device,
    /// Network input size.
    pub input: usize,
    /// The validation images letterboxed once, at the first validation (`None` inside:
    /// too many to keep, read each time).
    pub val_inputs: std::sync::OnceLock<Option<InputCache>>,
}

impl Run<'_> {
    pub fn header(&self, st: &TrainState, epoch: usize, val: Option<Stats>) -> Header {
        Header {
            format: FORMAT,
            chicktrain: env!("CARGO_PKG_VERSION").into(),
            model: self.mcfg.clone(),
            category_ids: self.real.cat_ids.clone(),
            class_names: self.class_names.clone(),
            config: self.cfg.clone(),
            split: self.split.clone(),
            proxy: self.real.proxy,
            epoch,
            ema_updates: st.ema.updates,
            best_fitness: st.best_fitness,
            val,
            loss_scale: st.scaler,
        }
    }

    /// Ctrl-C: saves `last.bpk` as it is now and returns the error that stops the run.
    /// Completed epochs stay `epoch`: --resume redoes this one from its start, with the
    /// weights, optimiser state and EMA as they are now.
    pub fn save_interrupted(&self, st: &TrainState, epoch: usize, step: usize) -> anyhow::Error {
        let p = self.run_dir.join("last.bpk");
        let saved = module_bytes(&st.eval_model(self.cfg.train.ema))
            .and_then(|b| st.last_checkpoint(self.header(st, epoch, None), b))
            .and_then(|ck| ck.save(&p));
        match saved {
            Ok(()) => anyhow::anyhow!(
                "interrupted (Ctrl-C) at epoch {}, step {step}; saved {} — continue with the same command plus --resume",
                epoch + 1,
                p.display()
            ),
            Err(e) => e.context(format!("interrupted (Ctrl-C) at epoch {}, step {step}", epoch + 1)),
        }
    }

    /// After the steps of `epoch` (started at `te`, steps done after `t_train` s):
    /// weight checks, validation (every `train.val_every` epochs and after the last), the
    /// epoch's record in the run files, `best.bpk` when validation segm AP improved and
    /// `last.bpk`. Returns whether it improved (never on an epoch without validation).
    pub fn finish_epoch(
        &self,
        st: &mut TrainState,
        steps: &EpochSteps,
        epoch: usize,
        te: Instant,
        t_train: f64,
    ) -> Result<bool> {
        let (cfg, loss_names) = (self.cfg, st.model.loss_names());
        check_weights(&st.model.valid(), "model", epoch)?;
        if cfg.train.ema {
            check_weights(&st.ema.model, "EMA", epoch)?;
        }
        let eval_model = st.eval_model(cfg.train.ema);
        let validate = (epoch + 1) % cfg.train.val_every == 0 || epoch + 1 == cfg.train.epochs;
        let (val, val_time) = if validate {
            let t0 = Instant::now();
            let cache = match self.val_inputs.get() {
                Some(c) => c.as_ref(),
                None => {
                    let c = InputCache::load(self.real, &self.split.val, self.input)?;
                    self.val_inputs.get_or_init(|| c).as_ref()
                }
            };
            let ev = evaluate_ids(
                &copy_in(&eval_model, float_dtype(cfg.train.precision)),
                self.real,
                &self.split.val,
                self.input,
                self.base,
                cache,
                false,
            )?;
            let time = ValTime {
                forward: ev.timing.forward,
                total: t0.elapsed().as_secs_f64(),
            };
            (Some(ev.stats), Some(time))
        } else {
            (None, None)
        };
        let n = steps.steps.max(1) as f64;
        st.records.push(EpochRecord {
            data_wait_s: steps.data_wait,
            epoch: epoch + 1,
            images_per_s: steps.images as f64 / t_train.max(1e-9),
            loss: loss_names
                .iter()
                .zip(&steps.sums)
                .map(|(k, s)| (k.to_string(), s / n))
                .collect(),
            loss_scale: st.scaler.map(|s| s.scale),
            lr: steps.last_lr,
            proxy: self.real.proxy,
            skipped_steps: steps.skipped,
            steps: steps.steps,
            time: te.elapsed().as_secs_f64(),
            train_time: t_train,
            val: val.as_ref().map(StatsRecord::from),
            val_time,
        });
        run_files::write_metrics(self.run_dir, &st.records, loss_names)?;

        let improved = val.as_ref().is_some_and(|v| v.segm[0] > st.best_fitness);
        if let (true, Some(v)) = (improved, &val) {
            st.best_fitness = v.segm[0];
            st.best_epoch = epoch + 1;
        }
        let eval_bytes = module_bytes(&eval_model)?;
        let header = self.header(st, epoch + 1, val);
        if improved {
            Checkpoint {
                header: header.clone(),
                sections: vec![("ema".into(), eval_bytes.clone())],
            }
            .save(&self.run_dir.join("best.bpk"))?;
        }
        st.last_checkpoint(header, eval_bytes)?
            .save(&self.run_dir.join("last.bpk"))?;
        Ok(improved)
    }
}

/// Scores `best.bpk` on the test split and writes `test.json`; returns the stats and the
/// checkpoint's epoch.
pub fn test_best(run: &Run) -> Result<(Stats, usize)> {
    let best = Checkpoint::load(&run.run_dir.join("best.bpk"))?;
    let model = best.model("ema", run.base)?;
    let input = best.header.model.input_size();
    let test = evaluate_ids(
        &model,
        run.real,
        &run.split.test,
        input,
        run.base,
        None,
        false,
    )?
    .stats;
    if !run.split.val.is_empty() {
        let ev = evaluate_ids(
            &model,
            run.real,
            &run.split.val,
            input,
            run.base,
            None,
            false,
        )?;
        let gt = gt_subset(&run.real.gt, &run.split.val);
        super::run_plots::write_val_plots(run.run_dir, &gt, &ev.detections, &run.class_names)?;
        super::batch_plots::write_val_batches(
            run.run_dir,
            run.real,
            &gt,
            &run.split.val,
            &ev.detections,
        )?;
    }
    run_files::write_test(
        run.run_dir,
        &TestRecord {
            bbox: run_files::IouStats { stats: test.bbox },
            checkpoint: "best.bpk".into(),
            epoch: best.header.epoch,
            images: run.split.test.len(),
            proxy: run.real.proxy,
            segm: run_files::IouStats { stats: test.segm },
            split: "test".into(),
        },
    )?;
    Ok((test, best.header.epoch))
}
