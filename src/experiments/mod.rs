//! Training experiments: studies that train a config's variants with several seeds, score
//! every run and report mean ± std over seeds, all on one loop, [`runner`] (a study is
//! data: config, overrides, named variants, seeds), summarised by [`summary`]:
//!
//! - [`sweep`]: the paper's synthetic-data experiment (one variant per synthetic-image
//!   count, scored on each run's test split).
//! - [`ablation`]: the scene ablation (one model option changed per variant; AP vs
//!   latency, a recommended default).
//! - [`transfer`]: randomisation groups and augmentations turned off one at a time, every
//!   run scored on an external set.

pub mod ablation;
pub mod runner;
pub mod summary;
pub mod sweep;
pub mod transfer;
