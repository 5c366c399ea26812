//! The optimiser steps of one epoch: the loader thread's batches → forward and loss (in
//! the run's precision) → divergence checks → backward, clipping (or f16 loss scaling) →
//! optimiser step and EMA update, with the progress bar and the Ctrl-C check. What an
//! epoch did comes back as [`EpochSteps`] for the epoch's record.

use std::time::Instant;

use anyhow::{Context, Result};
use burn::optim::GradientsParams;
use burn::tensor::{Device, FloatDType, Tensor, TensorData};

use crate::config::Config;
use crate::data::batch::Batch;
use crate::infer::precision::{float_dtype, graph_cast};
use crate::util::progress;

use super::divergence::{At, DivergenceGuard};
use super::loader::{epoch_batches, mix, Item, Loader, Mix};
use super::optim;
use super::schedule::step_lr;
use super::self_training::mix_in;
use super::state::TrainState;

/// The steps of one epoch, as far as they got.
pub struct EpochSteps {
    /// Sum over steps of each loss term.
    pub sums: Vec<f64>,
    pub last_lr: f64,
    pub steps: usize,
    pub images: usize,
    /// Steps done when Ctrl-C stopped the epoch.
    pub interrupted: Option<usize>,
    /// Seconds spent waiting for the loader thread's batches.
    pub data_wait: f64,
    /// f16: steps skipped by the loss scaler.
    pub skipped: usize,
    /// Self-training: pseudo-labelled items in the epoch's plan.
    pub pseudo_items: usize,
}

/// Runs the optimiser steps of `epoch` over `loader`'s batches.
#[allow(clippy::too_many_arguments)]
pub fn run_epoch(
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
    let m = Mix::of(&cfg.train);
    // The LR schedule counts warmup in these steps, so it stays in epochs whatever
    // `train.steps_per_epoch` is.
    let per_epoch = m.steps(train_ids.len(), cfg.data.synthetic, bsz);
    let plan = epoch_batches(train_ids, cfg.data.synthetic, cfg.seed, epoch, bsz, m)?;
    // Self-training: pseudo-labelled images take their share of each batch, same steps.
    let plan = match &loader.pseudo {
        Some(p) => {
            let st = cfg.train.self_training.clone().unwrap_or_default();
            mix_in(plan, &p.pool(), st.per_batch(bsz), bsz, cfg.seed, epoch)
        }
        None => plan,
    };
    let pseudo_items = plan
        .iter()
        .filter(|i| matches!(i, Item::Unlabeled(_)))
        .count();
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
        pseudo_items,
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
            let at = At {
                epoch,
                step,
                per_epoch,
            };
            let total = optimiser_step(cfg, st, guard, batch, at, ad, &mut out)?;
            out.steps += 1;
            out.images += n;
            let el = te.elapsed().as_secs_f64();
            bar.set_message(format!(
                "loss {:.3} {:.2} img/s",
                total / n as f32,
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

/// One optimiser step on `batch` (step `at`): forward and loss in the run's precision,
/// the divergence checks, backward (of the scaled loss in f16, skipped when its
/// gradients overflowed), global-norm clipping, the optimiser step and the EMA update.
/// Adds the loss terms to `out.sums`, sets `out.last_lr`, counts a skipped step; returns
/// the step's total loss.
fn optimiser_step(
    cfg: &Config,
    st: &mut TrainState,
    guard: &mut DivergenceGuard,
    batch: Batch,
    at: At,
    ad: &Device,
    out: &mut EpochSteps,
) -> Result<f32> {
    let (epoch, step, per_epoch) = (at.epoch, at.step, at.per_epoch);
    let x = Tensor::<4>::from_data(TensorData::new(batch.pixels, batch.dims), ad);
    let sample_seed = mix(mix(cfg.seed ^ 0x5A3D, epoch as u64), step as u64);
    let loss = match float_dtype(cfg.train.precision) {
        FloatDType::F32 => st.model.loss(x, &batch.targets, sample_seed),
        // Forward on a reduced copy of the f32 masters, cast inside the graph.
        d => graph_cast(st.model.clone(), d).loss(x, &batch.targets, sample_seed),
    };
    let mut v = loss.terms.clone();
    v.push(loss.total_value);
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
    Ok(loss.total_value)
}
