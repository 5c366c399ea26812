//! Every command of the binary, as a library function that returns the text to print
//! (so tests call them directly; `main.rs` only parses flags): [`data`] (render,
//! convert, coco-eval, render/COCO benches), [`train`] (train, eval, predict),
//! [`bench`] (model and engine benches, ablation, sweep) and [`export`] (checkpoint →
//! other formats, each format in `crate::export`).

#[cfg(feature = "train")]
pub mod bench;
pub mod data;
#[cfg(feature = "train")]
pub mod export;
#[cfg(feature = "train")]
pub mod train;
