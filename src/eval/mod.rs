//! Evaluation: the pycocotools-exact COCO evaluator and what reports it — tables
//! ([`report`]: CSV and markdown), charts ([`plots`]: PNG panels with text), the
//! precision-recall and F1-confidence curves of a run ([`curves`]), and test-time
//! augmentation's views and fusion ([`tta`]).

pub mod coco_eval;
pub mod confusion;
pub mod curves;
pub mod mosaic;
pub mod overlay;
pub mod plots;
pub mod report;
pub mod tta;

pub use coco_eval::{evaluate, CocoEvalResult, IouType, STAT_NAMES};
