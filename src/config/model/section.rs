//! [`ModelSection`]: what the config layer needs of a family's `[model]` table, and the
//! small helpers the tables share (serde defaults, range checks).

use anyhow::{bail, Result};

/// What the config layer needs of a family's `[model]` table.
pub trait ModelSection {
    /// `model.init`: weights to start from.
    fn init(&self) -> Option<&str>;
    /// Channel-width multiplier.
    fn width_mult(&self) -> f64;
    /// Range checks of the family's own keys; `crop` is `data.crop`.
    fn validate(&self, crop: u32) -> Result<()>;
    /// The largest `train.freeze` and what its stages are (for the message).
    fn freeze_limit(&self) -> (usize, &'static str);
}

/// The freeze stages of a ResNet backbone (detectron2's `FREEZE_AT`).
pub(super) const RESNET_STAGES: &str = "1 = stem, 2–5 = stem and the first 1–4 ResNet stages";

/// Each optional key, when set, in `1..=max` (`(key, value, max)`).
pub(super) fn check_ranges(keys: &[(&str, Option<usize>, usize)]) -> Result<()> {
    for &(k, v, max) in keys {
        if let Some(v) = v {
            if !(1..=max).contains(&v) {
                bail!("model.{k} = {v} must be in 1..={max}");
            }
        }
    }
    Ok(())
}

pub(super) fn default_true() -> bool {
    true
}
pub(super) fn default_one() -> f64 {
    1.0
}
pub(super) fn default_depth() -> usize {
    50
}
