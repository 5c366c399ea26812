//! `chicktrain bench transfer`: which parts of the recipe carry over to images chicktrain
//! did not render. The base config and one variant per domain-randomisation group turned
//! off (`data.randomize.<group> = false`) and per augmentation turned off (each nonzero
//! augmentation key set to 0) are trained with N seeds each at the same optimiser steps
//! (only those keys change, so `train.epochs` and `train.steps_per_epoch` are the
//! base's), and every run's `best.bpk` is scored on an external set (`--data-eval`, e.g.
//! the cross-domain set, all images test) through the code path of `chicktrain eval
//! --checkpoint --data`.
//!
//! Output folder (`runs/transfer/<config name>/` or `--out`): `<variant>/seed<S>/` run
//! folders, each with `transfer.json` (its score on the external set, reused unless the
//! set or the checkpoint epoch changed), `runs.csv` (one row per run), `transfer.csv` /
//! `transfer.md` (mean ± sample std over seeds of bbox AP, segm AP, AP50, AP75, the
//! change of segm AP against the base, and the optimiser steps per run). Resumable like
//! `sweep`: finished runs are read, a stopped run continues from `last.bpk`,
//! `--no-train` reports what finished and names the rest.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::config::Randomize;
use crate::config::{self, Config, DeviceKind};
use crate::eval::report::{stat_cells, stat_columns, Table};
use crate::infer::checkpoint::Checkpoint;
use crate::infer::validate::{score_checkpoint, SplitName};
use crate::train::run_files::{self, IouStats};
use crate::train::trainer::{train, TrainOptions};
use crate::util::stats::mean_std;

/// One variant: its name (its folder), what it changes, the `--set` overrides.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferVariant {
    pub name: String,
    pub change: String,
    pub overrides: Vec<String>,
}

/// The augmentation keys a variant can turn off: (variant suffix, key, value that turns
/// it off, whether `cfg` has it on).
fn augmentations(cfg: &Config) -> [(&'static str, &'static str, &'static str, bool); 8] {
    let t = &cfg.train;
    [
        ("fliplr", "train.fliplr", "0.0", t.fliplr > 0.0),
        (
            "hsv",
            "train.hsv",
            "[0.0, 0.0, 0.0]",
            t.hsv.iter().any(|&g| g > 0.0),
        ),
        ("degrees", "train.degrees", "0.0", t.degrees > 0.0),
        ("scale", "train.scale", "0.0", t.scale > 0.0),
        ("translate", "train.translate", "0.0", t.translate > 0.0),
        ("flipud", "train.flipud", "0.0", t.flipud > 0.0),
        ("mosaic", "train.mosaic", "0.0", t.mosaic > 0.0),
        ("copy-paste", "train.copy_paste", "0.0", t.copy_paste > 0.0),
    ]
}

/// `base`, then `no-<group>` for each randomisation group `cfg` has on (only when it
/// trains on synthetic images: the groups change nothing else), then `no-<aug>` for each
/// augmentation it has on.
pub fn variants(cfg: &Config) -> Result<Vec<TransferVariant>> {
    let mut v = vec![TransferVariant {
        name: "base".into(),
        change: "the config as given".into(),
        overrides: Vec::new(),
    }];
    if cfg.data.synthetic > 0 {
        let r: Randomize = cfg.data.randomize;
        for g in Randomize::GROUPS {
            if r.with(g, false)? != r {
                v.push(TransferVariant {
                    name: format!("no-{g}"),
                    change: format!("domain-randomisation group `{g}` off"),
                    overrides: vec![format!("data.randomize.{g}=false")],
                });
            }
        }
    }
    for (name, key, off, on) in augmentations(cfg) {
        if on {
            v.push(TransferVariant {
                name: format!("no-{name}"),
                change: format!("`{key} = {off}`"),
                overrides: vec![format!("{key}={off}")],
            });
        }
    }
    Ok(v)
}

/// The variants named in `only` (all when empty), in [`variants`] order; an unknown name
/// is an error listing the known ones.
pub fn choose(all: Vec<TransferVariant>, only: &[String]) -> Result<Vec<TransferVariant>> {
    for n in only {
        if !all.iter().any(|v| &v.name == n) {
            let names: Vec<&str> = all.iter().map(|v| v.name.as_str()).collect();
            bail!(
                "unknown transfer variant {n:?} for this config (known: {}; a group or augmentation that is already off has no variant)",
                names.join(", ")
            );
        }
    }
    Ok(all
        .into_iter()
        .filter(|v| only.is_empty() || only.contains(&v.name))
        .collect())
}

/// Options of `bench transfer`.
#[derive(Clone, Debug)]
pub struct TransferOptions {
    pub config: String,
    /// Data config of the external set every run is scored on (its test split).
    pub data_eval: String,
    pub seeds: usize,
    /// Variant names to run (all when empty).
    pub only: Vec<String>,
    /// `--set` overrides applied to every run, before the variant's own.
    pub overrides: Vec<String>,
    pub out: PathBuf,
    pub no_train: bool,
    pub device: Option<DeviceKind>,
    pub quiet: bool,
}

/// `<run>/transfer.json`: a run's `best.bpk` scored on the external set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransferEval {
    pub bbox: IouStats,
    /// The `--data-eval` config it was scored on.
    pub data: String,
    /// Epoch of the scored `best.bpk`.
    pub epoch: usize,
    pub images: usize,
    pub segm: IouStats,
}

