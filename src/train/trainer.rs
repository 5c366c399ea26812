//! The training loop: data → epochs of steps → per-epoch COCO evaluation → checkpoints
//! and run files → test evaluation of the best checkpoint.
//!
//! Run directory (`runs/<name>/` or `--run-dir`): `config.toml` (resolved), `split.json`,
//! `metrics.jsonl` (one object per epoch), `results.csv`, `best.bpk`, `last.bpk`,
//! `test.json`, and `plots.png` when plotting is built in. Every file is written
//! atomically. A diverging run (non-finite or exploding loss, see [`super::divergence`])
//! stops with an error naming the epoch, step and loss term; `last.bpk` then still holds
//! the last good epoch.
//!
//! Batches are built on a loader thread (rendering, decoding and augmenting the next
//! batch in parallel with rayon) while the current step runs; each item's augmentation
//! RNG is keyed by (seed, epoch, position), so a run does not depend on thread timing.

use std::path::{Path, PathBuf};
use std::sync::mpsc::sync_channel;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::json;

use crate::config::{Config, DeviceKind, ModelKind};
use crate::data::augment::{augment, AugmentConfig};
use crate::data::batch::{collate, Batch};
use crate::data::dataset::{RealSet, Sample, SyntheticSet};
use crate::data::split::Split;
use crate::util::write_atomic;

use super::checkpoint::{module_bytes, optim_bytes, Checkpoint, Header, Stats, FORMAT};
use super::detector::{Detector, DetectorConfig};
use super::divergence::{check_weights, At, DivergenceGuard};
use super::ema::Ema;
use super::evaluate::evaluate_ids;
use super::schedule::step_lr;
use super::{optim, progress};

/// How to run (everything that is not in the config file).
#[derive(Clone, Debug, Default)]
pub struct TrainOptions {
    /// Outputs here instead of `runs/<name>/`.
    pub run_dir: Option<PathBuf>,
    /// Continue from `<run_dir>/last.bpk`.
    pub resume: bool,
    /// Shrink the config to a ~1 minute run ([`smoke_config`]).
    pub smoke: bool,
    /// Override `device`.
    pub device: Option<DeviceKind>,
    /// No progress bars and no per-epoch lines on stderr.
    pub quiet: bool,
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
}

/// `--smoke`: any config shrunk to about a minute that still goes through every stage:
/// 64 px images (no crop), at most 9 real and 4 synthetic images, 2 epochs, batch 4.
/// A Mask R-CNN keeps its depth (so the R101 code paths run) but gets quarter widths,
/// anchors sized for 64 px and a few dozen proposals and RoIs.
pub fn smoke_config(cfg: &mut Config) {
    cfg.name = format!("{}_smoke", cfg.name);
    let d = &mut cfg.data;
    d.image_size = 64;
    d.crop = 64;
    d.real.count = d.real.count.min(9);
    d.real.limit = Some(d.real.limit.unwrap_or(9).min(9));
    d.synthetic = d.synthetic.min(4);
    let t = &mut cfg.train;
    t.epochs = t.epochs.min(2);
    t.batch = t.batch.min(4);
    t.warmup_epochs = t.warmup_epochs.min(1.0);
    t.warmup_iters = t.warmup_iters.min(2);
    t.milestones.retain(|&m| m < t.epochs);
    let m = &mut cfg.model;
    if m.kind == ModelKind::Maskrcnn {
        m.width_mult = m.width_mult.min(0.25);
        m.fpn_channels = Some(32);
        m.anchor_sizes = Some(vec![12.0, 24.0, 48.0, 96.0, 192.0]);
        m.rpn_batch = Some(64);
        m.rpn_pre_nms_topk_train = Some(200);
        m.rpn_post_nms_topk_train = Some(50);
        m.rpn_pre_nms_topk_test = Some(200);
        m.rpn_post_nms_topk_test = Some(50);
        m.roi_batch = Some(32);
        m.box_fc_dim = Some(64);
        m.mask_conv_dim = Some(32);
    }
}

/// The Burn device of a kind.
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
pub fn device_of(kind: DeviceKind) -> Device {
    match kind {
        DeviceKind::Flex => Device::flex(),
        DeviceKind::Ndarray => Device::ndarray(),
    }
}

