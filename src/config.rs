//! Run configuration: TOML → typed structs → validated values.
//!
//! Every table rejects unknown keys (`deny_unknown_fields`), so a typo such as
//! `epoch = 5` fails with the key's name, the file and the line instead of silently
//! training with the default. `--set a.b=v` overrides edit the TOML tree before it is
//! typed, so they go through exactly the same checks.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

/// The configs shipped in `configs/`, embedded so `--config NAME.toml` works anywhere.
pub const SHIPPED: &[(&str, &str)] = &[
    (
        "cpu_protocol.toml",
        include_str!("../configs/cpu_protocol.toml"),
    ),
    (
        "cpu_protocol_maskrcnn.toml",
        include_str!("../configs/cpu_protocol_maskrcnn.toml"),
    ),
    (
        "quickstart.toml",
        include_str!("../configs/quickstart.toml"),
    ),
    (
        "yolo_real_baseline.toml",
        include_str!("../configs/yolo_real_baseline.toml"),
    ),
    (
        "yolo_syn250.toml",
        include_str!("../configs/yolo_syn250.toml"),
    ),
    (
        "yolo_syn500.toml",
        include_str!("../configs/yolo_syn500.toml"),
    ),
    (
        "yolo_syn750.toml",
        include_str!("../configs/yolo_syn750.toml"),
    ),
    (
        "yolo_syn1000.toml",
        include_str!("../configs/yolo_syn1000.toml"),
    ),
    (
        "maskrcnn_r50_real_baseline.toml",
        include_str!("../configs/maskrcnn_r50_real_baseline.toml"),
    ),
    (
        "maskrcnn_r50_syn250.toml",
        include_str!("../configs/maskrcnn_r50_syn250.toml"),
    ),
    (
        "maskrcnn_r50_syn500.toml",
        include_str!("../configs/maskrcnn_r50_syn500.toml"),
    ),
    (
        "maskrcnn_r50_syn750.toml",
        include_str!("../configs/maskrcnn_r50_syn750.toml"),
    ),
    (
        "maskrcnn_r50_syn1000.toml",
        include_str!("../configs/maskrcnn_r50_syn1000.toml"),
    ),
    (
        "maskrcnn_r101_real_baseline.toml",
        include_str!("../configs/maskrcnn_r101_real_baseline.toml"),
    ),
    (
        "maskrcnn_r101_syn250.toml",
        include_str!("../configs/maskrcnn_r101_syn250.toml"),
    ),
    (
        "maskrcnn_r101_syn500.toml",
        include_str!("../configs/maskrcnn_r101_syn500.toml"),
    ),
    (
        "maskrcnn_r101_syn750.toml",
        include_str!("../configs/maskrcnn_r101_syn750.toml"),
    ),
    (
        "maskrcnn_r101_syn1000.toml",
        include_str!("../configs/maskrcnn_r101_syn1000.toml"),
    ),
];

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    Flex,
    Ndarray,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Run name: outputs go to `runs/<name>/`.
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_device")]
    pub device: DeviceKind,
    pub data: DataConfig,
    #[serde(default)]
    pub model: ModelConfig,
    #[serde(default)]
    pub train: TrainConfig,
}

fn default_device() -> DeviceKind {
    DeviceKind::Flex
}

/// Where the "real" images come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RealKind {
    /// Rendered with the `proxy-real` preset: a stand-in, not real photos.
    Proxy,
    Coco,
    Labelme,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealConfig {
    pub kind: RealKind,
    /// Proxy: how many images to render (the paper has 300 real photos).
    #[serde(default = "default_real_count")]
    pub count: usize,
    /// COCO: the annotations file.
    #[serde(default)]
    pub annotations: Option<PathBuf>,
    /// COCO: folder that `file_name`s are relative to.
    #[serde(default)]
    pub images: Option<PathBuf>,
    /// LabelMe: folder of `.json` + images.
    #[serde(default)]
    pub dir: Option<PathBuf>,
    /// LabelMe: optional `labels.txt` fixing the category order.
    #[serde(default)]
    pub labels: Option<PathBuf>,
    /// Use only the first N images (by id) of the real set (`--smoke` sets it).
    #[serde(default)]
    pub limit: Option<usize>,
}

