//! `chicktrain bench models`: size, speed and memory of each model variant × input size,
//! plus test AP of trained checkpoints, as a CSV, a markdown table and PNG plots.
//!
//! Every (variant, size) is measured in a fresh child process of the same binary (`bench
//! model-worker`, hidden), so the peak-memory high-water mark (`VmHWM`) of one variant
//! never includes another's, and allocator state does not carry over. A worker prints one
//! JSON [`Measurement`]:
//! - **latency**: batch-1 forward pass until the outputs are on the host, after warm-up
//!   runs; YOLO with BatchNorm folded (as deployed), its box decoding and NMS excluded
//!   (ultralytics' "inference" time); Mask R-CNN's `forward_infer`, which includes its
//!   proposal, box and mask stages. Median, 10th and 90th percentile.
//! - **training throughput**: images/s of full steps at batch 8 — forward, the real loss
//!   (task-aligned assigner + losses for YOLO; RPN + RoI losses for Mask R-CNN),
//!   backward, SGD step — on procedural scenes with 6 objects per image, median step.
//! - **peak memory**: the process' resident-set high-water mark after inference and
//!   after training (Linux `/proc/self/status`; `getrusage` elsewhere).

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::optim::momentum::MomentumConfig;
use burn::optim::{GradientsParams, SgdConfig};
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::DeviceKind;
use crate::data::ellipses::ellipse_batch;
use crate::eval::plots::{pareto_front, write_png, Mark, Panel, Series, PALETTE};
use crate::eval::report::{percentile, Table};
use crate::model::maskrcnn::MaskRcnnConfig;
use crate::model::yolo::loss::{yolo_loss, LossWeights};
use crate::model::yolo::{HeadLevels, Scale, YoloSegConfig};
use crate::train::detector::DetectorConfig;
use crate::train::device::device_of;
use crate::train::evaluate::SplitName;
use crate::train::run_files;
use crate::util::tensor::to_host;

/// A model variant by name: `yolo-<n|s>` with optional suffixes `-p45` (heads on P4–P5
/// only), `-nopsa` (no C2PSA attention), `-w<f>` (width multiplier), `-m<k>` (mask
/// prototypes); or `mrcnn-r<depth>` (the compact Mask R-CNN, ResNet 18/34/50/101).
#[derive(Clone, Debug, PartialEq)]
pub enum Variant {
    Yolo {
        scale: Scale,
        levels: HeadLevels,
        c2psa: bool,
        width: f64,
        protos: usize,
    },
    MaskRcnn {
        depth: usize,
    },
}

impl FromStr for Variant {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Variant> {
        let help = "expected yolo-n / yolo-s with optional -p45 -nopsa -w<f> -m<k> (e.g. yolo-n-p45-w0.5), or mrcnn-r18 / r34 / r50 / r101";
        let mut parts = s.split('-');
        match (parts.next(), parts.next()) {
            (Some("yolo"), Some(sc)) => {
                let scale: Scale = sc
                    .parse()
                    .map_err(|e: String| anyhow::anyhow!("variant {s:?}: {e}"))?;
                let mut v = Variant::Yolo {
                    scale,
                    levels: HeadLevels::P3P5,
                    c2psa: true,
                    width: 1.0,
                    protos: 32,
                };
                if let Variant::Yolo {
                    levels,
                    c2psa,
                    width,
                    protos,
                    ..
                } = &mut v
                {
                    for p in parts {
                        match p {
                            "p45" => *levels = HeadLevels::P4P5,
                            "nopsa" => *c2psa = false,
                            _ if p.starts_with('w') => {
                                *width = p[1..]
                                    .parse()
                                    .ok()
                                    .filter(|w: &f64| w.is_finite() && *w > 0.0)
                                    .with_context(|| {
                                        format!("variant {s:?}: bad width {p:?}; {help}")
                                    })?
                            }
                            _ if p.starts_with('m') => {
                                *protos =
                                    p[1..].parse().ok().filter(|&k| k > 0).with_context(|| {
                                        format!("variant {s:?}: bad prototype count {p:?}; {help}")
                                    })?
                            }
                            _ => bail!("variant {s:?}: unknown option {p:?}; {help}"),
                        }
                    }
                }
                Ok(v)
            }
            (Some("mrcnn"), Some(r)) if parts.next().is_none() => {
                let depth = r
                    .strip_prefix('r')
                    .and_then(|d| d.parse().ok())
                    .filter(|d| [18, 34, 50, 101].contains(d))
                    .with_context(|| format!("variant {s:?}: unknown depth; {help}"))?;
                Ok(Variant::MaskRcnn { depth })
            }
            _ => bail!("unknown model variant {s:?}; {help}"),
        }
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Variant::Yolo {
                scale,
                levels,
                c2psa,
                width,
                protos,
            } => {
                write!(f, "yolo-{}", scale.name())?;
                if *levels == HeadLevels::P4P5 {
                    write!(f, "-p45")?;
                }
                if !c2psa {
                    write!(f, "-nopsa")?;
                }
                if *width != 1.0 {
                    write!(f, "-w{width}")?;
                }
                if *protos != 32 {
                    write!(f, "-m{protos}")?;
                }
                Ok(())
            }
            Variant::MaskRcnn { depth } => write!(f, "mrcnn-r{depth}"),
        }
    }
}

