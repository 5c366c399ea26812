//! The one interface a model family implements ([`Family`]): its `[model]` table, how it
//! is built, its loss with named terms, its inference to [`Detection`]s, its freeze
//! stages, the foreign weights it starts from, its `--smoke` sizes, its `bench models`
//! names and probe. Everything outside `model/<family>/` reaches a family through this
//! trait; the families are registered in one list (`model/mod.rs`'s `with_families!`),
//! which builds the `[model]` enums here (`ModelKind`, `ModelConfig`) and the closed
//! enums in `infer::detector` (`Detector`, `DetectorConfig`) the trainer, the checkpoints
//! and the benches work on.
//!
//! The shape follows detectron2's `META_ARCH_REGISTRY` (a family is found by its config
//! `kind`, nothing else names it) with Rust's usual answer to Burn's constraints: the
//! trait is implemented by the model type itself (`impl Family for MaskRcnn`), its
//! associated types say which config builds it, and the enum at the registration point
//! dispatches (Burn modules are not object-safe, so there is no `dyn Family`).
//!
//! What is not here: the `[model]` table itself (`model/<family>/config.rs`, checked
//! through `model::section::ModelSection`), and the command side of export (`export/`:
//! loading the checkpoint, refusing a format a family lacks by name).

use std::fmt::Debug;
use std::path::Path;

use anyhow::{bail, Result};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::annotations::targets::Targets;
use crate::model::detection::{nms_detections, Detection};
use crate::model::summary::ModelSummary;
use crate::model::weights::{Applied, Format};

/// Loss of one training batch: the tensor to back-propagate and the host values of its
/// named terms (in [`Family::LOSS_NAMES`] order) and of the total.
pub struct StepLoss {
    pub total: Tensor<1>,
    pub terms: Vec<f32>,
    pub total_value: f32,
}

/// A family's training loss ([`Family::train_loss`]): the tensor to back-propagate, and
/// its terms read back to the host only when asked (a benchmark's step never asks).
pub trait TrainingLoss {
    /// The total alone.
    fn into_total(self) -> Tensor<1>;
    /// The total and the host values of the terms (syncs the device).
    fn into_step(self) -> StepLoss;
}

impl StepLoss {
    /// `values` are the terms in [`Family::LOSS_NAMES`] order, then the total.
    pub fn new(total: Tensor<1>, values: &[f32]) -> Self {
        let (total_value, terms) = values.split_last().expect("a loss has a total");
        StepLoss {
            total,
            terms: terms.to_vec(),
            total_value: *total_value,
        }
    }
}

/// The training loss of a batch with every random draw from `sample_seed`, so a step
/// does not depend on what ran before it.
pub fn seeded_loss<F: Family>(
    model: &F,
    images: Tensor<4>,
    targets: &Targets,
    sample_seed: u64,
) -> StepLoss {
    let mut rng = ChaCha8Rng::seed_from_u64(sample_seed);
    model.train_loss(images, targets, &mut rng).into_step()
}

/// What [`Family::load_foreign`] loaded: the model, the loader's account, one phrase
/// naming the source (`"PyTorch zip file, torchvision ResNet (backbone only)"`) and why
/// tensors that were not loaded keep their initialisation.
pub struct ForeignInit<M> {
    pub model: M,
    pub applied: Applied,
    pub what: String,
    pub fresh_why: &'static str,
}

/// What `export` hands a family's exporter: the checkpoint's facts and the command's
/// options.
pub struct ExportRequest<'a> {
    /// The checkpoint (for messages).
    pub checkpoint: &'a Path,
    /// The file to write (an exporter may write files beside it).
    pub out: &'a Path,
    pub class_names: &'a [String],
    /// COCO category id of each class.
    pub category_ids: &'a [u64],
    pub epoch: usize,
    /// ONNX: the batch of a static graph, a symbolic batch instead, and whether to write
    /// the reference file.
    pub batch: usize,
    pub dynamic: bool,
    pub reference: bool,
}

/// One export format of a family: writes `request.out` (and files beside it) and says
/// what it wrote.
pub type Exporter<F> = fn(&F, &<F as Family>::Config, &ExportRequest) -> Result<String>;

/// The export formats (`export --format`), for the registry's dispatch and messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportFormat {
    Onnx,
    Safetensors,
}

impl ExportFormat {
    /// The format in messages.
    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Onnx => "ONNX",
            ExportFormat::Safetensors => "safetensors",
        }
    }
}

/// A model family: implemented by its model type, which is a Burn [`Module`].
pub trait Family: Module + Sized {
    /// The family's typed model config (stored in checkpoint headers, so serde).
    type Config: Clone + Debug + PartialEq + Serialize + DeserializeOwned;
    /// The family's `[model]` table (`model/<family>/config.rs`).
    type Section;
    /// The loss of a training batch, with its named terms.
    type Loss: TrainingLoss;