fn default_real_count() -> usize {
    300
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    pub real: RealConfig,
    /// Train and val fractions of the real set; the rest is test (paper: 60/60/180).
    #[serde(default = "default_split")]
    pub split: [f64; 2],
    /// Synthetic images mixed into training (paper: 0, 250, 500, 750, 1000).
    #[serde(default)]
    pub synthetic: usize,
    /// Render new synthetic images every epoch instead of a fixed cached set.
    #[serde(default)]
    pub fresh_synthetic: bool,
    /// Side of the square images rendered or loaded (paper: 640).
    #[serde(default = "default_image_size")]
    pub image_size: u32,
    /// Random training crop (paper: 512 of 640); equal to `image_size` for none.
    #[serde(default = "default_crop")]
    pub crop: u32,
    /// Render cache root (relative to the working directory): rendered images are
    /// stored once under `<cache>/<key>/` and read back by later runs and `eval`.
    #[serde(default = "default_cache")]
    pub cache: PathBuf,
}

fn default_cache() -> PathBuf {
    PathBuf::from("runs/cache")
}

fn default_split() -> [f64; 2] {
    [0.2, 0.2]
}
fn default_image_size() -> u32 {
    640
}
fn default_crop() -> u32 {
    512
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    Yolo,
    Maskrcnn,
}

/// Size preset of a Mask R-CNN: `compact` (CPU- and scene-sized) or `paper` (detectron2's
/// R-FPN sizes). Single `model.*` keys override either.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaskRcnnPreset {
    Compact,
    Paper,
}

/// `[model]`. One flat table for both kinds so `--set model.depth=101` works; keys of the
/// other kind are rejected by [`Config::validate`] (they stay `None` unless given), and
/// [`Config::resolve`] writes the chosen kind's main defaults into the resolved
/// `config.toml` of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    #[serde(default = "default_model_kind")]
    pub kind: ModelKind,
    /// Width multiplier (YOLO: on top of the scale; Mask R-CNN: ResNet widths).
    #[serde(default = "default_one")]
    pub width_mult: f64,
    // --- YOLO only ---
    /// YOLO scale `n` or `s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<String>,
    /// Pyramid levels that carry heads: [3, 4, 5] (default) or [4, 5].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub levels: Option<Vec<u32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub c2psa: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prototypes: Option<usize>,
    // --- Mask R-CNN only ---
    /// ResNet depth: 18, 34, 50 or 101.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<MaskRcnnPreset>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fpn_channels: Option<usize>,
    /// Anchor sizes in input pixels, one per level P2…P6.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchor_sizes: Option<Vec<f32>>,
    /// Anchors sampled per image for the RPN loss.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_batch: Option<usize>,
    /// RPN proposals per level before NMS and per image after NMS, in training.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_pre_nms_topk_train: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_post_nms_topk_train: Option<usize>,
    /// The same at inference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_pre_nms_topk_test: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpn_post_nms_topk_test: Option<usize>,
    /// RoIs sampled per image for the box and mask losses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roi_batch: Option<usize>,
    /// Width of the box head's FC layers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub box_fc_dim: Option<usize>,
    /// Width of the mask head's convolutions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_conv_dim: Option<usize>,
    /// One mask per RoI instead of one per class.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_class_agnostic: Option<bool>,
}

fn default_model_kind() -> ModelKind {
    ModelKind::Yolo
}
fn default_true() -> bool {
    true
}
fn default_one() -> f64 {
    1.0
}

impl Default for ModelConfig {
    fn default() -> Self {
        toml::from_str("").expect("model defaults")
    }
}

