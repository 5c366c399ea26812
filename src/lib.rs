//! chicktrain: render → mix real + synthetic → train → COCO eval → checkpoints, for
//! instance segmentation of chicken carcasses on a processing line.
//!
//! Data flows one way: `render` → `data` → `model` → `train` → `eval`. The binary in
//! `main.rs` only parses arguments; every command is a function here so tests can call it.

pub mod bench;
pub mod cli;
pub mod config;
pub mod data;
pub mod eval;
pub mod model;
pub mod render;
pub mod train;
pub mod util;
