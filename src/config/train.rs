//! `[train]`: optimiser, schedule, EMA, clipping and augmentation settings.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::self_training::SelfTrainingConfig;

/// The training augmentations by name (the `[train]` keys that set them; `affine` is
/// `degrees`, `scale` and `translate`, `crop` is `data.crop`), in the order they run
/// unless `train.augment_order` says otherwise: ultralytics' order, copy-paste and mosaic
/// on whole images first, then the warp that crops the mosaic back, the paper's crop, and
/// flips and colour last. `data::augment::pipeline` builds the list from these names.
pub const AUGMENTATIONS: [&str; 7] = [
    "copy_paste",
    "mosaic",
    "affine",
    "crop",
    "fliplr",
    "hsv",
    "flipud",
];

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OptimizerKind {
    Sgd,
    Adamw,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScheduleKind {
    Linear,
    Cosine,
    Multistep,
}

/// Float type of parameters and activations (`train.precision`). Burn has no autocast:
/// a reduced type is the device's default float type for the whole run (see
/// `infer::precision`); f16 adds dynamic loss scaling (`train::loss_scale`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    #[default]
    F32,
    F16,
    Bf16,
}

impl Precision {
    /// The value as written in a config.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
            Precision::Bf16 => "bf16",
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    #[serde(default = "default_epochs")]
    pub epochs: usize,
    #[serde(default = "default_batch")]
    pub batch: usize,
    #[serde(default = "default_optimizer")]
    pub optimizer: OptimizerKind,
    #[serde(default = "default_lr")]
    pub lr: f64,
    /// Final learning rate as a fraction of `lr` (linear / cosine).
    #[serde(default = "default_lrf")]
    pub lrf: f64,
    #[serde(default = "default_momentum")]
    pub momentum: f64,
    #[serde(default = "default_wd")]
    pub weight_decay: f64,
    #[serde(default)]
    pub nesterov: bool,
    #[serde(default = "default_warmup")]
    pub warmup_epochs: f64,
    /// Learning rate biases start warmup at, falling linearly to `lr` (ultralytics'
    /// `warmup_bias_lr`, 0.1 in its SGD recipe; 0 = biases warm up like weights).
    #[serde(default)]
    pub warmup_bias_lr: f64,
    /// Warmup length in iterations (the Mask R-CNN paper: 500); when > 0 it replaces
    /// `warmup_epochs`.
    #[serde(default)]
    pub warmup_iters: usize,
    #[serde(default = "default_schedule")]
    pub schedule: ScheduleKind,
    /// Multistep: epochs where the learning rate drops ×0.1 (paper: 30, 60, 100).
    #[serde(default = "default_milestones")]
    pub milestones: Vec<usize>,
    /// Global gradient-norm clip (ultralytics uses 10).
    #[serde(default = "default_clip")]
    pub grad_clip: f64,
    /// Learning-rate factor of the parameters under `backbone.` (weights and biases;
    /// Mask2Former's recipe: 0.1). 1 = one rate for the whole model.
    #[serde(default = "default_backbone_lr_mult")]
    pub backbone_lr_mult: f64,
    #[serde(default = "default_true")]
    pub ema: bool,
    #[serde(default = "default_fliplr")]
    pub fliplr: f64,
    /// HSV jitter gains (ultralytics: 0.015, 0.7, 0.4).
    #[serde(default = "default_hsv")]
    pub hsv: [f64; 3],
    /// Freeze the first N stages (ultralytics' `freeze`): YOLO layers `0..N` by
    /// ultralytics' indices (≤ 23), Mask R-CNN detectron2's `FREEZE_AT` (≤ 5: 1 = stem,
    /// 2 = stem + res2, …). Frozen weights take no gradient and their BatchNorm runs in
    /// eval mode. 0 = train everything.
    #[serde(default)]
    pub freeze: usize,
    /// Validate every N epochs, and always after the last one (detectron2's
    /// `TEST.EVAL_PERIOD`; N = `epochs` is ultralytics' `val=False`). Validation costs
    /// inference over the val images, so on a CPU a short-epoch run spends much of its
    /// time there; `best.bpk` is chosen among the validated epochs only.
    #[serde(default = "default_val_every")]
    pub val_every: usize,
    /// Optimiser steps per epoch (detectron2's MAX_ITER, per epoch); unset = every item
    /// once, `ceil((real train + synthetic) / batch)`. Fixing it makes recipes with
    /// different synthetic counts cost the same compute.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps_per_epoch: Option<usize>,
    /// Share of real images in every batch, `round(real_fraction × batch)` of them (the
    /// few real ones oversampled); unset = the natural proportion of the shuffled items.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub real_fraction: Option<f64>,
    /// Rotation uniform in ±degrees (ultralytics' `degrees`; a pile seen from above has
    /// no up, 180 = any angle). 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub degrees: f64,
    /// Scale jitter uniform in 1 ± scale (ultralytics' `scale`). 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub scale: f64,
    /// Shift uniform in ±translate of the image size (ultralytics' `translate`). 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub translate: f64,
    /// Vertical flip probability (ultralytics' `flipud`). 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub flipud: f64,
    /// Probability of a 2×2 mosaic of four samples, cropped to the training size
    /// (ultralytics' `mosaic`). 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub mosaic: f64,
    /// Probability per image of pasting instances of another sample on top (ultralytics'
    /// `copy_paste`, Ghiasi et al. 2021). 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub copy_paste: f64,
    /// The order the augmentations run in: each name of [`AUGMENTATIONS`] once. Unset =
    /// that list's order (ultralytics'), and left out of resolved configs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub augment_order: Option<Vec<String>>,
    /// Float type of the run: "f32" (default), "bf16" or "f16" (with dynamic loss
    /// scaling). Checkpoints are written in f32 whatever it is. f32 is left out of
    /// resolved configs and checkpoint headers, which then read as before this key.
    #[serde(default, skip_serializing_if = "is_f32")]
    pub precision: Precision,
    /// `[train.self_training]`: the knobs of self-training on `[data.unlabeled]` (which
    /// turns it on; its defaults apply when this table is left out). Left out of resolved
    /// configs when unset, which then read as before this key.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub self_training: Option<SelfTrainingConfig>,
}

