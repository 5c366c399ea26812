//! The `chicktrain` binary: flags in, one library call, errors printed once.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

use chicktrain::commands::bench::{self as bench_cmd, EffortFlags};
use chicktrain::commands::data;
use chicktrain::commands::export as export_cmd;
use chicktrain::commands::train::{self as train_cmd, SplitName};
use chicktrain::config::DeviceKind;
use chicktrain::eval::IouType;
use chicktrain::train::trainer::TrainOptions;

/// Train instance segmentation of chicken carcass piles from real + rendered images.
///
/// `chicktrain --config configs/X.toml` is the same as `chicktrain train --config …`.
#[derive(Parser)]
#[command(name = "chicktrain", version, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    train: TrainArgs,
}

#[derive(Args, Clone)]
struct TrainArgs {
    /// Config file, or the name of a shipped config (e.g. yolo_syn1000.toml).
    #[arg(long)]
    config: Option<String>,
    /// Override a config key, e.g. --set train.epochs=5 (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Write outputs here instead of runs/<name>/.
    #[arg(long)]
    run_dir: Option<PathBuf>,
    /// Shrink the config to a ~1 minute run that still goes through every stage.
    #[arg(long)]
    smoke: bool,
    /// Continue the run from <run dir>/last.bpk.
    #[arg(long)]
    resume: bool,
    /// Override the config's device: flex, ndarray, cuda[:N] or wgpu.
    #[arg(long)]
    device: Option<DeviceKind>,
}

impl TrainArgs {
    fn run(self) -> anyhow::Result<String> {
        let Some(c) = self.config else {
            anyhow::bail!("train needs --config FILE (or a shipped name like quickstart.toml)")
        };
        let opts = TrainOptions {
            run_dir: self.run_dir,
            resume: self.resume,
            smoke: self.smoke,
            device: self.device,
            quiet: false,
        };
        train_cmd::train_cmd(&c, &self.set, &opts)
    }
}

/// `export --format`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum ExportFormatArg {
    Onnx,
    Safetensors,
}

