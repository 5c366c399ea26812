//! `chicktrain bench ablation`: what this top-view, one-class, large-object scene does not
//! need. Each variant changes one model option of a base config (the smallest-object head
//! P3, the C2PSA attention block, width, input resolution, prototype count), is trained
//! with the same data and schedule, scored on the test split, and timed like `bench
//! models`; the report is AP vs latency with the Pareto front, and a recommendation: the
//! fastest variant whose test segm AP is within [`AP_TOLERANCE`] of the best.
//!
//! Trainings are deterministic, so their AP holds on a loaded machine; only the timings
//! need a quiet one (`--no-train` re-times finished runs without training).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::config::{self, Config, DeviceKind};
use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::DetectorConfig;
use crate::train::trainer::{train, TrainOptions};

use super::accuracy::run_accuracy;
use super::measure::Effort;
use super::report::{finished_report, write_report, Row};
use super::variant::Variant;
use super::worker::measure_in_child;

/// One ablation variant: a name (its run folder), what it changes, the `--set` overrides.
pub struct AblationVariant {
    pub name: &'static str,
    pub change: &'static str,
    pub overrides: &'static [&'static str],
}

/// The variants, base first.
pub const VARIANTS: [AblationVariant; 7] = [
    AblationVariant {
        name: "base",
        change:
            "the config's model (cpu_protocol: YOLO11n-seg, P3–P5, C2PSA, 32 prototypes, 256 px)",
        overrides: &[],
    },
    AblationVariant {
        name: "no_p3",
        change: "heads on P4–P5 only (no stride-8 head; prototypes at 1/8)",
        overrides: &["model.levels=[4, 5]"],
    },
    AblationVariant {
        name: "no_c2psa",
        change: "no C2PSA attention block",
        overrides: &["model.c2psa=false"],
    },
    AblationVariant {
        name: "width_0.5",
        change: "half the channels (width ×0.5)",
        overrides: &["model.width_mult=0.5"],
    },
    AblationVariant {
        name: "protos_16",
        change: "16 mask prototypes instead of 32",
        overrides: &["model.prototypes=16"],
    },
    AblationVariant {
        name: "px192",
        change: "192 px input (crop 160)",
        overrides: &["data.image_size=192", "data.crop=160"],
    },
    AblationVariant {
        name: "px320",
        change: "320 px input (crop 288)",
        overrides: &["data.image_size=320", "data.crop=288"],
    },
];

/// A variant may lose this much test segm AP against the best and still be recommended.
pub const AP_TOLERANCE: f64 = 0.01;

/// Options of `bench ablation`.
#[derive(Clone, Debug)]
pub struct AblationOptions {
    pub config: String,
    pub synthetic: usize,
    pub overrides: Vec<String>,
    /// Variant names to run (all when empty).
    pub only: Vec<String>,
    pub out: PathBuf,
    /// Train missing runs, skip the timing.
    pub train_only: bool,
    /// Never train: time every variant, AP only where a finished run exists.
    pub no_train: bool,
    pub effort: Effort,
    pub device: DeviceKind,
    pub exe: PathBuf,
    pub quiet: bool,
}

/// The fastest row whose segm AP is within `tol` of the best (rows without AP ignored).
pub fn recommend(rows: &[Row], tol: f64) -> Option<usize> {
    let best = rows
        .iter()
        .filter_map(|r| r.acc.as_ref().map(|a| a.segm[0]))
        .fold(f64::NEG_INFINITY, f64::max);
    (0..rows.len())
        .filter(|&i| {
            rows[i]
                .acc
                .as_ref()
                .is_some_and(|a| a.segm[0] >= best - tol)
        })
        .min_by(|&a, &b| rows[a].m.latency_ms[0].total_cmp(&rows[b].m.latency_ms[0]))
}

/// `chicktrain bench ablation`.
pub fn ablation(o: &AblationOptions) -> Result<String> {
    if o.train_only && o.no_train {
        bail!("--train-only and --no-train exclude each other");
    }
    let chosen = chosen_variants(&o.only)?;
    std::fs::create_dir_all(&o.out)
        .with_context(|| format!("cannot create {}", o.out.display()))?;
    crate::train::interrupt::install();
    let mut rows = Vec::new();
    let mut changes = Vec::new();
    for v in &chosen {
        if let Some((row, change)) = run_variant(o, v)? {
            rows.push(row);
            changes.push(change);
        }
    }
    if o.train_only {
        return Ok(format!(
            "trained the ablation runs in {} (timings skipped: --train-only)",
            o.out.display()
        ));
    }
    let mut pre = preamble(o, &changes);
    pre.push_str(&recommendation(&rows));
    write_report(&o.out, &rows, &pre)?;
    finished_report(&o.out)
}

/// The variants named in `only` (all when empty), in [`VARIANTS`] order; an unknown
/// name is an error listing the known ones.
fn chosen_variants(only: &[String]) -> Result<Vec<&'static AblationVariant>> {
    for n in only {
        if !VARIANTS.iter().any(|v| v.name == n) {
            let names: Vec<&str> = VARIANTS.iter().map(|v| v.name).collect();
            bail!(
                "unknown ablation variant {n:?} (known: {})",
                names.join(", ")
            );
        }
    }
    Ok(VARIANTS
        .iter()
        .filter(|v| only.is_empty() || only.iter().any(|n| n == v.name))
        .collect())
}

fn say(o: &AblationOptions, s: String) {
    if !o.quiet {
        eprintln!("{s}");
    }
}

