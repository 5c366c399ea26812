//! The one loop every study runs on: a study is data — a config, the `--set` overrides of
//! every run, a list of named config variants and a number of seeds — and [`Study::run`]
//! trains each (variant, seed) into its own folder, hands each finished run to the study's
//! score, and returns the scores with the runs it left untrained. What a study scores and
//! how it reports ([`super::sweep`], [`super::ablation`], [`super::transfer`]) is its own;
//! the summary over seeds is [`super::summary`].
//!
//! Resumable the same way for every study: a run whose folder has `test.json` is read, not
//! retrained; one with a `last.bpk` of an earlier epoch continues from it; with
//! `no_train` nothing trains and the unfinished runs are named. Seed `k` of a study is the
//! config's seed `+ k`, and every variant's config is loaded and validated before the
//! first run trains, so a bad variant fails in seconds, not after hours.
//!
//! The shape follows ultralytics' `engine/tuner.py`, whose one `Tuner` loop (change the
//! config, train, record the score in `tune_results.csv`, resume from that file) serves
//! every search; here a study lists its variants instead of mutating one.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::config::{self, Config, DeviceKind};
use crate::infer::checkpoint::Checkpoint;
use crate::train::smoke::smoke_config;
use crate::train::trainer::{train, TrainOptions};

/// The flags every study takes (`sweep`, `bench ablation`, `bench transfer`), flattened
/// into each one's own.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct StudyFlags {
    /// Override a config key in every run, e.g. --set train.epochs=20 (repeatable;
    /// applied before the study's own).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Write the runs and the report here (default: runs/<study>/<config name>/).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Train nothing: report from the runs already in the output folder and name the
    /// missing ones (a study split over several processes or cut short; `bench ablation`
    /// times every variant, with AP where its run finished).
    #[arg(long)]
    pub no_train: bool,
    /// No progress bars or per-epoch lines.
    #[arg(long)]
    pub quiet: bool,
}

impl StudyFlags {
    /// `--out`, or `runs/<study>/<config name>/`.
    pub fn out_or_default(&self, study: &str, config_name: &str) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| PathBuf::from("runs").join(study).join(config_name))
    }
}

/// `--variants a,b,c` as names (blanks dropped); none given means all.
pub fn variant_names(flag: &Option<String>) -> Vec<String> {
    flag.as_deref()
        .map(|v| {
            v.split(',')
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .collect()
        })
        .unwrap_or_default()
}

/// A named config variant of a study: its name (its folder and its row), what it changes
/// (for the report), and the `--set` overrides that make it.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    pub name: String,
    pub change: String,
    pub overrides: Vec<String>,
}

/// Where a study keeps a run: the folder below the study's output folder, from the
/// variant's name and the seed.
pub type Folder = fn(&str, u64) -> String;

/// What to train: configs × seeds, and how.
#[derive(Clone, Debug)]
pub struct Study {
    /// Names the study in progress lines and errors (`sweep`, `ablation`, `transfer`).
    pub name: &'static str,
    /// Config file or shipped config name.
    pub config: String,
    /// Overrides of every run, applied before the variant's own.
    pub overrides: Vec<String>,
    pub variants: Vec<Variant>,
    /// Runs per variant: the config's seed, seed + 1, …
    pub seeds: usize,
    pub folder: Folder,
    pub out: PathBuf,
    /// Train nothing: finished runs are scored, the others named.
    pub no_train: bool,
    /// Shrink every run to a smoke run (`train --smoke`).
    pub smoke: bool,
    pub device: Option<DeviceKind>,
    pub quiet: bool,
}

/// One run of a study: a variant's config with one seed, and its folder.
#[derive(Clone, Debug)]
pub struct Run {
    /// Index into [`Study::variants`].
    pub variant: usize,
    pub seed: u64,
    pub config: Config,
    /// Its folder below the study's output folder ([`Study::dir`]; how a report names a
    /// missing run).
    pub label: String,
}

/// Whether a run has finished training (its `test.json` is there) when it is scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    Finished,
    /// Left untrained by `no_train`.
    NotTrained,
}

/// What [`Study::run`] returns: the scores in run order, and the runs neither finished
/// nor scored (their labels).
#[derive(Clone, Debug)]
pub struct Outcome<S> {
    pub scores: Vec<S>,
    pub missing: Vec<String>,
}

impl Study {
    /// Prints `<study>: <line>` on stderr unless quiet.
    pub fn say(&self, line: &str) {
        if !self.quiet {
            eprintln!("{}: {line}", self.name);
        }
    }

