//! What the trainer feeds the model each epoch: the plan of items (real image ids and
//! synthetic indices), and batches built from it on a loader thread — rendering,
//! decoding and augmenting the next batch in parallel with rayon while the current step
//! runs. Each item's augmentation RNG is keyed by (seed, epoch, position), so a run does
//! not depend on thread timing; mosaic and copy-paste partners are positions of the same
//! plan drawn from that key.
//!
//! The plan is every item once, shuffled ([`epoch_plan`]), unless `train.steps_per_epoch`
//! or `train.real_fraction` is set ([`Mix`]): then an epoch is a fixed number of
//! optimiser steps whatever the synthetic count (detectron2's MAX_ITER, counted per
//! epoch), each batch `round(real_fraction × batch)` real images — the few real ones
//! oversampled by cycling through them, reshuffled every pass — and synthetic ones for
//! the rest, so recipes can be compared at equal compute.

use std::sync::mpsc::{sync_channel, Receiver};

use anyhow::{bail, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::config::{Config, TrainConfig};
use crate::data::augment::{augment, augment_full, draw_partners, AugmentConfig, PartnerSamples};
use crate::data::batch::{collate, Batch};
use crate::data::dataset::{RealSet, Sample, SyntheticSet};
use crate::data::unlabeled::PseudoLabels;
use crate::util::hash::mix64;

/// One item of an epoch: a real image id, a synthetic index, or the index of a
/// pseudo-labelled unlabeled image (self-training, `train::self_training`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Item {
    Real(u64),
    Synthetic(u64),
    Unlabeled(u64),
}

/// Seed of `b` under `a`: the one derivation of every per-epoch and per-step key.
pub fn mix(a: u64, b: u64) -> u64 {
    mix64(a ^ mix64(b.wrapping_add(0x9E37_79B9_7F4A_7C15)))
}

/// Shuffled items of `epoch`: every real train id and synthetic index once.
pub fn epoch_plan(train_ids: &[u64], synthetic: usize, seed: u64, epoch: usize) -> Vec<Item> {
    let mut items: Vec<Item> = train_ids.iter().map(|&i| Item::Real(i)).collect();
    items.extend((0..synthetic as u64).map(Item::Synthetic));
    items.shuffle(&mut ChaCha8Rng::seed_from_u64(mix(seed, epoch as u64)));
    items
}

/// How an epoch's batches are drawn (`train.steps_per_epoch`, `train.real_fraction`);
/// both unset is [`epoch_plan`] in batches.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mix {
    pub steps_per_epoch: Option<usize>,
    pub real_fraction: Option<f64>,
}

impl Mix {
    pub fn of(t: &TrainConfig) -> Mix {
        Mix {
            steps_per_epoch: t.steps_per_epoch,
            real_fraction: t.real_fraction,
        }
    }

    /// Optimiser steps of an epoch over `n_real` real and `synthetic` synthetic items.
    pub fn steps(&self, n_real: usize, synthetic: usize, batch: usize) -> usize {
        self.steps_per_epoch
            .unwrap_or((n_real + synthetic).div_ceil(batch.max(1)))
    }
}

/// An endless stream over `pool`: shuffled, and reshuffled at the start of every pass.
pub struct Cycle<'a, T> {
    pool: &'a [T],
    order: Vec<usize>,
    next: usize,
    pass: u64,
    seed: u64,
}

impl<'a, T: Copy> Cycle<'a, T> {
    pub fn new(pool: &'a [T], seed: u64) -> Self {
        Cycle {
            pool,
            order: Vec::new(),
            next: 0,
            pass: 0,
            seed,
        }
    }

    pub fn take(&mut self) -> T {
        if self.next == self.order.len() {
            self.order = (0..self.pool.len()).collect();
            self.order
                .shuffle(&mut ChaCha8Rng::seed_from_u64(mix(self.seed, self.pass)));
            self.pass += 1;
            self.next = 0;
        }
        self.next += 1;
        self.pool[self.order[self.next - 1]]
    }
}

