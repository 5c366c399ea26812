//! The training run: prepare the run folder (and what `--resume` continues from), load
//! the data, build or restore the model state, then epochs of steps → per-epoch COCO
//! evaluation → checkpoints and run files → the test evaluation of the best checkpoint.
//!
//! Run directory (`runs/<name>/` or `--run-dir`): `config.toml` (resolved), `split.json`,
//! `metrics.jsonl` (one object per epoch), `results.csv`, `best.bpk`, `last.bpk`,
//! `test.json`, and `plots.png`; their formats live in [`super::run_files`]. Every file
//! is written atomically. A diverging run (non-finite or exploding loss, see
//! [`super::divergence`]) stops with an error naming the epoch, step and loss term;
//! `last.bpk` then still holds the last good epoch.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, FloatDType, Tensor, TensorData};

use crate::annotations::split::Split;
use crate::config::{Config, DeviceKind};
use crate::data::dataset::{RealSet, SyntheticSet};

use super::divergence::{check_weights, At, DivergenceGuard};
use super::loader::{epoch_batches, mix, Loader, Mix};
use super::run_files::{self, EpochRecord, StatsRecord, TestRecord, ValTime};
use super::run_folder::run_folder;
use super::schedule::step_lr;
use super::smoke::smoke_config;
use super::state::TrainState;
use super::{optim, plot};
use crate::infer::checkpoint::{module_bytes, Checkpoint, Header, Stats, FORMAT};
use crate::infer::detector::DetectorConfig;
use crate::infer::device::device_with;
use crate::infer::precision::{copy_in, float_dtype, graph_cast};
use crate::infer::validate::{evaluate_ids, gt_subset, InputCache};
use crate::util::progress;

/// How to run (everything that is not in the config file): `train`'s flags.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct TrainOptions {
    /// Write outputs here instead of runs/<name>/.
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
    /// Continue the run from <run dir>/last.bpk.
    #[arg(long)]
    pub resume: bool,
    /// Shrink the config to a ~1 minute run that still goes through every stage.
    #[arg(long)]
    pub smoke: bool,
    /// Override the config's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long)]
    pub device: Option<DeviceKind>,
    /// No progress bars and no per-epoch lines: only errors and the final summary.
    #[arg(long)]
    pub quiet: bool,
    /// Reuse runs/<name>/ when it exists instead of writing to the next free
    /// runs/<name>-2, -3, … (ultralytics' exist_ok; --resume and --run-dir always use
    /// the folder they name).
    #[arg(long)]
    pub exist_ok: bool,
}

/// What a finished run reports.
#[derive(Clone, Debug)]
pub struct TrainSummary {
    pub run_dir: PathBuf,
    pub epochs: usize,
    pub best_epoch: usize,
    pub test: Stats,
    pub test_images: usize,
    pub proxy: bool,
    pub seconds: f64,
    pub train_images_per_s: f64,
    /// Optimiser steps over all epochs (resumed ones included): what equal compute means.
    pub steps: usize,
}

/// The config as it will run (`--smoke`, `--device` applied) and its run folder, created.
fn prepare_run(mut cfg: Config, opts: &TrainOptions) -> Result<(Config, PathBuf)> {
    if opts.smoke {
        smoke_config(&mut cfg);
        cfg.validate().context("smoke config")?;
    }
    if let Some(d) = opts.device {
        cfg.device = d;
    }
    let run_dir = run_folder(
        opts.run_dir.as_deref(),
        &cfg.name,
        opts.resume,
        opts.exist_ok,
    )?;
    Ok((cfg, run_dir))
}

