//! Self-training on unlabeled photos (`[data.unlabeled]`, `[train.self_training]`): a
//! teacher labels the unlabeled images, and the pseudo-labelled ones take a fixed share of
//! every batch, beside the renders and the real images, through the same augmentations.
//!
//! - **Teacher.** The run's EMA model (Mean Teacher / Unbiased Teacher: the slowly moving
//!   average is a better labeller than the live weights), relabelling every
//!   `refresh_every` epochs from `start_epoch` on; or a fixed checkpoint that labels once.
//! - **Labels.** Each image is letterboxed to the network input and, with `tta`, seen in
//!   the eight symmetries of the square (`infer::validate::augmented`); the fused
//!   detections scoring at least the threshold become pseudo-instances, mask and box from
//!   the same fused instance. Without `tta` one forward pass at that confidence. The
//!   threshold may follow a curriculum (`final_threshold`). Only images with at least one
//!   pseudo-instance join the pool (`data::unlabeled`).
//! - **Batches.** `round(share × batch)` places of each batch go to pool images, cycled
//!   and reshuffled from the run seed; they are the last places of the batch (the
//!   renders' side of a `train.real_fraction` batch, a random part of the shuffled mix
//!   otherwise). The number of optimiser steps, and so equal-steps comparisons, do not
//!   change.
//! - **Record.** `self_training.jsonl` in the run folder: one line per epoch with the
//!   labelling done before it (if any) and how many pseudo-labelled items it trained on.
//!
//! Deterministic from the config seed: labelling is a forward pass, the draws are keyed by
//! (seed, epoch). A `--resume`d run labels again at its first epoch (from the resumed
//! EMA) when that epoch is past `start_epoch`; it equals the uninterrupted run only when
//! resumed at a labelling epoch.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::config::{Config, SelfTrainingConfig, Teacher};
use crate::data::unlabeled::{PseudoInstance, PseudoLabels, UnlabeledSet};
use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::Detector;
use crate::infer::precision::{copy_in, float_dtype};
use crate::infer::validate::{augmented, push_planes};
use crate::util::write_atomic;

use super::loader::{mix, Cycle, Item, Loader};
use super::state::TrainState;

/// One line of `self_training.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SelfTrainingRecord {
    /// 1-based, as in `metrics.jsonl`.
    pub epoch: usize,
    /// Whether the images were labelled before this epoch.
    pub labelled: bool,
    /// The threshold the current labels were kept at (none before the first labelling).
    pub threshold: Option<f64>,
    /// Images with at least one pseudo-instance, and all pseudo-instances.
    pub pool: usize,
    pub instances: usize,
    /// Pseudo-labelled items trained on in this epoch.
    pub items: usize,
    /// Seconds the labelling took (0 without one).
    pub label_seconds: f64,
}

/// The self-training of a run: its settings, the unlabeled set and a checkpoint teacher.
pub struct SelfTraining {
    pub cfg: SelfTrainingConfig,
    pub set: UnlabeledSet,
    teacher: Option<Detector>,
    pub records: Vec<SelfTrainingRecord>,
}

impl SelfTraining {
    /// `None` without `[data.unlabeled]`; else the scanned folder (errors name a missing
    /// folder, no images, an unreadable image) and the checkpoint teacher, loaded on
    /// `base` and checked to have `num_classes` classes. Records of epochs up to `done`
    /// (a resumed run's) are kept from `run_dir`.
    pub fn for_run(
        cfg: &Config,
        num_classes: usize,
        base: &Device,
        run_dir: &Path,
        done: usize,
    ) -> Result<Option<SelfTraining>> {
        let Some(u) = &cfg.data.unlabeled else {
            return Ok(None);
        };
        let st = cfg.train.self_training.clone().unwrap_or_default();
        let set = UnlabeledSet::scan(&u.images)?;
        let teacher = match &st.teacher {
            Teacher::Ema => None,
            Teacher::Checkpoint(p) => {
                let ck = Checkpoint::load(p)
                    .with_context(|| format!("train.self_training.teacher = {}", p.display()))?;
                let n = ck.header.model.num_classes();
                if n != num_classes {
                    bail!(
                        "train.self_training.teacher = {}: the checkpoint has {n} classes, the run's data {num_classes}",
                        p.display()
                    );
                }
                Some(ck.model("ema", base)?)
            }
        };
        let records = read_records(run_dir)?
            .into_iter()
            .filter(|r| r.epoch <= done)
            .collect();
        Ok(Some(SelfTraining {
            cfg: st,
            set,
            teacher,
            records,
        }))
    }

