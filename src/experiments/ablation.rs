//! `chicktrain bench ablation`: what this top-view, one-class, large-object scene does not
//! need. Each variant changes one model option of a base config (the smallest-object head
//! P3, the C2PSA attention block, width, input resolution, prototype count), is trained
//! with the same data and schedule, scored on the test split, and timed like `bench
//! models`; the report is AP vs latency with the Pareto front, and a recommendation: the
//! fastest variant whose test segm AP is within [`AP_TOLERANCE`] of the best.
//!
//! A study on [`super::runner`] (one seed per variant, folder `<variant>/`). Trainings
//! are deterministic, so their AP holds on a loaded machine; only the timings need a quiet
//! one (`--no-train` re-times finished runs without training).

use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::bench::accuracy::run_accuracy;
use crate::bench::effort::EffortFlags;
use crate::bench::measure::Effort;
use crate::bench::report::{finished_report, write_report, Row};
use crate::bench::variant::Variant as ModelVariant;
use crate::bench::worker::{measure_in_child, this_exe};
use crate::config::{self, DeviceKind};
use crate::infer::detector::DetectorConfig;

use super::runner::{choose, variant_names, Run, State, Study, StudyFlags, Variant};

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

/// `bench ablation`'s flags.
#[derive(Clone, Debug, clap::Args)]
pub struct AblationOptions {
    /// Base config file, or the name of a shipped config.
    #[arg(long, default_value = "cpu_protocol.toml")]
    pub config: String,
    /// Synthetic images added to the real training set of every variant.
    #[arg(long = "syn", default_value_t = 50)]
    pub synthetic: usize,
    /// Comma-separated subset of: base, no_p3, no_c2psa, width_0.5, protos_16, px192, px320.
    #[arg(long)]
    pub variants: Option<String>,
    #[command(flatten)]
    pub study: StudyFlags,
    /// Only train the missing runs (no timing).
    #[arg(long)]
    pub train_only: bool,
    #[command(flatten)]
    pub effort: EffortFlags,
    /// Device of training and timing: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long, default_value = "flex")]
    pub device: DeviceKind,
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

impl AblationVariant {
    /// As a variant of the study.
    fn variant(&self) -> Variant {
        Variant {
            name: self.name.into(),
            change: self.change.into(),
            overrides: self.overrides.iter().map(|s| s.to_string()).collect(),
        }
    }
}

/// The ablation as a study: the chosen variants, one seed each, folder `<variant>/`.
fn study(o: &AblationOptions) -> Result<Study> {
    let all = VARIANTS.iter().map(AblationVariant::variant).collect();
    let mut overrides = o.study.overrides.clone();
    overrides.push(format!("data.synthetic={}", o.synthetic));
    let name = config::load(&o.config, &o.study.overrides)?.name;
    Ok(Study {
        name: "ablation",
        config: o.config.clone(),
        overrides,
        variants: choose("ablation", all, &variant_names(&o.variants), "")?,
        seeds: 1,
        folder: |v, _| v.to_string(),
        out: o.study.out_or_default("ablation", &name),
        no_train: o.study.no_train,
        smoke: false,
        device: Some(o.device),
        quiet: o.study.quiet,
    })
}

/// `chicktrain bench ablation`.
pub fn ablation(o: &AblationOptions) -> Result<String> {
    if o.train_only && o.study.no_train {
        bail!("--train-only and --no-train exclude each other");
    }
    let study = study(o)?;
    let runs = study.plan()?;
    let out = &study.out;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let exe = this_exe()?;
    let effort = o.effort.over(Effort::default());
    // Every variant is timed, trained or not (`--no-train`); none with `--train-only`.
    let done = study.run(&runs, |r, state| {
        if o.train_only {
            return Ok(None);
        }
        time_run(&exe, effort, o.device, &study, r, state).map(Some)
    })?;
    if o.train_only {
        return Ok(format!(
            "trained the ablation runs in {} (timings skipped: --train-only)",
            out.display()
        ));
    }
    let (rows, changes): (Vec<Row>, Vec<String>) = done.scores.into_iter().unzip();
    let mut pre = preamble(o, effort, &changes);
    pre.push_str(&recommendation(&rows));
    write_report(out, &rows, &pre)?;
    finished_report(out)
}

/// Times one variant's model in a fresh process, with its test AP when its run finished;
/// returns its report row and its line of the change list.
fn time_run(
    exe: &Path,
    effort: Effort,
    device: DeviceKind,
    study: &Study,
    r: &Run,
    state: State,
) -> Result<(Row, String)> {
    let v = &study.variants[r.variant];
    let acc = match state {
        State::Finished => Some(run_accuracy(&study.dir(r))?),
        State::NotTrained => None,
    };
    let mc = DetectorConfig::from_config(&r.config, 1)?;
    let variant = ModelVariant::of_detector(&mc);
    let size = mc.input_size();
    study.say(&format!("timing {} ({variant} at {size} px)", v.name));
    let m = measure_in_child(exe, &variant, size, effort, device)?;
    let row = Row {
        label: v.name.clone(),
        m,
        acc,
    };
    Ok((row, format!("- `{}`: {} (`{variant}`)", v.name, v.change)))
}

/// The report's opening: the config, the protocol, and the change list.
fn preamble(o: &AblationOptions, e: Effort, changes: &[String]) -> String {
    format!(
        "# Scene ablation\n\nConfig `{}` + {} synthetic{}, one option changed per variant; \
         AP on each run's test split (`best.bpk`). Latency: batch 1, {} warm-up + {} runs \
         (median, p10, p90); training: batch {}, median of {} steps; fresh process per \
         variant.\n\n{}",
        o.config,
        o.synthetic,
        if o.study.overrides.is_empty() {
            String::new()
        } else {
            format!(", `--set {}`", o.study.overrides.join(" --set "))
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
    use super::*;
    use crate::bench::accuracy::Accuracy;
    use crate::bench::measure::Measurement;

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

    #[test]
    fn the_study_is_the_chosen_variants_in_order_one_seed_each() {
        let o = AblationOptions {
            config: "cpu_protocol.toml".into(),
            synthetic: 7,
            variants: Some("px192,base".into()),
            study: StudyFlags {
                overrides: vec!["seed=3".into()],
                out: None,
                no_train: true,
                quiet: true,
            },
            train_only: false,
            effort: EffortFlags::default(),
            device: DeviceKind::Flex,
        };
        let s = study(&o).unwrap();
        let runs = s.plan().unwrap();
        let labels: Vec<&str> = runs.iter().map(|r| r.label.as_str()).collect();
        assert_eq!(labels, ["base", "px192"]);
        assert_eq!((runs[1].seed, runs[1].config.data.synthetic), (3, 7));
        assert_eq!(runs[1].config.data.image_size, 192);
        let name = config::load("cpu_protocol.toml", &[]).unwrap().name;
        assert_eq!(s.out, Path::new("runs/ablation").join(name));
        let e = study(&AblationOptions {
            variants: Some("no_such".into()),
            ..o
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("\"no_such\"") && e.contains("px320"), "{e}");
    }
}
