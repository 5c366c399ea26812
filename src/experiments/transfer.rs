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
//! change of segm AP against the base, and the optimiser steps per run). A study on
//! [`super::runner`], resumable like every study there: finished runs are read, a stopped
//! run continues from `last.bpk`, `--no-train` reports what finished and names the rest.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::config::Randomize;
use crate::config::{self, Config, DeviceKind};
use crate::eval::report::Table;
use crate::infer::validate::{score_checkpoint, SplitName};
use crate::train::run_files::{self, IouStats};

use super::runner::{choose, not_trained, variant_names, State, Study, StudyFlags, Variant};
use super::summary::{group, md_cell, mean_std_cells, mean_std_columns, runs_table, Group};

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
pub fn variants(cfg: &Config) -> Result<Vec<Variant>> {
    let mut v = vec![Variant {
        name: "base".into(),
        change: "the config as given".into(),
        overrides: Vec::new(),
    }];
    if cfg.data.synthetic > 0 {
        let r: Randomize = cfg.data.randomize;
        for g in Randomize::GROUPS {
            if r.with(g, false)? != r {
                v.push(Variant {
                    name: format!("no-{g}"),
                    change: format!("domain-randomisation group `{g}` off"),
                    overrides: vec![format!("data.randomize.{g}=false")],
                });
            }
        }
    }
    for (name, key, off, on) in augmentations(cfg) {
        if on {
            v.push(Variant {
                name: format!("no-{name}"),
                change: format!("`{key} = {off}`"),
                overrides: vec![format!("{key}={off}")],
            });
        }
    }
    Ok(v)
}

