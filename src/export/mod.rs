//! Export: a checkpoint's weights in formats other tools read, one module per format —
//! [`onnx`] (YOLO-seg in ultralytics' layout; Mask R-CNN as three graphs; the graph
//! builders of each family are `model::<family>::onnx`) and [`safetensors`] (the state
//! dict under ultralytics' / torchvision's key names). The `export` command
//! (`commands::export`) picks one; running an export back is `infer::onnx`.
//!
//! It sits above `infer` (it loads checkpoints) and below the commands; nothing but the
//! commands and benches imports it.

pub mod onnx;
pub mod safetensors;
