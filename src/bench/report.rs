//! The bench report shared by `bench models` and `bench ablation`: [`Row`]s of
//! measurements (and AP where a trained model was given) written as `bench.csv`,
//! `bench.md` and PNG plots — speed per input size, and AP against latency (Pareto front
//! marked) and against training time. Kept apart from the measuring so both commands
//! report alike and the CSV columns ([`COLUMNS`]) are defined once.

use std::path::Path;

use anyhow::{Context, Result};

use crate::eval::plots::{pareto_front, write_png, Mark, Panel, Series, PALETTE};
use crate::eval::report::Table;

use super::accuracy::Accuracy;
use super::measure::Measurement;

/// One row of the bench report.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Row label (the variant, or an ablation name).
    pub label: String,
    pub m: Measurement,
    pub acc: Option<Accuracy>,
}

/// `v` with `d` decimals; empty for NaN / infinite (not measured).
fn f(v: f64, d: usize) -> String {
    if v.is_finite() {
        format!("{v:.d$}")
    } else {
        String::new()
    }
}

/// The report columns, in CSV and markdown order.
pub const COLUMNS: [&str; 18] = [
    "variant",
    "size",
    "params_M",
    "GFLOPs",
    "latency_ms_median",
    "latency_ms_p10",
    "latency_ms_p90",
    "train_img_s",
    "infer_peak_MiB",
    "train_peak_MiB",
    "bbox_AP",
    "bbox_AP50",
    "bbox_AP75",
    "segm_AP",
    "segm_AP50",
    "segm_AP75",
    "train_min",
    "ap_source",
];

/// The table of `rows` (AP cells empty where no trained model was given).
pub fn table(rows: &[Row]) -> Table {
    let mut t = Table::new(COLUMNS);
    for r in rows {
        let m = &r.m;
        let mut row = vec![
            r.label.clone(),
            m.size.to_string(),
            f(m.params as f64 / 1e6, 3),
            f(m.gflops, 2),
            f(m.latency_ms[0], 1),
            f(m.latency_ms[1], 1),
            f(m.latency_ms[2], 1),
            f(m.train_img_s, 2),
            f(m.infer_peak_mib, 0),
            f(m.peak_mib, 0),
        ];
        match &r.acc {
            Some(a) => {
                row.extend(a.bbox[..3].iter().chain(&a.segm[..3]).map(|&v| f(v, 3)));
                row.push(f(a.train_seconds / 60.0, 1));
                row.push(a.source.clone());
            }
            None => row.extend(std::iter::repeat_n(String::new(), 8)),
        }
        t.push(row);
    }
    t
}

/// Writes `bench.csv`, `bench.md`, `speed.png` and, when some rows have AP,
/// `ap_vs_latency.png` (Pareto front marked) and `ap_vs_train_time.png`.
pub fn write_report(out: &Path, rows: &[Row], preamble: &str) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let t = table(rows);
    crate::util::write_atomic(&out.join("bench.csv"), t.to_csv().as_bytes())?;
    let mut md = format!("{preamble}\n\n{}", t.to_markdown());
    write_speed_png(out, rows)?;
    let with_ap: Vec<&Row> = rows.iter().filter(|r| r.acc.is_some()).collect();
    if !with_ap.is_empty() {
        let front_text = write_ap_vs_latency_png(out, &with_ap)?;
        write_ap_vs_train_time_png(out, &with_ap)?;
        md.push_str(&front_text);
    }
    crate::util::write_atomic(&out.join("bench.md"), md.as_bytes())
}