/// The items of `epoch`, batch `b` being `plan[b * batch..(b + 1) * batch]`: with `m`
/// unset, [`epoch_plan`] (the last batch may be short); with `steps_per_epoch` alone,
/// that shuffled mix cycled (reshuffled per pass) for the steps; with `real_fraction`,
/// each batch `round(real_fraction × batch)` real ids then synthetic indices, both
/// cycled. Errors name the key when a part the mix asks for is empty.
pub fn epoch_batches(
    train_ids: &[u64],
    synthetic: usize,
    seed: u64,
    epoch: usize,
    batch: usize,
    m: Mix,
) -> Result<Vec<Item>> {
    if m == Mix::default() {
        return Ok(epoch_plan(train_ids, synthetic, seed, epoch));
    }
    let steps = m.steps(train_ids.len(), synthetic, batch);
    let key = mix(seed, epoch as u64);
    let Some(f) = m.real_fraction else {
        let all = epoch_plan(train_ids, synthetic, seed, epoch);
        if all.is_empty() {
            bail!("train.steps_per_epoch = {steps}: there are no training items (no real train images and data.synthetic = 0)");
        }
        let mut c = Cycle::new(&all, mix(key, 3));
        // The first pass is the shuffled plan itself.
        c.order = (0..all.len()).collect();
        c.pass = 1;
        return Ok((0..steps * batch).map(|_| c.take()).collect());
    };
    let n_real = (f * batch as f64).round() as usize;
    let n_syn = batch - n_real.min(batch);
    if n_real > 0 && train_ids.is_empty() {
        bail!("train.real_fraction = {f} puts {n_real} real images in every batch, but the split has no real train images (set train.real_fraction = 0 or give data.split a train part)");
    }
    if n_syn > 0 && synthetic == 0 {
        bail!("train.real_fraction = {f} leaves {n_syn} of {batch} batch places to synthetic images, but data.synthetic = 0 (set data.synthetic > 0 or train.real_fraction = 1)");
    }
    let real: Vec<Item> = train_ids.iter().map(|&i| Item::Real(i)).collect();
    let syn: Vec<Item> = (0..synthetic as u64).map(Item::Synthetic).collect();
    let (mut r, mut s) = (
        Cycle::new(&real, mix(key, 1)),
        Cycle::new(&syn, mix(key, 2)),
    );
    let mut plan = Vec::with_capacity(steps * batch);
    for _ in 0..steps {
        plan.extend((0..n_real).map(|_| r.take()));
        plan.extend((0..n_syn).map(|_| s.take()));
    }
    Ok(plan)
}

/// Second RNG stream of an item (the augmentations beyond crop, flip and HSV), apart
/// from the first so that turning them on leaves those draws unchanged.
const EXTRA_STREAM: u64 = 0xA06_0E57;

/// The training sources and how their samples are augmented.
pub struct Loader {
    pub real: RealSet,
    pub synthetic: SyntheticSet,
    pub aug: AugmentConfig,
    /// Network input size the real images are letterboxed to.
    pub input: u32,
    pub seed: u64,
    /// Self-training: the current pseudo-labels (`None` before the first labelling).
    pub pseudo: Option<PseudoLabels>,
}

impl Loader {
    /// The loader a run of `cfg` trains with: its augmentations (`train.*`), inputs of
    /// `input` px and the run's seed; an error when `train.augment_order` is not a
    /// permutation of the augmentations.
    pub fn for_run(
        cfg: &Config,
        real: RealSet,
        synthetic: SyntheticSet,
        input: u32,
    ) -> Result<Loader> {
        let t = &cfg.train;
        Ok(Loader {
            real,
            synthetic,
            aug: AugmentConfig {
                degrees: t.degrees,
                scale: t.scale,
                translate: t.translate,
                flipud: t.flipud,
                mosaic: t.mosaic,
                copy_paste: t.copy_paste,
                order: t.augment_permutation()?,
                ..AugmentConfig::basic(cfg.data.crop, t.fliplr, t.hsv)
            },
            input,
            seed: cfg.seed,
            pseudo: None,
        })
    }

