//! Evaluation: the pycocotools-exact COCO evaluator and what reports it — tables
//! ([`report`]: CSV and markdown) and charts ([`plots`]: PNG panels with text), and
//! test-time augmentation's views and fusion ([`tta`]).

pub mod coco_eval;
pub mod plots;
pub mod report;
pub mod tta;

pub use coco_eval::{evaluate, CocoEvalResult, IouType, STAT_NAMES};