/// The model config of a run config with `nc` classes.
pub fn model_config(cfg: &Config, nc: usize) -> Result<DetectorConfig> {
    DetectorConfig::from_config(cfg, nc)
}

/// One item of an epoch: a real image id or a synthetic index.
#[derive(Clone, Copy, Debug)]
enum Item {
    Real(u64),
    Synthetic(u64),
}

fn mix(a: u64, b: u64) -> u64 {
    crate::render::noise::mix64(
        a ^ crate::render::noise::mix64(b.wrapping_add(0x9E37_79B9_7F4A_7C15)),
    )
}

/// Shuffled items of `epoch`.
fn epoch_plan(train_ids: &[u64], synthetic: usize, seed: u64, epoch: usize) -> Vec<Item> {
    let mut items: Vec<Item> = train_ids.iter().map(|&i| Item::Real(i)).collect();
    items.extend((0..synthetic as u64).map(Item::Synthetic));
    items.shuffle(&mut ChaCha8Rng::seed_from_u64(mix(seed, epoch as u64)));
    items
}

struct Data {
    real: RealSet,
    synthetic: SyntheticSet,
    aug: AugmentConfig,
    seed: u64,
}

impl Data {
    fn batch(&self, items: &[Item], epoch: usize, first_pos: usize) -> Result<Batch> {
        let samples: Result<Vec<Sample>> = items
            .par_iter()
            .enumerate()
            .map(|(k, it)| {
                let s = match *it {
                    Item::Real(id) => self.real.sample(id)?,
                    Item::Synthetic(i) => self.synthetic.sample(i, epoch as u64)?,
                };
                let key = mix(mix(self.seed, epoch as u64), (first_pos + k) as u64);
                Ok(augment(&s, &self.aug, &mut ChaCha8Rng::seed_from_u64(key)))
            })
            .collect();
        collate(&samples?)
    }
}

fn stats_json(s: &Stats) -> serde_json::Value {
    json!({"bbox": {"stats": s.bbox}, "segm": {"stats": s.segm}})
}

const STAT_NAMES: [&str; 12] = [
    "AP", "AP50", "AP75", "APs", "APm", "APl", "AR1", "AR10", "AR100", "ARs", "ARm", "ARl",
];

fn csv_header(loss_names: &[&str]) -> String {
    let mut h = vec!["epoch".to_string(), "lr".into(), "time".into()];
    h.extend(loss_names.iter().map(|s| format!("train/{s}_loss")));
    for t in ["bbox", "segm"] {
        h.extend(STAT_NAMES.iter().map(|n| format!("val/{t}_{n}")));
    }
    h.join(",")
}

fn csv_row(m: &serde_json::Value, loss_names: &[&str]) -> String {
    let mut r = vec![
        m["epoch"].to_string(),
        m["lr"].to_string(),
        m["time"].to_string(),
    ];
    for k in loss_names {
        r.push(m["loss"][k].to_string());
    }
    for t in ["bbox", "segm"] {
        if let Some(a) = m["val"][t]["stats"].as_array() {
            r.extend(a.iter().map(|v| v.to_string()));
        }
    }
    r.join(",")
}

/// Writes `metrics.jsonl` and `results.csv` from the per-epoch records.
fn write_metrics(dir: &Path, records: &[serde_json::Value], loss_names: &[&str]) -> Result<()> {
    let mut jl = String::new();
    let mut csv = csv_header(loss_names) + "\n";
    for r in records {
        jl.push_str(&serde_json::to_string(r)?);
        jl.push('\n');
        csv.push_str(&csv_row(r, loss_names));
        csv.push('\n');
    }
    write_atomic(&dir.join("metrics.jsonl"), jl.as_bytes())?;
    write_atomic(&dir.join("results.csv"), csv.as_bytes())?;
    Ok(())
}

fn read_metrics(dir: &Path, upto_epoch: usize) -> Result<Vec<serde_json::Value>> {
    let p = dir.join("metrics.jsonl");
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for (i, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let v: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("{} line {} is not JSON", p.display(), i + 1))?;
        if v["epoch"]
            .as_u64()
            .is_some_and(|e| e as usize <= upto_epoch)
        {
            out.push(v);
        }
    }
    Ok(out)
}