impl ModelConfig {
    /// YOLO scale (default `n`).
    pub fn scale(&self) -> &str {
        self.scale.as_deref().unwrap_or("n")
    }
    /// YOLO head levels (default [3, 4, 5]).
    pub fn levels(&self) -> Vec<u32> {
        self.levels.clone().unwrap_or_else(|| vec![3, 4, 5])
    }
    /// YOLO C2PSA block (default on).
    pub fn c2psa(&self) -> bool {
        self.c2psa.unwrap_or(true)
    }
    /// YOLO mask prototypes (default 32).
    pub fn prototypes(&self) -> usize {
        self.prototypes.unwrap_or(32)
    }
    /// Mask R-CNN ResNet depth (default 50).
    pub fn depth(&self) -> usize {
        self.depth.unwrap_or(50)
    }
    /// Mask R-CNN size preset (default compact).
    pub fn preset(&self) -> MaskRcnnPreset {
        self.preset.unwrap_or(MaskRcnnPreset::Compact)
    }

    /// `(key, given)` of the YOLO-only keys and of the Mask R-CNN-only keys.
    fn kind_keys(&self) -> [Vec<(&'static str, bool)>; 2] {
        [
            vec![
                ("scale", self.scale.is_some()),
                ("levels", self.levels.is_some()),
                ("c2psa", self.c2psa.is_some()),
                ("prototypes", self.prototypes.is_some()),
            ],
            vec![
                ("depth", self.depth.is_some()),
                ("preset", self.preset.is_some()),
                ("fpn_channels", self.fpn_channels.is_some()),
                ("anchor_sizes", self.anchor_sizes.is_some()),
                ("rpn_batch", self.rpn_batch.is_some()),
                (
                    "rpn_pre_nms_topk_train",
                    self.rpn_pre_nms_topk_train.is_some(),
                ),
                (
                    "rpn_post_nms_topk_train",
                    self.rpn_post_nms_topk_train.is_some(),
                ),
                (
                    "rpn_pre_nms_topk_test",
                    self.rpn_pre_nms_topk_test.is_some(),
                ),
                (
                    "rpn_post_nms_topk_test",
                    self.rpn_post_nms_topk_test.is_some(),
                ),
                ("roi_batch", self.roi_batch.is_some()),
                ("box_fc_dim", self.box_fc_dim.is_some()),
                ("mask_conv_dim", self.mask_conv_dim.is_some()),
                ("mask_class_agnostic", self.mask_class_agnostic.is_some()),
            ],
        ]
    }
}

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
    #[serde(default = "default_true")]
    pub ema: bool,
    #[serde(default = "default_fliplr")]
    pub fliplr: f64,
    /// HSV jitter gains (ultralytics: 0.015, 0.7, 0.4).
    #[serde(default = "default_hsv")]
    pub hsv: [f64; 3],
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
fn default_clip() -> f64 {
    10.0
}
fn default_fliplr() -> f64 {
    0.5
}
fn default_hsv() -> [f64; 3] {
    [0.015, 0.7, 0.4]
}

impl Default for TrainConfig {
    fn default() -> Self {
        toml::from_str("").expect("train defaults")
    }
}

/// Finds a config: an existing path, else a shipped config by name (`yolo_syn1000` or
/// `yolo_syn1000.toml`). Returns the text and where it came from.
pub fn locate(name: &str) -> Result<(String, String)> {
    let path = Path::new(name);
    if path.exists() {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config {}", path.display()))?;
        return Ok((text, path.display().to_string()));
    }
    let file = path
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let want = if file.ends_with(".toml") {
        file
    } else {
        format!("{file}.toml")
    };
    if let Some((n, text)) = SHIPPED.iter().find(|(n, _)| *n == want) {
        return Ok((text.to_string(), format!("<shipped>/configs/{n}")));
    }
    let names: Vec<&str> = SHIPPED.iter().map(|(n, _)| *n).collect();
    bail!(
        "config {name:?} is neither a file nor a shipped config (shipped: {})",
        names.join(", ")
    )
}

/// Parses, applies `key.path=value` overrides, types and validates a config.
pub fn load(name: &str, overrides: &[String]) -> Result<Config> {
    let (text, origin) = locate(name)?;
    parse(&text, &origin, overrides)
}

pub fn parse(text: &str, origin: &str, overrides: &[String]) -> Result<Config> {
    let mut tree: toml::Table =
        toml::from_str(text).with_context(|| format!("config {origin} is not valid TOML"))?;
    // Typed from text (not from the tree) so errors quote the offending `key = value`
    // line; with overrides, from the re-serialised tree, which quotes the override.
    let typed_text = if overrides.is_empty() {
        text.to_string()
    } else {
        for o in overrides {
            apply_override(&mut tree, o).with_context(|| format!("bad override --set {o}"))?;
        }
        toml::to_string(&tree)?
    };
    let cfg: Config = toml::from_str(&typed_text).with_context(|| {
        if overrides.is_empty() {
            format!("in config {origin}")
        } else {
            format!("in config {origin} with overrides {}", overrides.join(" "))
        }
    })?;
    let mut cfg = cfg;
    cfg.validate()
        .with_context(|| format!("in config {origin}"))?;
    cfg.resolve();
    Ok(cfg)
}

fn apply_override(tree: &mut toml::Table, o: &str) -> Result<()> {
    let (key, raw) = o
        .split_once('=')
        .context("expected KEY=VALUE, e.g. train.epochs=5")?;
    let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_string()));
    let parts: Vec<&str> = key.trim().split('.').collect();
    let mut table = tree;
    for p in &parts[..parts.len() - 1] {
        table = table
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .with_context(|| format!("{p} is not a table"))?;
    }
    table.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

