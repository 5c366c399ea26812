//! `chicktrain bench models`: size, speed and memory of each model variant × input size,
//! plus test AP of trained checkpoints, as a CSV, a markdown table and PNG plots. This
//! file is the orchestration — the options, the default grid, and the loop over rows;
//! the parts are [`super::variant`] (names), [`super::measure`] (what a row measures and
//! how), [`super::worker`] (one fresh child process per row), [`super::accuracy`]
//! (checkpoint AP) and [`super::report`] (CSV, markdown, plots).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::config::DeviceKind;

use super::accuracy::checkpoint_accuracy;
use super::measure::Effort;
use super::report::{finished_report, write_report, Row};
use super::variant::Variant;
use super::worker::measure_in_child;

/// Options of `bench models`.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub variants: Vec<Variant>,
    pub sizes: Vec<usize>,
    pub effort: Effort,
    pub checkpoints: Vec<PathBuf>,
    pub out: PathBuf,
    pub device: DeviceKind,
    /// The binary that runs the workers (normally this one).
    pub exe: PathBuf,
}

/// The default selection: every YOLO scene option, every Mask R-CNN depth and the
/// compact Mask2Former at R18 and R50, × 5 sizes.
pub fn default_variants() -> Vec<Variant> {
    [
        "yolo-n",
        "yolo-s",
        "yolo-n-p45",
        "yolo-n-nopsa",
        "yolo-n-w0.5",
        "yolo-n-m16",
        "mrcnn-r18",
        "mrcnn-r34",
        "mrcnn-r50",
        "mrcnn-r101",
        "m2f-r18",
        "m2f-r50",
    ]
    .iter()
    .map(|s| s.parse().expect("valid default variant"))
    .collect()
}

pub const DEFAULT_SIZES: [usize; 5] = [256, 320, 416, 512, 640];

/// `--quick`: three variants, two small sizes, few repeats (a couple of minutes).
pub fn quick(o: &mut BenchOptions) {
    o.variants = ["yolo-n", "yolo-n-p45", "mrcnn-r18"]
        .iter()
        .map(|s| s.parse().expect("valid quick variant"))
        .collect();
    o.sizes = vec![256, 320];
    o.effort = Effort {
        warmup: 1,
        repeats: 5,
        train_batch: 8,
        train_steps: 1,
    };
}

/// Parses `--sizes 256,320`.
pub fn parse_sizes(s: &str) -> Result<Vec<usize>> {
    s.split(',')
        .map(str::trim)
        .filter(|p| !p.is_empty())
        .map(|p| {
            p.parse::<usize>()
                .ok()
                .filter(|&v| v >= 32 && v % 32 == 0)
                .with_context(|| format!("--sizes {s:?}: {p:?} is not a multiple of 32 ≥ 32"))
        })
        .collect()
}

fn preamble(o: &BenchOptions, done: usize, total: usize, t0: Instant) -> String {
    let e = o.effort;
    format!(
        "# Model bench\n\n{done} of {total} rows on {} ({} threads available), device {:?}; \
         latency: batch 1, {} warm-up + {} timed runs (median, p10, p90); training: batch \
         {}, 1 warm-up + {} timed steps (median); peak memory: RSS high-water mark of a fresh \
         process per row. AP: test split of each checkpoint (`chicktrain eval --split test`). \
         Took {:.0} s.",
        std::env::consts::ARCH,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        o.device,
        e.warmup,
        e.repeats,
        e.train_batch,
        e.train_steps,
        t0.elapsed().as_secs_f64()
    )
}

/// `chicktrain bench models`.
pub fn bench_models(o: &BenchOptions, quiet: bool) -> Result<String> {
    if o.checkpoints.is_empty() && (o.variants.is_empty() || o.sizes.is_empty()) {
        bail!("nothing to measure: give --variants and --sizes, or --checkpoints");
    }
    // Read every checkpoint first: a bad path fails before minutes of timing.
    let cks = o
        .checkpoints
        .iter()
        .map(|p| crate::infer::checkpoint::Checkpoint::load(p).map(|c| (p, c.header.model)))
        .collect::<Result<Vec<_>>>()?;
    let mut rows = Vec::new();
    let total = o.variants.len() * o.sizes.len() + o.checkpoints.len();
    let t0 = Instant::now();
    let mut k = 0;
    let mut note = |label: &str, size: usize| {
        k += 1;
        if !quiet {
            eprintln!(
                "bench {k}/{total}: {label} at {size} px ({:.0} s so far)",
                t0.elapsed().as_secs_f64()
            );
        }
    };
    for v in &o.variants {
        for &s in &o.sizes {
            note(&v.to_string(), s);
            let m = measure_in_child(&o.exe, v, s, o.effort, o.device)?;
            rows.push(Row {
                label: v.to_string(),
                m,
                acc: None,
            });
            // Rewritten after every row, so a stopped bench keeps what it measured.
            write_report(&o.out, &rows, &preamble(o, rows.len(), total, t0))?;
        }
    }
    for (ck, model) in cks {
        let v = Variant::of_detector(&model);
        let size = model.input_size();
        note(&format!("{} ({v})", ck.display()), size);
        let acc = checkpoint_accuracy(ck, Some(o.device))?;
        let m = measure_in_child(&o.exe, &v, size, o.effort, o.device)?;
        rows.push(Row {
            label: v.to_string(),
            m,
            acc: Some(acc),
        });
        write_report(&o.out, &rows, &preamble(o, rows.len(), total, t0))?;
    }
    write_report(&o.out, &rows, &preamble(o, rows.len(), total, t0))?;
    finished_report(&o.out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_sizes("256, 320").unwrap(), vec![256, 320]);
        assert!(parse_sizes("250").is_err());
        assert!(parse_sizes("0").is_err());
    }

    #[test]
    fn default_and_quick_variants_parse() {
        assert_eq!(default_variants().len(), 12);
        let mut o = BenchOptions {
            variants: vec![],
            sizes: vec![],
            effort: Effort::default(),
            checkpoints: vec![],
            out: PathBuf::new(),
            device: DeviceKind::Flex,
            exe: PathBuf::new(),
        };
        quick(&mut o);
        assert_eq!(o.variants.len(), 3);
    }
}
