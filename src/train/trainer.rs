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
//!
//! The pieces: [`super::prepare`] (flags, run folder, resume point, data),
//! [`super::epoch`] (the steps of an epoch), [`super::run`] (the end of an epoch, the
//! test of the best checkpoint), [`super::lines`] (what is printed).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;

use crate::config::Config;
use crate::infer::checkpoint::Stats;
use crate::infer::detector::DetectorConfig;
use crate::infer::device::device_with;

use super::divergence::DivergenceGuard;
use super::epoch::run_epoch;
use super::lines::{data_line, epoch_line, model_line, plan_line};
use super::loader::Loader;
use super::plot;
pub use super::prepare::TrainOptions;
use super::prepare::{load_data, prepare_run, resume_point};
use super::run::{test_best, Run};
use super::run_files;
use super::self_training::SelfTraining;
use super::state::TrainState;

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
    say(data_line(&cfg, &real, &split, t0.elapsed().as_secs_f64()));
    say(plan_line(&cfg, &split));

    let base = device_with(cfg.device, cfg.train.precision)?;
    base.seed(cfg.seed);
    let ad = base.clone().autodiff();
    let mcfg = DetectorConfig::from_config(&cfg, real.num_classes())?;
    let input = mcfg.input_size();
    let mut st = TrainState::new(&cfg, &mcfg, resume.as_ref(), &run_dir, &ad, &base, &say)?;
    if resume.is_some() {
        say(format!("resuming after epoch {}", st.epoch));
    }
    say(model_line(&cfg, &mcfg, &st, input));
    let loss_names = st.model.loss_names();
    let run = Run::new(&cfg, &run_dir, &real, &split, &mcfg, &base, input);
    let resumed = resume.is_some().then_some(st.epoch);
    let mut selftrain = SelfTraining::for_run(&cfg, real.num_classes(), &base, &run_dir, resumed)?;
    if let Some(s) = &selftrain {
        say(s.describe(cfg.train.epochs, cfg.train.batch));
    }
    let mut loader = Loader::for_run(&cfg, real.clone(), synthetic, input as u32)?;
    if st.epoch == 0 {
        super::batch_plots::write_train_batches(&run_dir, &cfg, &loader, &split.train)?;
    }
    let (mut train_imgs, mut train_secs) = (0usize, 0f64);
    let guard_names: Vec<&str> = loss_names.iter().copied().chain(["total"]).collect();
    let mut guard = DivergenceGuard::new(&guard_names);
    for epoch in st.epoch..cfg.train.epochs {
        let labelled = match &selftrain {
            Some(s) => s.before_epoch(&cfg, epoch, &st, &mut loader, &base, &say)?,
            None => None,
        };
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
        if let Some(s) = &mut selftrain {
            s.record(&run_dir, epoch, &loader, labelled, steps.pseudo_items)?;
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::infer::checkpoint::Checkpoint;
    use crate::train::prepare::tests::{tiny, tmp};

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
}