fn is_f32(p: &Precision) -> bool {
    *p == Precision::F32
}

fn default_epochs() -> usize {
    200
}
fn default_batch() -> usize {
    8
}
fn default_optimizer() -> OptimizerKind {
    OptimizerKind::Sgd
}
fn default_lr() -> f64 {
    0.01
}
fn default_lrf() -> f64 {
    0.01
}
fn default_momentum() -> f64 {
    0.937
}
fn default_wd() -> f64 {
    5e-4
}
fn default_warmup() -> f64 {
    3.0
}
fn default_schedule() -> ScheduleKind {
    ScheduleKind::Linear
}
fn default_milestones() -> Vec<usize> {
    vec![30, 60, 100]
}
fn default_backbone_lr_mult() -> f64 {
    1.0
}
fn default_clip() -> f64 {
    10.0
}
fn default_fliplr() -> f64 {
    0.5
}
fn default_hsv() -> [f64; 3] {
    [0.015, 0.7, 0.4]
}
fn default_val_every() -> usize {
    1
}

impl Default for TrainConfig {
    fn default() -> Self {
        toml::from_str("").expect("train defaults")
    }
}

impl TrainConfig {
    /// Range checks, with messages that say what to change.
    pub fn validate(&self) -> Result<()> {
        let t = self;
        if t.epochs == 0 {
            bail!("train.epochs must be at least 1");
        }
        if t.batch == 0 {
            bail!("train.batch must be at least 1");
        }
        if t.val_every == 0 {
            bail!(
                "train.val_every must be at least 1 (1 validates every epoch; train.epochs validates only after the last)"
            );
        }
        for (k, v) in [("train.lr", t.lr), ("train.lrf", t.lrf)] {
            if !(v.is_finite() && v > 0.0) {
                bail!("{k} = {v} must be a positive number");
            }
        }
        if !(0.0..1.0).contains(&t.momentum) {
            bail!("train.momentum = {} must be in [0, 1)", t.momentum);
        }
        if !(t.weight_decay.is_finite() && t.weight_decay >= 0.0) {
            bail!("train.weight_decay = {} must be >= 0", t.weight_decay);
        }
        if !(t.warmup_epochs.is_finite() && t.warmup_epochs >= 0.0) {
            bail!("train.warmup_epochs = {} must be >= 0", t.warmup_epochs);
        }
        if !(t.warmup_bias_lr.is_finite() && (0.0..=1.0).contains(&t.warmup_bias_lr)) {
            bail!(
                "train.warmup_bias_lr = {} must be in [0, 1]",
                t.warmup_bias_lr
            );
        }
        if !(t.backbone_lr_mult.is_finite()
            && t.backbone_lr_mult > 0.0
            && t.backbone_lr_mult <= 10.0)
        {
            bail!(
                "train.backbone_lr_mult = {} must be in (0, 10]",
                t.backbone_lr_mult
            );
        }
        if !(t.grad_clip.is_finite() && t.grad_clip > 0.0) {
            bail!("train.grad_clip = {} must be positive", t.grad_clip);
        }
        if !(0.0..=1.0).contains(&t.fliplr) {
            bail!("train.fliplr = {} must be a probability", t.fliplr);
        }
        if t.hsv.iter().any(|v| !(0.0..=1.0).contains(v)) {
            bail!("train.hsv = {:?} must be three gains in [0, 1]", t.hsv);
        }
        if t.steps_per_epoch == Some(0) {
            bail!("train.steps_per_epoch = 0 must be at least 1 (or left out: every item once per epoch)");
        }
        if let Some(f) = t.real_fraction {
            t.validate_real_fraction(f)?;
        }
        if !(t.degrees.is_finite() && (0.0..=180.0).contains(&t.degrees)) {
            bail!(
                "train.degrees = {} must be in [0, 180] (180 = any angle)",
                t.degrees
            );
        }
        if !(0.0..1.0).contains(&t.scale) {
            bail!(
                "train.scale = {} must be in [0, 1) (scale jitter 1 ± scale)",
                t.scale
            );
        }
        if !(0.0..1.0).contains(&t.translate) {
            bail!(
                "train.translate = {} must be in [0, 1) (a fraction of the image size)",
                t.translate
            );
        }
        for (k, v) in [
            ("train.flipud", t.flipud),
            ("train.mosaic", t.mosaic),
            ("train.copy_paste", t.copy_paste),
        ] {
            if !(0.0..=1.0).contains(&v) {
                bail!("{k} = {v} must be a probability in [0, 1]");
            }
        }
        if t.milestones.windows(2).any(|w| w[0] >= w[1]) {
            bail!("train.milestones = {:?} must be increasing", t.milestones);
        }
        t.augment_permutation()?;
        Ok(())
    }

