//! `[data]`: where the real images come from, how many renders to mix in, sizes, split
//! and the render cache.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::negatives::Negatives;
use super::randomize::Randomize;
use super::self_training::UnlabeledConfig;

/// Where the "real" images come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RealKind {
    /// Rendered with the `proxy-real` preset: a stand-in, not real photos.
    Proxy,
    /// One COCO instances file (`annotations`) or one per split (`train`, `val`, `test`).
    Coco,
    Labelme,
    /// A YOLO-seg dataset (ultralytics, Roboflow): its `data.yaml` (`yaml`).
    Yolo,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealConfig {
    pub kind: RealKind,
    /// Proxy: how many images to render (the paper has 300 real photos).
    #[serde(default = "default_real_count")]
    pub count: usize,
    /// COCO: the annotations file of a dataset without a split of its own.
    #[serde(default)]
    pub annotations: Option<PathBuf>,
    /// COCO split into files: the train, val and test annotations files (instead of
    /// `annotations`); the run keeps this split instead of drawing `data.split`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train: Option<PathBuf>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub val: Option<PathBuf>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test: Option<PathBuf>,
    /// COCO: folder that `file_name`s are relative to (default: each annotations
    /// file's folder).
    #[serde(default)]
    pub images: Option<PathBuf>,
    /// YOLO: the dataset's `data.yaml`; its `train`/`val`/`test` are the split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaml: Option<PathBuf>,
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
    /// Not used when the dataset has its own split (a YOLO `data.yaml`, COCO files per
    /// split). `[0, 0]` makes every image test: a set to score with `eval --data`, not to
    /// train on.
    #[serde(default = "default_split")]
    pub split: [f64; 2],
    /// Train on only N of the split's train images (drawn by the seed), val and test as
    /// split (ultralytics' `fraction`, as a count): a few-shot curve over N keeps one
    /// test set. None = the whole train split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_limit: Option<usize>,
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
    /// Domain-randomisation groups of the synthetic renders (`[data.randomize]`, e.g.
    /// `lighting = false`); the proxy-real set is never randomised. See
    /// `config::randomize`.
    #[serde(default = "default_randomize")]
    pub randomize: Randomize,
    /// `[data.unlabeled]`: photos without labels; setting it turns self-training on
    /// (`[train.self_training]`, see `config::self_training`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unlabeled: Option<UnlabeledConfig>,
    /// Shares of carcass-free renders and of renders with distractors
    /// (`[data.negatives]`, see `config::negatives`); the proxy-real set never has them.
    #[serde(default)]
    pub negatives: Negatives,
}

/// The geometry groups on, the appearance groups opt-in (see `Randomize::TRAINING`).
fn default_randomize() -> Randomize {
    Randomize::TRAINING
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

impl DataConfig {
    /// Range checks, and that the files the real set names exist.
    pub fn validate(&self) -> Result<()> {
        let d = self;
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
        let all_test = ft == 0.0 && fv == 0.0;
        if !(all_test || (ft > 0.0 && fv > 0.0 && ft + fv < 1.0)) {
            bail!("data.split = [{ft}, {fv}] must be two positive fractions (train, val) summing to less than 1, or [0, 0] (every image is test: for `eval --data` on an external set)");
        }
        d.negatives.validate()?;
        if d.train_limit == Some(0) {
            bail!("data.train_limit = 0 leaves no real train image (leave it out to train on the whole train split)");
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
                let r = &d.real;
                let split_files = r.train.is_some() || r.val.is_some() || r.test.is_some();
                match (&r.annotations, split_files) {
                    (Some(_), true) => bail!("data.real.annotations and data.real.train/val/test are two ways to give a COCO set: one file without a split, or one file per split; set one of them"),
                    (Some(a), false) => must_exist(a, "data.real.annotations")?,
                    (None, true) => {
                        let (Some(t), Some(v)) = (&r.train, &r.val) else {
                            bail!("a COCO set split into files needs data.real.train and data.real.val (and data.real.test for the final scores)");
                        };
                        must_exist(t, "data.real.train")?;
                        must_exist(v, "data.real.val")?;
                        if let Some(t) = &r.test {
                            must_exist(t, "data.real.test")?;
                        }
                    }
                    (None, false) => bail!("data.real.kind = \"coco\" needs data.real.annotations (a COCO .json), or data.real.train, .val and .test (one per split)"),
                }
                if let Some(i) = &r.images {
                    must_exist(i, "data.real.images")?;
                }
            }
            RealKind::Yolo => {
                let y = d.real.yaml.as_ref().context(
                    "data.real.kind = \"yolo\" needs data.real.yaml (the dataset's data.yaml)",
                )?;
                must_exist(y, "data.real.yaml")?;
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
        if let Some(u) = &d.unlabeled {
            if !u.images.is_dir() {
                bail!(
                    "data.unlabeled.images = {:?} is not a folder (a folder of .jpg/.jpeg/.png photos without labels)",
                    u.images.display().to_string()
                );
            }
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
