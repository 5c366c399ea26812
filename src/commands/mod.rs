//! Every command of the binary, as a library function that returns the text to print
//! (so tests call them directly), each taking a request struct that derives clap's
//! `Args` (its flags): [`cli`] (the command tree the binary parses), [`data`] (render,
//! convert, coco-eval, render/COCO benches), [`train`], [`eval`], [`predict`] (its
//! flags; predicting itself is `infer::predict`), [`bench`] (model and engine benches,
//! ablation, sweep) and [`export`] (checkpoint → other formats, each format in
//! `crate::export`).

#[cfg(feature = "train")]
pub mod bench;
#[cfg(feature = "train")]
pub mod cli;
pub mod data;
#[cfg(feature = "train")]
pub mod eval;
#[cfg(feature = "train")]
pub mod export;
#[cfg(feature = "train")]
pub mod predict;
#[cfg(feature = "train")]
pub mod train;
