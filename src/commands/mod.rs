//! Every command of the binary, as a library function that returns the text to print
//! (so tests call them directly; `main.rs` only parses flags): [`data`] (render,
//! convert, coco-eval, render/COCO benches), [`train`] (train, eval, predict),
//! [`bench`] (model bench, ablation, sweep), [`export`] (checkpoint → other formats) and
//! [`onnx`] (ONNX export and `predict --onnx`).

#[cfg(feature = "train")]
pub mod bench;
pub mod data;
#[cfg(feature = "train")]
pub mod export;
#[cfg(feature = "train")]
pub mod export_safetensors;
#[cfg(feature = "train")]
pub mod onnx;
#[cfg(feature = "train")]
pub mod train;