    /// `train.augment_order` as positions in [`AUGMENTATIONS`] (unset: `0, 1, …, 6`); an
    /// error names an unknown augmentation, one named twice, or one left out.
    pub fn augment_permutation(&self) -> Result<[usize; AUGMENTATIONS.len()]> {
        let mut order = std::array::from_fn(|i| i);
        let Some(names) = &self.augment_order else {
            return Ok(order);
        };
        let all = AUGMENTATIONS.join(", ");
        let mut seen = [false; AUGMENTATIONS.len()];
        for (k, name) in names.iter().enumerate() {
            let Some(i) = AUGMENTATIONS.iter().position(|a| a == name) else {
                bail!(
                    "train.augment_order: unknown augmentation {name:?} (the augmentations: {all})"
                );
            };
            if seen[i] {
                bail!(
                    "train.augment_order names {name:?} twice: list each augmentation once ({all})"
                );
            }
            seen[i] = true;
            if k < order.len() {
                order[k] = i;
            }
        }
        if let Some(i) = seen.iter().position(|s| !s) {
            bail!(
                "train.augment_order leaves out {:?}: list every augmentation once ({all}; one that is off does nothing wherever it stands)",
                AUGMENTATIONS[i]
            );
        }
        Ok(order)
    }

    /// `train.real_fraction = f`: a share in [0, 1] that leaves both kinds of image in a
    /// batch of `train.batch` (unless it is 0 or 1).
    fn validate_real_fraction(&self, f: f64) -> Result<()> {
        if !(0.0..=1.0).contains(&f) {
            bail!(
                "train.real_fraction = {f} must be in [0, 1] (the share of real images in a batch)"
            );
        }
        let n = (f * self.batch as f64).round() as usize;
        if f > 0.0 && n == 0 {
            bail!(
                "train.real_fraction = {f} × train.batch = {} rounds to 0 real images per batch (raise it to at least {:.3}, or set 0 for synthetic only)",
                self.batch,
                0.5 / self.batch as f64
            );
        }
        if f < 1.0 && n == self.batch {
            bail!(
                "train.real_fraction = {f} × train.batch = {} rounds to a batch of only real images (lower it to at most {:.3}, or set 1 for real only)",
                self.batch,
                1.0 - 0.5 / self.batch as f64
            );
        }
        Ok(())
    }
}

