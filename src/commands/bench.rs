//! The measurement commands: `bench models`, `bench engines`, `bench loader`, `bench
//! convs` and the hidden per-row `bench model-worker`. The training studies (`sweep`, `bench ablation`,
//! `bench transfer`) take their flags straight from `experiments/`, whose option structs
//! derive clap's `Args`. Defaults that depend on several flags at once (which grid, which
//! folder) are decided here, not in `main`.

use std::path::PathBuf;

use anyhow::Result;

use crate::bench::convs::{self, ConvsArgs};
use crate::bench::effort::EffortFlags;
use crate::bench::engines::bench_engines;
use crate::bench::measure::Effort;
use crate::bench::models as bm;
use crate::bench::models::parse_sizes;
use crate::bench::variant::Variant;
use crate::bench::worker::{this_exe, worker};
use crate::config::{self, DeviceKind};
/// `chicktrain sweep` is the experiment itself: [`sweep`] over [`SweepOptions`], the
/// counts parsed by [`parse_counts`].
pub use crate::experiments::sweep::{parse_counts, sweep, SweepOptions};
use crate::util::all_cores;

/// `bench models` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct ModelsRequest {
    /// Comma-separated variants: yolo-n, yolo-s, suffixes -p45 -nopsa -w<f> -m<k>;
    /// mrcnn-r18/r34/r50/r101, suffix -paper for the detectron2-sized preset;
    /// m2f-r18/r34/r50/r101 (Mask2Former), suffix -paper for the paper's sizes
    /// (default: all scene options and compact depths).
    #[arg(long)]
    pub variants: Option<String>,
    /// Comma-separated input sizes (default 256,320,416,512,640).
    #[arg(long)]
    pub sizes: Option<String>,
    /// Trained checkpoints (best.bpk) to score on their test split and time.
    #[arg(long, num_args = 1..)]
    pub checkpoints: Vec<PathBuf>,
    /// A couple of minutes: 3 variants, 256 and 320 px, 5 repeats, 1 training step
    /// (--variants / --sizes still override).
    #[arg(long)]
    pub quick: bool,
    /// Report folder name under runs/bench/ (default: models, or quick).
    #[arg(long)]
    pub name: Option<String>,
    /// Report folder (overrides --name).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub effort: EffortFlags,
    /// Device of the measurements: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long, default_value = "flex")]
    pub device: DeviceKind,
    /// No progress lines, only the report.
    #[arg(long)]
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

/// `bench loader` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct LoaderRequest {
    /// Config file, or the name of a shipped config.
    #[arg(long, default_value = "quickstart.toml")]
    pub config: String,
    /// Override a config key (repeatable), e.g. data.fresh_synthetic=true.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Batches to time (they run on across epochs).
    #[arg(long, default_value_t = 50)]
    pub batches: usize,
    /// Loader threads (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// `chicktrain bench loader`: the report's lines.
pub fn loader_cmd(r: &LoaderRequest) -> Result<String> {
    let cfg = config::load(&r.config, &r.overrides)?;
    Ok(crate::bench::loader::bench_loader(&cfg, r.batches, r.threads)?.report(&r.config))
}

/// `bench convs` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct ConvsRequest {
    /// Comma-separated input sizes, multiples of 64.
    #[arg(long, default_value = "256,640")]
    pub sizes: String,
    /// Comma-separated models: yolo11n-seg, maskrcnn-r18.
    #[arg(long, default_value = "yolo11n-seg,maskrcnn-r18")]
    pub models: String,
    /// Images per convolution call.
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// Interleaved repeats per pass (the median is reported).
    #[arg(long, default_value_t = 10)]
    pub repeats: usize,
    /// Clock in GHz for the peak FLOP/s (default: the first `cpu MHz` of /proc/cpuinfo).
    #[arg(long)]
    pub ghz: Option<f64>,
    /// Folder for convs.csv and convs.md.
    #[arg(long, default_value = "bench/results/convs")]
    pub out: PathBuf,
}

/// `chicktrain bench convs`: the markdown report (also written under `--out`).
pub fn convs_cmd(r: &ConvsRequest) -> Result<String> {
    let args = ConvsArgs {
        sizes: parse_sizes(&r.sizes)?,
        models: r.models.split(',').map(|m| m.trim().to_string()).collect(),
        batch: r.batch,
        repeats: r.repeats,
        ghz: r.ghz,
    };
    convs::run(&args, &r.out)
}

/// `bench model-worker` (hidden): the row `bench models` asks a fresh process for.
#[derive(Clone, Debug, clap::Args)]
pub struct WorkerRequest {
    /// The variant of the row (see `bench models --help`).
    #[arg(long)]
    pub variant: String,
    /// The input size of the row.
    #[arg(long)]
    pub size: usize,
    #[command(flatten)]
    pub effort: EffortFlags,
    /// Device of the measurement: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long, default_value = "flex")]
    pub device: DeviceKind,
}

/// `chicktrain bench model-worker`: one row, as a JSON line.
pub fn model_worker(r: &WorkerRequest) -> Result<String> {
    worker(
        &r.variant,
        r.size,
        r.effort.over(Effort::default()),
        r.device,
    )
}

/// `bench engines` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct EnginesRequest {
    /// Comma-separated YOLO variants (see `bench models --help`).
    #[arg(long, default_value = "yolo-n")]
    pub variants: String,
    /// Comma-separated input sizes.
    #[arg(long, default_value = "256,640")]
    pub sizes: String,
    /// Timed runs per engine and size; the median is reported.
    #[arg(long, default_value_t = 10)]
    pub repeats: usize,
    /// Untimed runs before the timed ones.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// tract threads (default: every core; flex always uses every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Also write each exported file here (<variant>_<size>.onnx).
    #[arg(long)]
    pub save_onnx: Option<PathBuf>,
}

/// `chicktrain bench engines --variants yolo-n --sizes 256,640`: flex vs tract latency.
pub fn bench_engines_cmd(r: &EnginesRequest) -> Result<String> {
    let vs = r
        .variants
        .split(',')
        .map(|v| v.trim().parse())
        .collect::<Result<Vec<Variant>>>()?;
    let sizes = parse_sizes(&r.sizes)?;
    bench_engines(
        &vs,
        &sizes,
        r.warmup,
        r.repeats,
        r.threads.unwrap_or_else(all_cores),
        r.save_onnx.as_deref(),
    )
}
