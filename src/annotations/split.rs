//! The train/val/test split of a real dataset, decided in one place
//! ([`Split::for_dataset`]): the dataset's own split when its files declare one (a
//! YOLO `data.yaml`'s `train`/`val`/`test`, one COCO file per split), otherwise a
//! deterministic seeded draw (the paper's 60/60/180 of 300).

use std::path::Path;

use anyhow::{bail, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// One part of a split, as dataset files name it (`train`, `val`, `test`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    Train,
    Val,
    Test,
}

impl Part {
    pub const ALL: [Part; 3] = [Part::Train, Part::Val, Part::Test];

    pub fn key(self) -> &'static str {
        match self {
            Part::Train => "train",
            Part::Val => "val",
            Part::Test => "test",
        }
    }
}

/// The split a dataset's own files declare: image ids per part, disjoint. A part may be
/// empty (a YOLO `data.yaml` without `test`); [`Split::for_dataset`] says what then.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OwnSplit {
    pub train: Vec<u64>,
    pub val: Vec<u64>,
    pub test: Vec<u64>,
}

impl OwnSplit {
    /// Puts image `id` into `part`.
    pub fn push(&mut self, part: Part, id: u64) {
        match part {
            Part::Train => self.train.push(id),
            Part::Val => self.val.push(id),
            Part::Test => self.test.push(id),
        }
    }

    /// Keeps only the ids in `keep` (sorted), e.g. after `data.real.limit`.
    pub fn retain(&mut self, keep: &[u64]) {
        for part in [&mut self.train, &mut self.val, &mut self.test] {
            part.retain(|i| keep.binary_search(i).is_ok());
        }
    }
}

/// Image ids per split, written next to a run so it can be reproduced.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    pub seed: u64,
    pub train: Vec<u64>,
    pub val: Vec<u64>,
    pub test: Vec<u64>,
}

impl Split {
    /// Shuffles the sorted ids with ChaCha8(seed) and cuts `fractions` = [train, val]
    /// (rounded), the rest being test. Each split's ids are returned sorted.
    pub fn new(ids: &[u64], fractions: [f64; 2], seed: u64) -> Result<Split> {
        let [ft, fv] = fractions;
        if !(0.0..=1.0).contains(&ft) || !(0.0..=1.0).contains(&fv) || ft + fv > 1.0 {
            bail!(
                "split fractions train {ft} + val {fv} must be within 0..=1 and sum to at most 1"
            );
        }
        let mut all = ids.to_vec();
        all.sort_unstable();
        all.dedup();
        all.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        let n = all.len();
        let nt = (n as f64 * ft).round() as usize;
        let nv = ((n as f64 * fv).round() as usize).min(n - nt);
        let mut train = all[..nt].to_vec();
        let mut val = all[nt..nt + nv].to_vec();
        let mut test = all[nt + nv..].to_vec();
        train.sort_unstable();
        val.sort_unstable();
        test.sort_unstable();
        Ok(Split {
            seed,
            train,
            val,
            test,
        })
    }

    /// The one decision point for a dataset `ids` with its own split `own` (if any):
    /// `fractions = [0, 0]` makes every image test (scoring an external set); otherwise
    /// the dataset's own split when it has one (`fractions` unused), else
    /// [`Split::new`]'s seeded draw. An own split without test images is an error:
    /// the final numbers are taken on held-out test images, never on val.
    pub fn for_dataset(
        ids: &[u64],
        own: Option<&OwnSplit>,
        fractions: [f64; 2],
        seed: u64,
    ) -> Result<Split> {
        let Some(own) = own.filter(|_| fractions != [0.0, 0.0]) else {
            return Split::new(ids, fractions, seed);
        };
        if own.test.is_empty() {
            bail!(
                "the dataset's own split has {} train / {} val images and no test images: chicktrain scores the final checkpoint on held-out test images, so give the dataset a test part (`test:` in data.yaml, data.real.test for COCO)",
                own.train.len(),
                own.val.len()
            );
        }
        let sorted = |v: &[u64]| {
            let mut v = v.to_vec();
            v.sort_unstable();
            v
        };
        Ok(Split {
            seed,
            train: sorted(&own.train),
            val: sorted(&own.val),
            test: sorted(&own.test),
        })
    }