/// Augmentation keys at 0 (off) are left out of resolved configs and checkpoint
/// headers, which then read as before these keys existed.
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn default_true() -> bool {
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn val_every_defaults_to_every_epoch_and_rejects_zero() {
        assert_eq!(TrainConfig::default().val_every, 1);
        let t: TrainConfig = toml::from_str("val_every = 5").unwrap();
        assert_eq!(t.val_every, 5);
        t.validate().unwrap();
        let t: TrainConfig = toml::from_str("val_every = 0").unwrap();
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("train.val_every must be at least 1"), "{e}");
    }

    #[test]
    fn mix_and_augmentation_keys_default_off_and_are_range_checked() {
        let t = TrainConfig::default();
        assert_eq!((t.steps_per_epoch, t.real_fraction), (None, None));
        assert_eq!(
            [
                t.degrees,
                t.scale,
                t.translate,
                t.flipud,
                t.mosaic,
                t.copy_paste
            ],
            [0.0; 6]
        );
        // Unset keys are not written to a resolved config, so old run folders read the same.
        let text = toml::to_string(&t).unwrap();
        assert!(
            !text.contains("steps_per_epoch") && !text.contains("real_fraction"),
            "{text}"
        );
        let ok: TrainConfig = toml::from_str(
            "steps_per_epoch = 50\nreal_fraction = 0.25\ndegrees = 180\nscale = 0.3\ntranslate = 0.1\nflipud = 0.5\nmosaic = 1.0\ncopy_paste = 0.3",
        )
        .unwrap();
        ok.validate().unwrap();
        for (text, needle) in [
            ("steps_per_epoch = 0", "train.steps_per_epoch = 0"),
            (
                "real_fraction = 1.5",
                "train.real_fraction = 1.5 must be in [0, 1]",
            ),
            ("real_fraction = 0.05", "rounds to 0 real images"),
            ("real_fraction = 0.97", "only real images"),
            ("degrees = 181", "train.degrees"),
            ("scale = 1.0", "train.scale"),
            ("translate = -0.1", "train.translate"),
            ("flipud = 2", "train.flipud"),
            ("mosaic = -1", "train.mosaic"),
            ("copy_paste = 1.1", "train.copy_paste"),
        ] {
            let t: TrainConfig = toml::from_str(text).unwrap();
            let e = t.validate().unwrap_err().to_string();
            assert!(e.contains(needle), "{text}: {e}");
        }
        assert!(toml::from_str::<TrainConfig>("mosaics = 1").is_err());
    }

    #[test]
    fn augment_order_is_a_permutation_of_the_names_and_left_out_when_unset() {
        let t = TrainConfig::default();
        assert_eq!(t.augment_permutation().unwrap(), [0, 1, 2, 3, 4, 5, 6]);
        assert!(!toml::to_string(&t).unwrap().contains("augment_order"));
        let t: TrainConfig = toml::from_str(
            r#"augment_order = ["hsv", "fliplr", "crop", "affine", "mosaic", "copy_paste", "flipud"]"#,
        )
        .unwrap();
        t.validate().unwrap();
        assert_eq!(t.augment_permutation().unwrap(), [5, 4, 3, 2, 1, 0, 6]);
        assert!(toml::to_string(&t).unwrap().contains("augment_order"));
        for (order, needle) in [
            (
                r#"["crop", "flip", "hsv"]"#,
                r#"train.augment_order: unknown augmentation "flip" (the augmentations: copy_paste, mosaic"#,
            ),
            (
                r#"["crop", "crop", "hsv", "fliplr", "flipud", "affine", "mosaic", "copy_paste"]"#,
                r#"train.augment_order names "crop" twice"#,
            ),
            (
                r#"["crop", "hsv", "fliplr", "flipud", "affine", "mosaic"]"#,
                r#"train.augment_order leaves out "copy_paste""#,
            ),
            ("[]", r#"leaves out "copy_paste""#),
        ] {
            let t: TrainConfig = toml::from_str(&format!("augment_order = {order}")).unwrap();
            let e = t.validate().unwrap_err().to_string();
            assert!(e.contains(needle), "{order}: {e}");
        }
    }

    #[test]
    fn precision_defaults_to_f32_is_left_out_and_bad_values_list_the_choices() {
        let t = TrainConfig::default();
        assert_eq!(t.precision, Precision::F32);
        assert!(!toml::to_string(&t).unwrap().contains("precision"));
        for (text, want) in [("f16", Precision::F16), ("bf16", Precision::Bf16)] {
            let t: TrainConfig = toml::from_str(&format!("precision = \"{text}\"")).unwrap();
            assert_eq!(t.precision, want);
            assert_eq!(want.name(), text);
            assert!(toml::to_string(&t)
                .unwrap()
                .contains(&format!("precision = \"{text}\"")));
        }
        let e = toml::from_str::<TrainConfig>("precision = \"fp16\"")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("fp16") && e.contains("`f32`, `f16`, `bf16`"),
            "{e}"
        );
    }
}
