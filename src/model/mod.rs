//! Instance-segmentation models.
//!
//! - [`common`]: blocks shared by the model families (Conv-BN-SiLU, C3k2, SPPF, C2PSA, Proto).
//! - [`yolo`]: the YOLO11-seg-style one-stage model, its task-aligned assigner, losses and
//!   postprocess.
//!
//! Nothing here reads the training config: every model is built from its own typed config.

pub mod common;
pub mod yolo;