/// One finished run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunScore {
    pub variant: String,
    pub seed: u64,
    pub bbox: [f64; 12],
    pub segm: [f64; 12],
    /// Optimiser steps of the whole run (`metrics.jsonl`).
    pub steps: usize,
}

/// The score of `dir`'s `best.bpk` on `data`: `transfer.json` when it is for this set
/// and this checkpoint epoch, else evaluated now and written there.
fn score_run(dir: &Path, data: &str, device: Option<DeviceKind>) -> Result<TransferEval> {
    let cached = dir.join("transfer.json");
    let epoch = run_files::read_test(dir)?.epoch;
    if let Ok(text) = std::fs::read_to_string(&cached) {
        if let Ok(t) = serde_json::from_str::<TransferEval>(&text) {
            if t.data == data && t.epoch == epoch {
                return Ok(t);
            }
        }
    }
    let s = score_checkpoint(
        &dir.join("best.bpk"),
        SplitName::Test,
        Some(data),
        device,
        None,
        false,
    )
    .with_context(|| format!("scoring {} on {data}", dir.join("best.bpk").display()))?;
    let t = TransferEval {
        bbox: IouStats {
            stats: s.stats.bbox,
        },
        data: data.to_string(),
        epoch: s.epoch,
        images: s.images,
        segm: IouStats {
            stats: s.stats.segm,
        },
    };
    crate::util::write_atomic(&cached, serde_json::to_string_pretty(&t)?.as_bytes())?;
    Ok(t)
}

/// One row per variant: (name, runs, [bbox AP, segm AP, segm AP50, segm AP75] as
/// (mean, sample std), mean optimiser steps).
pub type Summary = Vec<(String, usize, [(f64, f64); 4], f64)>;

/// Mean ± sample std per variant, in the order the variants first appear in `runs`.
pub fn summarise(runs: &[RunScore]) -> Summary {
    let mut names: Vec<&str> = Vec::new();
    for r in runs {
        if !names.contains(&r.variant.as_str()) {
            names.push(&r.variant);
        }
    }
    names
        .into_iter()
        .map(|n| {
            let rs: Vec<&RunScore> = runs.iter().filter(|r| r.variant == n).collect();
            let col = |f: &dyn Fn(&RunScore) -> f64| {
                mean_std(&rs.iter().map(|r| f(r)).collect::<Vec<_>>())
            };
            let ms = [
                col(&|r| r.bbox[0]),
                col(&|r| r.segm[0]),
                col(&|r| r.segm[1]),
                col(&|r| r.segm[2]),
            ];
            let steps = col(&|r| r.steps as f64).0;
            (n.to_string(), rs.len(), ms, steps)
        })
        .collect()
}