impl Variant {
    /// The variant of a model config (e.g. a checkpoint's). A Mask R-CNN is timed as the
    /// compact model of its depth.
    pub fn of_detector(c: &DetectorConfig) -> Variant {
        match c {
            DetectorConfig::Yolo(c) => Variant::Yolo {
                scale: c.scale,
                levels: c.levels,
                c2psa: c.c2psa,
                width: c.width_mult,
                protos: c.num_masks,
            },
            DetectorConfig::Maskrcnn(c) => Variant::MaskRcnn { depth: c.depth },
        }
    }

    fn yolo_config(&self, size: usize) -> Option<YoloSegConfig> {
        match *self {
            Variant::Yolo {
                scale,
                levels,
                c2psa,
                width,
                protos,
            } => Some(
                YoloSegConfig::new(scale, 1)
                    .with_input_size(size)
                    .with_levels(levels)
                    .with_c2psa(c2psa)
                    .with_width_mult(width)
                    .with_num_masks(protos),
            ),
            Variant::MaskRcnn { .. } => None,
        }
    }
}

/// What one worker measured for one (variant, size).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    pub variant: String,
    pub size: usize,
    pub params: usize,
    pub gflops: f64,
    /// Batch-1 latency, ms: median, 10th and 90th percentile over `repeats` runs.
    pub latency_ms: [f64; 3],
    pub repeats: usize,
    /// Training images/s at `train_batch` (median over `train_steps` timed steps).
    pub train_img_s: f64,
    pub train_batch: usize,
    pub train_steps: usize,
    /// Resident-set high-water mark after inference, and after training, MiB.
    pub infer_peak_mib: f64,
    pub peak_mib: f64,
}

/// How much to measure per row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Effort {
    /// Untimed batch-1 runs first.
    pub warmup: usize,
    /// Timed batch-1 runs.
    pub repeats: usize,
    pub train_batch: usize,
    /// Timed training steps (after one untimed step).
    pub train_steps: usize,
}

impl Default for Effort {
    fn default() -> Effort {
        Effort {
            warmup: 3,
            repeats: 30,
            train_batch: 8,
            train_steps: 3,
        }
    }
}

/// The process' peak resident set so far, MiB.
pub fn peak_rss_mib() -> f64 {
    if let Ok(s) = std::fs::read_to_string("/proc/self/status") {
        if let Some(kb) = s
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        {
            return kb / 1024.0;
        }
    }
    rusage_peak_mib()
}

#[cfg(unix)]
fn rusage_peak_mib() -> f64 {
    // SAFETY: getrusage writes into the zeroed struct we own.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return f64::NAN;
    }
    // kB on Linux, bytes on macOS.
    let kb = if cfg!(target_os = "macos") {
        u.ru_maxrss as f64 / 1024.0
    } else {
        u.ru_maxrss as f64
    };
    kb / 1024.0
}

#[cfg(not(unix))]
fn rusage_peak_mib() -> f64 {
    f64::NAN
}

fn median(v: &[f64]) -> f64 {
    percentile(v, 50.0)
}

