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
//! A study on [`super::runner`]: one variant per count. Resumable like every study there:
//! a setting whose folder already has `test.json` is read, not retrained; one with only
//! `last.bpk` continues from it; `--no-train` reports what finished and names the rest,
//! for a sweep whose seeds ran in separate processes. Seed `k` of a sweep is `seed + k`. That seed drives everything the config's seed drives — the proxy-real draw
//! and the split included — so with proxy-real data the spread over seeds also covers
//! test-set variation, where the paper keeps one split and varies only training.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::bench::accuracy::run_accuracy;
use crate::config::DeviceKind;
use crate::eval::plots::{write_png, Panel, Series, PALETTE};
use crate::eval::report::Table;
use crate::train::smoke::smoke_config;

use super::runner::{not_trained, State, Study, StudyFlags, Variant};
use super::summary::{group, md_cell, mean_std_cells, mean_std_columns, runs_table, Group};

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
    #[command(flatten)]
    pub study: StudyFlags,
    /// Shrink every run to a ~1 minute smoke run.
    #[arg(long)]
    pub smoke: bool,
    /// Override the config's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long)]
    pub device: Option<DeviceKind>,
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
    let a = run_accuracy(dir)?;
    Ok(RunResult {
        synthetic,
        seed,
        bbox: a.bbox,
        segm: a.segm,
        train_seconds: a.train_seconds,
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

/// One row per synthetic count (ascending): its runs, [`METRICS`] then the training
/// seconds as (mean, sample std).
pub fn summarise(results: &[RunResult]) -> Vec<Group<usize>> {
    let mut g = group(
        results,
        |r| r.synthetic,
        |r| {
            METRICS
                .iter()
                .map(|&(_, k, i)| metric(r, k, i))
                .chain([r.train_seconds])
                .collect()
        },
    );
    g.sort_by_key(|g| g.key);
    g
}

/// The best synthetic count per metric (highest mean; the smaller count on a tie).
pub fn best_counts(s: &[Group<usize>]) -> [(usize, f64); 6] {
    std::array::from_fn(|j| {
        s.iter()
            .map(|g| (g.key, g.columns[j].0))
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
pub fn write_report(
    out: &Path,
    results: &[RunResult],
    protocol: &str,
) -> Result<Vec<Group<usize>>> {
    let runs = runs_table(
        &["synthetic", "seed", "train_seconds"],
        results.iter().map(|r| {
            let ids = vec![
                r.synthetic.to_string(),
                r.seed.to_string(),
                format!("{:.1}", r.train_seconds),
            ];
            (ids, &r.bbox, &r.segm)
        }),
    );
    crate::util::write_atomic(&out.join("runs.csv"), runs.to_csv().as_bytes())?;

    let s = summarise(results);
    let names = METRICS.map(|m| m.0);
    let mut csv = Table::new(
        ["synthetic", "runs", "train_minutes"]
            .into_iter()
            .map(String::from)
            .chain(mean_std_columns(&names)),
    );
    let mut md = Table::new(
        ["setting", "runs"]
            .into_iter()
            .chain(names)
            .chain(["train min"]),
    );
    for g in &s {
        let (n, k, ms, secs) = (g.key, g.runs, &g.columns[..6], g.columns[6].0);
        let mut row = vec![n.to_string(), k.to_string(), format!("{:.2}", secs / 60.0)];
        row.extend(mean_std_cells(ms));
        csv.push(row);
        let mut row = vec![setting_name(n), k.to_string()];
        row.extend(ms.iter().map(|&m| md_cell(m, k)));
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
    for (name, (n, v)) in names.iter().zip(best) {
        text.push_str(&format!("- {name}: {} ({v:.3})\n", setting_name(n)));
    }
    crate::util::write_atomic(&out.join("sweep.md"), text.as_bytes())?;
    write_plot(out, &s)?;
    Ok(s)
}

/// `sweep.png`: bbox and segm AP, AP50, AP75 against the synthetic count, ± std bars.
fn write_plot(out: &Path, s: &[Group<usize>]) -> Result<()> {
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
                    s.iter().map(|g| (g.key as f64, g.columns[j].0)).collect(),
                    PALETTE[c],
                )
                .err(s.iter().map(|g| g.columns[j].1).collect()),
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
    )
}

/// The sweep as a study: one variant per synthetic count (`syn<N>`, folders
/// `syn<N>_seed<S>/`), in `out`.
fn study(o: &SweepOptions, out: PathBuf) -> Study {
    Study {
        name: "sweep",
        config: o.config.clone(),
        overrides: o.study.overrides.clone(),
        variants: o
            .synthetic
            .iter()
            .map(|n| Variant {
                name: format!("syn{n}"),
                change: format!("data.synthetic = {n} (--syn {n})"),
                overrides: vec![format!("data.synthetic={n}")],
            })
            .collect(),
        seeds: o.seeds,
        folder: |v, seed| format!("{v}_seed{seed}"),
        out,
        no_train: o.study.no_train,
        smoke: o.smoke,
        device: o.device,
        quiet: o.study.quiet,
    }
}

/// Runs (or reads back) every setting of the sweep and writes the report.
pub fn sweep(o: &SweepOptions) -> Result<String> {
    // Each count's config is validated before anything trains, as it will run: with its
    // `data.synthetic` (a setting such as `train.real_fraction` needs synthetic images, so
    // the config as given may be invalid alone and valid for every count of the sweep).
    let mut study = study(o, PathBuf::new());
    let runs = study.plan()?;
    let mut c = runs[0].config.clone();
    if o.smoke {
        smoke_config(&mut c);
    }
    study.out = o.study.out_or_default("sweep", &c.name);
    let done = study.run(&runs, |r, state| {
        Ok(match state {
            State::Finished => Some(read_run(&study.dir(r), o.synthetic[r.variant], r.seed)?),
            State::NotTrained => None,
        })
    })?;
    let out = &study.out;
    if done.scores.is_empty() {
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
    let (first, last) = Study::seed_range(&runs);
    let mut protocol = format!(
        "{}{}; {} seed(s) per setting (seed {first}…{last}); test split of each run, \
         `best.bpk` (best val segm AP). Runs: `{}`.",
        study.config_clause(),
        if o.smoke { ", `--smoke`" } else { "" },
        o.seeds,
        out.display()
    );
    if let Some(note) = not_trained(&done.missing) {
        protocol.push(' ');
        protocol.push_str(&note);
    }
    write_report(out, &done.scores, &protocol)?;
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
        assert_eq!(s[0].runs, 2);
        assert!((s[0].columns[0].0 - 0.5).abs() < 1e-12);
        assert!((s[0].columns[0].1 - 0.1414213562373095).abs() < 1e-12);
        assert_eq!(s[1].columns[0].1, 0.0);
        assert_eq!(s[0].columns[6], (60.0, 0.0));
        // Rows come by count, whatever the order of the runs.
        let keys: Vec<usize> = summarise(&[run(500, 0, 0.1), run(0, 0, 0.2)])
            .iter()
            .map(|g| g.key)
            .collect();
        assert_eq!(keys, [0, 500]);
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