    /// The split a training run uses: [`Split::for_dataset`], then at most `train_limit`
    /// of its train ids ([`Split::limit_train`]). The trainer and `bench loader` both
    /// call it.
    pub fn for_training(
        ids: &[u64],
        own: Option<&OwnSplit>,
        fractions: [f64; 2],
        seed: u64,
        train_limit: Option<usize>,
    ) -> Result<Split> {
        let mut s = Split::for_dataset(ids, own, fractions, seed)?;
        if let Some(n) = train_limit {
            s.limit_train(n);
        }
        Ok(s)
    }

    /// Keeps `n` of the train ids, drawn by the split's seed (all when there are no more
    /// than `n`); val and test are untouched, so runs over several `n` share them.
    pub fn limit_train(&mut self, n: usize) {
        if n >= self.train.len() {
            return;
        }
        // A stream apart from the split's own shuffle.
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x7EA1_11D1);
        self.train.shuffle(&mut rng);
        self.train.truncate(n);
        self.train.sort_unstable();
    }

    pub fn save(&self, path: &Path) -> Result<()> {
        crate::util::write_atomic(path, serde_json::to_string_pretty(self)?.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_split_of_300_is_60_60_180_and_reproducible() {
        let ids: Vec<u64> = (1..=300).collect();
        let s = Split::new(&ids, [0.2, 0.2], 7).unwrap();
        assert_eq!((s.train.len(), s.val.len(), s.test.len()), (60, 60, 180));
        assert_eq!(s, Split::new(&ids, [0.2, 0.2], 7).unwrap());
        assert_ne!(s.train, Split::new(&ids, [0.2, 0.2], 8).unwrap().train);
        let mut all: Vec<u64> = [s.train, s.val, s.test].concat();
        all.sort_unstable();
        assert_eq!(all, ids);
    }

    #[test]
    fn own_split_is_kept_unless_every_image_is_asked_for_as_test() {
        let ids: Vec<u64> = (1..=6).collect();
        let own = OwnSplit {
            train: vec![3, 1],
            val: vec![2],
            test: vec![6, 4, 5],
        };
        let s = Split::for_training(&ids, Some(&own), [0.2, 0.2], 9, None).unwrap();
        assert_eq!(
            (s.train, s.val, s.test),
            (vec![1, 3], vec![2], vec![4, 5, 6])
        );
        let all = Split::for_dataset(&ids, Some(&own), [0.0, 0.0], 9).unwrap();
        assert_eq!(all.test, ids);
        // No own split: the seeded draw, as before.
        assert_eq!(
            Split::for_dataset(&ids, None, [0.5, 0.2], 9).unwrap(),
            Split::new(&ids, [0.5, 0.2], 9).unwrap()
        );
        let no_test = OwnSplit {
            test: vec![],
            ..own
        };
        let e = Split::for_dataset(&ids, Some(&no_test), [0.2, 0.2], 9).unwrap_err();
        assert!(e.to_string().contains("no test images"), "{e}");
        let mut limited = no_test.clone();
        limited.retain(&[1, 2]);
        assert_eq!((limited.train, limited.val), (vec![1], vec![2]));
    }

    #[test]
    fn limit_train_keeps_a_seeded_subset_and_leaves_val_and_test() {
        let ids: Vec<u64> = (1..=120).collect();
        let full = Split::new(&ids, [0.2, 0.2], 3).unwrap();
        let mut six = full.clone();
        six.limit_train(6);
        assert_eq!(six.train.len(), 6);
        assert!(six.train.iter().all(|i| full.train.contains(i)));
        assert!(six.train.windows(2).all(|w| w[0] < w[1]));
        assert_eq!((&six.val, &six.test), (&full.val, &full.test));
        // Not simply the lowest ids, and the same for the same seed.
        assert_ne!(six.train, full.train[..6].to_vec());
        let mut again = full.clone();
        again.limit_train(6);
        assert_eq!(again, six);
        // More than there are: all of them.
        let mut all = full.clone();
        all.limit_train(1000);
        assert_eq!(all, full);
    }
}