impl Config {
    /// Range and consistency checks, with messages that say what to change.
    pub fn validate(&self) -> Result<()> {
        let d = &self.data;
        let t = &self.train;
        let m = &self.model;
        if self.name.is_empty() || self.name.contains(['/', '\\']) {
            bail!("name {:?} must be a non-empty folder name", self.name);
        }
        if !(32..=4096).contains(&d.image_size) || d.image_size % 32 != 0 {
            bail!(
                "data.image_size = {} must be a multiple of 32 in 32..=4096",
                d.image_size
            );
        }
        if d.crop > d.image_size || d.crop < 32 || d.crop % 32 != 0 {
            bail!(
                "data.crop = {} must be a multiple of 32, at least 32 and at most data.image_size ({})",
                d.crop,
                d.image_size
            );
        }
        let [ft, fv] = d.split;
        if !(ft > 0.0 && fv > 0.0 && ft + fv < 1.0) {
            bail!("data.split = [{ft}, {fv}] must be two positive fractions (train, val) summing to less than 1");
        }
        if d.real.limit.is_some_and(|l| l < 3) {
            bail!(
                "data.real.limit = {:?} must be at least 3 (one image per split)",
                d.real.limit
            );
        }
        match d.real.kind {
            RealKind::Proxy => {
                if d.real.count < 3 {
                    bail!(
                        "data.real.count = {} must be at least 3 (one image per split)",
                        d.real.count
                    );
                }
            }
            RealKind::Coco => {
                let a = d.real.annotations.as_ref().context(
                    "data.real.kind = \"coco\" needs data.real.annotations (a COCO .json)",
                )?;
                must_exist(a, "data.real.annotations")?;
                if let Some(i) = &d.real.images {
                    must_exist(i, "data.real.images")?;
                }
            }
            RealKind::Labelme => {
                let dir = d
                    .real
                    .dir
                    .as_ref()
                    .context("data.real.kind = \"labelme\" needs data.real.dir (a folder of LabelMe .json files)")?;
                must_exist(dir, "data.real.dir")?;
                if let Some(l) = &d.real.labels {
                    must_exist(l, "data.real.labels")?;
                }
            }
        }
        if t.epochs == 0 {
            bail!("train.epochs must be at least 1");
        }
        if t.batch == 0 {
            bail!("train.batch must be at least 1");
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
        if !(t.grad_clip.is_finite() && t.grad_clip > 0.0) {
            bail!("train.grad_clip = {} must be positive", t.grad_clip);
        }
        if !(0.0..=1.0).contains(&t.fliplr) {
            bail!("train.fliplr = {} must be a probability", t.fliplr);
        }
        if t.hsv.iter().any(|v| !(0.0..=1.0).contains(v)) {
            bail!("train.hsv = {:?} must be three gains in [0, 1]", t.hsv);
        }
        if t.milestones.windows(2).any(|w| w[0] >= w[1]) {
            bail!("train.milestones = {:?} must be increasing", t.milestones);
        }
        if !(m.width_mult.is_finite() && m.width_mult > 0.0 && m.width_mult <= 4.0) {
            bail!("model.width_mult = {} must be in (0, 4]", m.width_mult);
        }
        let [yolo_keys, mrcnn_keys] = m.kind_keys();
        let (kind, foreign, other) = match m.kind {
            ModelKind::Yolo => ("yolo", mrcnn_keys, "maskrcnn"),
            ModelKind::Maskrcnn => ("maskrcnn", yolo_keys, "yolo"),
        };
        if let Some((k, _)) = foreign.iter().find(|(_, given)| *given) {
            bail!(
                "model.{k} is a {other} key, but model.kind = \"{kind}\" (remove it, or set model.kind = \"{other}\")"
            );
        }
        match m.kind {
            ModelKind::Yolo => {
                if !matches!(m.scale(), "n" | "s") {
                    bail!("model.scale = {:?} must be \"n\" or \"s\"", m.scale());
                }
                let levels = m.levels();
                if levels != [3, 4, 5] && levels != [4, 5] {
                    bail!("model.levels = {levels:?} must be [3, 4, 5] or [4, 5]");
                }
                if !(1..=256).contains(&m.prototypes()) {
                    bail!("model.prototypes = {} must be in 1..=256", m.prototypes());
                }
            }
            ModelKind::Maskrcnn => {
                if ![18, 34, 50, 101].contains(&m.depth()) {
                    bail!("model.depth = {} must be 18, 34, 50 or 101", m.depth());
                }
                if d.crop < 64 {
                    bail!(
                        "data.crop = {} must be at least 64 for model.kind = \"maskrcnn\"",
                        d.crop
                    );
                }
                if let Some(a) = &m.anchor_sizes {
                    if a.len() != 5 || a.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                        bail!(
                            "model.anchor_sizes = {a:?} must be 5 positive sizes in pixels (P2…P6)"
                        );
                    }
                }
                for (k, v, max) in [
                    ("fpn_channels", m.fpn_channels, 1024),
                    ("rpn_batch", m.rpn_batch, 4096),
                    ("rpn_pre_nms_topk_train", m.rpn_pre_nms_topk_train, 100_000),
                    (
                        "rpn_post_nms_topk_train",
                        m.rpn_post_nms_topk_train,
                        100_000,
                    ),
                    ("rpn_pre_nms_topk_test", m.rpn_pre_nms_topk_test, 100_000),
                    ("rpn_post_nms_topk_test", m.rpn_post_nms_topk_test, 100_000),
                    ("roi_batch", m.roi_batch, 4096),
                    ("box_fc_dim", m.box_fc_dim, 8192),
                    ("mask_conv_dim", m.mask_conv_dim, 1024),
                ] {
                    if let Some(v) = v {
                        if !(1..=max).contains(&v) {
                            bail!("model.{k} = {v} must be in 1..={max}");
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Fills in the defaults of the chosen model kind (call after [`Config::validate`]): all
    /// YOLO keys, and a Mask R-CNN's depth and preset (the preset's sizes stay implicit; the
    /// checkpoint header holds the complete model config).
    pub fn resolve(&mut self) {
        let m = &mut self.model;
        match m.kind {
            ModelKind::Yolo => {
                m.scale = Some(m.scale().to_string());
                m.levels = Some(m.levels());
                m.c2psa = Some(m.c2psa());
                m.prototypes = Some(m.prototypes());
            }
            ModelKind::Maskrcnn => {
                m.depth = Some(m.depth());
                m.preset = Some(m.preset());
            }
        }
    }
}

fn must_exist(p: &Path, key: &str) -> Result<()> {
    if !p.exists() {
        bail!("{key} = {:?} does not exist", p.display().to_string());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_configs_parse_and_validate() {
        for (name, text) in SHIPPED {
            parse(text, name, &[]).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        }
    }

    #[test]
    fn errors_name_the_key() {
        let base = SHIPPED[0].1;
        let cases: Vec<(String, Vec<String>, &str)> = vec![
            (
                format!("{base}\nepoch = 3\n"),
                vec![],
                "unknown field `epoch`",
            ),
            (
                base.replace("[train]", "[train]\nepoch = 3"),
                vec![],
                "unknown field `epoch`",
            ),
            (
                base.to_string(),
                vec!["train.epochs=0".into()],
                "train.epochs",
            ),
            (
                base.to_string(),
                vec!["train.epochs=-3".into()],
                "epochs = -3",
            ),
            (
                base.to_string(),
                vec!["train.lr=\"fast\"".into()],
                "invalid type",
            ),
            (
                base.to_string(),
                vec!["data.image_size=100".into()],
                "data.image_size",
            ),
            (
                base.to_string(),
                vec!["model.scale=\"x\"".into()],
                "model.scale",
            ),
            (
                base.to_string(),
                vec!["data.real.kind=\"coco\"".into()],
                "data.real.annotations",
            ),
            (
                base.to_string(),
                vec![
                    "data.real.kind=\"labelme\"".into(),
                    "data.real.dir=\"/nonexistent/x\"".into(),
                ],
                "does not exist",
            ),
            ("name = ".to_string(), vec![], "not valid TOML"),
        ];
        for (text, ov, needle) in cases {
            let err = format!("{:#}", parse(&text, "test.toml", &ov).unwrap_err());
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
            assert!(err.contains("test.toml"), "{err:?} should name the file");
        }
    }

    #[test]
    fn model_keys_belong_to_their_kind() {
        let yolo = SHIPPED[0].1;
        let (mrcnn, _) = locate("maskrcnn_r101_syn1000").unwrap();
        let cases: Vec<(&str, Vec<String>, &str)> = vec![
            (
                yolo,
                vec!["model.depth=50".into()],
                "model.depth is a maskrcnn key, but model.kind = \"yolo\"",
            ),
            (
                &mrcnn,
                vec!["model.scale=\"n\"".into()],
                "model.scale is a yolo key, but model.kind = \"maskrcnn\"",
            ),
            (
                &mrcnn,
                vec!["model.depth=42".into()],
                "model.depth = 42 must be 18, 34, 50 or 101",
            ),
            (
                &mrcnn,
                vec!["model.anchor_sizes=[8.0, 16.0]".into()],
                "model.anchor_sizes",
            ),
            (
                &mrcnn,
                vec!["model.roi_batch=0".into()],
                "model.roi_batch = 0",
            ),
            (
                &mrcnn,
                vec!["model.preset=\"huge\"".into()],
                "unknown variant",
            ),
        ];
        for (text, ov, needle) in cases {
            let err = format!("{:#}", parse(text, "test.toml", &ov).unwrap_err());
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
        }
        // The resolved config (what a run folder holds) parses back to the same model.
        let cfg = parse(&mrcnn, "m", &["model.depth=50".into()]).unwrap();
        assert_eq!(cfg.model.depth, Some(50));
        assert_eq!(cfg.model.preset, Some(MaskRcnnPreset::Compact));
        assert!(cfg.model.scale.is_none());
        let back = parse(&toml::to_string(&cfg).unwrap(), "resolved", &[]).unwrap();
        assert_eq!(back.model.depth, Some(50));
        assert_eq!(back.train.warmup_iters, 500);
        let y = parse(yolo, "q", &[]).unwrap();
        assert_eq!(y.model.scale.as_deref(), Some("n"));
        assert_eq!(y.model.prototypes, Some(32));
        assert!(y.model.depth.is_none());
    }

    #[test]
    fn overrides_set_nested_keys() {
        let cfg = parse(
            SHIPPED[0].1,
            "q",
            &["train.epochs=5".into(), "data.synthetic=7".into()],
        )
        .unwrap();
        assert_eq!(cfg.train.epochs, 5);
        assert_eq!(cfg.data.synthetic, 7);
    }
}
