//! Evaluation: the pycocotools-exact COCO evaluator and what reports it.

pub mod coco_eval;

pub use coco_eval::{evaluate, CocoEvalResult, IouType, STAT_NAMES};
