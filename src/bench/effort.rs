//! The per-row effort flags (`--warmup`, `--repeats`, `--train-batch`, `--train-steps`)
//! shared by `bench models`, `bench ablation` and the hidden worker, laid over a base
//! [`Effort`] (the defaults, or `--quick`'s).

use super::measure::Effort;

/// Per-row effort flags of `bench models` / `bench ablation`; unset ones keep the base
/// (the defaults of [`Effort`], or `--quick`'s).
#[derive(Clone, Copy, Debug, Default, clap::Args)]
pub struct EffortFlags {
    /// Untimed batch-1 runs before the timed ones [default: 3].
    #[arg(long)]
    pub warmup: Option<usize>,
    /// Timed batch-1 inference runs; median, p10, p90 reported [default: 30].
    #[arg(long)]
    pub repeats: Option<usize>,
    /// Training batch size of the throughput column [default: 8].
    #[arg(long)]
    pub train_batch: Option<usize>,
    /// Timed training steps, after one warm-up step [default: 3].
    #[arg(long)]
    pub train_steps: Option<usize>,
}

impl EffortFlags {
    pub fn over(self, base: Effort) -> Effort {
        Effort {
            warmup: self.warmup.unwrap_or(base.warmup),
            repeats: self.repeats.unwrap_or(base.repeats),
            train_batch: self.train_batch.unwrap_or(base.train_batch),
            train_steps: self.train_steps.unwrap_or(base.train_steps),
        }
    }
}
