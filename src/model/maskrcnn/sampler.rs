//! Balanced foreground/background subsampling (detectron2 `modeling/sampling.py`,
//! `subsample_labels`): at most `num_samples · positive_fraction` positives, the rest filled
//! with negatives, each drawn uniformly without replacement from a caller-seeded RNG so a
//! training step is reproducible.

use rand::seq::index::sample;
use rand::Rng;

use super::matcher::{NEGATIVE, POSITIVE};

/// Indices of the sampled positives and negatives (each in increasing order).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sampled {
    pub positive: Vec<usize>,
    pub negative: Vec<usize>,
}

/// Subsamples `labels` ([`POSITIVE`], [`NEGATIVE`], anything else ignored).
///
/// Panics naming the values unless `0 ≤ positive_fraction ≤ 1`.
pub fn subsample_labels<R: Rng>(
    labels: &[i8],
    num_samples: usize,
    positive_fraction: f32,
    rng: &mut R,
) -> Sampled {
    assert!(
        (0.0..=1.0).contains(&positive_fraction),
        "subsample_labels: positive_fraction must be in [0, 1], got {positive_fraction}"
    );
    let pos: Vec<usize> = (0..labels.len())
        .filter(|&i| labels[i] == POSITIVE)
        .collect();
    let neg: Vec<usize> = (0..labels.len())
        .filter(|&i| labels[i] == NEGATIVE)
        .collect();
    let num_pos = ((num_samples as f32 * positive_fraction) as usize).min(pos.len());
    let num_neg = (num_samples - num_pos).min(neg.len());
    let pick = |v: &[usize], k: usize, rng: &mut R| {
        let mut out: Vec<usize> = sample(rng, v.len(), k).into_iter().map(|i| v[i]).collect();
        out.sort_unstable();
        out
    };
    Sampled {
        positive: pick(&pos, num_pos, rng),
        negative: pick(&neg, num_neg, rng),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn caps_positives_and_fills_with_negatives() {
        let mut labels = vec![NEGATIVE; 100];
        for l in labels.iter_mut().take(40) {
            *l = POSITIVE;
        }
        labels[99] = -1;
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let s = subsample_labels(&labels, 64, 0.25, &mut rng);
        assert_eq!(s.positive.len(), 16);
        assert_eq!(s.negative.len(), 48);
        assert!(s.positive.iter().all(|&i| labels[i] == POSITIVE));
        assert!(s.negative.iter().all(|&i| labels[i] == NEGATIVE));
        // Few positives: all of them, the rest negatives.
        let mut few = vec![NEGATIVE; 30];
        few[3] = POSITIVE;
        let s = subsample_labels(&few, 16, 0.5, &mut rng);
        assert_eq!(s.positive, vec![3]);
        assert_eq!(s.negative.len(), 15);
        // Not enough of anything: everything.
        let s = subsample_labels(&few, 100, 0.5, &mut rng);
        assert_eq!(s.positive.len() + s.negative.len(), 30);
    }

    #[test]
    fn seeded_and_varied() {
        let labels = vec![NEGATIVE; 1000];
        let a = subsample_labels(&labels, 10, 0.5, &mut ChaCha8Rng::seed_from_u64(7));
        let b = subsample_labels(&labels, 10, 0.5, &mut ChaCha8Rng::seed_from_u64(7));
        let c = subsample_labels(&labels, 10, 0.5, &mut ChaCha8Rng::seed_from_u64(8));
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    #[should_panic(expected = "positive_fraction must be in [0, 1], got 1.5")]
    fn rejects_fraction() {
        subsample_labels(&[0], 1, 1.5, &mut ChaCha8Rng::seed_from_u64(0));
    }
}