    /// The family in messages: `"YOLO-seg"`, `"Mask R-CNN"`, `"Mask2Former"`.
    const NAME: &'static str;
    /// Names of the loss terms, as logged in `metrics.jsonl` (`loss.<name>`).
    const LOSS_NAMES: &'static [&'static str];
    /// The `bench models` names of the family, for the help and error text.
    const VARIANT_HELP: &'static str;

    /// The model of a validated `[model]` table at `input_size` px with `num_classes`.
    fn config(section: &Self::Section, input_size: usize, num_classes: usize) -> Self::Config;
    /// A freshly initialised model.
    fn build(config: &Self::Config, device: &Device) -> Self;
    fn num_classes_of(config: &Self::Config) -> usize;
    /// Square inference input size (px).
    fn input_size_of(config: &Self::Config) -> usize;
    fn set_input_size(config: &mut Self::Config, size: usize);
    /// One line naming the architecture.
    fn describe(config: &Self::Config) -> String;

    /// Module-path prefixes of the stages `train.freeze = n` freezes (`model::freeze`).
    fn frozen_prefixes(n: usize) -> Result<Vec<String>>;
    /// Whether the tensor at module path `path` depends on the class count (such tensors
    /// keep their initialisation when weights of another class count are loaded).
    fn class_dependent(path: &str) -> bool;
    /// `--smoke`: shrink the `[model]` table to a model that trains in seconds but still
    /// runs every code path of the family.
    fn smoke(section: &mut Self::Section);

    /// Training loss of a batch. `images` are `[B, 3, H, W]` in `[0, 1]`; `rng` drives
    /// every random draw of the step (anchor, RoI or point sampling).
    fn train_loss(&self, images: Tensor<4>, targets: &Targets, rng: &mut ChaCha8Rng) -> Self::Loss;
    /// Detections per image with score ≥ `conf` and the seconds of the network alone (call
    /// on the eval-mode, plain-device model).
    fn predict_timed(&self, images: Tensor<4>, conf: f32) -> (Vec<Vec<Detection>>, f64);
    /// Detections at `predict --conf --iou --max-det`: by default the family's own
    /// detections (its NMS already applied) through [`nms_detections`].
    fn predict_nms(
        &self,
        images: Tensor<4>,
        conf: f32,
        iou: f32,
        max_det: usize,
    ) -> Vec<Vec<Detection>> {
        self.predict_timed(images, conf)
            .0
            .into_iter()
            .map(|d| nms_detections(d, iou, max_det))
            .collect()
    }
    /// Parameters and GFLOPs at `input` px.
    fn summary_at(&self, input: usize) -> ModelSummary;

    /// `model.init` from a file of another framework (`format` is not a chicktrain
    /// checkpoint; those load through [`Self::class_dependent`] for every family). The
    /// default refuses, naming the family.
    fn load_foreign(
        self,
        _config: &Self::Config,
        path: &Path,
        format: Format,
        origin: &str,
    ) -> Result<ForeignInit<Self>> {
        let _ = path;
        bail!(
            "{origin}: a {} cannot start from a {}",
            Self::NAME,
            format.name()
        )
    }

    /// `export --format onnx`, if the family has it (`None`: `export` refuses, naming
    /// the family and those that export).
    const ONNX: Option<Exporter<Self>> = None;
    /// `export --format safetensors` (the state dict under the Python model's key
    /// names), if the family has it.
    const SAFETENSORS: Option<Exporter<Self>> = None;

    /// `bench models`: the model whose batch-1 inference is timed (by default the
    /// eval-mode model; YOLO folds its BatchNorms, as deployed).
    fn bench_model(&self) -> Self {
        self.valid()
    }
    /// `bench models`: one batch-1 inference of the [`Self::bench_model`], up to outputs
    /// on the host (what the family's latency means is said in `bench::measure`).
    fn bench_forward(&self, image: Tensor<4>) -> Result<()>;
    /// `bench models`: a sum over one weight the optimiser updates, read back after each
    /// training step so the step has really run on a lazy backend.
    fn probe(&self) -> Tensor<1>;
    /// `bench models`: the one-class config a variant name of this family names (`None`:
    /// not this family's name; an error: this family's prefix with a bad option).
    fn parse_variant(name: &str) -> Option<Result<Self::Config>>;
    /// The variant name a config is timed as (the inverse of [`Self::parse_variant`] on its
    /// presets).
    fn variant_name(config: &Self::Config) -> String;
    /// The one-class config [`Self::parse_variant`] gives for [`Self::variant_name`] of
    /// `config` (what a checkpoint's model is timed as).
    fn variant_config(config: &Self::Config) -> Self::Config;
}

/// The family's exporter of `format`, if it has one.
pub fn exporter<F: Family>(format: ExportFormat) -> Option<Exporter<F>> {
    match format {
        ExportFormat::Onnx => F::ONNX,
        ExportFormat::Safetensors => F::SAFETENSORS,
    }
}

/// The two-stage and query-based families return one detection list per image; a batch
/// of one must give one (their [`Family::bench_forward`]).
pub fn one_result(n: usize, family: &str) -> Result<()> {
    if n != 1 {
        bail!("{family} returned {n} results for 1 image");
    }
    Ok(())
}

/// [`Family::predict_timed`] of the families whose `forward_infer` applies their own
/// score threshold and NMS: the score filter at `conf`, timed whole.
pub fn timed_infer(
    images: Tensor<4>,
    conf: f32,
    infer: impl FnOnce(Tensor<4>) -> Vec<Vec<Detection>>,
) -> (Vec<Vec<Detection>>, f64) {
    let t = std::time::Instant::now();
    let mut out = infer(images);
    for d in &mut out {
        d.retain(|x| x.score >= conf);
    }
    (out, t.elapsed().as_secs_f64())
}
