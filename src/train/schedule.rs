//! Learning-rate schedule: linear warmup over `warmup_epochs` (per iteration) or
//! `warmup_iters` (the Mask R-CNN paper's 500 iterations), then the
//! per-epoch factor of ultralytics' schedulers — linear `(1 − e/E)(1 − lrf) + lrf`,
//! cosine `1 + (lrf − 1)(1 − cos(πe/E))/2` — or the paper's multi-step (×0.1 at each
//! milestone epoch).
//!
//! Warmup ramps weights from 0 and biases (incl. normalisation shifts) from
//! `warmup_bias_lr`, like ultralytics, through a per-group learning rate. Ultralytics
//! also ramps SGD momentum 0.8 → 0.937 during warmup; Burn's optimisers hold a fixed
//! momentum, so that part is not reproduced.

use burn::module::ParamGroup;
use burn::optim::lr_scheduler::module_lr_scheduler::{ModuleLearningRate, ModuleLrScheduler};

use crate::config::{ScheduleKind, TrainConfig};

/// Parameters that warm up from `warmup_bias_lr`: biases and normalisation shifts
/// (ultralytics' bias group, `"bias" in name`).
pub const BIAS: &str = r"(^|\.)(bias|beta)$";

/// [`BIAS`] compiled once: [`step_lr`] runs every optimiser step.
static BIAS_GROUP: std::sync::LazyLock<ParamGroup> =
    std::sync::LazyLock::new(|| ParamGroup::from_regex(BIAS).expect("BIAS is a valid regex"));

/// Parameters `train.backbone_lr_mult` scales (every family names its backbone so), and
/// their biases, which keep their warmup on the scaled rate.
static BACKBONE_GROUP: std::sync::LazyLock<ParamGroup> = std::sync::LazyLock::new(|| {
    ParamGroup::from_regex(r"^backbone\.").expect("backbone regex is valid")
});
static BACKBONE_BIAS_GROUP: std::sync::LazyLock<ParamGroup> = std::sync::LazyLock::new(|| {
    ParamGroup::from_regex(r"^backbone\..*(^|\.)(bias|beta)$")
        .expect("backbone bias regex is valid")
});

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

/// Warmup length in iterations: `warmup_iters` when set, else `warmup_epochs` worth.
fn warmup_len(t: &TrainConfig, per_epoch: usize) -> f64 {
    if t.warmup_iters > 0 {
        t.warmup_iters as f64
    } else {
        (t.warmup_epochs * per_epoch as f64).round()
    }
}

/// Learning rate of iteration `iter` (0-based) of `epoch`, with `per_epoch` iterations.
pub fn lr_at(t: &TrainConfig, epoch: usize, iter: usize, per_epoch: usize) -> f64 {
    let base = t.lr * epoch_factor(t, epoch);
    let warm = warmup_len(t, per_epoch);
    let global = (epoch * per_epoch + iter) as f64;
    if warm > 0.0 && global < warm {
        base * (global + 1.0) / (warm + 1.0)
    } else {
        base
    }
}

/// Learning rate of biases at iteration `iter` of `epoch`: from `warmup_bias_lr` down
/// (or up) to [`lr_at`]'s value over the warmup, then equal to it.
pub fn bias_lr_at(t: &TrainConfig, epoch: usize, iter: usize, per_epoch: usize) -> f64 {
    let base = t.lr * epoch_factor(t, epoch);
    let warm = warmup_len(t, per_epoch);
    let global = (epoch * per_epoch + iter) as f64;
    if warm > 0.0 && global < warm {
        t.warmup_bias_lr + (base - t.warmup_bias_lr) * (global + 1.0) / (warm + 1.0)
    } else {
        base
    }
}

/// The per-parameter learning rates of one optimiser step, and the weights' rate (logged).
pub fn step_lr(
    t: &TrainConfig,
    epoch: usize,
    iter: usize,
    per_epoch: usize,
) -> (ModuleLearningRate, f64) {
    let lr = lr_at(t, epoch, iter, per_epoch);
    let bias = bias_lr_at(t, epoch, iter, per_epoch);
    // Burn takes the last group that matches a parameter.
    let mut s = ModuleLrScheduler::new(lr).with_group(BIAS_GROUP.clone(), bias);
    if t.backbone_lr_mult != 1.0 {
        let m = t.backbone_lr_mult;
        s = s
            .with_group(BACKBONE_GROUP.clone(), lr * m)
            .with_group(BACKBONE_BIAS_GROUP.clone(), bias * m);
    }
    (s.step(), lr)
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
    fn biases_warm_down_from_warmup_bias_lr() {
        let mut t = cfg(ScheduleKind::Linear);
        t.warmup_bias_lr = 0.1;
        let per = 10;
        let b: Vec<f64> = (0..40)
            .map(|i| bias_lr_at(&t, i / per, i % per, per))
            .collect();
        assert!(b[0] > 0.09 && b[0] < 0.1, "{}", b[0]);
        for w in b[..30].windows(2) {
            assert!(w[1] < w[0]);
        }
        assert_eq!(b[35], lr_at(&t, 3, 5, per));
        // 0 = biases follow the weights.
        t.warmup_bias_lr = 0.0;
        for i in 0..40 {
            assert_eq!(
                bias_lr_at(&t, i / per, i % per, per),
                lr_at(&t, i / per, i % per, per)
            );
        }
    }

    #[test]
    fn step_lr_gives_biases_and_shifts_their_own_rate() {
        let mut t = cfg(ScheduleKind::Linear);
        t.warmup_bias_lr = 0.1;
        let (rates, lr) = step_lr(&t, 0, 0, 10);
        let id = burn::module::ParamId::new();
        let bias = bias_lr_at(&t, 0, 0, 10);
        assert_eq!(rates.lr_from_param(id, Some("head.cv2.0.conv.weight")), lr);
        assert_eq!(rates.lr_from_param(id, Some("head.cv2.0.bias")), bias);
        assert_eq!(rates.lr_from_param(id, Some("backbone.0.bn.beta")), bias);
        assert_eq!(rates.lr_from_param(id, Some("backbone.0.bn.gamma")), lr);
        assert_eq!(rates.lr_from_param(id, Some("unbiased")), lr);
        t.backbone_lr_mult = 0.1;
        let (rates, lr) = step_lr(&t, 0, 0, 10);
        let scaled = |a: f64, b: f64| (a - b).abs() < 1e-15;
        let r = |p: &str| rates.lr_from_param(id, Some(p));
        assert!(scaled(r("backbone.stem.conv.weight"), lr * 0.1));
        assert!(scaled(
            r("backbone.stages.0.blocks.0.convs.0.bn.beta"),
            bias * 0.1
        ));
        assert!(scaled(
            r("backbone.stages.0.blocks.0.convs.0.bn.gamma"),
            lr * 0.1
        ));
        assert_eq!(r("pixel_decoder.mask_features.bias"), bias);
        assert_eq!(r("transformer_decoder.class_embed.weight"), lr);
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