    /// Every run's config, variant by variant and seed by seed, each loaded and validated
    /// as it will train.
    pub fn plan(&self) -> Result<Vec<Run>> {
        if self.seeds == 0 {
            bail!(
                "--seeds 0: every {} variant needs at least one seed",
                self.name
            );
        }
        if self.variants.is_empty() {
            bail!("the {} names no variant to run", self.name);
        }
        let mut runs = Vec::new();
        for (i, v) in self.variants.iter().enumerate() {
            let mut set = self.overrides.clone();
            set.extend(v.overrides.iter().cloned());
            let cfg = config::load(&self.config, &set)
                .with_context(|| format!("{} variant {}: {}", self.name, v.name, v.change))?;
            for k in 0..self.seeds as u64 {
                let seed = cfg.seed + k;
                let label = (self.folder)(&v.name, seed);
                let mut config = cfg.clone();
                config.seed = seed;
                runs.push(Run {
                    variant: i,
                    seed,
                    config,
                    label,
                });
            }
        }
        Ok(runs)
    }

    /// The folder of run `r`.
    pub fn dir(&self, r: &Run) -> PathBuf {
        self.out.join(&r.label)
    }

    /// The seeds of the study's runs: (first, last).
    pub fn seed_range(runs: &[Run]) -> (u64, u64) {
        let first = runs.iter().map(|r| r.seed).min().unwrap_or(0);
        (first, runs.iter().map(|r| r.seed).max().unwrap_or(first))
    }

    /// Trains every run that has not finished (unless `no_train`) and scores each with
    /// `score`, in order; a run `score` gives nothing for is missing when it did not
    /// finish. Fails on the first run that fails to train or score.
    pub fn run<S>(
        &self,
        runs: &[Run],
        mut score: impl FnMut(&Run, State) -> Result<Option<S>>,
    ) -> Result<Outcome<S>> {
        if !self.no_train {
            std::fs::create_dir_all(&self.out).with_context(|| {
                format!("cannot create {} folder {}", self.name, self.out.display())
            })?;
        }
        crate::train::interrupt::install();
        let mut out = Outcome {
            scores: Vec::new(),
            missing: Vec::new(),
        };
        for (i, r) in runs.iter().enumerate() {
            let dir = self.dir(r);
            let state = if dir.join("test.json").exists() {
                self.say(&format!("{} done, reading it", dir.display()));
                State::Finished
            } else if self.no_train {
                State::NotTrained
            } else {
                self.train_run(r, &format!("{}/{}", i + 1, runs.len()))?;
                State::Finished
            };
            match score(r, state)? {
                Some(s) => out.scores.push(s),
                None if state == State::NotTrained => out.missing.push(r.label.clone()),
                None => {}
            }
        }
        Ok(out)
    }

    /// Trains one run into its folder, resuming its `last.bpk` when that stopped early.
    fn train_run(&self, r: &Run, which: &str) -> Result<()> {
        let v = &self.variants[r.variant];
        let dir = self.dir(r);
        let resume = resumable(&dir, &r.config, self.smoke);
        self.say(&format!(
            "run {which}: {}, seed {}{} → {}",
            v.name,
            r.seed,
            if resume { " (resuming)" } else { "" },
            dir.display()
        ));
        let opts = TrainOptions {
            run_dir: Some(dir.clone()),
            resume,
            smoke: self.smoke,
            device: self.device,
            quiet: self.quiet,
            exist_ok: false,
        };
        train(r.config.clone(), &opts).with_context(|| {
            format!(
                "{} variant {}, seed {} ({})",
                self.name,
                v.name,
                r.seed,
                dir.display()
            )
        })?;
        Ok(())
    }

    /// "Config `X` with `--set a --set b`" (the overrides of every run, when any).
    pub fn config_clause(&self) -> String {
        format!("Config `{}`{}", self.config, with_set(&self.overrides))
    }
}

/// " with `--set a --set b`", or nothing without overrides.
pub fn with_set(overrides: &[String]) -> String {
    if overrides.is_empty() {
        String::new()
    } else {
        format!(" with `--set {}`", overrides.join(" --set "))
    }
}

/// The report's note on runs left untrained, or `None` when every run finished.
pub fn not_trained(missing: &[String]) -> Option<String> {
    (!missing.is_empty()).then(|| {
        format!(
            "Not trained (left out; the runs column counts the finished ones): {}.",
            missing.join(", ")
        )
    })
}

/// Whether `dir` holds a `last.bpk` of an epoch before the run's last (smoke runs stop
/// at the smoke schedule's last epoch).
fn resumable(dir: &Path, cfg: &Config, smoke: bool) -> bool {
    let epochs = if smoke {
        let mut c = cfg.clone();
        smoke_config(&mut c);
        c.train.epochs
    } else {
        cfg.train.epochs
    };
    let last = dir.join("last.bpk");
    last.exists() && Checkpoint::load(&last).is_ok_and(|c| c.header.epoch < epochs)
}

