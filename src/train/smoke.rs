//! `--smoke`: any config shrunk to about a minute that still goes through every stage.

use crate::config::Config;
use crate::infer::detector::smoke_section;

/// 64 px images (no crop), at most 9 real and 4 synthetic images, 2 epochs (of at
/// most 3 steps when `train.steps_per_epoch` is set), batch 4; the `[model]` table as
/// its family shrinks it (`Family::smoke`: widths, proposal and query counts, never
/// the depth, so every code path still runs).
pub fn smoke_config(cfg: &mut Config) {
    cfg.name = format!("{}_smoke", cfg.name);
    let d = &mut cfg.data;
    d.image_size = 64;
    d.crop = 64;
    d.real.count = d.real.count.min(9);
    d.real.limit = Some(d.real.limit.unwrap_or(9).min(9));
    d.synthetic = d.synthetic.min(4);
    let t = &mut cfg.train;
    t.epochs = t.epochs.min(2);
    t.steps_per_epoch = t.steps_per_epoch.map(|n| n.min(3));
    t.batch = t.batch.min(4);
    t.warmup_epochs = t.warmup_epochs.min(1.0);
    t.warmup_iters = t.warmup_iters.min(2);
    t.milestones.retain(|&m| m < t.epochs);
    smoke_section(&mut cfg.model);
}
