//! The command tree the binary parses: each subcommand holds the request struct of its
//! library function (every request derives clap's `Args`, so a flag is written once,
//! beside the field it fills), and [`Cli::run`] hands it over. It lives in the library
//! so tests can walk the tree (every argument has a help line) without the binary.

use clap::{Args, Parser, Subcommand};

use super::bench::{self as bench_cmd, ConvsRequest, LoaderRequest, ModelsRequest, WorkerRequest};
use super::bench::{bench_engines_cmd, EnginesRequest};
use super::data::{
    self, BenchCocoRequest, BenchRenderRequest, Coco2yoloRequest, CocoEvalRequest, LabelmeRequest,
    RenderRequest,
};
use super::eval::{eval_cmd, EvalRequest};
use super::export::{export_cmd, ExportRequest};
use super::predict::{predict, PredictRequest};
use crate::experiments::ablation::{ablation, AblationOptions};
use crate::experiments::sweep::{sweep, SweepOptions};
use crate::experiments::transfer::{transfer, TransferOptions};
use crate::train::trainer::TrainOptions;

/// Train instance segmentation of chicken carcass piles from real + rendered images.
///
/// `chicktrain --config configs/X.toml` is the same as `chicktrain train --config …`.
#[derive(Parser)]
#[command(name = "chicktrain", version, args_conflicts_with_subcommands = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub train: TrainArgs,
}

/// `train`'s flags: the config, its overrides, and how to run it.
#[derive(Args, Clone, Debug)]
pub struct TrainArgs {
    /// Config file, or the name of a shipped config (e.g. yolo_syn1000.toml).
    #[arg(long)]
    pub config: Option<String>,
    /// Override a config key, e.g. --set train.epochs=5 (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    #[command(flatten)]
    pub opts: TrainOptions,
}

impl TrainArgs {
    fn run(&self) -> anyhow::Result<String> {
        let Some(c) = &self.config else {
            anyhow::bail!("train needs --config FILE (or a shipped name like quickstart.toml)")
        };
        super::train::train_cmd(c, &self.set, &self.opts)
    }
}

#[derive(Subcommand)]
pub enum Command {
    /// Train a model from a config (render, mix, train, evaluate every epoch, checkpoint).
    Train(TrainArgs),
    /// Evaluate a checkpoint on a split of the data it was trained with (COCO bbox + segm).
    Eval(EvalRequest),
    /// Predict masks on an image or a folder of images: overlay PNGs + COCO results JSON
    /// (+ YOLO-seg txt with --save-txt).
    Predict(PredictRequest),
    /// Export a checkpoint for other tools: ONNX (YOLO: ultralytics' layout; Mask R-CNN:
    /// three graphs) or safetensors (ultralytics' / torchvision's key names).
    Export(ExportRequest),
    /// Render auto-labelled carcass piles: images/, annotations.json (COCO), preview.png.
    Render(RenderRequest),
    /// Measure: `bench models` (model variants × sizes), `bench engines` (flex vs tract),
    /// `bench ablation` (what the scene needs), `bench transfer` (what transfers to an
    /// external set), `bench render` (the renderer), `bench loader` (the training loader),
    /// `bench coco` (the COCO evaluator), `bench convs` (flex's convolutions).
    Bench {
        #[command(subcommand)]
        what: BenchWhat,
    },
    /// COCO evaluation of a results file, identical to pycocotools' COCOeval.
    CocoEval(CocoEvalRequest),
    /// The paper's experiment: train a config with each synthetic-image count and several
    /// seeds, score each run on its test split, and report mean ± std (runs/sweep/<name>/).
    Sweep(SweepOptions),
    /// Convert between annotation formats.
    Convert {
        #[command(subcommand)]
        what: ConvertWhat,
    },
}

#[derive(Subcommand)]
pub enum BenchWhat {
    /// Model variants × input sizes: parameters, GFLOPs, batch-1 latency, training
    /// images/s, peak memory (a fresh process per row), and test AP of --checkpoints.
    Models(ModelsRequest),
    /// Batch-1 inference latency of YOLO variants on flex vs tract (the ONNX export of
    /// the same weights), and their max output difference.
    Engines(EnginesRequest),
    /// Scene ablation: train one variant per dropped/shrunk model option, report test AP
    /// vs latency and a recommended default (runs/ablation/<config name>/).
    Ablation(AblationOptions),
    /// Transfer ablation: train the base config and one variant per randomisation group
    /// and per augmentation turned off, N seeds each at the same optimiser steps, score
    /// every best.bpk on an external set, report mean ± std (runs/transfer/<config name>/).
    Transfer(TransferOptions),
    /// One (variant, size) measurement as a JSON line (what `bench models` runs per row).
    #[command(hide = true)]
    ModelWorker(WorkerRequest),
    /// Renderer speed: images/s with shadows and masks, and where the time goes.
    Render(BenchRenderRequest),
    /// Training loader speed: a config's batches (read or render, augment, collate)
    /// built as its run would, with no model; what a device can consume before it waits.
    Loader(LoaderRequest),
    /// Time load + evaluate + accumulate (bbox and segm) on a GT/DT pair.
    Coco(BenchCocoRequest),
    /// Every convolution shape of YOLO11n-seg and Mask R-CNN R18 timed alone on flex: the
    /// convolution engine beside the path it replaced, forward and both gradients, in
    /// GFLOP/s and % of the machine's peak (issue 37).
    Convs(ConvsRequest),
}