/// Measures `variant` at `size` in this process (what a worker runs).
pub fn measure(variant: &Variant, size: usize, e: Effort, device: &Device) -> Result<Measurement> {
    if size < 32 || size % 32 != 0 {
        bail!("input size {size} must be a multiple of 32, at least 32");
    }
    if e.repeats == 0 || e.train_batch == 0 {
        bail!("--repeats and the training batch must be at least 1");
    }
    device.seed(0);
    let ad = device.clone().autodiff();
    let (px1, _) = ellipse_batch(1, size, 6, 1);
    let x1 = Tensor::<4>::from_data(TensorData::new(px1, [1, 3, size, size]), device);
    let (pxb, targets) = ellipse_batch(e.train_batch, size, 6, 2);
    let xb = Tensor::<4>::from_data(TensorData::new(pxb, [e.train_batch, 3, size, size]), &ad);
    let mut optim = SgdConfig::new()
        .with_momentum(Some(
            MomentumConfig::new().with_momentum(0.9).with_dampening(0.0),
        ))
        .init();
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    let (mut lat, mut steps) = (Vec::new(), Vec::new());
    let (summary, infer_peak) = match variant {
        Variant::Yolo { .. } => {
            let cfg = variant.yolo_config(size).expect("a YOLO variant");
            let mut model = cfg.init(&ad);
            let summary = model.summary(size);
            let fused = model.valid().fuse();
            for r in 0..e.warmup + e.repeats {
                let t = Instant::now();
                let out = fused.forward(x1.clone());
                let _ = to_host(out.cls_logits);
                let _ = to_host(out.proto);
                if r >= e.warmup {
                    lat.push(ms(t));
                }
            }
            drop(fused);
            let infer_peak = peak_rss_mib();
            let w = LossWeights::default();
            for r in 0..1 + e.train_steps {
                let t = Instant::now();
                let out = model.forward(xb.clone());
                let loss = yolo_loss(&out, &targets, &w);
                let grads = GradientsParams::from_grads(loss.total.backward(), &model);
                model = optim.step(0.01, model, grads);
                let _ = to_host(model.head.boxes[0].out.weight.val().sum());
                if r >= 1 {
                    steps.push(ms(t));
                }
            }
            (summary, infer_peak)
        }
        Variant::MaskRcnn { depth } => {
            let cfg = MaskRcnnConfig::new(*depth, 1).with_input_size(size);
            let mut model = cfg.init(&ad);
            let summary = model.summary(size);
            let eval = model.valid();
            for r in 0..e.warmup + e.repeats {
                let t = Instant::now();
                let dets = eval.forward_infer(x1.clone());
                if dets.len() != 1 {
                    bail!("Mask R-CNN returned {} results for 1 image", dets.len());
                }
                if r >= e.warmup {
                    lat.push(ms(t));
                }
            }
            drop(eval);
            let infer_peak = peak_rss_mib();
            let mut rng = ChaCha8Rng::seed_from_u64(0);
            for r in 0..1 + e.train_steps {
                let t = Instant::now();
                let losses = model.forward_train(xb.clone(), &targets.images, &mut rng);
                let grads = GradientsParams::from_grads(losses.total.backward(), &model);
                model = optim.step(0.01, model, grads);
                let _ = to_host(model.box_head.cls_score.weight.val().sum());
                if r >= 1 {
                    steps.push(ms(t));
                }
            }
            (summary, infer_peak)
        }
    };
    Ok(Measurement {
        variant: variant.to_string(),
        size,
        params: summary.params,
        gflops: summary.gflops,
        latency_ms: [median(&lat), percentile(&lat, 10.0), percentile(&lat, 90.0)],
        repeats: e.repeats,
        train_img_s: if steps.is_empty() {
            f64::NAN
        } else {
            e.train_batch as f64 * 1e3 / median(&steps)
        },
        train_batch: e.train_batch,
        train_steps: e.train_steps,
        infer_peak_mib: infer_peak,
        peak_mib: peak_rss_mib(),
    })
}

/// `bench model-worker`: measures one (variant, size) and returns its JSON line.
pub fn worker(variant: &str, size: usize, e: Effort, device: DeviceKind) -> Result<String> {
    let v: Variant = variant.parse()?;
    let m = measure(&v, size, e, &device_of(device)?)?;
    Ok(serde_json::to_string(&m)?)
}

fn effort_args(e: Effort) -> Vec<String> {
    vec![
        "--warmup".into(),
        e.warmup.to_string(),
        "--repeats".into(),
        e.repeats.to_string(),
        "--train-batch".into(),
        e.train_batch.to_string(),
        "--train-steps".into(),
        e.train_steps.to_string(),
    ]
}

/// Runs `exe bench model-worker` for one (variant, size) and parses its line.
pub fn measure_in_child(
    exe: &Path,
    variant: &Variant,
    size: usize,
    e: Effort,
    device: DeviceKind,
) -> Result<Measurement> {
    let out = std::process::Command::new(exe)
        .args(["bench", "model-worker", "--variant", &variant.to_string()])
        .args(["--size", &size.to_string(), "--device", &device.to_string()])
        .args(effort_args(e))
        .output()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!(
            "measuring {variant} at {size} px failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let line = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(line)
        .with_context(|| format!("measuring {variant} at {size} px: bad worker output {line:?}"))
}

/// Test accuracy of a trained model and what its training took.
#[derive(Clone, Debug, PartialEq)]
pub struct Accuracy {
    pub bbox: [f64; 12],
    pub segm: [f64; 12],
    /// Sum of the epoch times of its run (`metrics.jsonl` next to the checkpoint).
    pub train_seconds: f64,
    /// Where the numbers come from (checkpoint or run folder).
    pub source: String,
}

/// One row of the bench report.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Row label (the variant, or an ablation name).
    pub label: String,
    pub m: Measurement,
    pub acc: Option<Accuracy>,
}