/// Trains `cfg` (already validated) and returns the test metrics of the best checkpoint.
pub fn train(mut cfg: Config, opts: &TrainOptions) -> Result<TrainSummary> {
    let t_start = Instant::now();
    if opts.smoke {
        smoke_config(&mut cfg);
        cfg.validate().context("smoke config")?;
    }
    if let Some(d) = opts.device {
        cfg.device = d;
    }
    let run_dir = opts
        .run_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&cfg.name));
    std::fs::create_dir_all(&run_dir)
        .with_context(|| format!("cannot create run folder {}", run_dir.display()))?;
    let say = |s: String| {
        if !opts.quiet {
            eprintln!("{s}");
        }
    };

    let resume = if opts.resume {
        let p = run_dir.join("last.bpk");
        if !p.exists() {
            bail!(
                "--resume: {} does not exist (nothing to resume)",
                p.display()
            );
        }
        let ck = Checkpoint::load(&p)?;
        if ck.header.model.kind() != cfg.model.kind {
            // Checked before anything is written to the run folder.
            let probe = DetectorConfig::from_config(&cfg, ck.header.model.num_classes())?;
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
        Some(ck)
    } else {
        None
    };

    let text = format!(
        "# chicktrain resolved config (schema 1){}\n{}",
        if cfg.data.real.kind == crate::config::RealKind::Proxy {
            "; data.real is the proxy-real render preset, a stand-in for real photos"
        } else {
            ""
        },
        toml::to_string(&cfg)?
    );
    write_atomic(&run_dir.join("config.toml"), text.as_bytes())?;

    // Data.
    let t0 = Instant::now();
    let real = RealSet::load(&cfg.data, cfg.seed)?;
    let split = match &resume {
        Some(ck) => ck.header.split.clone(),
        None => Split::new(&real.ids(), cfg.data.split, cfg.seed)?,
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

    // Model, optimiser, EMA.
    let base = device_of(cfg.device);
    base.seed(cfg.seed);
    let ad = base.clone().autodiff();
    let mcfg = model_config(&cfg, real.num_classes())?;
    let mut optim = optim::build(&cfg.train);
    let (mut model, mut ema, start_epoch, mut best_fitness, mut records) = match &resume {
        Some(ck) => {
            if let Some(why) = mcfg.mismatch(&ck.header.model) {
                bail!(
                    "--resume: cannot continue from {}: {why}",
                    run_dir.join("last.bpk").display()
                );
            }
            let in_last = || format!("--resume: in {}", run_dir.join("last.bpk").display());
            let model = ck.model("model", &ad).with_context(in_last)?;
            let ema = Ema {
                model: ck.model("ema", &base).with_context(in_last)?,
                updates: ck.header.ema_updates,
            };
            optim = ck.optimizer(optim).with_context(in_last)?;
            let recs = read_metrics(&run_dir, ck.header.epoch)?;
            say(format!("resuming after epoch {}", ck.header.epoch));
            (model, ema, ck.header.epoch, ck.header.best_fitness, recs)
        }
        None => {
            let model = mcfg.init(&ad);
            let ema = Ema::new(&model, 0);
            (model, ema, 0, f64::NEG_INFINITY, Vec::new())
        }
    };
    say(format!(
        "model: {}: {} on {:?}",
        mcfg.describe(),
        model.summary(cfg.data.image_size as usize),
        cfg.device
    ));
    let loss_names = model.loss_names();

    let data = Data {
        real: real.clone(),
        synthetic,
        aug: AugmentConfig {
            crop: cfg.data.crop,
            fliplr: cfg.train.fliplr,
            hsv: cfg.train.hsv,
        },
        seed: cfg.seed,
    };
    let n_items = split.train.len() + cfg.data.synthetic;
    let bsz = cfg.train.batch;
    let per_epoch = n_items.div_ceil(bsz);
    let class_names = real.class_names();
    let header_for = |epoch: usize, best: f64, updates: u64, val: Option<Stats>| Header {
        format: FORMAT,
        chicktrain: env!("CARGO_PKG_VERSION").into(),
        model: mcfg.clone(),
        category_ids: real.cat_ids.clone(),
        class_names: class_names.clone(),
        config: cfg.clone(),
        split: split.clone(),
        proxy: real.proxy,
        epoch,
        ema_updates: updates,
        best_fitness: best,
        val,
    };

    let mut best_epoch = resume.as_ref().map_or(0, |_| {
        records
            .iter()
            .max_by(|a, b| {
                let f =
                    |v: &serde_json::Value| v["val"]["segm"]["stats"][0].as_f64().unwrap_or(-1.0);
                f(a).total_cmp(&f(b))
            })
            .and_then(|r| r["epoch"].as_u64())
            .unwrap_or(0) as usize
    });
    let (mut train_imgs, mut train_secs) = (0usize, 0f64);
    let guard_names: Vec<&str> = loss_names.iter().copied().chain(["total"]).collect();
    let mut guard = DivergenceGuard::new(&guard_names);
    for epoch in start_epoch..cfg.train.epochs {
        let te = Instant::now();
        let plan = epoch_plan(&split.train, cfg.data.synthetic, cfg.seed, epoch);
        let bar = if opts.quiet {
            indicatif::ProgressBar::hidden()
        } else {
            progress::bar(
                per_epoch as u64,
                &format!("{}/{}", epoch + 1, cfg.train.epochs),
            )
        };
        let mut sums = vec![0f64; loss_names.len()];
        let mut last_lr = 0.0;
        let mut seen = 0usize;
        let mut interrupted: Option<usize> = None;
        let step_result: Result<()> = std::thread::scope(|sc| {
            let (tx, rx) = sync_channel::<Result<Batch>>(2);
            let data = &data;
            let plan = &plan;
            sc.spawn(move || {
                for (b, chunk) in plan.chunks(bsz).enumerate() {
                    if tx.send(data.batch(chunk, epoch, b * bsz)).is_err() {
                        return;
                    }
                }
            });
            for (step, batch) in rx.iter().enumerate() {
                let batch = batch.with_context(|| {
                    format!("building batch {} of epoch {}", step + 1, epoch + 1)
                })?;
                let n = batch.dims[0];
                let x = Tensor::<4>::from_data(TensorData::new(batch.pixels, batch.dims), &ad);
                let loss = model.loss(
                    x,
                    &batch.targets,
                    mix(mix(cfg.seed ^ 0x5A3D, epoch as u64), step as u64),
                );
                let mut v = loss.terms.clone();
                v.push(loss.total_value);
                let at = At {
                    epoch,
                    step,
                    per_epoch,
                };
                guard.check_step(at, &v)?;
                let mut grads = GradientsParams::from_grads(loss.total.backward(), &model);
                let norm = optim::clip_global_norm(&model, &mut grads, cfg.train.grad_clip)?;
                guard.check_grad_norm(at, norm)?;
                let (rates, lr) = step_lr(&cfg.train, epoch, step, per_epoch);
                model = optim.step(rates, model.clone(), grads);
                if cfg.train.ema {
                    ema.update(&model);
                }
                for (s, t) in sums.iter_mut().zip(&loss.terms) {
                    *s += *t as f64;
                }
                last_lr = lr;
                seen += 1;
                train_imgs += n;
                let el = te.elapsed().as_secs_f64();
                bar.set_message(format!(
                    "loss {:.3} {:.2} img/s",
                    loss.total_value / n as f32,
                    (seen * bsz) as f64 / el.max(1e-9)
                ));
                bar.inc(1);
                if super::interrupt::requested() {
                    interrupted = Some(step + 1);
                    break;
                }
            }
            Ok(())
        });
        bar.finish_and_clear();
        step_result?;
        if let Some(step) = interrupted {
            // Completed epochs stay `epoch`: --resume redoes this one from its start, with
            // the weights, optimiser state and EMA as they are now.
            let p = run_dir.join("last.bpk");
            Checkpoint {
                header: header_for(epoch, best_fitness, ema.updates, None),
                sections: vec![
                    (
                        "ema".into(),
                        module_bytes(&if cfg.train.ema {
                            ema.model.clone()
                        } else {
                            model.valid()
                        })?,
                    ),
                    ("model".into(), module_bytes(&model)?),
                    ("optim".into(), optim_bytes(&optim)?),
                ],
            }
            .save(&p)?;
            bail!(
                "interrupted (Ctrl-C) at epoch {}, step {step}; saved {} — continue with the same command plus --resume",
                epoch + 1,
                p.display()
            );
        }
        let t_train = te.elapsed().as_secs_f64();
        train_secs += t_train;
        check_weights(&model.valid(), "model", epoch)?;
        if cfg.train.ema {
            check_weights(&ema.model, "EMA", epoch)?;
        }

        // Evaluate.
        let eval_model: Detector = if cfg.train.ema {
            ema.model.clone()
        } else {
            model.valid()
        };
        let (val, _) = evaluate_ids(&eval_model, &real, &split.val, &base)?;
        let secs = te.elapsed().as_secs_f64();
        let steps = seen.max(1) as f64;
        let rec = json!({
            "epoch": epoch + 1,
            "lr": last_lr,
            "loss": loss_names.iter().zip(&sums).map(|(k, s)| (k.to_string(), json!(s / steps))).collect::<serde_json::Map<_, _>>(),
            "time": secs,
            "train_time": t_train,
            "images_per_s": (seen * bsz).min(n_items) as f64 / t_train.max(1e-9),
            "val": stats_json(&val),
            "proxy": real.proxy,
        });
        records.push(rec);
        write_metrics(&run_dir, &records, loss_names)?;

        // Checkpoints.
        let fitness = val.segm[0];
        let improved = fitness > best_fitness;
        if improved {
            best_fitness = fitness;
            best_epoch = epoch + 1;
        }
        let ema_bytes = module_bytes(&eval_model)?;
        let header = header_for(epoch + 1, best_fitness, ema.updates, Some(val.clone()));
        if improved {
            Checkpoint {
                header: header.clone(),
                sections: vec![("ema".into(), ema_bytes.clone())],
            }
            .save(&run_dir.join("best.bpk"))?;
        }
        Checkpoint {
            header,
            sections: vec![
                ("ema".into(), ema_bytes),
                ("model".into(), module_bytes(&model)?),
                ("optim".into(), optim_bytes(&optim)?),
            ],
        }
        .save(&run_dir.join("last.bpk"))?;
        say(format!(
            "epoch {}/{}  lr {:.2e}  loss {}  {:.1} s ({:.2} img/s)  val bbox AP {:.3} AP50 {:.3}  segm AP {:.3} AP50 {:.3}{}",
            epoch + 1,
            cfg.train.epochs,
            last_lr,
            loss_names
                .iter()
                .zip(&sums)
                .map(|(k, s)| format!("{k} {:.3}", s / steps))
                .collect::<Vec<_>>()
                .join(" "),
            secs,
            (seen * bsz).min(n_items) as f64 / t_train.max(1e-9),
            val.bbox[0],
            val.bbox[1],
            val.segm[0],
            val.segm[1],
            if improved { "  *best" } else { "" }
        ));
    }

    // Test evaluation of the best checkpoint.
    let best = Checkpoint::load(&run_dir.join("best.bpk"))?;
    let best_model = best.model("ema", &base)?;
    let (test, _) = evaluate_ids(&best_model, &real, &split.test, &base)?;
    let test_json = json!({
        "checkpoint": "best.bpk",
        "epoch": best.header.epoch,
        "split": "test",
        "images": split.test.len(),
        "proxy": real.proxy,
        "bbox": {"stats": test.bbox},
        "segm": {"stats": test.segm},
    });
    write_atomic(
        &run_dir.join("test.json"),
        serde_json::to_string_pretty(&test_json)?.as_bytes(),
    )?;
    super::plot::write_plots(&run_dir, &records, loss_names)?;
    Ok(TrainSummary {
        run_dir,
        epochs: cfg.train.epochs,
        best_epoch: best.header.epoch.max(best_epoch),
        test,
        test_images: split.test.len(),
        proxy: real.proxy,
        seconds: t_start.elapsed().as_secs_f64(),
        train_images_per_s: train_imgs as f64 / train_secs.max(1e-9),
    })
}
