//! Evaluation: the pycocotools-exact COCO evaluator and what reports it — tables
//! ([`report`]: CSV and markdown) and charts ([`plots`]: PNG panels with text).
//! Test-time augmentation runs a model, so it is `infer::tta`.

pub mod coco_eval;
pub mod plots;
pub mod report;

pub use coco_eval::{evaluate, CocoEvalResult, IouType, STAT_NAMES};
