//! ONNX out and back in: [`graph`] writes ONNX protobuf (tract-onnx's generated types,
//! prost's encoder), [`engine`] runs a file with tract. The model walks that emit graphs
//! live with their models (`yolo::onnx`).

pub mod engine;
pub mod graph;
pub mod layers;
pub mod reference;