#[derive(Subcommand)]
pub enum ConvertWhat {
    /// A folder of LabelMe .json files → one COCO instances file.
    Labelme(LabelmeRequest),
    /// A COCO instances file → YOLO-seg label files (ultralytics format).
    Coco2yolo(Coco2yoloRequest),
}

impl Cli {
    /// Runs the parsed command; returns the text to print.
    pub fn run(self) -> anyhow::Result<String> {
        let Some(command) = self.command else {
            return match self.train.config {
                Some(_) => self.train.run(),
                None => {
                    anyhow::bail!("nothing to do: give --config FILE or a subcommand (see --help)")
                }
            };
        };
        match command {
            Command::Train(t) => t.run(),
            Command::Eval(r) => eval_cmd(&r),
            Command::Predict(r) => predict(&r),
            Command::Export(r) => export_cmd(&r),
            Command::Render(r) => data::render(&r),
            Command::Bench { what } => what.run(),
            Command::CocoEval(r) => data::coco_eval(&r),
            Command::Sweep(r) => sweep(&r),
            Command::Convert { what } => match what {
                ConvertWhat::Labelme(r) => data::convert_labelme(&r),
                ConvertWhat::Coco2yolo(r) => data::convert_coco2yolo(&r),
            },
        }
    }
}

impl BenchWhat {
    fn run(self) -> anyhow::Result<String> {
        match self {
            BenchWhat::Models(r) => bench_cmd::models(r),
            BenchWhat::Engines(r) => bench_engines_cmd(&r),
            BenchWhat::Ablation(r) => ablation(&r),
            BenchWhat::Transfer(r) => transfer(&r),
            BenchWhat::ModelWorker(r) => bench_cmd::model_worker(&r),
            BenchWhat::Render(r) => data::bench_render(&r),
            BenchWhat::Loader(r) => bench_cmd::loader_cmd(&r),
            BenchWhat::Coco(r) => data::bench_coco(&r),
            BenchWhat::Convs(r) => bench_cmd::convs_cmd(&r),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every argument of every (sub)command, hidden ones included, as `path: --name`,
    /// where it has no help line.
    fn undocumented(cmd: &clap::Command, path: &str, out: &mut Vec<String>) {
        for a in cmd.get_arguments() {
            let builtin = matches!(a.get_id().as_str(), "help" | "version");
            if !builtin && a.get_help().is_none() && a.get_long_help().is_none() {
                out.push(format!("{path}: {}", a.get_id()));
            }
        }
        for s in cmd.get_subcommands() {
            if s.get_about().is_none() && s.get_name() != "help" {
                out.push(format!("{path} {}: (no about)", s.get_name()));
            }
            undocumented(s, &format!("{path} {}", s.get_name()), out);
        }
    }

    #[test]
    fn every_flag_argument_and_subcommand_has_a_help_line() {
        let cmd = Cli::command();
        cmd.clone().debug_assert();
        let mut missing = Vec::new();
        undocumented(&cmd, "chicktrain", &mut missing);
        assert!(missing.is_empty(), "no help line: {missing:#?}");
        // The walk reaches the leaves (a tree it could not descend would pass vacuously).
        let bench = cmd.find_subcommand("bench").expect("bench");
        assert!(bench.find_subcommand("transfer").is_some());
        assert!(cmd.get_subcommands().count() >= 9);
    }

    #[test]
    fn the_bench_summary_names_every_bench_subcommand() {
        let cmd = Cli::command();
        let bench = cmd.find_subcommand("bench").expect("bench");
        let about = bench.get_about().expect("about").to_string();
        for s in bench.get_subcommands().filter(|s| !s.is_hide_set()) {
            let name = s.get_name();
            if name != "help" {
                assert!(
                    about.contains(&format!("`bench {name}`")),
                    "{about:?} omits {name}"
                );
            }
        }
    }
}