/// `--resume`: `<run_dir>/last.bpk`, checked against `cfg` before anything is written.
fn resume_point(cfg: &Config, run_dir: &Path) -> Result<Checkpoint> {
    let p = run_dir.join("last.bpk");
    if !p.exists() {
        bail!(
            "--resume: {} does not exist (nothing to resume)",
            p.display()
        );
    }
    let ck = Checkpoint::load(&p)?;
    let (was, now) = (ck.header.config.train.precision, cfg.train.precision);
    if was != now {
        bail!(
            "--resume: {} was trained with train.precision = \"{}\", the config asks for \"{}\"; a resume continues a run as it was trained (its loss scaling, and the same steps as an uninterrupted run), so continue with --set train.precision={} (or start a new run from its weights with --set model.init=\"{}\")",
            p.display(),
            was.name(),
            now.name(),
            was.name(),
            p.display()
        );
    }
    if ck.header.model.kind() != cfg.model.kind() {
        let probe = DetectorConfig::from_config(cfg, ck.header.model.num_classes())?;
        if let Some(why) = probe.mismatch(&ck.header.model) {
            bail!("--resume: cannot continue from {}: {why}", p.display());
        }
    }
    if ck.header.epoch >= cfg.train.epochs {
        bail!(
            "--resume: {} already completed {} of {} epochs (raise train.epochs with --set to train longer)",
            p.display(),
            ck.header.epoch,
            cfg.train.epochs
        );
    }
    Ok(ck)
}

/// The real set, its split (the resumed run's, or a new seeded one, saved to the run
/// folder) and the synthetic set, rendered into the cache.
fn load_data(
    cfg: &Config,
    run_dir: &Path,
    resume: Option<&Checkpoint>,
) -> Result<(RealSet, Split, SyntheticSet)> {
    let real = RealSet::load(&cfg.data, cfg.seed)?;
    let split = match resume {
        Some(ck) => ck.header.split.clone(),
        None => Split::for_training(
            &real.ids(),
            real.own_split.as_ref(),
            cfg.data.split,
            cfg.seed,
            cfg.data.train_limit,
        )?,
    };
    if split.train.is_empty() || split.val.is_empty() || split.test.is_empty() {
        bail!(
            "the split of {} real images gives {} train / {} val / {} test; every part needs at least one image (raise the image count or change data.split)",
            real.gt.images.len(),
            split.train.len(),
            split.val.len(),
            split.test.len()
        );
    }
    split.save(&run_dir.join("split.json"))?;
    let synthetic = SyntheticSet::new(&cfg.data, cfg.seed);
    synthetic.prepare()?;
    Ok((real, split, synthetic))
}

/// What a run keeps fixed across epochs: the config, the data and the model config, and
/// the checkpoint header they make.
struct Run<'a> {
    cfg: &'a Config,
    run_dir: &'a Path,
    real: &'a RealSet,
    split: &'a Split,
    mcfg: &'a DetectorConfig,
    class_names: Vec<String>,
    /// The plain (no autodiff) device that evaluates.
    base: &'a Device,
    /// Network input size.
    input: usize,
    /// The validation images letterboxed once, at the first validation (`None` inside:
    /// too many to keep, read each time).
    val_inputs: std::sync::OnceLock<Option<InputCache>>,
}

