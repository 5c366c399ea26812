//! Deterministic train/val/test split of a real dataset (the paper's 60/60/180 of 300).

use std::path::Path;

use anyhow::{bail, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

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
}