/// One variant: trains its run unless finished (or `--no-train`), then — unless
/// `--train-only` — times it and returns its report row and its line of the change list.
fn run_variant(o: &AblationOptions, v: &AblationVariant) -> Result<Option<(Row, String)>> {
    let mut set = o.overrides.clone();
    set.push(format!("data.synthetic={}", o.synthetic));
    set.extend(v.overrides.iter().map(|s| s.to_string()));
    let cfg =
        config::load(&o.config, &set).with_context(|| format!("ablation variant {}", v.name))?;
    let dir = o.out.join(v.name);
    if !dir.join("test.json").exists() && !o.no_train {
        train_run(o, v, &cfg, &dir)?;
    }
    if o.train_only {
        return Ok(None);
    }
    let acc = if dir.join("test.json").exists() {
        Some(run_accuracy(&dir)?)
    } else {
        None
    };
    let mc = DetectorConfig::from_config(&cfg, 1)?;
    let variant = Variant::of_detector(&mc);
    let size = mc.input_size();
    say(
        o,
        format!("ablation: timing {} ({variant} at {size} px)", v.name),
    );
    let m = measure_in_child(&o.exe, &variant, size, o.effort, o.device)?;
    let row = Row {
        label: v.name.to_string(),
        m,
        acc,
    };
    Ok(Some((
        row,
        format!("- `{}`: {} (`{variant}`)", v.name, v.change),
    )))
}

/// Trains `v`'s run into `dir`, resuming its `last.bpk` when that stopped early.
fn train_run(o: &AblationOptions, v: &AblationVariant, cfg: &Config, dir: &Path) -> Result<()> {
    let last = dir.join("last.bpk");
    let resume =
        last.exists() && Checkpoint::load(&last).is_ok_and(|c| c.header.epoch < cfg.train.epochs);
    say(
        o,
        format!("ablation: training {} → {}", v.name, dir.display()),
    );
    let opts = TrainOptions {
        run_dir: Some(dir.to_path_buf()),
        resume,
        smoke: false,
        device: Some(o.device),
        quiet: o.quiet,
        exist_ok: false,
    };
    train(cfg.clone(), &opts)
        .with_context(|| format!("ablation variant {} ({})", v.name, dir.display()))?;
    Ok(())
}

/// The report's opening: the config, the protocol, and the change list.
fn preamble(o: &AblationOptions, changes: &[String]) -> String {
    let e = o.effort;
    format!(
        "# Scene ablation\n\nConfig `{}` + {} synthetic{}, one option changed per variant; \
         AP on each run's test split (`best.bpk`). Latency: batch 1, {} warm-up + {} runs \
         (median, p10, p90); training: batch {}, median of {} steps; fresh process per \
         variant.\n\n{}",
        o.config,
        o.synthetic,
        if o.overrides.is_empty() {
            String::new()
        } else {
            format!(", `--set {}`", o.overrides.join(" --set "))
        },
        e.warmup,
        e.repeats,
        e.train_batch,
        e.train_steps,
        changes.join("\n")
    )
}

/// The "**Recommended:**" paragraph ([`recommend`], compared with the base when that
/// has AP), or nothing when no row has AP.
fn recommendation(rows: &[Row]) -> String {
    let Some(i) = recommend(rows, AP_TOLERANCE) else {
        return String::new();
    };
    let r = &rows[i];
    let a = r.acc.as_ref().expect("recommend only picks rows with AP");
    let base = rows.iter().find(|r| r.label == "base");
    let mut s = format!(
        "\n\n**Recommended:** `{}` — the fastest variant within {AP_TOLERANCE} segm AP of the best: {:.1} ms median latency, {:.2} GFLOPs, segm AP {:.3}, bbox AP {:.3}",
        r.label, r.m.latency_ms[0], r.m.gflops, a.segm[0], a.bbox[0]
    );
    if let Some(b) = base.filter(|b| b.label != r.label) {
        if let Some(ba) = &b.acc {
            s.push_str(&format!(
                " (base: {:.1} ms, {:.2} GFLOPs, segm AP {:.3}, bbox AP {:.3}; latency ×{:.2} and GFLOPs ×{:.2} of the base)",
                b.m.latency_ms[0],
                b.m.gflops,
                ba.segm[0],
                ba.bbox[0],
                r.m.latency_ms[0] / b.m.latency_ms[0],
                r.m.gflops / b.m.gflops
            ));
        }
    }
    s.push('.');
    s
}

#[cfg(test)]
mod tests {
    use super::super::accuracy::Accuracy;
    use super::super::measure::Measurement;
    use super::*;

    fn row(label: &str, ms: f64, ap: Option<f64>) -> Row {
        Row {
            label: label.into(),
            m: Measurement {
                variant: "yolo-n".into(),
                size: 256,
                params: 1,
                gflops: 1.0,
                latency_ms: [ms, ms, ms],
                repeats: 1,
                train_img_s: 1.0,
                train_batch: 8,
                train_steps: 1,
                infer_peak_mib: 1.0,
                peak_mib: 1.0,
            },
            acc: ap.map(|a| Accuracy {
                bbox: [a; 12],
                segm: [a; 12],
                train_seconds: 1.0,
                source: String::new(),
            }),
        }
    }

    #[test]
    fn recommendation_is_the_fastest_near_the_best() {
        let rows = [
            row("base", 10.0, Some(0.700)),
            row("small", 6.0, Some(0.695)),
            row("tiny", 3.0, Some(0.600)),
            row("untrained", 1.0, None),
        ];
        assert_eq!(recommend(&rows, 0.01), Some(1));
        assert_eq!(recommend(&rows, 0.2), Some(2));
        assert_eq!(recommend(&rows[3..], 0.01), None);
    }

    #[test]
    fn every_variant_makes_a_valid_config() {
        for v in &VARIANTS {
            let set: Vec<String> = v.overrides.iter().map(|s| s.to_string()).collect();
            config::load("cpu_protocol.toml", &set).unwrap();
        }
    }
}