impl Run<'_> {
    fn header(&self, st: &TrainState, epoch: usize, val: Option<Stats>) -> Header {
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
    fn save_interrupted(&self, st: &TrainState, epoch: usize, step: usize) -> anyhow::Error {
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
    fn finish_epoch(
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

/// The steps of one epoch, as far as they got.
struct EpochSteps {
    /// Sum over steps of each loss term.
    sums: Vec<f64>,
    last_lr: f64,
    steps: usize,
    images: usize,
    /// Steps done when Ctrl-C stopped the epoch.
    interrupted: Option<usize>,
    /// Seconds spent waiting for the loader thread's batches.
    data_wait: f64,
    /// f16: steps skipped by the loss scaler.
    skipped: usize,
}

/// Runs the optimiser steps of `epoch` over `loader`'s batches.
#[allow(clippy::too_many_arguments)]
fn run_epoch(
    cfg: &Config,
    st: &mut TrainState,
    loader: &Loader,
    guard: &mut DivergenceGuard,
    train_ids: &[u64],
    epoch: usize,
    ad: &Device,
    quiet: bool,
) -> Result<EpochSteps> {
    let te = Instant::now();
    let bsz = cfg.train.batch;
    let dtype = float_dtype(cfg.train.precision);
    let m = Mix::of(&cfg.train);
    // The LR schedule counts warmup in these steps, so it stays in epochs whatever
    // `train.steps_per_epoch` is.
    let per_epoch = m.steps(train_ids.len(), cfg.data.synthetic, bsz);
    let plan = epoch_batches(train_ids, cfg.data.synthetic, cfg.seed, epoch, bsz, m)?;
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        progress::bar(
            per_epoch as u64,
            &format!("{}/{}", epoch + 1, cfg.train.epochs),
        )
    };
    let n_terms = st.model.loss_names().len();
    let mut out = EpochSteps {
        sums: vec![0f64; n_terms],
        last_lr: 0.0,
        steps: 0,
        images: 0,
        interrupted: None,
        data_wait: 0.0,
        skipped: 0,
    };
    let result: Result<()> = std::thread::scope(|sc| {
        let rx = loader.spawn(sc, &plan, bsz, epoch);
        let mut batches = rx.iter().enumerate();
        loop {
            let tw = Instant::now();
            let Some((step, batch)) = batches.next() else {
                break;
            };
            out.data_wait += tw.elapsed().as_secs_f64();
            let batch = batch
                .with_context(|| format!("building batch {} of epoch {}", step + 1, epoch + 1))?;
            let n = batch.dims[0];
            let x = Tensor::<4>::from_data(TensorData::new(batch.pixels, batch.dims), ad);
            let sample_seed = mix(mix(cfg.seed ^ 0x5A3D, epoch as u64), step as u64);
            let loss = match dtype {
                FloatDType::F32 => st.model.loss(x, &batch.targets, sample_seed),
                // Forward on a reduced copy of the f32 masters, cast inside the graph.
                d => graph_cast(st.model.clone(), d).loss(x, &batch.targets, sample_seed),
            };
            let mut v = loss.terms.clone();
            v.push(loss.total_value);
            let at = At {
                epoch,
                step,
                per_epoch,
            };
            guard.check_step(at, &v)?;
            let (rates, lr) = step_lr(&cfg.train, epoch, step, per_epoch);
            let stepped = match &mut st.scaler {
                None => {
                    let mut grads = GradientsParams::from_grads(loss.total.backward(), &st.model);
                    let norm = optim::clip_global_norm(&st.model, &mut grads, cfg.train.grad_clip)?;
                    guard.check_grad_norm(at, norm)?;
                    Some(grads)
                }
                // f16: backward of the scaled loss, unscale (and clip) in one pass over
                // the gradients, or skip the step when they overflowed.
                Some(scaler) => {
                    let scale = scaler.scale;
                    let scaled = loss.total.mul_scalar(scale);
                    let mut grads = GradientsParams::from_grads(scaled.backward(), &st.model);
                    let norm = optim::grad_norm(&st.model, &grads) / scale as f64;
                    let finite = norm.is_finite();
                    scaler.update(finite).with_context(|| {
                        format!("training diverged at {}: {}", at.describe(), at.kept())
                    })?;
                    finite.then(|| {
                        let c = optim::clip_factor(norm, cfg.train.grad_clip);
                        optim::scale_grads(&st.model, &mut grads, (c / scale as f64) as f32);
                        grads
                    })
                }
            };
            match stepped {
                Some(grads) => {
                    st.model = st.optim.step(rates, st.model.clone(), grads);
                    if cfg.train.ema {
                        st.ema.update(&st.model);
                    }
                }
                None => out.skipped += 1,
            }
            for (s, t) in out.sums.iter_mut().zip(&loss.terms) {
                *s += *t as f64;
            }
            out.last_lr = lr;
            out.steps += 1;
            out.images += n;
            let el = te.elapsed().as_secs_f64();
            bar.set_message(format!(
                "loss {:.3} {:.2} img/s",
                loss.total_value / n as f32,
                (out.steps * bsz) as f64 / el.max(1e-9)
            ));
            bar.inc(1);
            if super::interrupt::requested() {
                out.interrupted = Some(step + 1);
                break;
            }
        }
        Ok(())
    });
    bar.finish_and_clear();
    result?;
    Ok(out)
}

/// The line printed after an epoch.
fn epoch_line(rec: &EpochRecord, epochs: usize, loss_names: &[&str], improved: bool) -> String {
    let val = match &rec.val {
        Some(v) => {
            let (b, s) = (&v.bbox.stats, &v.segm.stats);
            let cost = match &rec.val_time {
                Some(t) => format!(
                    " ({:.1} s, {:.2}× forward)",
                    t.total,
                    t.total / t.forward.max(1e-9)
                ),
                None => String::new(),
            };
            format!(
                "val{cost} bbox AP {:.3} AP50 {:.3}  segm AP {:.3} AP50 {:.3}",
                b[0], b[1], s[0], s[1]
            )
        }
        None => "not validated (train.val_every)".into(),
    };
    let scale = match rec.loss_scale {
        Some(s) => format!(", loss scale {s}, {} skipped", rec.skipped_steps),
        None => String::new(),
    };
    format!(
        "epoch {}/{}  lr {:.2e}  loss {}  {:.1} s ({:.2} img/s, {:.1} s data wait{scale})  {val}{}",
        rec.epoch,
        epochs,
        rec.lr,
        loss_names
            .iter()
            .map(|k| format!("{k} {:.3}", rec.loss[*k]))
            .collect::<Vec<_>>()
            .join(" "),
        rec.time,
        rec.images_per_s,
        rec.data_wait_s,
        if improved { "  *best" } else { "" }
    )
}

/// Trains `cfg` (already validated) and returns the test metrics of the best checkpoint.
pub fn train(cfg: Config, opts: &TrainOptions) -> Result<TrainSummary> {
    let t_start = Instant::now();
    let (cfg, run_dir) = prepare_run(cfg, opts)?;
    let say = |s: String| {
        if !opts.quiet {
            eprintln!("{s}");
        }
    };
    let resume = opts
        .resume
        .then(|| resume_point(&cfg, &run_dir))
        .transpose()?;
    run_files::write_config(&run_dir, &cfg)?;

    let t0 = Instant::now();
    let (real, split, synthetic) = load_data(&cfg, &run_dir, resume.as_ref())?;
    say(format!(
        "data: {} real images{} ({} train / {} val / {} test), {} synthetic{}, {} px (crop {}), ready in {:.1} s",
        real.gt.images.len(),
        if real.proxy { " [proxy-real renders, not real photos]" } else { "" },
        split.train.len(),
        split.val.len(),
        split.test.len(),
        cfg.data.synthetic,
        if cfg.data.fresh_synthetic { " (fresh each epoch)" } else { "" },
        cfg.data.image_size,
        cfg.data.crop,
        t0.elapsed().as_secs_f64()
    ));

    let m = Mix::of(&cfg.train);
    say(format!(
        "plan: {} optimiser steps per epoch of batch {}{}",
        m.steps(split.train.len(), cfg.data.synthetic, cfg.train.batch),
        cfg.train.batch,
        match m.real_fraction {
            Some(f) => format!(
                ", {} real per batch (train.real_fraction = {f})",
                (f * cfg.train.batch as f64).round()
            ),
            None => ", real and synthetic in their natural proportion".into(),
        }
    ));

    let base = device_with(cfg.device, cfg.train.precision)?;
    base.seed(cfg.seed);
    let ad = base.clone().autodiff();
    let mcfg = DetectorConfig::from_config(&cfg, real.num_classes())?;
    let input = mcfg.input_size();
    let mut st = TrainState::new(&cfg, &mcfg, resume.as_ref(), &run_dir, &ad, &base, &say)?;
    if resume.is_some() {
        say(format!("resuming after epoch {}", st.epoch));
    }
    say(format!(
        "model: {}: {} on {:?}{}",
        mcfg.describe(),
        st.model.summary(input),
        cfg.device,
        match cfg.train.precision {
            crate::config::Precision::F32 => String::new(),
            p => format!(
                " in {} (f32 master weights, EMA and checkpoints{})",
                p.name(),
                if st.scaler.is_some() {
                    ", dynamic loss scaling"
                } else {
                    ""
                }
            ),
        }
    ));
    let loss_names = st.model.loss_names();
    let run = Run {
        cfg: &cfg,
        run_dir: &run_dir,
        real: &real,
        split: &split,
        mcfg: &mcfg,
        class_names: real.class_names(),
        base: &base,
        input,
        val_inputs: Default::default(),
    };
    let loader = Loader::for_run(&cfg, real.clone(), synthetic, input as u32);
    if st.epoch == 0 {
        super::batch_plots::write_train_batches(&run_dir, &cfg, &loader, &split.train)?;
    }
    let (mut train_imgs, mut train_secs) = (0usize, 0f64);
    let guard_names: Vec<&str> = loss_names.iter().copied().chain(["total"]).collect();
    let mut guard = DivergenceGuard::new(&guard_names);
    for epoch in st.epoch..cfg.train.epochs {
        let te = Instant::now();
        let steps = run_epoch(
            &cfg,
            &mut st,
            &loader,
            &mut guard,
            &split.train,
            epoch,
            &ad,
            opts.quiet,
        )?;
        train_imgs += steps.images;
        if let Some(step) = steps.interrupted {
            return Err(run.save_interrupted(&st, epoch, step));
        }
        let t_train = te.elapsed().as_secs_f64();
        train_secs += t_train;
        let improved = run.finish_epoch(&mut st, &steps, epoch, te, t_train)?;
        let rec = st.records.last().expect("finish_epoch pushed it");
        say(epoch_line(rec, cfg.train.epochs, loss_names, improved));
    }

    let (test, best) = test_best(&run)?;
    plot::write_plots(&run_dir, &st.records, loss_names)?;
    Ok(TrainSummary {
        run_dir: run_dir.clone(),
        epochs: cfg.train.epochs,
        best_epoch: best.max(st.best_epoch),
        test,
        test_images: split.test.len(),
        proxy: real.proxy,
        seconds: t_start.elapsed().as_secs_f64(),
        train_images_per_s: train_imgs as f64 / train_secs.max(1e-9),
        steps: st.records.iter().map(|r| r.steps).sum(),
    })
}

/// Scores `best.bpk` on the test split and writes `test.json`; returns the stats and the
/// checkpoint's epoch.
fn test_best(run: &Run) -> Result<(Stats, usize)> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{self, ModelConfig};
    use crate::train::run_files::IouStats;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ct-trainer-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// quickstart at 64 px with 4 proxy images and no renders, cache in `dir`.
    fn tiny(dir: &Path, extra: &[&str]) -> Config {
        let mut ov = vec![
            format!("data.cache=\"{}\"", dir.join("cache").display()),
            "data.image_size=64".into(),
            "data.crop=64".into(),
            "data.real.count=4".into(),
            "data.synthetic=0".into(),
        ];
        ov.extend(extra.iter().map(|s| s.to_string()));
        config::load("quickstart.toml", &ov).unwrap()
    }

    #[test]
    fn prepare_run_applies_smoke_and_device_and_creates_the_folder() {
        let dir = tmp("prepare");
        let mut cfg = config::load("maskrcnn_r50_syn250.toml", &[]).unwrap();
        cfg.train.epochs = 9;
        let opts = TrainOptions {
            run_dir: Some(dir.join("run")),
            smoke: true,
            device: Some(DeviceKind::Ndarray),
            ..Default::default()
        };
        let (cfg, run_dir) = prepare_run(cfg, &opts).unwrap();
        assert!(run_dir.is_dir() && run_dir == dir.join("run"));
        assert_eq!((cfg.device, cfg.train.epochs), (DeviceKind::Ndarray, 2));
        assert!(cfg.name.ends_with("_smoke"));
        let ModelConfig::Maskrcnn(m) = &cfg.model else {
            panic!("smoke changed the model kind")
        };
        assert_eq!((m.depth, m.fpn_channels), (50, Some(32)));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn resume_needs_a_last_checkpoint_and_says_so() {
        let dir = tmp("resume");
        std::fs::create_dir_all(&dir).unwrap();
        let e = format!("{:#}", resume_point(&tiny(&dir, &[]), &dir).unwrap_err());
        assert!(
            e.contains("last.bpk") && e.contains("nothing to resume"),
            "{e}"
        );
        std::fs::write(dir.join("last.bpk"), b"not a checkpoint").unwrap();
        let e = format!("{:#}", resume_point(&tiny(&dir, &[]), &dir).unwrap_err());
        assert!(e.contains("not a chicktrain checkpoint"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn load_data_splits_and_refuses_an_all_test_split() {
        let dir = tmp("data");
        let (real, split, synthetic) = load_data(&tiny(&dir, &[]), &dir, None).unwrap();
        assert_eq!(real.ids(), [1, 2, 3, 4]);
        assert_eq!(split.train.len() + split.val.len() + split.test.len(), 4);
        assert!(dir.join("split.json").is_file());
        assert_eq!(synthetic.count, 0);
        // data.train_limit keeps a subset of the train split, val and test as split.
        let ten = ["data.real.count=10", "data.split=[0.6, 0.2]"];
        let (_, full, _) = load_data(&tiny(&dir, &ten), &dir, None).unwrap();
        let (_, two, _) = load_data(
            &tiny(&dir, &[ten[0], ten[1], "data.train_limit=2"]),
            &dir,
            None,
        )
        .unwrap();
        assert_eq!((full.train.len(), two.train.len()), (6, 2));
        assert!(two.train.iter().all(|i| full.train.contains(i)));
        assert_eq!((&two.val, &two.test), (&full.val, &full.test));
        // `[0, 0]` is an evaluation set (every image test), not something to train on.
        let e = load_data(&tiny(&dir, &["data.split=[0.0, 0.0]"]), &dir, None).unwrap_err();
        let e = format!("{e:#}");
        assert!(e.contains("0 train / 0 val / 4 test"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn val_every_validates_every_nth_and_the_last_epoch_only() {
        // 3 epochs with train.val_every = 2: epochs 2 and 3 are validated, epoch 1 is
        // not; best.bpk comes from a validated epoch and test.json scores it.
        let dir = tmp("val-every");
        let cfg = tiny(
            &dir,
            &["train.epochs=3", "train.val_every=2", "train.batch=2"],
        );
        let opts = TrainOptions {
            run_dir: Some(dir.join("run")),
            quiet: true,
            ..Default::default()
        };
        let s = train(cfg, &opts).unwrap();
        let run = dir.join("run");
        let recs = run_files::read_metrics(&run, 9).unwrap();
        let validated: Vec<bool> = recs.iter().map(|r| r.val.is_some()).collect();
        assert_eq!(validated, [false, true, true]);
        let jl = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
        assert!(!jl.lines().next().unwrap().contains("\"val\""), "{jl}");
        let csv = std::fs::read_to_string(run.join("results.csv")).unwrap();
        let rows: Vec<Vec<&str>> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect())
            .collect();
        let n_loss = 4;
        assert!(
            rows[0][3 + n_loss..].iter().all(|c| *c == "null"),
            "{:?}",
            rows[0]
        );
        assert!(
            rows[1][3 + n_loss..].iter().all(|c| *c != "null"),
            "{:?}",
            rows[1]
        );
        let best = Checkpoint::load(&run.join("best.bpk")).unwrap();
        assert!(
            matches!(best.header.epoch, 2 | 3),
            "best from epoch {}",
            best.header.epoch
        );
        assert!(best.header.val.is_some());
        assert_eq!(s.best_epoch, best.header.epoch);
        assert_eq!(run_files::read_test(&run).unwrap().epoch, best.header.epoch);
        let last = Checkpoint::load(&run.join("last.bpk")).unwrap();
        assert_eq!(last.header.epoch, 3);
        assert!(run.join("plots.png").is_file());
        // Epoch 3 validated from the inputs kept at epoch 2 (`InputCache`): scoring its
        // checkpoint afresh, every image read again, gives the same stats bit for bit.
        let timed: Vec<bool> = recs.iter().map(|r| r.val_time.is_some()).collect();
        assert_eq!(timed, [false, true, true]);
        let again = crate::infer::validate::score_checkpoint(
            &run.join("last.bpk"),
            crate::infer::validate::SplitName::Val,
            None,
            None,
            None,
            false,
        )
        .unwrap();
        let logged = recs[2].val.as_ref().unwrap();
        assert_eq!(again.stats.bbox, logged.bbox.stats);
        assert_eq!(again.stats.segm, logged.segm.stats);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn steps_per_epoch_and_real_fraction_fix_the_compute_with_every_augmentation_on() {
        // 4 proxy images (2 train) + 3 renders; 3 steps of 1 real + 1 synthetic per
        // epoch whatever the counts, through mosaic, copy-paste, the warp and flipud.
        let dir = tmp("mix");
        let cfg = tiny(
            &dir,
            &[
                "data.synthetic=3",
                "train.epochs=2",
                "train.batch=2",
                "train.val_every=2",
                "train.steps_per_epoch=3",
                "train.real_fraction=0.5",
                "train.degrees=180",
                "train.scale=0.3",
                "train.translate=0.1",
                "train.flipud=0.5",
                "train.mosaic=1.0",
                "train.copy_paste=0.5",
            ],
        );
        let opts = TrainOptions {
            run_dir: Some(dir.join("run")),
            quiet: true,
            ..Default::default()
        };
        let s = train(cfg, &opts).unwrap();
        assert_eq!(s.steps, 6);
        let recs = run_files::read_metrics(&dir.join("run"), 9).unwrap();
        assert_eq!(recs.iter().map(|r| r.steps).collect::<Vec<_>>(), [3, 3]);
        assert_eq!(run_files::total_steps(&dir.join("run")).unwrap(), 6);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn epoch_line_reports_every_term_and_the_best_mark() {
        let mut segm = [0.0; 12];
        segm[..2].copy_from_slice(&[0.5, 0.75]);
        let rec = EpochRecord {
            data_wait_s: 0.5,
            epoch: 3,
            images_per_s: 6.5,
            loss: [("box".to_string(), 1.25), ("seg".to_string(), 0.5)].into(),
            loss_scale: None,
            lr: 0.01,
            proxy: true,
            skipped_steps: 0,
            steps: 4,
            time: 12.0,
            train_time: 10.0,
            val: Some(StatsRecord {
                bbox: IouStats { stats: [0.25; 12] },
                segm: IouStats { stats: segm },
            }),
            val_time: None,
        };
        let timed = EpochRecord {
            val_time: Some(ValTime {
                total: 1.5,
                forward: 1.25,
            }),
            ..rec.clone()
        };
        assert!(
            epoch_line(&timed, 25, &["box", "seg"], false)
                .contains("val (1.5 s, 1.20× forward) bbox AP 0.250"),
            "{}",
            epoch_line(&timed, 25, &["box", "seg"], false)
        );
        let line = epoch_line(&rec, 25, &["box", "seg"], true);
        assert_eq!(
            line,
            "epoch 3/25  lr 1.00e-2  loss box 1.250 seg 0.500  12.0 s (6.50 img/s, 0.5 s data wait)  val bbox AP 0.250 AP50 0.250  segm AP 0.500 AP50 0.750  *best"
        );
        assert!(!epoch_line(&rec, 25, &["box", "seg"], false).contains("best"));
        let skipped = EpochRecord {
            val: None,
            val_time: None,
            ..rec
        };
        assert_eq!(
            epoch_line(&skipped, 25, &["box", "seg"], false),
            "epoch 3/25  lr 1.00e-2  loss box 1.250 seg 0.500  12.0 s (6.50 img/s, 0.5 s data wait)  not validated (train.val_every)"
        );
        let f16 = EpochRecord {
            loss_scale: Some(16384.0),
            skipped_steps: 2,
            ..skipped
        };
        assert!(
            epoch_line(&f16, 25, &["box", "seg"], false)
                .contains("(6.50 img/s, 0.5 s data wait, loss scale 16384, 2 skipped)"),
            "{}",
            epoch_line(&f16, 25, &["box", "seg"], false)
        );
    }
}
