//! Instance-segmentation models.
//!
//! - [`yolo`]: the YOLO11-seg-style one-stage model (its blocks, task-aligned assigner,
//!   losses and postprocess).
//! - [`maskrcnn`]: the two-stage Mask R-CNN (ResNet-FPN, RPN, RoIAlign, box and mask heads).
//! - [`mask2former`]: the set-prediction Mask2Former (Mask R-CNN's ResNet, FPN pixel decoder,
//!   masked-attention transformer decoder, Hungarian matching, point-sampled losses).
//! - Shared by both: [`detection`] (what a model predicts, box IoU, NMS),
//!   [`instance_mask`] (a detection's mask, decoded at the input or the original size), [`layers`]
//!   (parameter and MAC counts, upsampling), [`loss`] (overflow-free primitives) and
//!   [`summary`] (model size).
//! - [`weights`]: weights from files (chicktrain checkpoints, PyTorch, safetensors) as
//!   named snapshots, and the one loader that applies them with shape checks; `freeze`
//!   (the first N stages of either family).
//! - [`onnx`]: the ONNX graph writer, the tract engine that runs exported files, and the
//!   reference file written beside an export.
//! - [`family`]: the interface every family implements (`model/<family>/family.rs`), so
//!   that the rest of the crate reaches a family in one place (`infer::detector`).
//!
//! Models read their ground truth as [`crate::annotations::targets::Targets`] and import
//! nothing of the renderer, the loader or the trainer (only the foundation): every model is
//! built from its own typed config.

pub mod detection;
pub mod family;
pub mod freeze;
pub mod instance_mask;
pub mod layers;
pub mod loss;
pub mod mask2former;
pub mod maskrcnn;
pub mod onnx;
pub mod summary;
pub mod weights;
pub mod yolo;