/// The variants named in `only` (all when empty), in `all`'s order; an unknown name is an
/// error listing the known ones (`note` is added to that list, e.g. why one is absent).
pub fn choose(study: &str, all: Vec<Variant>, only: &[String], note: &str) -> Result<Vec<Variant>> {
    for n in only {
        if !all.iter().any(|v| &v.name == n) {
            let names: Vec<&str> = all.iter().map(|v| v.name.as_str()).collect();
            bail!(
                "unknown {study} variant {n:?} (known: {}{note})",
                names.join(", ")
            );
        }
    }
    Ok(all
        .into_iter()
        .filter(|v| only.is_empty() || only.contains(&v.name))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn variant(name: &str, overrides: &[&str]) -> Variant {
        Variant {
            name: name.into(),
            change: format!("{name}'s change"),
            overrides: overrides.iter().map(|s| s.to_string()).collect(),
        }
    }

    fn study(variants: Vec<Variant>, seeds: usize) -> Study {
        Study {
            name: "test study",
            config: "quickstart.toml".into(),
            overrides: vec!["seed=5".into()],
            variants,
            seeds,
            folder: |v, s| format!("{v}/seed{s}"),
            out: PathBuf::from("out"),
            no_train: true,
            smoke: false,
            device: None,
            quiet: true,
        }
    }

    #[test]
    fn plan_is_variants_times_seeds_from_the_config_seed() {
        let s = study(
            vec![
                variant("a", &[]),
                variant("b", &["train.fliplr=0.0", "seed=9"]),
            ],
            2,
        );
        let runs = s.plan().unwrap();
        let got: Vec<(usize, u64, &str)> = runs
            .iter()
            .map(|r| (r.variant, r.seed, r.label.as_str()))
            .collect();
        // A variant's own overrides come last (here one moves its seed).
        assert_eq!(
            got,
            [
                (0, 5, "a/seed5"),
                (0, 6, "a/seed6"),
                (1, 9, "b/seed9"),
                (1, 10, "b/seed10")
            ]
        );
        assert_eq!(runs[2].config.train.fliplr, 0.0);
        assert_eq!(runs[3].config.seed, 10);
        assert_eq!(s.dir(&runs[1]), Path::new("out/a/seed6"));
        assert_eq!(Study::seed_range(&runs), (5, 10));
    }

    #[test]
    fn plan_rejects_no_seeds_and_names_the_bad_variant() {
        let e = study(vec![variant("a", &[])], 0).plan().unwrap_err();
        assert!(format!("{e:#}").contains("--seeds 0"), "{e:#}");
        let e = study(
            vec![variant("a", &[]), variant("bad", &["train.nope=1"])],
            1,
        )
        .plan()
        .unwrap_err();
        let e = format!("{e:#}");
        assert!(e.contains("test study variant bad: bad's change"), "{e}");
    }

    #[test]
    fn untrained_runs_without_a_score_are_missing_in_order() {
        let dir = std::env::temp_dir().join(format!("ct-runner-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut s = study(vec![variant("a", &[]), variant("b", &[])], 2);
        s.out = dir.clone();
        let runs = s.plan().unwrap();
        std::fs::create_dir_all(s.dir(&runs[1])).unwrap();
        std::fs::write(s.dir(&runs[1]).join("test.json"), "{}").unwrap();
        let mut seen = Vec::new();
        let out = s
            .run(&runs, |r, state| {
                seen.push((r.label.clone(), state));
                // The study scores finished runs, and one unfinished run anyway.
                Ok((state == State::Finished || r.variant == 1 && r.seed == 6).then_some(r.seed))
            })
            .unwrap();
        assert_eq!(out.scores, [6, 6]);
        assert_eq!(out.missing, ["a/seed5", "b/seed5"]);
        assert_eq!(seen.len(), 4);
        assert_eq!(seen[1], ("a/seed6".to_string(), State::Finished));
        assert!(!dir.join("a/seed5").exists(), "no_train must not train");
        assert_eq!(
            not_trained(&out.missing).unwrap(),
            "Not trained (left out; the runs column counts the finished ones): a/seed5, b/seed5."
        );
        assert_eq!(not_trained(&[]), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn variant_names_drop_blanks_and_out_defaults_per_study() {
        assert_eq!(variant_names(&Some(" a,,b ,".into())), ["a", "b"]);
        assert!(variant_names(&None).is_empty());
        let f = StudyFlags::default();
        assert_eq!(f.out_or_default("sweep", "q"), Path::new("runs/sweep/q"));
        let f = StudyFlags {
            out: Some("x".into()),
            ..f
        };
        assert_eq!(f.out_or_default("sweep", "q"), Path::new("x"));
    }

    #[test]
    fn choose_keeps_order_and_lists_the_known_names() {
        let all = vec![variant("a", &[]), variant("b", &[]), variant("c", &[])];
        let got = choose("x", all.clone(), &["c".into(), "a".into()], "").unwrap();
        assert_eq!(
            got.iter().map(|v| v.name.as_str()).collect::<Vec<_>>(),
            ["a", "c"]
        );
        assert_eq!(choose("x", all.clone(), &[], "").unwrap(), all);
        let e = choose("x", all, &["d".into()], "; d is off")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "unknown x variant \"d\" (known: a, b, c; d is off)");
    }
}
