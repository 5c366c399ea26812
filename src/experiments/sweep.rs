//! `chicktrain sweep`: the paper's central experiment (Table 2) with one command — the
//! same config trained with each synthetic-image count and several seeds, every run
//! scored on its test split, summarised as mean ± std over seeds.
//!
//! Output folder (`runs/sweep/<config name>/` or `--out`): one training run folder per
//! setting (`syn<N>_seed<S>/`, the usual run files), `runs.csv` (one row per run, all
//! 12 + 12 test stats), `sweep.csv` / `sweep.md` (one row per synthetic count: bbox and
//! segm AP, AP50, AP75 as mean and std; the best count per metric named under the
//! markdown table) and `sweep.png` (AP vs synthetic count, ± std bars).
//!
//! Resumable: a setting whose folder already has `test.json` is read, not retrained; one
//! with only `last.bpk` continues from it; `--no-train` reports what finished and names
//! the rest, for a sweep whose seeds ran in separate processes. Seed `k` of a sweep is
//! `seed + k`. That seed drives everything the config's seed drives — the proxy-real draw
//! and the split included — so with proxy-real data the spread over seeds also covers
//! test-set variation, where the paper keeps one split and varies only training.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::config::{self, DeviceKind};
use crate::eval::plots::{write_png, Panel, Series, PALETTE};
use crate::eval::report::{stat_cells, stat_columns, Table};
use crate::infer::checkpoint::Checkpoint;
use crate::train::run_files;
use crate::train::smoke::smoke_config;
use crate::train::trainer::{train, TrainOptions};
use crate::util::stats::mean_std;

/// What to sweep (`chicktrain sweep`'s flags).
#[derive(Clone, Debug, clap::Args)]
pub struct SweepOptions {
    /// Config file or shipped config name (e.g. yolo_real_baseline.toml).
    #[arg(long)]
    pub config: String,
    /// Synthetic-image counts (`data.synthetic`), comma-separated, one row each.
    // The full path keeps clap from reading the Vec as a repeated flag.
    #[arg(long = "syn", value_name = "COUNTS", default_value = "0,250,500,750,1000", value_parser = counts_flag)]
    pub synthetic: ::std::vec::Vec<usize>,
    /// Seeds per count (config seed, seed + 1, …).
    #[arg(long, default_value_t = 1)]
    pub seeds: usize,
    /// Override a config key in every run, e.g. --set train.epochs=20 (repeatable;
    /// applied before the sweep's own two).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Shrink every run to a ~1 minute smoke run.
    #[arg(long)]
    pub smoke: bool,
    /// Write the runs and the report here instead of runs/sweep/<name>/.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Train nothing: report the finished runs in the output folder and name the
    /// missing ones (for a sweep split over several processes or cut short).
    #[arg(long)]
    pub no_train: bool,
    /// Override the config's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long)]
    pub device: Option<DeviceKind>,
    /// No progress bars or per-epoch lines.
    #[arg(long)]
    pub quiet: bool,
}

/// [`parse_counts`] as clap's value parser of `--syn`.
fn counts_flag(s: &str) -> std::result::Result<Vec<usize>, String> {
    parse_counts(s).map_err(|e| format!("{e:#}"))
}

/// Test metrics of one finished run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunResult {
    pub synthetic: usize,
    pub seed: u64,
    pub bbox: [f64; 12],
    pub segm: [f64; 12],
    /// Training wall time: sum of the per-epoch times in `metrics.jsonl` (steps and
    /// validation; rendering and the test evaluation excluded).
    pub train_seconds: f64,
}

/// Parses `--syn 0,250,500` (sorted, duplicates removed).
pub fn parse_counts(s: &str) -> Result<Vec<usize>> {
    let mut v = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        v.push(
            part.parse::<usize>().with_context(|| {
                format!("--syn {s:?}: {part:?} is not a non-negative image count")
            })?,
        );
    }
    if v.is_empty() {
        bail!("--syn {s:?} names no synthetic-image count (e.g. --syn 0,250,500)");
    }
    v.sort_unstable();
    v.dedup();
    Ok(v)
}