    fn load(&self, it: Item, epoch: usize) -> Result<Sample> {
        match it {
            Item::Real(id) => self.real.sample(id, self.input),
            Item::Synthetic(i) => self.synthetic.sample(i, epoch as u64),
            Item::Unlabeled(k) => match &self.pseudo {
                Some(p) => p.sample(k),
                None => bail!("the plan has unlabeled image {k} but there are no pseudo-labels"),
            },
        }
    }

    /// Item `pos` of `plan` (in `epoch`), augmented; its partners come from `plan`.
    pub fn item(&self, plan: &[Item], pos: usize, epoch: usize) -> Result<Sample> {
        let s = self.load(plan[pos], epoch)?;
        let key = mix(mix(self.seed, epoch as u64), pos as u64);
        let mut rng = ChaCha8Rng::seed_from_u64(key);
        if !self.aug.extended() {
            return Ok(augment(&s, &self.aug, &mut rng));
        }
        let mut extra = ChaCha8Rng::seed_from_u64(mix(key, EXTRA_STREAM));
        let p = draw_partners(&self.aug, &mut extra, pos, plan.len());
        let cp = p
            .copy_paste
            .map(|q| self.load(plan[q], epoch))
            .transpose()?;
        let mo = match &p.mosaic {
            Some(qs) => Some(
                qs.iter()
                    .map(|&q| self.load(plan[q], epoch))
                    .collect::<Result<Vec<_>>>()?,
            ),
            None => None,
        };
        let partners = PartnerSamples {
            copy_paste: cp.as_ref(),
            mosaic: mo.as_ref().map(|v| v.iter().collect()),
        };
        Ok(augment_full(&s, &partners, &self.aug, &mut extra, &mut rng))
    }

    /// The batch of `plan[first_pos..first_pos + len]` of `epoch`.
    pub fn batch(
        &self,
        plan: &[Item],
        first_pos: usize,
        len: usize,
        epoch: usize,
    ) -> Result<Batch> {
        let samples: Result<Vec<Sample>> = (first_pos..first_pos + len)
            .into_par_iter()
            .map(|pos| self.item(plan, pos, epoch))
            .collect();
        collate(&samples?)
    }

