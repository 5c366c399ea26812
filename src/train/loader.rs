//! What the trainer feeds the model each epoch: the shuffled plan of items (real image
//! ids and synthetic indices), and batches built from it on a loader thread — rendering,
//! decoding and augmenting the next batch in parallel with rayon while the current step
//! runs. Each item's augmentation RNG is keyed by (seed, epoch, position), so a run does
//! not depend on thread timing.

use std::sync::mpsc::{sync_channel, Receiver};

use anyhow::Result;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::data::augment::{augment, AugmentConfig};
use crate::data::batch::{collate, Batch};
use crate::data::dataset::{RealSet, Sample, SyntheticSet};
use crate::util::hash::mix64;

/// One item of an epoch: a real image id or a synthetic index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Item {
    Real(u64),
    Synthetic(u64),
}

/// Seed of `b` under `a`: the one derivation of every per-epoch and per-step key.
pub fn mix(a: u64, b: u64) -> u64 {
    mix64(a ^ mix64(b.wrapping_add(0x9E37_79B9_7F4A_7C15)))
}

/// Shuffled items of `epoch`.
pub fn epoch_plan(train_ids: &[u64], synthetic: usize, seed: u64, epoch: usize) -> Vec<Item> {
    let mut items: Vec<Item> = train_ids.iter().map(|&i| Item::Real(i)).collect();
    items.extend((0..synthetic as u64).map(Item::Synthetic));
    items.shuffle(&mut ChaCha8Rng::seed_from_u64(mix(seed, epoch as u64)));
    items
}

/// The training sources and how their samples are augmented.
pub struct Loader {
    pub real: RealSet,
    pub synthetic: SyntheticSet,
    pub aug: AugmentConfig,
    /// Network input size the real images are letterboxed to.
    pub input: u32,
    pub seed: u64,
}

impl Loader {
    /// The batch of `items`, the `first_pos`-th item of `epoch` first.
    pub fn batch(&self, items: &[Item], epoch: usize, first_pos: usize) -> Result<Batch> {
        let samples: Result<Vec<Sample>> = items
            .par_iter()
            .enumerate()
            .map(|(k, it)| {
                let s = match *it {
                    Item::Real(id) => self.real.sample(id, self.input)?,
                    Item::Synthetic(i) => self.synthetic.sample(i, epoch as u64)?,
                };
                let key = mix(mix(self.seed, epoch as u64), (first_pos + k) as u64);
                Ok(augment(&s, &self.aug, &mut ChaCha8Rng::seed_from_u64(key)))
            })
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
                if tx.send(self.batch(chunk, epoch, b * batch)).is_err() {
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
}