/// Reads a finished run folder: `test.json` and the epoch times of `metrics.jsonl`.
pub fn read_run(dir: &Path, synthetic: usize, seed: u64) -> Result<RunResult> {
    let t = run_files::read_test(dir)?;
    Ok(RunResult {
        synthetic,
        seed,
        bbox: t.bbox.stats,
        segm: t.segm.stats,
        train_seconds: run_files::train_seconds(dir)?,
    })
}

/// The sweep's metrics: (column name, bbox or segm, index into the 12 stats).
pub const METRICS: [(&str, &str, usize); 6] = [
    ("bbox AP", "bbox", 0),
    ("bbox AP50", "bbox", 1),
    ("bbox AP75", "bbox", 2),
    ("segm AP", "segm", 0),
    ("segm AP50", "segm", 1),
    ("segm AP75", "segm", 2),
];

fn metric(r: &RunResult, kind: &str, i: usize) -> f64 {
    if kind == "bbox" {
        r.bbox[i]
    } else {
        r.segm[i]
    }
}

/// One row per synthetic count: (count, runs, [(mean, std); 6], mean train seconds).
pub type Summary = Vec<(usize, usize, [(f64, f64); 6], f64)>;

pub fn summarise(results: &[RunResult]) -> Summary {
    let mut counts: Vec<usize> = results.iter().map(|r| r.synthetic).collect();
    counts.sort_unstable();
    counts.dedup();
    counts
        .into_iter()
        .map(|n| {
            let rs: Vec<&RunResult> = results.iter().filter(|r| r.synthetic == n).collect();
            let ms = METRICS
                .map(|(_, k, i)| mean_std(&rs.iter().map(|r| metric(r, k, i)).collect::<Vec<_>>()));
            let secs = mean_std(&rs.iter().map(|r| r.train_seconds).collect::<Vec<_>>()).0;
            (n, rs.len(), ms, secs)
        })
        .collect()
}

/// The best synthetic count per metric (highest mean; the smaller count on a tie).
pub fn best_counts(s: &Summary) -> [(usize, f64); 6] {
    std::array::from_fn(|j| {
        s.iter()
            .map(|(n, _, ms, _)| (*n, ms[j].0))
            .fold((usize::MAX, f64::NEG_INFINITY), |b, c| {
                if c.1 > b.1 {
                    c
                } else {
                    b
                }
            })
    })
}

fn setting_name(n: usize) -> String {
    if n == 0 {
        "Real baseline".into()
    } else {
        format!("Real + {n} syn")
    }
}

/// Writes `runs.csv`, `sweep.csv`, `sweep.md` and `sweep.png` into `out`.
pub fn write_report(out: &Path, results: &[RunResult], protocol: &str) -> Result<Summary> {
    let mut runs = Table::new(
        ["synthetic", "seed", "train_seconds"]
            .into_iter()
            .map(String::from)
            .chain(stat_columns()),
    );
    for r in results {
        let mut row = vec![
            r.synthetic.to_string(),
            r.seed.to_string(),
            format!("{:.1}", r.train_seconds),
        ];
        row.extend(stat_cells(&r.bbox, &r.segm));
        runs.push(row);
    }
    crate::util::write_atomic(&out.join("runs.csv"), runs.to_csv().as_bytes())?;

    let s = summarise(results);
    let mut csv = Table::new(
        ["synthetic", "runs", "train_minutes"]
            .into_iter()
            .map(String::from)
            .chain(METRICS.iter().flat_map(|(n, _, _)| {
                let n = n.replace(' ', "_");
                [format!("{n}_mean"), format!("{n}_std")]
            })),
    );
    let mut md = Table::new(
        ["setting", "runs"]
            .into_iter()
            .map(String::from)
            .chain(METRICS.iter().map(|(n, _, _)| n.to_string()))
            .chain(["train min".to_string()]),
    );
    for (n, k, ms, secs) in &s {
        let mut row = vec![n.to_string(), k.to_string(), format!("{:.2}", secs / 60.0)];
        row.extend(
            ms.iter()
                .flat_map(|(m, sd)| [format!("{m:.4}"), format!("{sd:.4}")]),
        );
        csv.push(row);
        let mut row = vec![setting_name(*n), k.to_string()];
        row.extend(ms.iter().map(|(m, sd)| {
            if *k > 1 {
                format!("{m:.3} ± {sd:.3}")
            } else {
                format!("{m:.3}")
            }
        }));
        row.push(format!("{:.1}", secs / 60.0));
        md.push(row);
    }
    crate::util::write_atomic(&out.join("sweep.csv"), csv.to_csv().as_bytes())?;
    let best = best_counts(&s);
    let mut text = format!(
        "# Synthetic-data sweep\n\n{protocol}\n\n{}\n",
        md.to_markdown()
    );
    text.push_str("Best synthetic count per metric (highest mean over seeds):\n\n");
    for ((name, _, _), (n, v)) in METRICS.iter().zip(best) {
        text.push_str(&format!("- {name}: {} ({v:.3})\n", setting_name(n)));
    }
    crate::util::write_atomic(&out.join("sweep.md"), text.as_bytes())?;

    let panel = |kind: &str, j0: usize| {
        let mut p = Panel::new(
            format!("{kind}: test AP vs synthetic images"),
            "synthetic images added to the real training set",
            "COCO AP (mean ± std over seeds)",
        );
        for (c, j) in (j0..j0 + 3).enumerate() {
            p = p.push(
                Series::new(
                    METRICS[j].0,
                    s.iter().map(|(n, _, ms, _)| (*n as f64, ms[j].0)).collect(),
                    PALETTE[c],
                )
                .err(s.iter().map(|(_, _, ms, _)| ms[j].1).collect()),
            );
        }
        p
    };
    write_png(
        &out.join("sweep.png"),
        &[panel("bbox", 0), panel("segm", 3)],
        2,
        420,
        320,
    )?;
    Ok(s)
}