#[derive(Subcommand)]
enum Command {
    /// Train a model from a config (render, mix, train, evaluate every epoch, checkpoint).
    Train(TrainArgs),
    /// Evaluate a checkpoint on a split of the data it was trained with (COCO bbox + segm).
    Eval {
        /// A best.bpk / last.bpk written by `train`.
        #[arg(long)]
        checkpoint: PathBuf,
        #[arg(long, value_enum, default_value = "val")]
        split: SplitName,
        /// Evaluate on the real data of this config instead of the checkpoint's own.
        #[arg(long, value_name = "CONFIG")]
        data: Option<String>,
        /// Letterbox the images to this square size (a multiple of 32) instead of the
        /// size the checkpoint was trained at.
        #[arg(long)]
        imgsz: Option<usize>,
        /// Print {"bbox": {"stats": [12]}, "segm": {"stats": [12]}}.
        #[arg(long)]
        json: bool,
        /// Test-time augmentation: score each image in its eight top-view symmetries
        /// (quarter turns, mirrored) and fuse the detections (8× the inference time).
        #[arg(long)]
        augment: bool,
        #[arg(long)]
        device: Option<DeviceKind>,
    },
    /// Predict masks on an image or a folder of images: overlay PNGs + COCO results JSON.
    Predict {
        /// A best.bpk / last.bpk written by `train`.
        #[arg(long, required_unless_present = "onnx", conflicts_with = "onnx")]
        checkpoint: Option<PathBuf>,
        /// An ONNX file written by `export --format onnx`, run through tract.
        #[arg(long)]
        onnx: Option<PathBuf>,
        /// An image file or a folder of .jpg/.png images.
        #[arg(long)]
        input: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// Keep detections scoring above this.
        #[arg(long, default_value_t = train_cmd::PREDICT_CONF)]
        conf: f32,
        /// Threads of the tract engine (`--onnx`; default: every core).
        #[arg(long)]
        threads: Option<usize>,
        #[arg(long, conflicts_with = "onnx")]
        device: Option<DeviceKind>,
        /// Letterbox the images to this square size (a multiple of 32) instead of the
        /// size the checkpoint was trained at (`--checkpoint`; an ONNX graph has its own).
        #[arg(long, conflicts_with = "onnx")]
        imgsz: Option<usize>,
        /// Test-time augmentation: predict on each image's eight top-view symmetries
        /// (quarter turns, mirrored) and fuse the detections (8× the inference time; a
        /// fused score is the views' mean, so `--conf` applies to that mean too).
        #[arg(long)]
        augment: bool,
    },
    /// Export a checkpoint for other tools: ONNX (YOLO: ultralytics' layout; Mask R-CNN:
    /// three graphs) or safetensors (ultralytics' / torchvision's key names).
    Export {
        #[arg(long)]
        checkpoint: PathBuf,
        #[arg(long, value_enum)]
        format: ExportFormatArg,
        /// Output file (default: the checkpoint's path with .onnx / .safetensors).
        #[arg(long)]
        out: Option<PathBuf>,
        /// ONNX: a symbolic batch dimension instead of a fixed one.
        #[arg(long)]
        dynamic: bool,
        /// ONNX: batch size of a static graph (and of the reference input).
        #[arg(long, default_value_t = 1)]
        batch: usize,
        /// ONNX: also write <out>.reference.safetensors (a seeded input and chicktrain's
        /// outputs for it; `bench/onnx_check.py` compares ONNX Runtime against them).
        #[arg(long)]
        reference: bool,
    },
    /// Render auto-labelled carcass piles: images/, annotations.json (COCO), preview.png.
    Render {
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Number of images.
        #[arg(long, default_value_t = 16)]
        count: u32,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Image side in pixels.
        #[arg(long, default_value_t = 640)]
        size: u32,
        /// `synthetic` (training renders) or `proxy-real` (the stand-in for real photos).
        #[arg(long, default_value = "synthetic")]
        preset: String,
        /// A carcass mesh (.glb, skinned or rigid) instead of the embedded one.
        #[arg(long)]
        carcass: Option<PathBuf>,
        /// Domain-randomisation groups to switch on: a comma list of carcass, scene,
        /// distractors, lighting, camera, physics, or `all` / `none`.
        #[arg(long, default_value = "none")]
        randomize: String,
    },
    /// Measure speed: `bench models` (model variants × sizes), `bench ablation` (what the
    /// scene needs), `bench coco` (the COCO evaluator), `bench render` (the renderer),
    /// `bench loader` (the training loader).
    Bench {
        #[command(subcommand)]
        what: BenchWhat,
    },
    /// COCO evaluation of a results file, identical to pycocotools' COCOeval.
    CocoEval {
        /// Ground-truth COCO instances file.
        #[arg(long)]
        gt: PathBuf,
        /// Detections (COCO results JSON: a list of detections).
        #[arg(long)]
        dt: PathBuf,
        /// bbox or segm.
        #[arg(long, default_value = "segm")]
        iou_type: IouType,
        /// Print one JSON object with "stats" (the 12 numbers in pycocotools order).
        #[arg(long)]
        json: bool,
    },
    /// The paper's experiment: train a config with each synthetic-image count and several
    /// seeds, score each run on its test split, and report mean ± std (runs/sweep/<name>/).
    Sweep {
        /// Config file or shipped config name (e.g. yolo_real_baseline.toml).
        #[arg(long)]
        config: String,
        /// Synthetic-image counts, comma-separated.
        #[arg(long, default_value = "0,250,500,750,1000")]
        syn: String,
        /// Seeds per count (config seed, seed + 1, …).
        #[arg(long, default_value_t = 1)]
        seeds: usize,
        /// Override a config key in every run, e.g. --set train.epochs=20 (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Shrink every run to a ~1 minute smoke run.
        #[arg(long)]
        smoke: bool,
        /// Write the runs and the report here instead of runs/sweep/<name>/.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Train nothing: report the finished runs in the output folder and name the
        /// missing ones (for a sweep split over several processes or cut short).
        #[arg(long)]
        no_train: bool,
        #[arg(long)]
        device: Option<DeviceKind>,
        /// No progress bars or per-epoch lines.
        #[arg(long)]
        quiet: bool,
    },
    /// Convert between annotation formats.
    Convert {
        #[command(subcommand)]
        what: ConvertWhat,
    },
}

