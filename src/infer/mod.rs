//! Running a trained model, apart from training it: the trained-model wrapper every
//! family sits behind ([`detector`]), checkpoint files ([`checkpoint`]), the device and
//! float type a model runs in ([`device`], [`precision`]), scoring a model on a split
//! with the COCO evaluator ([`validate`]: per-epoch validation, `eval`, the test split),
//! test-time augmentation ([`tta`]) and `predict` on image files ([`predict`]), with a
//! checkpoint or an ONNX export through tract ([`onnx`]).
//!
//! It sits above the models and the evaluator and below the trainer: `eval`, `predict`,
//! `export` and `bench` run a trained model without importing the training loop
//! (ultralytics keeps `predictor` and `validator` beside `trainer`; detectron2 keeps
//! `checkpoint/` apart from `engine/`).

pub mod checkpoint;
pub mod detector;
pub mod device;
pub mod onnx;
pub mod precision;
pub mod predict;
pub mod tta;
pub mod validate;