/// `bench transfer`'s flags.
#[derive(Clone, Debug, clap::Args)]
pub struct TransferOptions {
    /// Base config file, or the name of a shipped config.
    #[arg(long)]
    pub config: String,
    /// Data config of the set to score on, every image test (e.g.
    /// bench/crossdomain/crossdomain.toml).
    #[arg(long)]
    pub data_eval: String,
    /// Seeds per variant (config seed, seed + 1, …).
    #[arg(long, default_value_t = 1)]
    pub seeds: usize,
    /// Comma-separated subset, e.g. base,no-lighting,no-mosaic (default: all of
    /// base, no-<group> per randomisation group on, no-<aug> per augmentation on).
    #[arg(long)]
    pub variants: Option<String>,
    #[command(flatten)]
    pub study: StudyFlags,
    /// Override the configs' device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long)]
    pub device: Option<DeviceKind>,
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

/// The summary's metrics, each (mean, sample std) per variant.
const METRICS: [&str; 4] = ["bbox AP", "segm AP", "segm AP50", "segm AP75"];

/// One row per variant, in the order the variants first appear in `runs`: [`METRICS`]
/// then the optimiser steps, each as (mean, sample std).
pub fn summarise(runs: &[RunScore]) -> Vec<Group<String>> {
    group(
        runs,
        |r| r.variant.clone(),
        |r| vec![r.bbox[0], r.segm[0], r.segm[1], r.segm[2], r.steps as f64],
    )
}

/// Writes `runs.csv`, `transfer.csv` and `transfer.md` into `out`; returns the markdown.
pub fn write_report(out: &Path, runs: &[RunScore], preamble: &str) -> Result<String> {
    let rc = runs_table(
        &["variant", "seed", "steps"],
        runs.iter().map(|r| {
            let ids = vec![r.variant.clone(), r.seed.to_string(), r.steps.to_string()];
            (ids, &r.bbox, &r.segm)
        }),
    );
    crate::util::write_atomic(&out.join("runs.csv"), rc.to_csv().as_bytes())?;

    let s = summarise(runs);
    let base = s.iter().find(|g| g.key == "base").map(|g| g.columns[1].0);
    let mut csv = Table::new(
        ["variant", "runs", "steps"]
            .into_iter()
            .map(String::from)
            .chain(mean_std_columns(&METRICS))
            .chain(["segm_AP_delta_vs_base".to_string()]),
    );
    let mut md = Table::new(
        ["variant", "runs", "optimiser steps"]
            .into_iter()
            .chain(METRICS)
            .chain(["Δ segm AP vs base"]),
    );
    for g in &s {
        let (n, k, ms, steps) = (&g.key, g.runs, &g.columns[..4], g.columns[4].0);
        let delta = base.map(|b| ms[1].0 - b);
        let mut row = vec![n.clone(), k.to_string(), format!("{steps:.0}")];
        row.extend(mean_std_cells(ms));
        row.push(delta.map_or(String::new(), |d| format!("{d:.4}")));
        csv.push(row);
        let mut row = vec![n.clone(), k.to_string(), format!("{steps:.0}")];
        row.extend(ms.iter().map(|&m| md_cell(m, k)));
        row.push(match delta {
            Some(d) if n != "base" => format!("{d:+.3}"),
            _ => String::new(),
        });
        md.push(row);
    }
    crate::util::write_atomic(&out.join("transfer.csv"), csv.to_csv().as_bytes())?;
    let text = format!(
        "# Transfer ablation\n\n{preamble}\n\n{}\n\n{}",
        compute_note(runs),
        md.to_markdown()
    );
    crate::util::write_atomic(&out.join("transfer.md"), text.as_bytes())?;
    Ok(text)
}

/// Whether every run took the same optimiser steps, in bold when they differ.
fn compute_note(runs: &[RunScore]) -> String {
    let mut steps: Vec<usize> = runs.iter().map(|r| r.steps).collect();
    steps.sort_unstable();
    steps.dedup();
    match steps.as_slice() {
        [one] => format!("Every run took {one} optimiser steps (equal compute)."),
        many => format!(
            "**The runs differ in optimiser steps ({}): compare at equal compute by setting `train.steps_per_epoch`.**",
            many.iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The transfer ablation as a study: the chosen variants × seeds, folders
/// `<variant>/seed<S>/`.
fn study(o: &TransferOptions) -> Result<Study> {
    let base = config::load(&o.config, &o.study.overrides)?;
    // Fail before any training when the external set cannot be loaded.
    config::load(&o.data_eval, &[]).with_context(|| format!("--data-eval {}", o.data_eval))?;
    Ok(Study {
        name: "transfer",
        config: o.config.clone(),
        variants: choose(
            "transfer",
            variants(&base)?,
            &variant_names(&o.variants),
            "; for this config, a group or augmentation that is already off has no variant",
        )?,
        seeds: o.seeds,
        folder: |v, seed| format!("{v}/seed{seed}"),
        out: o.study.out_or_default("transfer", &base.name),
        overrides: o.study.overrides.clone(),
        no_train: o.study.no_train,
        smoke: false,
        device: o.device,
        quiet: o.study.quiet,
    })
}

/// `chicktrain bench transfer`.
pub fn transfer(o: &TransferOptions) -> Result<String> {
    let study = study(o)?;
    let runs = study.plan()?;
    let done = study.run(&runs, |r, state| {
        if state == State::NotTrained {
            return Ok(None);
        }
        let dir = study.dir(r);
        study.say(&format!("scoring {} on {}", dir.display(), o.data_eval));
        let t = score_run(&dir, &o.data_eval, o.device)?;
        Ok(Some(RunScore {
            variant: study.variants[r.variant].name.clone(),
            seed: r.seed,
            bbox: t.bbox.stats,
            segm: t.segm.stats,
            steps: run_files::total_steps(&dir)?,
        }))
    })?;
    if done.scores.is_empty() {
        bail!(
            "--no-train: no finished run (a folder with test.json) under {} for variants {}",
            study.out.display(),
            study
                .variants
                .iter()
                .map(|v| v.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let (first, last) = Study::seed_range(&runs);
    let mut pre = format!(
        "{}; {} seed(s) per variant (seed {first}…{last}); `best.bpk` of each run (best val segm AP on its own split) scored on every image of `{}` (`chicktrain eval --checkpoint RUN/best.bpk --data {} --split test`). Variants:\n\n{}",
        study.config_clause(),
        o.seeds,
        o.data_eval,
        o.data_eval,
        study
            .variants
            .iter()
            .map(|v| format!("- `{}`: {}", v.name, v.change))
            .collect::<Vec<_>>()
            .join("\n")
    );
    if let Some(note) = not_trained(&done.missing) {
        pre.push_str("\n\n");
        pre.push_str(&note);
    }
    let md = write_report(&study.out, &done.scores, &pre)?;
    Ok(format!(
        "{md}\nwrote transfer.md, transfer.csv, runs.csv in {}",
        study.out.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[Variant]) -> Vec<&str> {
        v.iter().map(|v| v.name.as_str()).collect()
    }

    #[test]
    fn one_variant_per_group_and_per_augmentation_that_is_on() {
        let q = config::load("quickstart.toml", &[]).unwrap();
        // quickstart's augmentations that are on, after base and its groups.
        let augs = [
            "no-fliplr",
            "no-hsv",
            "no-degrees",
            "no-scale",
            "no-flipud",
            "no-copy-paste",
        ];
        let v = variants(&q).unwrap();
        assert_eq!(names(&v)[..3], ["base", "no-carcass", "no-physics"]);
        assert_eq!(names(&v)[3..], augs);
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
        let v = variants(&r).unwrap();
        assert_eq!((names(&v)[0], &names(&v)[1..]), ("base", &augs[..]));
    }

    #[test]
    fn choose_keeps_order_and_names_unknown_variants() {
        let o = |only: &str| TransferOptions {
            config: "quickstart.toml".into(),
            data_eval: "quickstart.toml".into(),
            seeds: 1,
            variants: Some(only.into()),
            study: StudyFlags::default(),
            device: None,
        };
        let v = study(&o("no-hsv,base,no-physics")).unwrap().variants;
        assert_eq!(names(&v), ["base", "no-physics", "no-hsv"]);
        let e = study(&o("no-mosaic")).unwrap_err().to_string();
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
        assert!((s[0].columns[1].0 - 0.5).abs() < 1e-12);
        assert!((s[0].columns[1].1 - 0.1414213562373095).abs() < 1e-12);
        assert!((s[0].columns[0].0 - 0.55).abs() < 1e-12);
        assert_eq!((s[1].columns[1].1, s[1].columns[4].0), (0.0, 100.0));
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
            variants: Some("base,no-fliplr".into()),
            study: StudyFlags {
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
                out: Some(dir.join("out")),
                no_train: false,
                quiet: true,
            },
            device: None,
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
            variants: Some("base,no-fliplr,no-hsv".into()),
            study: StudyFlags {
                no_train: true,
                ..o.study.clone()
            },
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
