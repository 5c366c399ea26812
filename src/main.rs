//! The `chicktrain` binary: flags in, one library call, errors printed once.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

use chicktrain::cli;
use chicktrain::config::DeviceKind;
use chicktrain::eval::IouType;
use chicktrain::train::commands::{self, SplitName};
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
    /// Override the config's device.
    #[arg(long, value_enum)]
    device: Option<DeviceArg>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum DeviceArg {
    Flex,
    Ndarray,
}

impl From<DeviceArg> for DeviceKind {
    fn from(d: DeviceArg) -> DeviceKind {
        match d {
            DeviceArg::Flex => DeviceKind::Flex,
            DeviceArg::Ndarray => DeviceKind::Ndarray,
        }
    }
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
            device: self.device.map(Into::into),
            quiet: false,
        };
        cli::train(&c, &self.set, &opts)
    }
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
        /// Print {"bbox": {"stats": [12]}, "segm": {"stats": [12]}}.
        #[arg(long)]
        json: bool,
        #[arg(long, value_enum)]
        device: Option<DeviceArg>,
    },
    /// Predict masks on an image or a folder of images: overlay PNGs + COCO results JSON.
    Predict {
        #[arg(long)]
        checkpoint: PathBuf,
        /// An image file or a folder of .jpg/.png images.
        #[arg(long)]
        input: PathBuf,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum)]
        device: Option<DeviceArg>,
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
    },
    /// Measure speed: `bench coco` times the COCO evaluator on a GT/DT pair.
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
    /// Convert between annotation formats.
    Convert {
        #[command(subcommand)]
        what: ConvertWhat,
    },
}

#[derive(Subcommand)]
enum BenchWhat {
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
            json,
            device,
        }) => commands::eval_cmd(
            &checkpoint,
            split,
            data.as_deref(),
            device.map(Into::into),
            json,
        ),
        Some(Command::Predict {
            checkpoint,
            input,
            out,
            device,
        }) => commands::predict_cmd(&checkpoint, &input, &out, device.map(Into::into)),
        Some(Command::Render {
            out,
            count,
            seed,
            size,
            preset,
            carcass,
        }) => cli::render(&out, count, seed, size, &preset, carcass),
        Some(Command::Bench { what }) => match what {
            BenchWhat::Coco { gt, dt, repeats } => cli::bench_coco(&gt, &dt, repeats),
            BenchWhat::Render {
                size,
                images,
                preset,
                seed,
            } => cli::bench_render(size, images, &preset, seed),
        },
        Some(Command::CocoEval {
            gt,
            dt,
            iou_type,
            json,
        }) => cli::coco_eval(&gt, &dt, iou_type, json),
        Some(Command::Convert { what }) => match what {
            ConvertWhat::Labelme { dir, out, labels } => {
                cli::convert_labelme(&dir, labels.as_deref(), &out)
            }
            ConvertWhat::Coco2yolo { coco, out } => cli::convert_coco2yolo(&coco, &out),
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
