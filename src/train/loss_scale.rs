//! Dynamic loss scaling for f16 training (`train.precision = "f16"`), PyTorch's
//! `torch.cuda.amp.GradScaler` rule: the loss is multiplied by the scale before
//! backward so small gradients do not flush to zero in f16; the gradients are divided by
//! it again before clipping. A step whose gradients overflowed (non-finite norm) is
//! skipped — no optimiser step, no EMA update — and the scale halves; after
//! [`GROWTH_INTERVAL`] good steps in a row it doubles.
//!
//! One difference: the initial (and largest) scale is 2¹⁵, not GradScaler's 2¹⁶. Without
//! autocast the loss itself is an f16 tensor, and 65 536 is past f16's largest value
//! (65 504), so every first step would overflow. A scale that would fall below
//! [`MIN_SCALE`] means the gradients overflow even unscaled: an error, never a silent 0.
//! A non-finite loss is not the scaler's business: the divergence guard stops the run.

use anyhow::{bail, Result};

/// Initial and largest scale: the largest power of two f16 holds.
pub const MAX_SCALE: f32 = 32768.0;
/// Below this the gradients overflow unscaled (2⁻¹⁴, f16's smallest normal number).
pub const MIN_SCALE: f32 = 1.0 / 16384.0;
/// Good steps in a row before the scale doubles (GradScaler's `growth_interval`).
pub const GROWTH_INTERVAL: u32 = 2000;

/// Scale state: the checkpoint format's [`LossScaleState`] (`last.bpk`'s header stores
/// it, so `--resume` continues with it, and the format must not import the trainer);
/// the rule that updates it is here.
pub use crate::infer::checkpoint::LossScaleState as LossScaler;

impl Default for LossScaler {
    fn default() -> Self {
        LossScaler {
            scale: MAX_SCALE,
            good_steps: 0,
            skipped: 0,
        }
    }
}

impl LossScaler {
    /// After backward of the scaled loss: `finite` is whether the gradients' norm is.
    /// Returns whether to take the optimiser step; an error when the scale would fall
    /// below [`MIN_SCALE`].
    pub fn update(&mut self, finite: bool) -> Result<bool> {
        if finite {
            self.good_steps += 1;
            if self.good_steps >= GROWTH_INTERVAL {
                self.good_steps = 0;
                self.scale = (self.scale * 2.0).min(MAX_SCALE);
            }
            return Ok(true);
        }
        self.good_steps = 0;
        self.skipped += 1;
        let next = self.scale * 0.5;
        if next < MIN_SCALE {
            bail!(
                "f16 gradients overflow even at loss scale {:.3e} (after {} skipped steps): the run diverged or does not fit f16's range; use train.precision = \"bf16\" or \"f32\", or lower train.lr",
                self.scale,
                self.skipped
            );
        }
        self.scale = next;
        Ok(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overflow_skips_the_step_and_halves_the_scale() {
        let mut s = LossScaler::default();
        assert_eq!(s.scale, MAX_SCALE);
        assert!(s.update(true).unwrap());
        assert_eq!(s.good_steps, 1);
        assert!(!s.update(false).unwrap(), "an overflowed step is skipped");
        assert_eq!((s.scale, s.good_steps, s.skipped), (MAX_SCALE / 2.0, 0, 1));
        assert!(!s.update(false).unwrap());
        assert_eq!((s.scale, s.skipped), (MAX_SCALE / 4.0, 2));
    }

    #[test]
    fn the_scale_doubles_after_the_growth_interval_and_never_passes_f16s_range() {
        let mut s = LossScaler {
            scale: 1024.0,
            ..Default::default()
        };
        for _ in 0..GROWTH_INTERVAL - 1 {
            assert!(s.update(true).unwrap());
        }
        assert_eq!(s.scale, 1024.0, "not before {GROWTH_INTERVAL} good steps");
        s.update(true).unwrap();
        assert_eq!((s.scale, s.good_steps), (2048.0, 0));
        // An overflow restarts the count.
        for _ in 0..GROWTH_INTERVAL - 1 {
            s.update(true).unwrap();
        }
        s.update(false).unwrap();
        s.update(true).unwrap();
        assert_eq!(s.scale, 1024.0);
        // Growth stops at MAX_SCALE, which f16 holds (65 536 would be inf there).
        let mut s = LossScaler::default();
        for _ in 0..3 * GROWTH_INTERVAL {
            s.update(true).unwrap();
        }
        assert_eq!(s.scale, MAX_SCALE);
        assert!(half::f16::from_f32(MAX_SCALE).is_finite());
        assert!(!half::f16::from_f32(MAX_SCALE * 2.0).is_finite());
    }

    #[test]
    fn the_scale_never_reaches_zero_silently() {
        let mut s = LossScaler::default();
        let mut n = 0;
        let e = loop {
            match s.update(false) {
                Ok(step) => assert!(!step),
                Err(e) => break e.to_string(),
            }
            assert!(s.scale >= MIN_SCALE && s.scale > 0.0);
            n += 1;
            assert!(n < 100, "the scale kept halving");
        };
        // 2^15 down to 2^-14 is 29 halvings; the 30th would pass below MIN_SCALE.
        assert_eq!(n, 29);
        assert!(
            e.contains("f16 gradients overflow") && e.contains("bf16"),
            "{e}"
        );
    }
}
