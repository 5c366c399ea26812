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

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    #[serde(default = "default_model_kind")]
    pub kind: ModelKind,
    /// YOLO scale `n` or `s`.
    #[serde(default = "default_scale")]
    pub scale: String,
    /// Pyramid levels that carry heads: [3, 4, 5] (default) or [4, 5].
    #[serde(default = "default_levels")]
    pub levels: Vec<u32>,
    #[serde(default = "default_true")]
    pub c2psa: bool,
    #[serde(default = "default_one")]
    pub width_mult: f64,
    #[serde(default = "default_protos")]
    pub prototypes: usize,
}

fn default_model_kind() -> ModelKind {
    ModelKind::Yolo
}
fn default_scale() -> String {
    "n".into()
}
fn default_levels() -> Vec<u32> {
    vec![3, 4, 5]
}
fn default_true() -> bool {
    true
}
fn default_one() -> f64 {
    1.0
}
fn default_protos() -> usize {
    32
}

impl Default for ModelConfig {
    fn default() -> Self {
        toml::from_str("").expect("model defaults")
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
    cfg.validate()
        .with_context(|| format!("in config {origin}"))?;
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
        if !matches!(m.scale.as_str(), "n" | "s") {
            bail!("model.scale = {:?} must be \"n\" or \"s\"", m.scale);
        }
        if m.levels != [3, 4, 5] && m.levels != [4, 5] {
            bail!("model.levels = {:?} must be [3, 4, 5] or [4, 5]", m.levels);
        }
        if !(m.width_mult.is_finite() && m.width_mult > 0.0 && m.width_mult <= 4.0) {
            bail!("model.width_mult = {} must be in (0, 4]", m.width_mult);
        }
        if !(1..=256).contains(&m.prototypes) {
            bail!("model.prototypes = {} must be in 1..=256", m.prototypes);
        }
        Ok(())
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