    /// Builds the batches of `plan` (`batch` items each) on a thread of scope `sc`, at
    /// most two ahead of the consumer; the thread stops when the receiver is dropped.
    pub fn spawn<'scope, 'env>(
        &'env self,
        sc: &'scope std::thread::Scope<'scope, 'env>,
        plan: &'env [Item],
        batch: usize,
        epoch: usize,
    ) -> Receiver<Result<Batch>> {
        let (tx, rx) = sync_channel::<Result<Batch>>(2);
        sc.spawn(move || {
            for (b, chunk) in plan.chunks(batch).enumerate() {
                if tx
                    .send(self.batch(plan, b * batch, chunk.len(), epoch))
                    .is_err()
                {
                    return;
                }
            }
        });
        rx
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_plan_is_a_seeded_permutation() {
        let ids = [4, 7, 9];
        let a = epoch_plan(&ids, 2, 11, 0);
        assert_eq!(a, epoch_plan(&ids, 2, 11, 0));
        assert_ne!(a, epoch_plan(&ids, 2, 11, 1));
        let mut sorted = a.clone();
        sorted.sort_by_key(|i| match i {
            Item::Real(id) => (0, *id),
            Item::Synthetic(k) => (1, *k),
            Item::Unlabeled(k) => (2, *k),
        });
        assert_eq!(
            sorted,
            [
                Item::Real(4),
                Item::Real(7),
                Item::Real(9),
                Item::Synthetic(0),
                Item::Synthetic(1)
            ]
        );
        assert_ne!(mix(1, 2), mix(2, 1));
    }

    fn count_real(b: &[Item]) -> usize {
        b.iter().filter(|i| matches!(i, Item::Real(_))).count()
    }

    #[test]
    fn without_the_mix_keys_the_plan_is_the_old_one() {
        let ids = [4, 7, 9];
        for epoch in 0..3 {
            assert_eq!(
                epoch_batches(&ids, 5, 11, epoch, 3, Mix::default()).unwrap(),
                epoch_plan(&ids, 5, 11, epoch)
            );
        }
        let t = TrainConfig::default();
        assert_eq!(Mix::of(&t), Mix::default());
        // Today's step count: ceil(items / batch).
        assert_eq!(Mix::default().steps(3, 5, 3), 3);
    }

    #[test]
    fn real_fraction_fixes_the_real_count_per_batch_and_the_steps() {
        let ids = [4, 7, 9];
        let m = Mix {
            steps_per_epoch: Some(10),
            real_fraction: Some(0.25),
        };
        let plan = epoch_batches(&ids, 100, 11, 0, 8, m).unwrap();
        assert_eq!(plan.len(), 80);
        for b in plan.chunks(8) {
            assert_eq!(count_real(b), 2);
        }
        // 20 real places over 3 ids: each id once per pass of 3, so 6 or 7 times each.
        for id in ids {
            let n = plan.iter().filter(|i| **i == Item::Real(id)).count();
            assert!(n == 6 || n == 7, "id {id} drawn {n} times");
        }
        // The synthetic side cycles 60 of 100 without repeats.
        let mut syn: Vec<&Item> = plan
            .iter()
            .filter(|i| matches!(i, Item::Synthetic(_)))
            .collect();
        syn.sort_by_key(|i| match i {
            Item::Synthetic(k) => *k,
            _ => u64::MAX,
        });
        syn.dedup();
        assert_eq!(syn.len(), 60);
        // The steps do not depend on the synthetic count.
        assert_eq!(epoch_batches(&ids, 1000, 11, 0, 8, m).unwrap().len(), 80);
        // Seeded: same per (seed, epoch), different across epochs.
        assert_eq!(plan, epoch_batches(&ids, 100, 11, 0, 8, m).unwrap());
        assert_ne!(plan, epoch_batches(&ids, 100, 11, 1, 8, m).unwrap());
        // real_fraction alone keeps today's step count.
        let f = Mix {
            steps_per_epoch: None,
            real_fraction: Some(0.5),
        };
        let plan = epoch_batches(&ids, 13, 11, 0, 4, f).unwrap();
        assert_eq!(plan.len(), 4 * 4);
        assert!(plan.chunks(4).all(|b| count_real(b) == 2));
        // All real and all synthetic.
        let all_real = Mix {
            steps_per_epoch: Some(2),
            real_fraction: Some(1.0),
        };
        let plan = epoch_batches(&ids, 0, 11, 0, 4, all_real).unwrap();
        assert_eq!((plan.len(), count_real(&plan)), (8, 8));
        let all_syn = Mix {
            steps_per_epoch: Some(2),
            real_fraction: Some(0.0),
        };
        assert_eq!(
            count_real(&epoch_batches(&[], 5, 11, 0, 4, all_syn).unwrap()),
            0
        );
    }

    #[test]
    fn steps_alone_cycle_the_natural_mix() {
        let ids = [4, 7, 9];
        let m = Mix {
            steps_per_epoch: Some(5),
            real_fraction: None,
        };
        let plan = epoch_batches(&ids, 2, 11, 0, 3, m).unwrap();
        assert_eq!(plan.len(), 15);
        // The first pass is the old plan; every item appears 3 times in 15.
        assert_eq!(plan[..5], epoch_plan(&ids, 2, 11, 0)[..]);
        for it in epoch_plan(&ids, 2, 11, 0) {
            assert_eq!(plan.iter().filter(|i| **i == it).count(), 3);
        }
    }

    #[test]
    fn a_mix_without_its_images_is_a_clear_error() {
        let m = Mix {
            steps_per_epoch: Some(2),
            real_fraction: Some(0.5),
        };
        let e = epoch_batches(&[1, 2], 0, 0, 0, 4, m)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("data.synthetic = 0") && e.contains("train.real_fraction"),
            "{e}"
        );
        let e = epoch_batches(&[], 9, 0, 0, 4, m).unwrap_err().to_string();
        assert!(e.contains("no real train images"), "{e}");
        let steps = Mix {
            steps_per_epoch: Some(2),
            real_fraction: None,
        };
        assert!(epoch_batches(&[], 0, 0, 0, 4, steps).is_err());
    }
}