/// `speed.png`: median batch-1 latency and training throughput against input size, one
/// line per row label.
fn write_speed_png(out: &Path, rows: &[Row]) -> Result<()> {
    let mut labels: Vec<&str> = rows.iter().map(|r| r.label.as_str()).collect();
    labels.dedup();
    let per_label = |y: &dyn Fn(&Measurement) -> f64| -> Vec<Series> {
        labels
            .iter()
            .enumerate()
            .map(|(i, l)| {
                Series::new(
                    *l,
                    rows.iter()
                        .filter(|r| r.label == *l)
                        .map(|r| (r.m.size as f64, y(&r.m)))
                        .collect(),
                    PALETTE[i % PALETTE.len()],
                )
            })
            .collect()
    };
    let mut lat = Panel::new("batch-1 latency (median)", "input size (px)", "ms");
    lat.series = per_label(&|m| m.latency_ms[0]);
    let batch = rows.first().map_or(0, |r| r.m.train_batch);
    let mut thr = Panel::new(
        format!("training throughput, batch {batch}"),
        "input size (px)",
        "images/s",
    );
    thr.series = per_label(&|m| m.train_img_s);
    write_png(&out.join("speed.png"), &[lat, thr], 2, 440, 340)
}

/// The `" label size"` point tags of the plots.
fn tags(rows: &[&Row]) -> Vec<String> {
    rows.iter()
        .map(|r| format!(" {} {}", r.label, r.m.size))
        .collect()
}

/// `ap_vs_latency.png`: segm and bbox AP against median latency with the Pareto front;
/// returns the fronts as markdown text for `bench.md`.
fn write_ap_vs_latency_png(out: &Path, with_ap: &[&Row]) -> Result<String> {
    let mut panels = Vec::new();
    let mut front_text = String::new();
    for (kind, j) in [("segm", 1), ("bbox", 0)] {
        let ap = |r: &Row| {
            let a = r.acc.as_ref().expect("filtered");
            if j == 1 {
                a.segm[0]
            } else {
                a.bbox[0]
            }
        };
        let pts: Vec<(f64, f64)> = with_ap.iter().map(|r| (r.m.latency_ms[0], ap(r))).collect();
        let front = pareto_front(&pts);
        front_text.push_str(&format!(
            "\n{kind} AP vs latency, Pareto front (fastest first): {}\n",
            front
                .iter()
                .map(|&i| format!(
                    "{} @ {} px ({:.1} ms, AP {:.3})",
                    with_ap[i].label, with_ap[i].m.size, pts[i].0, pts[i].1
                ))
                .collect::<Vec<_>>()
                .join(" → ")
        ));
        panels.push(
            Panel::new(
                format!("test {kind} AP vs batch-1 latency (line: Pareto front)"),
                "latency (ms, median)",
                &format!("{kind} AP"),
            )
            .push(
                Series::new(
                    "Pareto front",
                    front.iter().map(|&i| pts[i]).collect(),
                    PALETTE[3],
                )
                .mark(Mark::Front),
            )
            .push(
                Series::new("trained models", pts.clone(), PALETTE[0])
                    .mark(Mark::Points)
                    .tags(tags(with_ap)),
            ),
        );
    }
    write_png(&out.join("ap_vs_latency.png"), &panels, 2, 480, 360)?;
    Ok(front_text)
}

/// `ap_vs_train_time.png`: segm AP against the training wall time of each run.
fn write_ap_vs_train_time_png(out: &Path, with_ap: &[&Row]) -> Result<()> {
    let pts: Vec<(f64, f64)> = with_ap
        .iter()
        .map(|r| {
            let a = r.acc.as_ref().expect("filtered");
            (a.train_seconds / 60.0, a.segm[0])
        })
        .collect();
    write_png(
        &out.join("ap_vs_train_time.png"),
        &[Panel::new(
            "test segm AP vs training time",
            "training wall time (min, epochs + validation)",
            "segm AP",
        )
        .push(
            Series::new("trained models", pts, PALETTE[0])
                .mark(Mark::Points)
                .tags(tags(with_ap)),
        )],
        1,
        520,
        360,
    )
}

/// The finished report's table plus where its files are: what `bench models` and
/// `bench ablation` print last.
pub fn finished_report(out: &Path) -> Result<String> {
    let md = std::fs::read_to_string(out.join("bench.md"))?;
    Ok(format!(
        "{md}\nwrote bench.csv, bench.md and plots in {}",
        out.display()
    ))
}
