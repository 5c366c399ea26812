//! Run preparation: `train`'s flags ([`TrainOptions`]), the config as it will run and its
//! run folder, what `--resume` continues from (checked against the config before anything
//! is written), and the data the run reads — the real set, its split and the synthetic
//! renders. Nothing here trains: [`super::trainer`] calls these before step 1.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::annotations::split::Split;
use crate::config::{Config, DeviceKind};
use crate::data::dataset::{RealSet, SyntheticSet};
use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::DetectorConfig;

use super::run_folder::run_folder;
use super::smoke::smoke_config;

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

/// The config as it will run (`--smoke`, `--device` applied) and its run folder, created.
pub fn prepare_run(mut cfg: Config, opts: &TrainOptions) -> Result<(Config, PathBuf)> {
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
pub fn resume_point(cfg: &Config, run_dir: &Path) -> Result<Checkpoint> {
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
pub fn load_data(
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::config::{self, ModelConfig};

    pub(crate) fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ct-trainer-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// quickstart at 64 px with 4 proxy images and no renders, cache in `dir`.
    pub(crate) fn tiny(dir: &Path, extra: &[&str]) -> Config {
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
}
