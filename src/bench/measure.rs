//! Measuring one (variant, size) in this process: parameters, GFLOPs, batch-1 latency,
//! training throughput and peak memory, as a [`Measurement`]. This is what a `bench
//! model-worker` child runs ([`super::worker`] keeps every row in a fresh process, so the
//! peak-memory reading here is that row's alone).
//!
//! Every family is timed by the same code ([`Timer`]), through what its `Family`
//! implementation says a batch-1 inference and a training probe are:
//! - **latency**: batch-1 forward pass until the outputs are on the host, after warm-up
//!   runs; YOLO with BatchNorm folded (as deployed), its box decoding and NMS excluded
//!   (ultralytics' "inference" time); Mask R-CNN's `forward_infer`, which includes its
//!   proposal, box and mask-head stages (up to the 28×28 mask probabilities; pasting them
//!   into the image is the caller's, as decoding YOLO's masks is). Median, 10th and 90th
//!   percentile.
//! - **training throughput**: images/s of full steps at batch 8 — forward, the real loss
//!   (task-aligned assigner + losses for YOLO; RPN + RoI losses for Mask R-CNN),
//!   backward, SGD step — on procedural scenes with 6 objects per image, median step.
//! - **peak memory**: the process' resident-set high-water mark after inference and
//!   after training (Linux `/proc/self/status`; `getrusage` elsewhere).

use std::time::Instant;

use anyhow::{bail, Result};
use burn::module::Module;
use burn::optim::momentum::MomentumConfig;
use burn::optim::{GradientsParams, ModuleOptimizer, SgdConfig};
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::annotations::targets::Targets;
use crate::data::ellipses::ellipse_batch;
use crate::infer::detector::ConfigVisitor;
use crate::model::family::{Family, TrainingLoss};
use crate::model::summary::ModelSummary;
use crate::util::stats::percentile;
use crate::util::tensor::to_host;

use super::variant::Variant;

/// What one worker measured for one (variant, size).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    pub variant: String,
    pub size: usize,
    pub params: usize,
    pub gflops: f64,
    /// Batch-1 latency, ms: median, 10th and 90th percentile over `repeats` runs.
    pub latency_ms: [f64; 3],
    pub repeats: usize,
    /// Training images/s at `train_batch` (median over `train_steps` timed steps).
    pub train_img_s: f64,
    pub train_batch: usize,
    pub train_steps: usize,
    /// Resident-set high-water mark after inference, and after training, MiB.
    pub infer_peak_mib: f64,
    pub peak_mib: f64,
}

/// How much to measure per row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Effort {
    /// Untimed batch-1 runs first.
    pub warmup: usize,
    /// Timed batch-1 runs.
    pub repeats: usize,
    pub train_batch: usize,
    /// Timed training steps (after one untimed step).
    pub train_steps: usize,
}

impl Default for Effort {
    fn default() -> Effort {
        Effort {
            warmup: 3,
            repeats: 30,
            train_batch: 8,
            train_steps: 3,
        }
    }
}

/// The process' peak resident set so far, MiB.
pub fn peak_rss_mib() -> f64 {
    if let Ok(s) = std::fs::read_to_string("/proc/self/status") {
        if let Some(kb) = s
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        {
            return kb / 1024.0;
        }
    }
    rusage_peak_mib()
}

#[cfg(unix)]
fn rusage_peak_mib() -> f64 {
    // SAFETY: getrusage writes into the zeroed struct we own.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return f64::NAN;
    }
    // kB on Linux, bytes on macOS.
    let kb = if cfg!(target_os = "macos") {
        u.ru_maxrss as f64 / 1024.0
    } else {
        u.ru_maxrss as f64
    };
    kb / 1024.0
}

#[cfg(not(unix))]
fn rusage_peak_mib() -> f64 {
    f64::NAN
}

fn median(v: &[f64]) -> f64 {
    percentile(v, 50.0)
}

/// The inputs every variant is timed on: a batch-1 image (inference), a training batch
/// with its targets, and the SGD optimizer of the training steps.
struct Inputs {
    x1: Tensor<4>,
    xb: Tensor<4>,
    targets: Targets,
    optim: ModuleOptimizer,
}

