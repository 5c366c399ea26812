//! `[data.unlabeled]` and `[train.self_training]`: self-training on unlabeled photos.
//! Adding `[data.unlabeled]` with `images = "DIR"` to any config turns it on with the
//! defaults below; `[train.self_training]` changes them and is refused without it.
//!
//! Defaults, chosen so that nothing needs setting: the EMA model is the teacher, it
//! labels the unlabeled images first after 40 % of the epochs (a random or barely trained
//! teacher would teach noise: Unbiased Teacher and STAC both start from a trained
//! detector) and again every 5 epochs, with test-time augmentation (the eight views of
//! the square, fused), keeping fused instances scoring at least 0.5; a quarter of each
//! batch is pseudo-labelled images.

use std::path::PathBuf;

use anyhow::{bail, Result};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// `[data.unlabeled]`: photos without labels from the target domain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnlabeledConfig {
    /// Every `.jpg`, `.jpeg` and `.png` under this folder (recursively, sorted by path);
    /// any label files there are ignored.
    pub images: PathBuf,
}

/// Who labels the unlabeled images (`train.self_training.teacher`).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub enum Teacher {
    /// `"ema"`: the run's own EMA model (the live model when `train.ema = false`).
    #[default]
    Ema,
    /// Any other string: a chicktrain checkpoint (`.bpk`) that labels once, fixed.
    Checkpoint(PathBuf),
}

impl Serialize for Teacher {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Teacher::Ema => s.serialize_str("ema"),
            Teacher::Checkpoint(p) => s.serialize_str(&p.display().to_string()),
        }
    }
}

impl<'de> Deserialize<'de> for Teacher {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        Ok(if s == "ema" {
            Teacher::Ema
        } else {
            Teacher::Checkpoint(PathBuf::from(s))
        })
    }
}

/// `[train.self_training]`: how pseudo-labels are made and used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelfTrainingConfig {
    /// `"ema"` or the path of a `.bpk` checkpoint.
    #[serde(default)]
    pub teacher: Teacher,
    /// Fused (or, without TTA, plain) detections scoring at least this become
    /// pseudo-instances.
    #[serde(default = "default_threshold")]
    pub score_threshold: f64,
    /// Curriculum: the threshold moves linearly from `score_threshold` at the first
    /// labelling to this value at the last epoch (lower: more, less certain labels as the
    /// teacher improves). None: fixed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub final_threshold: Option<f64>,
    /// Share of each batch given to pseudo-labelled images (their places are taken from
    /// the renders' side of a `train.real_fraction` batch, else from the shuffled mix).
    /// The number of optimiser steps does not change.
    #[serde(default = "default_share")]
    pub share: f64,
    /// Relabel every this many epochs (EMA teacher; a checkpoint labels once).
    #[serde(default = "default_refresh")]
    pub refresh_every: usize,
    /// First epoch (0-based) that uses pseudo-labels: the warm-up before it trains on
    /// renders and real images only. Default: 40 % of `train.epochs` for the EMA
    /// teacher, 0 for a checkpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_epoch: Option<usize>,
    /// Label with test-time augmentation (`infer::tta`: eight views, masks and boxes
    /// from the same fused instance).
    #[serde(default = "default_tta")]
    pub tta: bool,
}

fn default_threshold() -> f64 {
    0.5
}
fn default_share() -> f64 {
    0.25
}
fn default_refresh() -> usize {
    5
}
fn default_tta() -> bool {
    true
}

impl Default for SelfTrainingConfig {
    fn default() -> Self {
        toml::from_str("").expect("self-training defaults")
    }
}

impl SelfTrainingConfig {
    /// The first epoch (0-based) that trains on pseudo-labels, of a run of `epochs`.
    pub fn first_epoch(&self, epochs: usize) -> usize {
        self.start_epoch.unwrap_or(match self.teacher {
            Teacher::Ema => epochs * 2 / 5,
            Teacher::Checkpoint(_) => 0,
        })
    }

    /// Whether the pseudo-labels are made anew before `epoch` (0-based).
    pub fn labels_at(&self, epoch: usize, epochs: usize) -> bool {
        let first = self.first_epoch(epochs);
        match self.teacher {
            Teacher::Checkpoint(_) => epoch == first,
            Teacher::Ema => epoch >= first && (epoch - first) % self.refresh_every == 0,
        }
    }

    /// The score threshold of a labelling before `epoch` (the curriculum, if any).
    pub fn threshold_at(&self, epoch: usize, epochs: usize) -> f64 {
        let Some(end) = self.final_threshold else {
            return self.score_threshold;
        };
        let first = self.first_epoch(epochs);
        let span = epochs.saturating_sub(1).saturating_sub(first).max(1) as f64;
        let t = (epoch.saturating_sub(first) as f64 / span).min(1.0);
        self.score_threshold + (end - self.score_threshold) * t
    }