/// Test AP of a checkpoint on its own test split.
pub fn checkpoint_accuracy(ck: &Path, device: Option<DeviceKind>) -> Result<Accuracy> {
    let score = crate::train::evaluate::score_checkpoint(ck, SplitName::Test, None, device)?;
    Ok(Accuracy {
        bbox: score.stats.bbox,
        segm: score.stats.segm,
        train_seconds: run_files::train_seconds(ck.parent().unwrap_or(Path::new(".")))?,
        source: ck.display().to_string(),
    })
}

/// Test AP of a finished run folder (its `test.json`).
pub fn run_accuracy(dir: &Path) -> Result<Accuracy> {
    let t = run_files::read_test(dir)?;
    Ok(Accuracy {
        bbox: t.bbox.stats,
        segm: t.segm.stats,
        train_seconds: run_files::train_seconds(dir)?,
        source: dir.display().to_string(),
    })
}

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
    write_png(&out.join("speed.png"), &[lat, thr], 2, 440, 340)?;

    let with_ap: Vec<&Row> = rows.iter().filter(|r| r.acc.is_some()).collect();
    if !with_ap.is_empty() {
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
            let tags: Vec<String> = with_ap
                .iter()
                .map(|r| format!(" {} {}", r.label, r.m.size))
                .collect();
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
                        .tags(tags),
                ),
            );
        }
        write_png(&out.join("ap_vs_latency.png"), &panels, 2, 480, 360)?;
        let pts: Vec<(f64, f64)> = with_ap
            .iter()
            .map(|r| {
                let a = r.acc.as_ref().expect("filtered");
                (a.train_seconds / 60.0, a.segm[0])
            })
            .collect();
        let tags = with_ap
            .iter()
            .map(|r| format!(" {} {}", r.label, r.m.size))
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
                    .tags(tags),
            )],
            1,
            520,
            360,
        )?;
        md.push_str(&front_text);
    }
    crate::util::write_atomic(&out.join("bench.md"), md.as_bytes())
}

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

/// The default selection: every YOLO scene option and every Mask R-CNN depth × 5 sizes.
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
        .map(|p| crate::train::checkpoint::Checkpoint::load(p).map(|c| (p, c.header.model)))
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

/// The finished report's table plus where its files are: what `bench models` and
/// `bench ablation` print last.
pub(super) fn finished_report(out: &std::path::Path) -> Result<String> {
    let md = std::fs::read_to_string(out.join("bench.md"))?;
    Ok(format!(
        "{md}\nwrote bench.csv, bench.md and plots in {}",
        out.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_names_round_trip_and_reject_junk() {
        for s in [
            "yolo-n",
            "yolo-s-p45",
            "yolo-n-nopsa-w0.5-m16",
            "mrcnn-r101",
        ] {
            assert_eq!(s.parse::<Variant>().unwrap().to_string(), s);
        }
        let v: Variant = "yolo-n-m16-p45".parse().unwrap();
        assert_eq!(v.to_string(), "yolo-n-p45-m16");
        for bad in [
            "yolo",
            "yolo-x",
            "yolo-n-q",
            "yolo-n-w0",
            "yolo-n-m0",
            "mrcnn-r19",
            "rcnn",
        ] {
            let e = bad.parse::<Variant>().unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_sizes("256, 320").unwrap(), vec![256, 320]);
        assert!(parse_sizes("250").is_err());
        assert!(parse_sizes("0").is_err());
    }

    #[test]
    fn a_tiny_yolo_measures_in_process() {
        let v: Variant = "yolo-n-p45-w0.25-m4".parse().unwrap();
        let e = Effort {
            warmup: 0,
            repeats: 2,
            train_batch: 2,
            train_steps: 1,
        };
        let m = measure(&v, 64, e, &Device::flex()).unwrap();
        assert_eq!((m.variant.as_str(), m.size), ("yolo-n-p45-w0.25-m4", 64));
        assert!(m.params > 0 && m.gflops > 0.0);
        assert!(m.latency_ms[1] <= m.latency_ms[0] && m.latency_ms[0] <= m.latency_ms[2]);
        assert!(m.train_img_s > 0.0 && m.peak_mib >= m.infer_peak_mib && m.infer_peak_mib > 0.0);
        assert!(measure(&v, 70, e, &Device::flex()).is_err());
    }
}