/// How much `bench models` / `bench ablation` measure per row (unset: the defaults of
/// `chicktrain::bench::measure::Effort`, or of `--quick`).
#[derive(Args, Clone, Copy)]
struct EffortArgs {
    /// Untimed batch-1 runs before the timed ones [default: 3].
    #[arg(long)]
    warmup: Option<usize>,
    /// Timed batch-1 inference runs; median, p10, p90 reported [default: 30].
    #[arg(long)]
    repeats: Option<usize>,
    /// Training batch size of the throughput column [default: 8].
    #[arg(long)]
    train_batch: Option<usize>,
    /// Timed training steps, after one warm-up step [default: 3].
    #[arg(long)]
    train_steps: Option<usize>,
}

impl From<EffortArgs> for EffortFlags {
    fn from(e: EffortArgs) -> EffortFlags {
        EffortFlags {
            warmup: e.warmup,
            repeats: e.repeats,
            train_batch: e.train_batch,
            train_steps: e.train_steps,
        }
    }
}

#[derive(Subcommand)]
enum BenchWhat {
    /// Model variants × input sizes: parameters, GFLOPs, batch-1 latency, training
    /// images/s, peak memory (a fresh process per row), and test AP of --checkpoints.
    Models {
        /// Comma-separated variants: yolo-n, yolo-s, suffixes -p45 -nopsa -w<f> -m<k>;
        /// mrcnn-r18/r34/r50/r101, suffix -paper for the detectron2-sized preset;
        /// m2f-r18/r34/r50/r101 (Mask2Former), suffix -paper for the paper's sizes
        /// (default: all scene options and compact depths).
        #[arg(long)]
        variants: Option<String>,
        /// Comma-separated input sizes (default 256,320,416,512,640).
        #[arg(long)]
        sizes: Option<String>,
        /// Trained checkpoints (best.bpk) to score on their test split and time.
        #[arg(long, num_args = 1..)]
        checkpoints: Vec<PathBuf>,
        /// A couple of minutes: 3 variants, 256 and 320 px, 5 repeats, 1 training step
        /// (--variants / --sizes still override).
        #[arg(long)]
        quick: bool,
        /// Report folder name under runs/bench/ (default: models, or quick).
        #[arg(long)]
        name: Option<String>,
        /// Report folder (overrides --name).
        #[arg(long)]
        out: Option<PathBuf>,
        #[command(flatten)]
        effort: EffortArgs,
        #[arg(long, default_value = "flex")]
        device: DeviceKind,
        #[arg(long)]
        quiet: bool,
    },
    /// Batch-1 inference latency of YOLO variants on flex vs tract (the ONNX export of
    /// the same weights), and their max output difference.
    Engines {
        /// Comma-separated YOLO variants (see `bench models --help`).
        #[arg(long, default_value = "yolo-n")]
        variants: String,
        #[arg(long, default_value = "256,640")]
        sizes: String,
        #[arg(long, default_value_t = 10)]
        repeats: usize,
        #[arg(long, default_value_t = 2)]
        warmup: usize,
        /// tract threads (default: every core; flex always uses every core).
        #[arg(long)]
        threads: Option<usize>,
        /// Also write each exported file here (<variant>_<size>.onnx).
        #[arg(long)]
        save_onnx: Option<PathBuf>,
    },
    /// Scene ablation: train one variant per dropped/shrunk model option, report test AP
    /// vs latency and a recommended default (runs/ablation/<config name>/).
    Ablation {
        #[arg(long, default_value = "cpu_protocol.toml")]
        config: String,
        /// Synthetic images added to the real training set of every variant.
        #[arg(long, default_value_t = 50)]
        syn: usize,
        /// Override a config key in every variant (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Comma-separated subset of: base, no_p3, no_c2psa, width_0.5, protos_16, px192, px320.
        #[arg(long)]
        variants: Option<String>,
        #[arg(long)]
        out: Option<PathBuf>,
        /// Only train the missing runs (no timing).
        #[arg(long)]
        train_only: bool,
        /// Never train: time every variant; AP where a finished run exists.
        #[arg(long)]
        no_train: bool,
        #[command(flatten)]
        effort: EffortArgs,
        #[arg(long, default_value = "flex")]
        device: DeviceKind,
        #[arg(long)]
        quiet: bool,
    },
    /// Transfer ablation: train the base config and one variant per randomisation group
    /// and per augmentation turned off, N seeds each at the same optimiser steps, score
    /// every best.bpk on an external set, report mean ± std (runs/transfer/<config name>/).
    Transfer {
        #[arg(long)]
        config: String,
        /// Data config of the set to score on, every image test (e.g.
        /// bench/crossdomain/crossdomain.toml).
        #[arg(long)]
        data_eval: String,
        /// Seeds per variant (config seed, seed + 1, …).
        #[arg(long, default_value_t = 1)]
        seeds: usize,
        /// Comma-separated subset, e.g. base,no-lighting,no-mosaic (default: all of
        /// base, no-<group> per randomisation group on, no-<aug> per augmentation on).
        #[arg(long)]
        variants: Option<String>,
        /// Override a config key in every run (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        #[arg(long)]
        out: Option<PathBuf>,
        /// Never train: score and report the finished runs, name the missing ones.
        #[arg(long)]
        no_train: bool,
        #[arg(long)]
        device: Option<DeviceKind>,
        #[arg(long)]
        quiet: bool,
    },
    /// One (variant, size) measurement as a JSON line (what `bench models` runs per row).
    #[command(hide = true)]
    ModelWorker {
        #[arg(long)]
        variant: String,
        #[arg(long)]
        size: usize,
        #[command(flatten)]
        effort: EffortArgs,
        #[arg(long, default_value = "flex")]
        device: DeviceKind,
    },
    /// Renderer speed: images/s with shadows and masks, and where the time goes.
    Render {
        #[arg(long, default_value_t = 640)]
        size: u32,
        #[arg(long, default_value_t = 12)]
        images: usize,
        #[arg(long, default_value = "synthetic")]
        preset: String,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Domain-randomisation groups to switch on (as for `render`).
        #[arg(long, default_value = "none")]
        randomize: String,
    },
    /// Training loader speed: a config's batches (read or render, augment, collate)
    /// built as its run would, with no model; what a device can consume before it waits.
    Loader {
        #[arg(long, default_value = "quickstart.toml")]
        config: String,
        /// Override a config key (repeatable), e.g. data.fresh_synthetic=true.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Batches to time (they run on across epochs).
        #[arg(long, default_value_t = 50)]
        batches: usize,
        /// Loader threads (default: every core).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Time load + evaluate + accumulate (bbox and segm) on a GT/DT pair.
    Coco {
        #[arg(long)]
        gt: PathBuf,
        #[arg(long)]
        dt: PathBuf,
        #[arg(long, default_value_t = 21)]
        repeats: usize,
    },
}

#[derive(Subcommand)]
enum ConvertWhat {
    /// A folder of LabelMe .json files → one COCO instances file.
    Labelme {
        dir: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// labelme's labels.txt (one label per line) to fix the category order.
        #[arg(long)]
        labels: Option<PathBuf>,
    },
    /// A COCO instances file → YOLO-seg label files (ultralytics format).
    Coco2yolo {
        coco: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
}

impl BenchWhat {
    fn run(self) -> anyhow::Result<String> {
        match self {
            BenchWhat::Coco { gt, dt, repeats } => data::bench_coco(&gt, &dt, repeats),
            BenchWhat::Loader {
                config,
                set,
                batches,
                threads,
            } => bench_cmd::loader_cmd(&config, &set, batches, threads),
            BenchWhat::Render {
                size,
                images,
                preset,
                seed,
                randomize,
            } => data::bench_render(size, images, &preset, seed, &randomize),
            BenchWhat::Models {
                variants,
                sizes,
                checkpoints,
                quick,
                name,
                out,
                effort,
                device,
                quiet,
            } => bench_cmd::models(bench_cmd::ModelsRequest {
                variants,
                sizes,
                checkpoints,
                quick,
                name,
                out,
                effort: effort.into(),
                device,
                quiet,
            }),
            BenchWhat::Engines {
                variants,
                sizes,
                repeats,
                warmup,
                threads,
                save_onnx,
            } => bench_cmd::bench_engines_cmd(
                &variants,
                &sizes,
                warmup,
                repeats,
                threads,
                save_onnx.as_deref(),
            ),
            BenchWhat::Ablation {
                config,
                syn,
                set,
                variants,
                out,
                train_only,
                no_train,
                effort,
                device,
                quiet,
            } => bench_cmd::ablation_cmd(bench_cmd::AblationRequest {
                config,
                synthetic: syn,
                overrides: set,
                variants,
                out,
                train_only,
                no_train,
                effort: effort.into(),
                device,
                quiet,
            }),
            BenchWhat::Transfer {
                config,
                data_eval,
                seeds,
                variants,
                set,
                out,
                no_train,
                device,
                quiet,
            } => bench_cmd::transfer_cmd(bench_cmd::TransferRequest {
                config,
                data_eval,
                seeds,
                variants,
                overrides: set,
                out,
                no_train,
                device,
                quiet,
            }),
            BenchWhat::ModelWorker {
                variant,
                size,
                effort,
                device,
            } => bench_cmd::model_worker(&variant, size, effort.into(), device),
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<String> {
    match cli.command {
        None => match cli.train.config {
            Some(_) => cli.train.run(),
            None => anyhow::bail!("nothing to do: give --config FILE or a subcommand (see --help)"),
        },
        Some(Command::Train(t)) => t.run(),
        Some(Command::Eval {
            checkpoint,
            split,
            data,
            imgsz,
            json,
            augment,
            device,
        }) => train_cmd::eval_cmd(
            &checkpoint,
            split,
            data.as_deref(),
            device,
            imgsz,
            json,
            augment,
        ),
        Some(Command::Predict {
            checkpoint,
            onnx,
            input,
            out,
            conf,
            threads,
            device,
            imgsz,
            augment,
        }) => match (checkpoint, onnx) {
            (_, Some(onnx)) => train_cmd::predict_onnx(&onnx, &input, &out, conf, threads, augment),
            (Some(c), None) => {
                train_cmd::predict_cmd(&c, &input, &out, conf, device, imgsz, augment)
            }
            (None, None) => anyhow::bail!("predict needs --checkpoint or --onnx"),
        },
        Some(Command::Export {
            checkpoint,
            format,
            out,
            dynamic,
            batch,
            reference,
        }) => export_cmd::export_cmd(&export_cmd::ExportRequest {
            checkpoint,
            format: match format {
                ExportFormatArg::Onnx => export_cmd::ExportFormat::Onnx,
                ExportFormatArg::Safetensors => export_cmd::ExportFormat::Safetensors,
            },
            out,
            batch,
            dynamic,
            reference,
        }),
        Some(Command::Render {
            out,
            count,
            seed,
            size,
            preset,
            carcass,
            randomize,
        }) => data::render(&out, count, seed, size, &preset, carcass, &randomize),
        Some(Command::Bench { what }) => what.run(),
        Some(Command::CocoEval {
            gt,
            dt,
            iou_type,
            json,
        }) => data::coco_eval(&gt, &dt, iou_type, json),
        Some(Command::Sweep {
            config,
            syn,
            seeds,
            set,
            smoke,
            out,
            no_train,
            device,
            quiet,
        }) => bench_cmd::sweep(&bench_cmd::SweepOptions {
            config,
            synthetic: bench_cmd::parse_counts(&syn)?,
            seeds,
            overrides: set,
            smoke,
            out,
            no_train,
            device,
            quiet,
        }),
        Some(Command::Convert { what }) => match what {
            ConvertWhat::Labelme { dir, out, labels } => {
                data::convert_labelme(&dir, labels.as_deref(), &out)
            }
            ConvertWhat::Coco2yolo { coco, out } => data::convert_coco2yolo(&coco, &out),
        },
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(msg) => {
            if !msg.is_empty() {
                println!("{}", msg.trim_end());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
