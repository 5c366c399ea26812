//! Run configuration: TOML → typed structs → validated values.
//!
//! Every table rejects unknown keys (`deny_unknown_fields`), so a typo such as
//! `epoch = 5` fails with the key's name, the file and the line instead of silently
//! training with the default. `--set a.b=v` overrides edit the TOML tree before it is
//! typed, so they go through exactly the same checks.
//!
//! `base = "other.toml"` (detectron2's `_BASE_`) starts a config from another one, so a
//! variant states only what differs (`run`, `BASE_KEY`).
//!
//! The tables are files of their own here; the root `Config` and its loading are `run`
//! (with the `train` feature: its `[model]` table is the model layer's `ModelConfig`, one
//! table per family in `model/<family>/config.rs`, re-exported here).

mod data;
mod device;
mod negatives;
mod randomize;
#[cfg(feature = "train")]
mod run;
mod self_training;
mod shipped;
mod train;

pub use data::{DataConfig, RealConfig, RealKind};
pub use device::DeviceKind;
// The `[model]` tables are the model layer's (each family's `config.rs`), re-exported
// under the names callers use.
#[cfg(feature = "train")]
pub use crate::model::mask2former::{Mask2FormerModelConfig, Mask2FormerPreset};
#[cfg(feature = "train")]
pub use crate::model::maskrcnn::{MaskRcnnModelConfig, MaskRcnnPreset};
#[cfg(feature = "train")]
pub use crate::model::yolo::{YoloModelConfig, YoloScale};
#[cfg(feature = "train")]
pub use crate::model::{ModelConfig, ModelKind};
pub use negatives::Negatives;
pub use randomize::Randomize;
#[cfg(feature = "train")]
pub use run::{load, locate, parse, Config, BASE_KEY};
pub use self_training::{SelfTrainingConfig, Teacher, UnlabeledConfig};
pub use shipped::SHIPPED;
pub use train::{OptimizerKind, Precision, ScheduleKind, TrainConfig, AUGMENTATIONS};