/// What a variant's timing loop gives back: the model's size, the inference peak
/// memory, and the per-run times (ms) of inference and of training steps.
struct Timed {
    summary: ModelSummary,
    infer_peak: f64,
    lat: Vec<f64>,
    steps: Vec<f64>,
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Measures `variant` at `size` in this process (what a worker runs).
pub fn measure(variant: &Variant, size: usize, e: Effort, device: &Device) -> Result<Measurement> {
    if size < 32 || size % 32 != 0 {
        bail!("input size {size} must be a multiple of 32, at least 32");
    }
    if e.repeats == 0 || e.train_batch == 0 {
        bail!("--repeats and the training batch must be at least 1");
    }
    device.seed(0);
    let ad = device.clone().autodiff();
    let (px1, _) = ellipse_batch(1, size, 6, 1);
    let x1 = Tensor::<4>::from_data(TensorData::new(px1, [1, 3, size, size]), device);
    let (pxb, targets) = ellipse_batch(e.train_batch, size, 6, 2);
    let xb = Tensor::<4>::from_data(TensorData::new(pxb, [e.train_batch, 3, size, size]), &ad);
    let optim = SgdConfig::new()
        .with_momentum(Some(
            MomentumConfig::new().with_momentum(0.9).with_dampening(0.0),
        ))
        .init();
    let inputs = Inputs {
        x1,
        xb,
        targets,
        optim,
    };
    let t = variant.config(size).visit(Timer {
        size,
        e,
        ad: &ad,
        inputs,
    })?;
    Ok(Measurement {
        variant: variant.to_string(),
        size,
        params: t.summary.params,
        gflops: t.summary.gflops,
        latency_ms: [
            median(&t.lat),
            percentile(&t.lat, 10.0),
            percentile(&t.lat, 90.0),
        ],
        repeats: e.repeats,
        train_img_s: if t.steps.is_empty() {
            f64::NAN
        } else {
            e.train_batch as f64 * 1e3 / median(&t.steps)
        },
        train_batch: e.train_batch,
        train_steps: e.train_steps,
        infer_peak_mib: t.infer_peak,
        peak_mib: peak_rss_mib(),
    })
}

/// Times `warmup + repeats` calls of `run` and keeps the last `repeats` (ms).
fn time_runs(
    warmup: usize,
    repeats: usize,
    mut run: impl FnMut() -> Result<()>,
) -> Result<Vec<f64>> {
    let mut times = Vec::with_capacity(repeats);
    for r in 0..warmup + repeats {
        let t = Instant::now();
        run()?;
        if r >= warmup {
            times.push(ms(t));
        }
    }
    Ok(times)
}

/// Times `1 + steps` training steps (the first untimed): `loss` of the model, backward,
/// an SGD step, then `probe` (a sum over one updated weight) read back to the host so the
/// step has really run on a lazy backend.
fn time_train_steps<M: Module>(
    steps: usize,
    model: M,
    optim: &mut ModuleOptimizer,
    mut loss: impl FnMut(&M) -> Tensor<1>,
    probe: impl Fn(&M) -> Tensor<1>,
) -> Result<Vec<f64>> {
    // The optimiser takes the model by value: a slot moves it through each step without
    // a clone (a second handle would keep the backend from updating weights in place).
    let mut slot = Some(model);
    time_runs(1, steps, || {
        let m = slot.take().expect("the model is put back after every step");
        let grads = GradientsParams::from_grads(loss(&m).backward(), &m);
        let m = optim.step(0.01, m, grads);
        let _ = to_host(probe(&m));
        slot = Some(m);
        Ok(())
    })
}

/// The timing of one family's variant ([`DetectorConfig::visit`]): batch-1 inference of
/// the family's `bench_model` (YOLO fused, the others eval-mode), then training steps of
/// the model with its real loss, the random draws of all steps from one stream seeded 0.
struct Timer<'a> {
    size: usize,
    e: Effort,
    ad: &'a Device,
    inputs: Inputs,
}

impl ConfigVisitor for Timer<'_> {
    type Out = Result<Timed>;
    fn visit<F: Family>(self, cfg: &F::Config) -> Result<Timed> {
        let Timer {
            size,
            e,
            ad,
            inputs,
        } = self;
        let Inputs {
            x1,
            xb,
            targets,
            mut optim,
        } = inputs;
        let model = F::build(cfg, ad);
        let summary = model.summary_at(size);
        let infer = model.bench_model();
        let lat = time_runs(e.warmup, e.repeats, || infer.bench_forward(x1.clone()))?;
        drop(infer);
        let infer_peak = peak_rss_mib();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let steps = time_train_steps(
            e.train_steps,
            model,
            &mut optim,
            |m| m.train_loss(xb.clone(), &targets, &mut rng).into_total(),
            |m| m.probe(),
        )?;
        Ok(Timed {
            summary,
            infer_peak,
            lat,
            steps,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tiny_yolo_measures_in_process() {
        let v: Variant = "yolo-n-p45-w0.25-m4".parse().unwrap();
        let e = Effort {
            warmup: 0,
            repeats: 2,
            train_batch: 2,
            train_steps: 1,
        };
        let m = measure(&v, 64, e, &Device::flex()).unwrap();
        assert_eq!((m.variant.as_str(), m.size), ("yolo-n-p45-w0.25-m4", 64));
        assert!(m.params > 0 && m.gflops > 0.0);
        assert!(m.latency_ms[1] <= m.latency_ms[0] && m.latency_ms[0] <= m.latency_ms[2]);
        assert!(m.train_img_s > 0.0 && m.peak_mib >= m.infer_peak_mib && m.infer_peak_mib > 0.0);
        assert!(measure(&v, 70, e, &Device::flex()).is_err());
    }
}