    /// Range checks for a run of `epochs` epochs and batch `batch`.
    pub fn validate(&self, epochs: usize, batch: usize) -> Result<()> {
        let unit = |k: &str, v: f64| -> Result<()> {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                bail!("train.self_training.{k} = {v} must be in (0, 1)");
            }
            Ok(())
        };
        unit("score_threshold", self.score_threshold)?;
        if let Some(f) = self.final_threshold {
            unit("final_threshold", f)?;
        }
        if !(self.share.is_finite() && self.share > 0.0 && self.share < 1.0) {
            bail!(
                "train.self_training.share = {} must be in (0, 1): the share of each batch given to pseudo-labelled images (the rest stays renders and real images)",
                self.share
            );
        }
        let n = (self.share * batch as f64).round() as usize;
        if n == 0 || n >= batch {
            bail!(
                "train.self_training.share = {} of train.batch = {batch} rounds to {n} pseudo-labelled images per batch; it must leave at least one place to them and one to the rest (raise train.batch or change the share)",
                self.share
            );
        }
        if self.refresh_every == 0 {
            bail!(
                "train.self_training.refresh_every must be at least 1 (epochs between labellings)"
            );
        }
        let first = self.first_epoch(epochs);
        if first >= epochs {
            bail!(
                "train.self_training.start_epoch = {first} must be less than train.epochs = {epochs} (epochs count from 0)"
            );
        }
        if let Teacher::Checkpoint(p) = &self.teacher {
            if !p.is_file() {
                bail!(
                    "train.self_training.teacher = {:?} is neither \"ema\" nor an existing checkpoint file",
                    p.display().to_string()
                );
            }
        }
        Ok(())
    }

    /// Pseudo-labelled images per batch of `batch`.
    pub fn per_batch(&self, batch: usize) -> usize {
        (self.share * batch as f64).round() as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_start_after_the_warm_up_and_refresh_every_five() {
        let s = SelfTrainingConfig::default();
        assert_eq!(s.teacher, Teacher::Ema);
        assert_eq!(s.first_epoch(25), 10);
        let at: Vec<usize> = (0..25).filter(|&e| s.labels_at(e, 25)).collect();
        assert_eq!(at, [10, 15, 20]);
        assert_eq!(s.threshold_at(20, 25), 0.5);
        assert_eq!(s.per_batch(8), 2);
        s.validate(25, 8).unwrap();
        let ck = SelfTrainingConfig {
            teacher: Teacher::Checkpoint("t.bpk".into()),
            ..s
        };
        let at: Vec<usize> = (0..25).filter(|&e| ck.labels_at(e, 25)).collect();
        assert_eq!(at, [0]);
    }

    #[test]
    fn the_curriculum_lowers_the_threshold_to_the_last_epoch() {
        let s = SelfTrainingConfig {
            score_threshold: 0.7,
            final_threshold: Some(0.3),
            start_epoch: Some(4),
            ..Default::default()
        };
        assert!((s.threshold_at(4, 9) - 0.7).abs() < 1e-12);
        assert!((s.threshold_at(6, 9) - 0.5).abs() < 1e-12);
        assert!((s.threshold_at(8, 9) - 0.3).abs() < 1e-12);
    }

    #[test]
    fn bad_values_name_the_key() {
        let d = SelfTrainingConfig::default();
        let cases: Vec<(SelfTrainingConfig, &str)> = vec![
            (
                SelfTrainingConfig {
                    share: 1.0,
                    ..d.clone()
                },
                "train.self_training.share = 1 must be in (0, 1)",
            ),
            (
                SelfTrainingConfig {
                    share: 0.01,
                    ..d.clone()
                },
                "rounds to 0",
            ),
            (
                SelfTrainingConfig {
                    score_threshold: 1.5,
                    ..d.clone()
                },
                "score_threshold = 1.5",
            ),
            (
                SelfTrainingConfig {
                    final_threshold: Some(0.0),
                    ..d.clone()
                },
                "final_threshold = 0",
            ),
            (
                SelfTrainingConfig {
                    refresh_every: 0,
                    ..d.clone()
                },
                "refresh_every",
            ),
            (
                SelfTrainingConfig {
                    start_epoch: Some(25),
                    ..d.clone()
                },
                "start_epoch = 25 must be less than train.epochs = 25",
            ),
            (
                SelfTrainingConfig {
                    teacher: Teacher::Checkpoint("no/such/teacher.bpk".into()),
                    ..d.clone()
                },
                "neither \"ema\" nor an existing checkpoint",
            ),
        ];
        for (c, want) in cases {
            let e = format!("{:#}", c.validate(25, 8).unwrap_err());
            assert!(e.contains(want), "{e} (wanted {want})");
        }
    }
}
