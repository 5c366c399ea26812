//! Instance-segmentation models.
//!
//! - [`common`]: blocks shared by the model families (Conv-BN-SiLU, C3k2, SPPF, C2PSA, Proto).
//! - [`maskrcnn`]: the two-stage Mask R-CNN (ResNet-FPN, RPN, RoIAlign, box and mask heads).
//! - [`yolo`]: the YOLO11-seg-style one-stage model, its task-aligned assigner, losses and
//!   postprocess.
//!
//! Nothing here reads the training config: every model is built from its own typed config.

pub mod common;
pub mod maskrcnn;
pub mod yolo;
