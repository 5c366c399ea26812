//! Instance-segmentation models.
//!
//! - [`yolo`]: the YOLO11-seg-style one-stage model (its blocks, task-aligned assigner,
//!   losses and postprocess).
//! - [`maskrcnn`]: the two-stage Mask R-CNN (ResNet-FPN, RPN, RoIAlign, box and mask heads).
//! - Shared by both: [`detection`] (what a model predicts, box IoU, NMS), [`layers`]
//!   (parameter and MAC counts, upsampling), [`loss`] (overflow-free primitives) and
//!   [`summary`] (model size).
//! - [`onnx`]: the ONNX graph writer and the tract engine that runs exported files.
//!
//! Models read their ground truth as [`crate::data::targets::Targets`] and nothing of the
//! trainer: every model is built from its own typed config.

pub mod detection;
pub mod layers;
pub mod loss;
pub mod maskrcnn;
pub mod onnx;
pub mod summary;
pub mod yolo;
