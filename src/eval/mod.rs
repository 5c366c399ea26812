//! Evaluation: the pycocotools-exact COCO evaluator and what reports it — tables
//! ([`report`]: CSV and markdown), charts ([`plots`]: PNG panels with text), the
//! precision-recall and F1-confidence curves of a run ([`curves`]), the confusion matrix ([`confusion`]), batch mosaics ([`mosaic`]) and
//! overlays ([`overlay`]). Test-time augmentation runs a model, so it is `infer::tta`.

pub mod coco_eval;
pub mod confusion;
pub mod curves;
pub mod mosaic;
pub mod overlay;
pub mod plots;
pub mod report;

pub use coco_eval::{evaluate, CocoEvalResult, IouType, STAT_NAMES};