/// Writes `runs.csv`, `transfer.csv` and `transfer.md` into `out`; returns the markdown.
pub fn write_report(out: &Path, runs: &[RunScore], preamble: &str) -> Result<String> {
    let mut rc = Table::new(
        ["variant", "seed", "steps"]
            .into_iter()
            .map(String::from)
            .chain(stat_columns()),
    );
    for r in runs {
        let mut row = vec![r.variant.clone(), r.seed.to_string(), r.steps.to_string()];
        row.extend(stat_cells(&r.bbox, &r.segm));
        rc.push(row);
    }
    crate::util::write_atomic(&out.join("runs.csv"), rc.to_csv().as_bytes())?;

    let s = summarise(runs);
    let base = s.iter().find(|r| r.0 == "base").map(|r| r.2[1].0);
    let names = ["bbox AP", "segm AP", "segm AP50", "segm AP75"];
    let mut csv = Table::new(
        ["variant", "runs", "steps"]
            .into_iter()
            .map(String::from)
            .chain(names.iter().flat_map(|n| {
                let n = n.replace(' ', "_");
                [format!("{n}_mean"), format!("{n}_std")]
            }))
            .chain(["segm_AP_delta_vs_base".to_string()]),
    );
    let mut md = Table::new(
        ["variant", "runs", "optimiser steps"]
            .into_iter()
            .chain(names)
            .chain(["Δ segm AP vs base"]),
    );
    for (n, k, ms, steps) in &s {
        let delta = base.map(|b| ms[1].0 - b);
        let mut row = vec![n.clone(), k.to_string(), format!("{steps:.0}")];
        row.extend(
            ms.iter()
                .flat_map(|(m, sd)| [format!("{m:.4}"), format!("{sd:.4}")]),
        );
        row.push(delta.map_or(String::new(), |d| format!("{d:.4}")));
        csv.push(row);
        let mut row = vec![n.clone(), k.to_string(), format!("{steps:.0}")];
        row.extend(ms.iter().map(|(m, sd)| {
            if *k > 1 {
                format!("{m:.3} ± {sd:.3}")
            } else {
                format!("{m:.3}")
            }
        }));
        row.push(match delta {
            Some(d) if n != "base" => format!("{d:+.3}"),
            _ => String::new(),
        });
        md.push(row);
    }
    crate::util::write_atomic(&out.join("transfer.csv"), csv.to_csv().as_bytes())?;
    let mut steps: Vec<usize> = runs.iter().map(|r| r.steps).collect();
    steps.sort_unstable();
    steps.dedup();
    let compute = match steps.as_slice() {
        [one] => format!("Every run took {one} optimiser steps (equal compute)."),
        many => format!(
            "**The runs differ in optimiser steps ({}): compare at equal compute by setting `train.steps_per_epoch`.**",
            many.iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let text = format!(
        "# Transfer ablation\n\n{preamble}\n\n{compute}\n\n{}",
        md.to_markdown()
    );
    crate::util::write_atomic(&out.join("transfer.md"), text.as_bytes())?;
    Ok(text)
}

/// `chicktrain bench transfer`.
pub fn transfer(o: &TransferOptions) -> Result<String> {
    if o.seeds == 0 {
        bail!("--seeds 0: every variant needs at least one seed");
    }
    let base = config::load(&o.config, &o.overrides)?;
    // Fail before any training when the external set cannot be loaded.
    config::load(&o.data_eval, &[]).with_context(|| format!("--data-eval {}", o.data_eval))?;
    let chosen = choose(variants(&base)?, &o.only)?;
    if !o.no_train {
        std::fs::create_dir_all(&o.out)
            .with_context(|| format!("cannot create {}", o.out.display()))?;
    }
    crate::train::interrupt::install();
    let say = |s: String| {
        if !o.quiet {
            eprintln!("{s}");
        }
    };
    let (mut runs, mut missing) = (Vec::new(), Vec::new());
    let total = chosen.len() * o.seeds;
    for v in &chosen {
        for k in 0..o.seeds as u64 {
            let seed = base.seed + k;
            let dir = o.out.join(&v.name).join(format!("seed{seed}"));
            let mut set = o.overrides.clone();
            set.extend(v.overrides.iter().cloned());
            set.push(format!("seed={seed}"));
            let cfg = config::load(&o.config, &set)
                .with_context(|| format!("transfer variant {}", v.name))?;
            if !dir.join("test.json").exists() {
                if o.no_train {
                    missing.push(format!("{}/seed{seed}", v.name));
                    continue;
                }
                train_run(o, &cfg, &dir, &format!("{}/{total}", runs.len() + 1))
                    .with_context(|| format!("transfer variant {} ({})", v.name, dir.display()))?;
            }
            say(format!(
                "transfer: scoring {} on {}",
                dir.display(),
                o.data_eval
            ));
            let t = score_run(&dir, &o.data_eval, o.device)?;
            runs.push(RunScore {
                variant: v.name.clone(),
                seed,
                bbox: t.bbox.stats,
                segm: t.segm.stats,
                steps: run_files::total_steps(&dir)?,
            });
        }
    }
    if runs.is_empty() {
        bail!(
            "--no-train: no finished run (a folder with test.json) under {} for variants {}",
            o.out.display(),
            chosen
                .iter()
                .map(|v| v.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let mut pre = format!(
        "Config `{}`{}; {} seed(s) per variant (seed {}…{}); `best.bpk` of each run (best val segm AP on its own split) scored on every image of `{}` (`chicktrain eval --checkpoint RUN/best.bpk --data {} --split test`). Variants:\n\n{}",
        o.config,
        if o.overrides.is_empty() {
            String::new()
        } else {
            format!(" with `--set {}`", o.overrides.join(" --set "))
        },
        o.seeds,
        base.seed,
        base.seed + o.seeds as u64 - 1,
        o.data_eval,
        o.data_eval,
        chosen
            .iter()
            .map(|v| format!("- `{}`: {}", v.name, v.change))
            .collect::<Vec<_>>()
            .join("\n")
    );
    if !missing.is_empty() {
        pre.push_str(&format!(
            "\n\nNot trained (left out; the runs column counts the finished ones): {}.",
            missing.join(", ")
        ));
    }
    let md = write_report(&o.out, &runs, &pre)?;
    Ok(format!(
        "{md}\nwrote transfer.md, transfer.csv, runs.csv in {}",
        o.out.display()
    ))
}

/// Trains one run into `dir`, resuming its `last.bpk` when that stopped early.
fn train_run(o: &TransferOptions, cfg: &Config, dir: &Path, which: &str) -> Result<()> {
    let last = dir.join("last.bpk");
    let resume =
        last.exists() && Checkpoint::load(&last).is_ok_and(|c| c.header.epoch < cfg.train.epochs);
    if !o.quiet {
        eprintln!(
            "transfer: run {which}{} → {}",
            if resume { " (resuming)" } else { "" },
            dir.display()
        );
    }
    let opts = TrainOptions {
        run_dir: Some(dir.to_path_buf()),
        resume,
        smoke: false,
        device: o.device,
        quiet: o.quiet,
        exist_ok: false,
    };
    train(cfg.clone(), &opts)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[TransferVariant]) -> Vec<&str> {
        v.iter().map(|v| v.name.as_str()).collect()
    }

    #[test]
    fn one_variant_per_group_and_per_augmentation_that_is_on() {
        let q = config::load("quickstart.toml", &[]).unwrap();
        let v = variants(&q).unwrap();
        assert_eq!(
            names(&v),
            [
                "base",
                "no-carcass",
                "no-physics",
                "no-fliplr",
                "no-hsv",
                "no-degrees",
                "no-scale",
                "no-flipud",
                "no-copy-paste"
            ]
        );
        let ov: Vec<String> = [
            "train.degrees=0",
            "train.mosaic=0.5",
            "train.copy_paste=0.3",
            "data.randomize.lighting=true",
            "data.randomize.scene=true",
            "data.randomize.carcass=false",
        ]
        .map(String::from)
        .to_vec();
        let c = config::load("quickstart.toml", &ov).unwrap();
        let v = variants(&c).unwrap();
        let n = names(&v);
        assert!(n.contains(&"no-mosaic") && n.contains(&"no-copy-paste"));
        assert!(n.contains(&"no-lighting") && n.contains(&"no-scene"));
        assert!(!n.contains(&"no-carcass") && !n.contains(&"no-degrees"));
        // Every variant is a valid config and turns its key off.
        for x in &v {
            let mut set = ov.clone();
            set.extend(x.overrides.iter().cloned());
            let cfg = config::load("quickstart.toml", &set).unwrap();
            if x.name == "no-mosaic" {
                assert_eq!(cfg.train.mosaic, 0.0);
            }
            if x.name == "no-scene" {
                assert!(!cfg.data.randomize.scene);
            }
            if x.name == "no-hsv" {
                assert_eq!(cfg.train.hsv, [0.0; 3]);
            }
        }
        // Without synthetic images the groups have nothing to change.
        let r = config::load("quickstart.toml", &["data.synthetic=0".into()]).unwrap();
        assert_eq!(
            names(&variants(&r).unwrap()),
            [
                "base",
                "no-fliplr",
                "no-hsv",
                "no-degrees",
                "no-scale",
                "no-flipud",
                "no-copy-paste"
            ]
        );
    }

    #[test]
    fn choose_keeps_order_and_names_unknown_variants() {
        let q = config::load("quickstart.toml", &[]).unwrap();
        let v = choose(
            variants(&q).unwrap(),
            &["no-hsv".into(), "base".into(), "no-physics".into()],
        )
        .unwrap();
        assert_eq!(names(&v), ["base", "no-physics", "no-hsv"]);
        let e = choose(variants(&q).unwrap(), &["no-mosaic".into()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"no-mosaic\"") && e.contains("no-fliplr"),
            "{e}"
        );
    }

    fn run(variant: &str, seed: u64, ap: f64, steps: usize) -> RunScore {
        let mut s = [0.0; 12];
        s[..3].copy_from_slice(&[ap, ap + 0.2, ap + 0.1]);
        RunScore {
            variant: variant.into(),
            seed,
            bbox: s.map(|v| v + 0.05),
            segm: s,
            steps,
        }
    }

    #[test]
    fn report_is_mean_and_sample_std_per_variant_with_steps_and_delta() {
        let dir = std::env::temp_dir().join(format!("ct-transfer-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let runs = [
            run("base", 0, 0.4, 100),
            run("base", 1, 0.6, 100),
            run("no-mosaic", 0, 0.3, 100),
            run("no-mosaic", 1, 0.3, 100),
        ];
        let s = summarise(&runs);
        assert_eq!(s.len(), 2);
        assert!((s[0].2[1].0 - 0.5).abs() < 1e-12);
        assert!((s[0].2[1].1 - 0.1414213562373095).abs() < 1e-12);
        assert!((s[0].2[0].0 - 0.55).abs() < 1e-12);
        assert_eq!((s[1].2[1].1, s[1].3), (0.0, 100.0));
        let md = write_report(&dir, &runs, "protocol").unwrap();
        assert!(md.contains("Every run took 100 optimiser steps"), "{md}");
        assert!(
            md.contains("| no-mosaic | 2 | 100 | 0.350 ± 0.000 | 0.300 ± 0.000 | 0.500 ± 0.000 | 0.400 ± 0.000 | -0.200 |"),
            "{md}"
        );
        assert!(
            md.contains("| base | 2 | 100 | 0.550 ± 0.141 | 0.500 ± 0.141 |"),
            "{md}"
        );
        let csv = std::fs::read_to_string(dir.join("transfer.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert!(lines[0].starts_with("variant,runs,steps,bbox_AP_mean,bbox_AP_std,segm_AP_mean"));
        assert!(lines[2].ends_with(",-0.2000"), "{}", lines[2]);
        let rc = std::fs::read_to_string(dir.join("runs.csv")).unwrap();
        assert_eq!(rc.lines().count(), 5);
        // Unequal steps are called out.
        let md = write_report(
            &dir,
            &[run("base", 0, 0.4, 100), run("no-hsv", 0, 0.4, 90)],
            "p",
        )
        .unwrap();
        assert!(md.contains("differ in optimiser steps (90, 100)"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn trains_scores_on_the_external_set_and_rereports_without_training() {
        let dir = std::env::temp_dir().join(format!("ct-transfer-e2e-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let cache = dir.join("cache");
        // The external set: other proxy-real renders (seed 7), every image test.
        let eval_cfg = dir.join("external.toml");
        std::fs::write(
            &eval_cfg,
            format!(
                "name = \"external\"\nseed = 7\n[data]\nsplit = [0.0, 0.0]\nimage_size = 64\ncrop = 64\ncache = \"{}\"\n[data.real]\nkind = \"proxy\"\ncount = 3\n",
                cache.display()
            ),
        )
        .unwrap();
        let o = TransferOptions {
            config: "quickstart.toml".into(),
            data_eval: eval_cfg.display().to_string(),
            seeds: 1,
            only: vec!["base".into(), "no-fliplr".into()],
            overrides: [
                format!("data.cache=\"{}\"", cache.display()),
                "data.image_size=64".into(),
                "data.crop=64".into(),
                "data.real.count=4".into(),
                "data.synthetic=0".into(),
                "train.epochs=1".into(),
                "train.batch=2".into(),
                "train.steps_per_epoch=2".into(),
            ]
            .to_vec(),
            out: dir.join("out"),
            no_train: false,
            device: None,
            quiet: true,
        };
        let md = transfer(&o).unwrap();
        assert!(md.contains("Every run took 2 optimiser steps"), "{md}");
        assert!(
            md.contains("| base | 1 | 2 |") && md.contains("| no-fliplr | 1 | 2 |"),
            "{md}"
        );
        let t: TransferEval = serde_json::from_str(
            &std::fs::read_to_string(dir.join("out/base/seed0/transfer.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(t.images, 3);
        assert_eq!(t.data, o.data_eval);
        // --no-train reports the same from the run folders; a variant never trained is
        // named as missing.
        let again = transfer(&TransferOptions {
            no_train: true,
            only: vec!["base".into(), "no-fliplr".into(), "no-hsv".into()],
            ..o.clone()
        })
        .unwrap();
        assert!(
            again.contains("Not trained") && again.contains("no-hsv/seed0"),
            "{again}"
        );
        let table = |s: &str| {
            s.lines()
                .filter(|l| l.starts_with("| base"))
                .collect::<Vec<_>>()
                .join("\n")
        };
        assert_eq!(table(&again), table(&md));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
