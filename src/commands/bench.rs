//! The measurement commands: `bench models`, `bench engines`, `bench ablation`, `bench transfer`, the hidden per-row
//! `bench model-worker`, and the paper's experiment `sweep`. Defaults that depend on
//! several flags at once (which grid, which folder) are decided here, not in `main`.

use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::bench::ablation::{ablation, AblationOptions};
use crate::bench::engines::bench_engines;
use crate::bench::measure::Effort;
use crate::bench::models as bm;
use crate::bench::models::parse_sizes;
use crate::bench::transfer::{transfer, TransferOptions};
use crate::bench::variant::Variant;
use crate::bench::worker::worker;
use crate::config::{self, DeviceKind};
/// `chicktrain sweep` is the experiment itself: [`sweep`] over [`SweepOptions`], the
/// counts parsed by [`parse_counts`].
pub use crate::experiments::sweep::{parse_counts, sweep, SweepOptions};
use crate::util::all_cores;

/// Per-row effort flags; unset ones keep the base (the defaults, or `--quick`'s).
#[derive(Clone, Copy, Debug, Default)]
pub struct EffortFlags {
    pub warmup: Option<usize>,
    pub repeats: Option<usize>,
    pub train_batch: Option<usize>,
    pub train_steps: Option<usize>,
}

impl EffortFlags {
    pub fn over(self, base: Effort) -> Effort {
        Effort {
            warmup: self.warmup.unwrap_or(base.warmup),
            repeats: self.repeats.unwrap_or(base.repeats),
            train_batch: self.train_batch.unwrap_or(base.train_batch),
            train_steps: self.train_steps.unwrap_or(base.train_steps),
        }
    }
}

/// The binary that runs the per-row worker processes.
fn this_exe() -> Result<PathBuf> {
    std::env::current_exe().map_err(|e| anyhow::anyhow!("cannot locate this binary: {e}"))
}

/// `bench models` as given on the command line.
#[derive(Clone, Debug)]
pub struct ModelsRequest {
    /// Comma-separated variants (None: the default grid).
    pub variants: Option<String>,
    /// Comma-separated sizes (None: the default sizes).
    pub sizes: Option<String>,
    pub checkpoints: Vec<PathBuf>,
    pub quick: bool,
    pub name: Option<String>,
    pub out: Option<PathBuf>,
    pub effort: EffortFlags,
    pub device: DeviceKind,
    pub quiet: bool,
}

/// `chicktrain bench models`.
pub fn models(r: ModelsRequest) -> Result<String> {
    // Checkpoints alone time just those models, not the whole default grid.
    let grid = r.checkpoints.is_empty() || r.quick || r.variants.is_some() || r.sizes.is_some();
    let (variants, sizes) = if grid {
        (bm::default_variants(), bm::DEFAULT_SIZES.to_vec())
    } else {
        (Vec::new(), Vec::new())
    };
    let mut o = bm::BenchOptions {
        variants,
        sizes,
        effort: Effort::default(),
        checkpoints: r.checkpoints,
        out: PathBuf::new(),
        device: r.device,
        exe: this_exe()?,
    };
    if r.quick {
        bm::quick(&mut o);
    }
    o.effort = r.effort.over(o.effort);
    if let Some(v) = r.variants {
        o.variants = v
            .split(',')
            .map(|s| s.trim().parse())
            .collect::<Result<_>>()?;
    }
    if let Some(s) = r.sizes {
        o.sizes = bm::parse_sizes(&s)?;
    }
    let name = r
        .name
        .unwrap_or_else(|| if r.quick { "quick" } else { "models" }.into());
    o.out = r
        .out
        .unwrap_or_else(|| PathBuf::from("runs/bench").join(name));
    bm::bench_models(&o, r.quiet)
}

/// `bench ablation` as given on the command line.
#[derive(Clone, Debug)]
pub struct AblationRequest {
    pub config: String,
    pub synthetic: usize,
    pub overrides: Vec<String>,
    /// Comma-separated variant names (None: all).
    pub variants: Option<String>,
    pub out: Option<PathBuf>,
    pub train_only: bool,
    pub no_train: bool,
    pub effort: EffortFlags,
    pub device: DeviceKind,
    pub quiet: bool,
}

/// `chicktrain bench ablation` (report in `runs/ablation/<config name>/` by default).
pub fn ablation_cmd(r: AblationRequest) -> Result<String> {
    let name = config::load(&r.config, &r.overrides)?.name;
    ablation(&AblationOptions {
        config: r.config,
        synthetic: r.synthetic,
        overrides: r.overrides,
        only: r
            .variants
            .map(|v| v.split(',').map(|s| s.trim().to_string()).collect())
            .unwrap_or_default(),
        out: r
            .out
            .unwrap_or_else(|| PathBuf::from("runs/ablation").join(name)),
        train_only: r.train_only,
        no_train: r.no_train,
        effort: r.effort.over(Effort::default()),
        device: r.device,
        exe: this_exe()?,
        quiet: r.quiet,
    })
}

/// `bench transfer` as given on the command line.
#[derive(Clone, Debug)]
pub struct TransferRequest {
    pub config: String,
    pub data_eval: String,
    pub seeds: usize,
    /// Comma-separated variant names (None: all).
    pub variants: Option<String>,
    pub overrides: Vec<String>,
    pub out: Option<PathBuf>,
    pub no_train: bool,
    pub device: Option<DeviceKind>,
    pub quiet: bool,
}

/// `chicktrain bench transfer` (report in `runs/transfer/<config name>/` by default).
pub fn transfer_cmd(r: TransferRequest) -> Result<String> {
    let name = config::load(&r.config, &r.overrides)?.name;
    transfer(&TransferOptions {
        config: r.config,
        data_eval: r.data_eval,
        seeds: r.seeds,
        only: r
            .variants
            .map(|v| {
                v.split(',')
                    .map(|s| s.trim().to_string())
                    .filter(|s| !s.is_empty())
                    .collect()
            })
            .unwrap_or_default(),
        overrides: r.overrides,
        out: r
            .out
            .unwrap_or_else(|| PathBuf::from("runs/transfer").join(name)),
        no_train: r.no_train,
        device: r.device,
        quiet: r.quiet,
    })
}

/// `chicktrain bench loader`: the report's lines.
pub fn loader_cmd(
    config: &str,
    overrides: &[String],
    batches: usize,
    threads: Option<usize>,
) -> Result<String> {
    let cfg = config::load(config, overrides)?;
    Ok(crate::bench::loader::bench_loader(&cfg, batches, threads)?.report(config))
}

/// `chicktrain bench model-worker`: one row, as a JSON line.
pub fn model_worker(
    variant: &str,
    size: usize,
    effort: EffortFlags,
    device: DeviceKind,
) -> Result<String> {
    worker(variant, size, effort.over(Effort::default()), device)
}

/// `chicktrain bench engines --variants yolo-n --sizes 256,640`: flex vs tract latency.
pub fn bench_engines_cmd(
    variants: &str,
    sizes: &str,
    warmup: usize,
    repeats: usize,
    threads: Option<usize>,
    save: Option<&Path>,
) -> Result<String> {
    let vs = variants
        .split(',')
        .map(|v| v.trim().parse())
        .collect::<Result<Vec<Variant>>>()?;
    let sizes = parse_sizes(sizes)?;
    bench_engines(
        &vs,
        &sizes,
        warmup,
        repeats,
        threads.unwrap_or_else(all_cores),
        save,
    )
}
