//! chicktrain: render → mix real + synthetic → train → COCO eval → checkpoints, for
//! instance segmentation of chicken carcasses on a processing line.
//!
//! Data flows one way: `render` → `data` → `model` → `train` → `eval`. The binary in
//! `main.rs` only parses arguments; every command is a function here so tests can call it.
//!
//! The default `train` feature brings in Burn: [`model`], [`train`] and the training
//! side of [`data`]. Without it (`default-features = false`) the crate is the data layer,
//! renderer and evaluator, which the fuzz targets in `fuzz/` build.

#[cfg(feature = "train")]
pub mod bench;
pub mod cli;
pub mod config;
pub mod data;
pub mod eval;
#[cfg(feature = "train")]
pub mod model;
pub mod render;
#[cfg(feature = "train")]
pub mod train;
pub mod util;