    /// The line printed before step 1.
    pub fn describe(&self, epochs: usize, batch: usize) -> String {
        let s = &self.cfg;
        format!(
            "self-training: {} unlabeled images in {}, teacher {}, {} of {batch} per batch from epoch {}{}, score >= {}{}{}",
            self.set.len(),
            self.set.root.display(),
            match &s.teacher {
                Teacher::Ema => "EMA".to_string(),
                Teacher::Checkpoint(p) => p.display().to_string(),
            },
            s.per_batch(batch),
            s.first_epoch(epochs) + 1,
            match s.teacher {
                Teacher::Ema => format!(", relabelled every {} epochs", s.refresh_every),
                Teacher::Checkpoint(_) => String::new(),
            },
            s.score_threshold,
            match s.final_threshold {
                Some(f) => format!(" (curriculum to {f})"),
                None => String::new(),
            },
            if s.tta { ", TTA" } else { "" }
        )
    }

    /// Before `epoch` (0-based; `resumed_here`: the first epoch of a resumed run): new
    /// pseudo-labels when the epoch labels, else `None` (the current ones stay). The
    /// EMA teacher is `st`'s evaluated model, in the run's precision, on `base`.
    pub fn labels_before(
        &self,
        cfg: &Config,
        epoch: usize,
        resumed_here: bool,
        st: &TrainState,
        input: u32,
        base: &Device,
    ) -> Result<Option<PseudoLabels>> {
        let epochs = cfg.train.epochs;
        let first = self.cfg.first_epoch(epochs);
        let due = self.cfg.labels_at(epoch, epochs) || (resumed_here && epoch > first);
        if !due {
            return Ok(None);
        }
        let threshold = self.cfg.threshold_at(epoch, epochs);
        let labels = match &self.teacher {
            Some(t) => label(t, &self.set, input, base, threshold, self.cfg.tta)?,
            None => {
                let m = copy_in(
                    &st.eval_model(cfg.train.ema),
                    float_dtype(cfg.train.precision),
                );
                label(&m, &self.set, input, base, threshold, self.cfg.tta)?
            }
        };
        Ok(Some(PseudoLabels {
            set: self.set.clone(),
            input,
            labels,
            made_before_epoch: epoch,
            threshold,
        }))
    }

    /// Before `epoch`: labels when due (see [`Self::labels_before`]) and hands the new
    /// labels to `loader`, saying what they are; returns the seconds labelling took.
    #[allow(clippy::too_many_arguments)]
    pub fn before_epoch(
        &self,
        cfg: &Config,
        epoch: usize,
        resumed_here: bool,
        st: &TrainState,
        loader: &mut Loader,
        base: &Device,
        say: &dyn Fn(String),
    ) -> Result<Option<f64>> {
        let t0 = Instant::now();
        let Some(p) = self.labels_before(cfg, epoch, resumed_here, st, loader.input, base)? else {
            return Ok(None);
        };
        let secs = t0.elapsed().as_secs_f64();
        say(format!(
            "self-training: labelled {} images before epoch {} in {secs:.1} s: {} pseudo-instances at score >= {:.3}, {} images with at least one",
            p.labels.len(),
            epoch + 1,
            p.instances(),
            p.threshold,
            p.pool().len()
        ));
        loader.pseudo = Some(p);
        Ok(Some(secs))
    }

    /// Records `epoch` (0-based) in `<run_dir>/self_training.jsonl`.
    pub fn record(
        &mut self,
        run_dir: &Path,
        epoch: usize,
        pseudo: Option<&PseudoLabels>,
        labelled_in: Option<f64>,
        items: usize,
    ) -> Result<()> {
        self.records.push(SelfTrainingRecord {
            epoch: epoch + 1,
            labelled: labelled_in.is_some(),
            threshold: pseudo.map(|p| p.threshold),
            pool: pseudo.map_or(0, |p| p.pool().len()),
            instances: pseudo.map_or(0, PseudoLabels::instances),
            items,
            label_seconds: labelled_in.unwrap_or(0.0),
        });
        let mut text = String::new();
        for r in &self.records {
            text.push_str(&serde_json::to_string(r)?);
            text.push('\n');
        }
        write_atomic(&run_dir.join("self_training.jsonl"), text.as_bytes())
    }
}

/// The records of `<dir>/self_training.jsonl` (none when it is missing).
pub fn read_records(dir: &Path) -> Result<Vec<SelfTrainingRecord>> {
    let p = dir.join("self_training.jsonl");
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(Vec::new());
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{} line {}: not a record", p.display(), i + 1))
        })
        .collect()
}

