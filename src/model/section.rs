//! [`ModelSection`]: what the run config needs of a family's `[model]` table (its range
//! checks and its `train.freeze` limit), and the small helpers the tables share (serde
//! defaults, range checks). Each family's table is `model/<family>/config.rs`; the enums
//! that pick one by `kind` ([`super::ModelKind`], [`super::ModelConfig`]) are built from
//! the family list in `model/mod.rs`, which also reads every table's `init` and
//! `width_mult` keys.

use anyhow::{bail, Result};

/// What the run config needs of a family's `[model]` table beyond the `init` and
/// `width_mult` keys every table has.
pub trait ModelSection {
    /// Range checks of the family's own keys; `crop` is `data.crop`.
    fn validate(&self, crop: u32) -> Result<()>;
    /// The largest `train.freeze` and what its stages are (for the message).
    fn freeze_limit(&self) -> (usize, &'static str);
}

/// The freeze stages of a ResNet backbone (detectron2's `FREEZE_AT`).
pub(super) const RESNET_STAGES: &str = "1 = stem, 2–5 = stem and the first 1–4 ResNet stages";

/// The checks of a ResNet-backed family (`kind` names it): `model.depth` one of
/// torchvision's ResNets, and `data.crop` at least 64.
pub(super) fn check_resnet(depth: usize, crop: u32, kind: &str) -> Result<()> {
    if ![18, 34, 50, 101].contains(&depth) {
        bail!("model.depth = {depth} must be 18, 34, 50 or 101");
    }
    if crop < 64 {
        bail!("data.crop = {crop} must be at least 64 for model.kind = \"{kind}\"");
    }
    Ok(())
}

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
