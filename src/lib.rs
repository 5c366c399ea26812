//! chicktrain: render → mix real + synthetic → train → COCO eval → checkpoints, for
//! instance segmentation of chicken carcasses on a processing line.
//!
//! Data flows one way, and the imports say so (a module uses only its own row and those
//! listed before it, and no two files import each other, even through others;
//! `tests/architecture.rs` checks both against `docs/architecture.md`):
//!
//! | layer | modules |
//! |---|---|
//! | foundation | [`util`], [`weights`] (PyTorch / safetensors files as host state dicts), [`annotations`] (COCO, masks, LabelMe, splits, the ground truth [`annotations::targets`]) |
//! | models | [`model`] (YOLO-seg, Mask R-CNN, Mask2Former, each with its `[model]` table; read `annotations::targets`, import only the foundation) |
//! | config | [`config`] (the typed run config; its `[model]` is the model layer's `ModelConfig`) |
//! | renderer | [`render`] (writes COCO through `annotations`) |
//! | loader | [`data`] (real + rendered samples, augmentation, batches of `annotations::targets`) |
//! | evaluator | [`eval`] (pycocotools-exact; reads only `annotations`) |
//! | inference | [`infer`] (the trained-model wrapper, checkpoints, validation, TTA, predict) |
//! | export | [`export`] (ONNX, safetensors) |
//! | trainer | [`train`] (loop, optimiser, EMA, run files) |
//! | on top | [`bench`] (timings), [`experiments`] (sweep, ablation, transfer: studies on one runner), [`commands`] (every CLI command) |
//!
//! The binary in `main.rs` only parses arguments and calls [`commands`].
//!
//! The default `train` feature brings in Burn: [`model`], [`infer`], [`export`],
//! [`train`], [`bench`], [`experiments`] and the training side of [`data`]. Without it
//! (`default-features = false`) the crate is the annotation layer, the config's tables
//! (not the root `Config`), renderer and evaluator, which the fuzz targets in `fuzz/`
//! build.

pub mod annotations;
#[cfg(feature = "train")]
pub mod bench;
pub mod commands;
pub mod config;
pub mod data;
pub mod eval;
#[cfg(feature = "train")]
pub mod experiments;
#[cfg(feature = "train")]
pub mod export;
#[cfg(feature = "train")]
pub mod infer;
#[cfg(feature = "train")]
pub mod model;
pub mod render;
#[cfg(feature = "train")]
pub mod train;
pub mod util;
pub mod weights;
