//! Learning-rate schedule: linear warmup over `warmup_epochs` (per iteration) or
//! `warmup_iters` (the Mask R-CNN paper's 500 iterations), then the
//! per-epoch factor of ultralytics' schedulers — linear `(1 − e/E)(1 − lrf) + lrf`,
//! cosine `1 + (lrf − 1)(1 − cos(πe/E))/2` — or the paper's multi-step (×0.1 at each
//! milestone epoch).
//!
//! Warmup ramps every parameter from 0 (ultralytics starts biases at 0.1 and ramps
//! momentum 0.8 → 0.937; Burn's optimisers take one learning rate per step and a fixed
//! momentum, so neither is reproduced).

use crate::config::{ScheduleKind, TrainConfig};

/// Factor of `lr` at (0-based) `epoch`, before warmup.
pub fn epoch_factor(t: &TrainConfig, epoch: usize) -> f64 {
    let e = epoch as f64;
    let n = t.epochs as f64;
    match t.schedule {
        ScheduleKind::Linear => (1.0 - e / n).max(0.0) * (1.0 - t.lrf) + t.lrf,
        ScheduleKind::Cosine => {
            1.0 + (t.lrf - 1.0) * (1.0 - (std::f64::consts::PI * e.min(n) / n).cos()) / 2.0
        }
        ScheduleKind::Multistep => {
            0.1f64.powi(t.milestones.iter().filter(|&&m| m <= epoch).count() as i32)
        }
    }
}

/// Learning rate of iteration `iter` (0-based) of `epoch`, with `per_epoch` iterations.
pub fn lr_at(t: &TrainConfig, epoch: usize, iter: usize, per_epoch: usize) -> f64 {
    let base = t.lr * epoch_factor(t, epoch);
    let warm = if t.warmup_iters > 0 {
        t.warmup_iters as f64
    } else {
        (t.warmup_epochs * per_epoch as f64).round()
    };
    let global = (epoch * per_epoch + iter) as f64;
    if warm > 0.0 && global < warm {
        base * (global + 1.0) / (warm + 1.0)
    } else {
        base
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(schedule: ScheduleKind) -> TrainConfig {
        let mut t = TrainConfig::default();
        t.epochs = 200;
        t.lr = 0.01;
        t.lrf = 0.01;
        t.warmup_epochs = 3.0;
        t.schedule = schedule;
        t
    }

    #[test]
    fn linear_and_cosine_end_at_lrf() {
        for k in [ScheduleKind::Linear, ScheduleKind::Cosine] {
            let t = cfg(k);
            assert!((epoch_factor(&t, 0) - 1.0).abs() < 1e-12);
            assert!((epoch_factor(&t, 200) - 0.01).abs() < 1e-12);
            let mid = epoch_factor(&t, 100);
            assert!((mid - 0.505).abs() < 1e-12, "{k:?} {mid}");
            for e in 1..200 {
                assert!(epoch_factor(&t, e) < epoch_factor(&t, e - 1));
            }
        }
        // Cosine stays higher early and lower late than linear.
        assert!(
            epoch_factor(&cfg(ScheduleKind::Cosine), 20)
                > epoch_factor(&cfg(ScheduleKind::Linear), 20)
        );
        assert!(
            epoch_factor(&cfg(ScheduleKind::Cosine), 180)
                < epoch_factor(&cfg(ScheduleKind::Linear), 180)
        );
    }

    #[test]
    fn multistep_drops_tenfold_at_milestones() {
        let t = cfg(ScheduleKind::Multistep);
        assert_eq!(t.milestones, vec![30, 60, 100]);
        assert_eq!(epoch_factor(&t, 29), 1.0);
        assert!((epoch_factor(&t, 30) - 0.1).abs() < 1e-12);
        assert!((epoch_factor(&t, 60) - 0.01).abs() < 1e-12);
        assert!((epoch_factor(&t, 150) - 0.001).abs() < 1e-12);
    }

    #[test]
    fn warmup_ramps_linearly_then_follows_the_schedule() {
        let t = cfg(ScheduleKind::Linear);
        let per = 10; // 3 warmup epochs = 30 iterations
        let lrs: Vec<f64> = (0..40).map(|i| lr_at(&t, i / per, i % per, per)).collect();
        assert!((lrs[0] - 0.01 * epoch_factor(&t, 0) / 31.0).abs() < 1e-12);
        for w in lrs[..30].windows(2) {
            assert!(w[1] > w[0]);
        }
        assert!((lrs[35] - 0.01 * epoch_factor(&t, 3)).abs() < 1e-12);
        let mut no = t.clone();
        no.warmup_epochs = 0.0;
        assert_eq!(lr_at(&no, 0, 0, per), 0.01);
    }

    #[test]
    fn warmup_iters_replaces_warmup_epochs() {
        let mut t = cfg(ScheduleKind::Multistep);
        t.warmup_iters = 25; // 2.5 epochs of 10 iterations, whatever warmup_epochs says
        let per = 10;
        assert!((lr_at(&t, 0, 0, per) - 0.01 / 26.0).abs() < 1e-12);
        assert!((lr_at(&t, 2, 4, per) - 0.01 * 25.0 / 26.0).abs() < 1e-12);
        assert_eq!(lr_at(&t, 2, 5, per), 0.01);
        assert_eq!(lr_at(&t, 3, 0, per), 0.01);
    }
}
