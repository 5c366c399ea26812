//! The negatives knob (`[data.negatives]`): shares of the synthetic renders that show
//! what is *not* a carcass — whole images with no carcass at all (an empty belt, plate
//! or crate: a pure negative) and piles with non-carcass objects among them (gloves,
//! hands, shackles, knives, scrapers, packaging, fat scraps; `render::distractor`).
//!
//! Unlike the `scene` and `distractors` randomisation groups ([`super::Randomize`]),
//! which change every image they touch (the scene group also swaps surfaces, smears and
//! framing), these are per-image coin flips from their own RNG stream ("negatives"), so
//! a share of 0 leaves every render exactly as it was (and its cache key too) and a
//! share > 0 changes only the images the coin picks. A third share replaces renders by
//! clutter pictures (`render::clutter`): an ordinary photo's shapes, no carcass. Issue 38
//! part 2 measured the shares (BENCHMARKS.md "Transfer"; `bench/results/negatives/`).

use anyhow::{ensure, Result};
use serde::{Deserialize, Serialize};

/// Shares of carcass-free and distractor images among the synthetic renders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Negatives {
    /// Probability that a render holds no carcass at all (ultralytics recommends 0–10 %
    /// background images in a training set).
    pub empty: f32,
    /// Probability that a render gets 1–4 distractors (`ranges.distractors`, at least
    /// one) on and around its pile; independent of `empty`, so an empty image can hold a
    /// glove or a knife.
    pub distractors: f32,
    /// Probability that a render is replaced by a clutter picture: dead leaves, random
    /// flat shapes of every size and colour, no carcass (`render::clutter`). Left out of
    /// the serialised options while 0, so older cache keys stay valid.
    #[serde(skip_serializing_if = "is_zero")]
    pub clutter: f32,
}

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

impl Negatives {
    /// True when every share is 0 (renders as before the knob; left out of the render
    /// options' serialisation and so of cache keys).
    pub fn is_off(&self) -> bool {
        self.empty == 0.0 && self.distractors == 0.0 && self.clutter == 0.0
    }

    /// Every share must be a probability; the error names the key.
    pub fn validate(&self) -> Result<()> {
        for (name, p) in [
            ("data.negatives.empty", self.empty),
            ("data.negatives.distractors", self.distractors),
            ("data.negatives.clutter", self.clutter),
        ] {
            ensure!(
                (0.0..=1.0).contains(&p),
                "{name} = {p} must be a share in [0, 1]"
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_parse_default_to_off_and_out_of_range_is_refused() {
        let n: Negatives = toml::from_str("empty = 0.1").unwrap();
        assert_eq!(n.empty, 0.1);
        assert_eq!(n.distractors, 0.0);
        assert!(!n.is_off() && Negatives::default().is_off());
        assert!(toml::from_str::<Negatives>("empy = 0.1").is_err());
        let bad = Negatives {
            distractors: 1.5,
            ..Negatives::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(
            e.contains("data.negatives.distractors") && e.contains("1.5"),
            "{e}"
        );
        let nan = Negatives {
            empty: f32::NAN,
            ..Negatives::default()
        };
        assert!(nan.validate().is_err());
        let c: Negatives = toml::from_str("clutter = 0.2").unwrap();
        assert_eq!(c.clutter, 0.2);
        assert!(!c.is_off());
        let e = Negatives { clutter: -0.1, ..c }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("data.negatives.clutter"), "{e}");
    }
}