/// Pseudo-instances of every image of `set`, letterboxed to `input`, by `model` on
/// `device`: with `tta` the fused detections of the eight views, else one forward pass;
/// kept at score >= `threshold`, masks at the input size.
pub fn label(
    model: &Detector,
    set: &UnlabeledSet,
    input: u32,
    device: &Device,
    threshold: f64,
    tta: bool,
) -> Result<Vec<Vec<PseudoInstance>>> {
    let size = input as usize;
    let forward = |px: Vec<f32>, n: usize| {
        let x = Tensor::<4>::from_data(TensorData::new(px, [n, 3, size, size]), device);
        model.predict(x, threshold as f32)
    };
    let mut out = Vec::with_capacity(set.len());
    for k in 0..set.len() {
        let img = set.image(k, input)?;
        let kept: Vec<PseudoInstance> = if tta {
            augmented(&img, input, &mut |px| Ok(forward(px, 1).swap_remove(0)))?
                .into_iter()
                .filter(|f| f.score as f64 >= threshold && f.mask.area() > 0)
                .map(|f| PseudoInstance {
                    class: f.class,
                    score: f.score,
                    mask: f.mask,
                })
                .collect()
        } else {
            let mut px = Vec::with_capacity(3 * size * size);
            push_planes(&img, &mut px);
            forward(px, 1)
                .swap_remove(0)
                .into_iter()
                .filter(|d| d.score as f64 >= threshold)
                .map(|d| PseudoInstance {
                    class: d.class,
                    score: d.score,
                    mask: d.mask_in((input, input), d.xyxy()),
                })
                .filter(|p| p.mask.area() > 0)
                .collect()
        };
        out.push(kept);
    }
    Ok(out)
}

/// `plan` (batches of `batch`) with the last `per_batch` places of every batch given to
/// `pool` images, cycled and reshuffled per pass from (seed, epoch); the plan's length,
/// and so the number of steps, is unchanged. A batch shorter than `per_batch + 1` (the
/// last one of a natural plan) keeps at least one of its own items. An empty pool leaves
/// the plan as it is.
pub fn mix_in(
    mut plan: Vec<Item>,
    pool: &[u64],
    per_batch: usize,
    batch: usize,
    seed: u64,
    epoch: usize,
) -> Vec<Item> {
    if pool.is_empty() || per_batch == 0 || batch == 0 {
        return plan;
    }
    let items: Vec<Item> = pool.iter().map(|&k| Item::Unlabeled(k)).collect();
    let mut c = Cycle::new(&items, mix(mix(seed, epoch as u64), 0x5E1F));
    for chunk in plan.chunks_mut(batch) {
        let n = per_batch.min(chunk.len().saturating_sub(1));
        let len = chunk.len();
        for slot in &mut chunk[len - n..] {
            *slot = c.take();
        }
    }
    plan
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mix_in_keeps_the_steps_and_fills_the_share_from_the_pool() {
        let plan: Vec<Item> = (0..8)
            .map(Item::Real)
            .chain((0..12).map(Item::Synthetic))
            .collect();
        let out = mix_in(plan.clone(), &[3, 5, 9], 2, 8, 1, 0);
        assert_eq!(out.len(), plan.len());
        for (b, chunk) in out.chunks(8).enumerate() {
            let n = chunk
                .iter()
                .filter(|i| matches!(i, Item::Unlabeled(_)))
                .count();
            // The last batch has 4 items: 2 of them pseudo-labelled.
            assert_eq!(n, 2, "batch {b}");
            assert!(matches!(chunk[chunk.len() - 1], Item::Unlabeled(3 | 5 | 9)));
            assert_eq!(
                chunk[..chunk.len() - 2],
                plan[b * 8..b * 8 + chunk.len() - 2]
            );
        }
        // 6 places over a pool of 3: each image twice (cycled without repeats per pass).
        for k in [3, 5, 9] {
            assert_eq!(out.iter().filter(|i| **i == Item::Unlabeled(k)).count(), 2);
        }
        assert_eq!(out, mix_in(plan.clone(), &[3, 5, 9], 2, 8, 1, 0));
        assert_ne!(out, mix_in(plan.clone(), &[3, 5, 9], 2, 8, 1, 1));
        assert_eq!(mix_in(plan.clone(), &[], 2, 8, 1, 0), plan);
        // A one-item batch keeps its own item.
        assert_eq!(
            mix_in(vec![Item::Real(1)], &[4], 2, 8, 1, 0),
            [Item::Real(1)]
        );
    }
}
