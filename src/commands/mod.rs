//! Every command of the binary, as a library function that returns the text to print
//! (so tests call them directly), each taking a request struct that derives clap's
//! `Args` (its flags): [`cli`] (the command tree the binary parses), [`data`] (render,
//! convert, coco-eval, render/COCO benches), [`train`] (train, predict's body),
//! [`eval`], [`predict`] (predict's flags and `--save-txt`), [`bench`] (model bench,
//! ablation, sweep), [`export`] (checkpoint → other formats) and [`onnx`] (ONNX export
//! and `predict --onnx`).

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
pub mod export_safetensors;
#[cfg(feature = "train")]
pub mod onnx;
#[cfg(feature = "train")]
pub mod predict;
#[cfg(feature = "train")]
pub mod train;
