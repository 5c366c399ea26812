//! chicktrain: render → mix real + synthetic → train → COCO eval → checkpoints, for
//! instance segmentation of chicken carcasses on a processing line.
//!
//! Data flows one way, and the imports say so (a module uses only those listed before
//! it):
//!
//! | layer | modules |
//! |---|---|
//! | foundation | [`util`], [`config`], [`annotations`] (COCO, masks, LabelMe, splits) |
//! | renderer | [`render`] (writes COCO through `annotations`) |
//! | loader | [`data`] (real + rendered samples, augmentation, batches, [`data::targets`]) |
//! | models | [`model`] (YOLO-seg, Mask R-CNN; read `data::targets`) |
//! | evaluator | [`eval`] (pycocotools-exact; reads only `annotations`) |
//! | trainer | [`train`] (loop, checkpoints, run files, per-epoch eval) |
//! | on top | [`bench`] (timings), [`experiments`] (the paper's sweep), [`commands`] (every CLI command) |
//!
//! The binary in `main.rs` only parses arguments and calls [`commands`].
//!
//! The default `train` feature brings in Burn: [`model`], [`train`], [`bench`],
//! [`experiments`] and the training side of [`data`]. Without it
//! (`default-features = false`) the crate is the annotation layer, renderer and
//! evaluator, which the fuzz targets in `fuzz/` build.

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