/// Runs (or reads back) every setting of the sweep and writes the report.
pub fn sweep(o: &SweepOptions) -> Result<String> {
    if o.seeds == 0 {
        bail!("--seeds 0: a sweep needs at least one seed per setting");
    }
    if o.synthetic.is_empty() {
        bail!("--syn names no synthetic-image count");
    }
    // Each count's config is validated before anything trains, as it will run: with its
    // `data.synthetic` (a setting such as `train.real_fraction` needs synthetic images, so
    // the config as given may be invalid alone and valid for every count of the sweep).
    // Each run is its count's config with the run's seed.
    let mut per_count = Vec::new();
    for &n in &o.synthetic {
        let mut set = o.overrides.clone();
        set.push(format!("data.synthetic={n}"));
        per_count.push(
            config::load(&o.config, &set)
                .with_context(|| format!("--syn {n}: the config with data.synthetic = {n}"))?,
        );
    }
    let base = &per_count[0];
    let mut name = base.name.clone();
    if o.smoke {
        let mut c = base.clone();
        smoke_config(&mut c);
        name = c.name;
    }
    let out = o
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join("sweep").join(&name));
    if !o.no_train {
        std::fs::create_dir_all(&out)
            .with_context(|| format!("cannot create sweep folder {}", out.display()))?;
    }
    crate::train::interrupt::install();
    let mut results = Vec::new();
    let mut missing = Vec::new();
    let total = o.synthetic.len() * o.seeds;
    for (&n, count_cfg) in o.synthetic.iter().zip(&per_count) {
        for k in 0..o.seeds as u64 {
            let seed = base.seed + k;
            let dir = out.join(format!("syn{n}_seed{seed}"));
            let say = |s: String| {
                if !o.quiet {
                    eprintln!("{s}");
                }
            };
            if dir.join("test.json").exists() {
                say(format!("sweep: {} done, reading it", dir.display()));
                results.push(read_run(&dir, n, seed)?);
                continue;
            }
            if o.no_train {
                missing.push(format!("syn{n}_seed{seed}"));
                continue;
            }
            let mut cfg = count_cfg.clone();
            cfg.seed = seed;
            let last = dir.join("last.bpk");
            let resume = last.exists()
                && Checkpoint::load(&last).is_ok_and(|c| {
                    let epochs = if o.smoke {
                        cfg.train.epochs.min(2)
                    } else {
                        cfg.train.epochs
                    };
                    c.header.epoch < epochs
                });
            say(format!(
                "sweep: run {}/{total}: {} synthetic, seed {seed}{} → {}",
                results.len() + 1,
                n,
                if resume { " (resuming)" } else { "" },
                dir.display()
            ));
            let opts = TrainOptions {
                run_dir: Some(dir.clone()),
                resume,
                smoke: o.smoke,
                device: o.device,
                quiet: o.quiet,
                exist_ok: false,
            };
            train(cfg, &opts).with_context(|| {
                format!("sweep run {n} synthetic, seed {seed} ({})", dir.display())
            })?;
            results.push(read_run(&dir, n, seed)?);
        }
    }
    if results.is_empty() {
        bail!(
            "--no-train: no finished run (a folder with test.json) in {} for --syn {} --seeds {}",
            out.display(),
            o.synthetic
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(","),
            o.seeds
        );
    }
    let mut protocol = format!(
        "Config `{}`{}{}; {} seed(s) per setting (seed {}…{}); test split of each run, \
         `best.bpk` (best val segm AP). Runs: `{}`.",
        o.config,
        if o.overrides.is_empty() {
            String::new()
        } else {
            format!(" with `--set {}`", o.overrides.join(" --set "))
        },
        if o.smoke { ", `--smoke`" } else { "" },
        o.seeds,
        base.seed,
        base.seed + o.seeds as u64 - 1,
        out.display()
    );
    if !missing.is_empty() {
        protocol.push_str(&format!(
            " Not trained (left out; the runs column counts the finished ones): {}.",
            missing.join(", ")
        ));
    }
    write_report(&out, &results, &protocol)?;
    let md = std::fs::read_to_string(out.join("sweep.md"))?;
    Ok(format!(
        "{md}\nwrote sweep.md, sweep.csv, runs.csv, sweep.png in {}",
        out.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(n: usize, seed: u64, ap: f64) -> RunResult {
        let mut s = [0.0; 12];
        s[0] = ap;
        s[1] = ap + 0.2;
        s[2] = ap + 0.1;
        RunResult {
            synthetic: n,
            seed,
            bbox: s,
            segm: s.map(|v| v / 2.0),
            train_seconds: 60.0,
        }
    }

    #[test]
    fn counts_parse_sorted_and_reject_junk() {
        assert_eq!(parse_counts("500, 0,250,0").unwrap(), vec![0, 250, 500]);
        assert!(parse_counts("0,x")
            .unwrap_err()
            .to_string()
            .contains("\"x\""));
        assert!(parse_counts(",").is_err());
        assert!(parse_counts("-5").is_err());
    }

    #[test]
    fn summary_is_mean_and_sample_std_and_best_breaks_ties_low() {
        let rs = [
            run(0, 0, 0.4),
            run(0, 1, 0.6),
            run(250, 0, 0.5),
            run(500, 0, 0.5),
        ];
        let s = summarise(&rs);
        assert_eq!(s.len(), 3);
        assert_eq!(s[0].1, 2);
        assert!((s[0].2[0].0 - 0.5).abs() < 1e-12);
        assert!((s[0].2[0].1 - 0.1414213562373095).abs() < 1e-12);
        assert_eq!(s[1].2[0].1, 0.0);
        let best = best_counts(&s);
        assert_eq!(best[0].0, 0); // 0.5 everywhere: the smallest count wins
        let rs = [run(0, 0, 0.4), run(250, 0, 0.7)];
        assert_eq!(best_counts(&summarise(&rs))[3], (250, 0.35));
    }

    #[test]
    fn report_files_have_a_row_per_count() {
        let dir = std::env::temp_dir().join(format!("ct-sweep-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rs = [run(0, 0, 0.4), run(0, 1, 0.6), run(250, 0, 0.7)];
        write_report(&dir, &rs, "test protocol").unwrap();
        let csv = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3);
        assert!(lines[0].starts_with("synthetic,runs,train_minutes,bbox_AP_mean,bbox_AP_std"));
        assert!(lines[1].starts_with("0,2,1.00,0.5000,0.1414"));
        let md = std::fs::read_to_string(dir.join("sweep.md")).unwrap();
        assert!(md.contains("| Real baseline | 2 | 0.500 ± 0.141 |"), "{md}");
        assert!(md.contains("- segm AP: Real + 250 syn (0.350)"), "{md}");
        assert_eq!(
            std::fs::read_to_string(dir.join("runs.csv"))
                .unwrap()
                .lines()
                .count(),
            4
        );
        assert!(image::open(dir.join("sweep.png")).is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
