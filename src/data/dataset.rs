//! Training data sources: the "real" set (proxy-real renders, a COCO file + image folder
//! or one COCO file per split, a LabelMe folder, a YOLO-seg dataset) and the synthetic
//! renders, both yielding [`Sample`]s at the network's square input size. A real set
//! whose files declare a split carries it ([`RealSet::own_split`]) for
//! `Split::for_dataset`.
//!
//! The real set keeps its COCO ground truth at the *original* image size (that is what
//! the evaluator scores against) and decodes images lazily, one per request, so a
//! 300-photo set does not sit in memory. Images of any shape are letterboxed into
//! `image_size × image_size` ([`Letterbox`]); predictions are mapped back by its inverse. Gray,
//! RGBA and 16-bit images are converted to RGB8. Missing or corrupt files fail with the
//! file's path.
//!
//! Synthetic images come from the renderer through its cache (`render::cache`),
//! deterministic per (seed, index), cached under the cache root; with `fresh_synthetic`
//! the seed changes every epoch and nothing is cached.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use image::RgbImage;
use rayon::prelude::*;

use crate::annotations::coco::{CocoCategory, CocoDataset, CocoImage};
use crate::annotations::coco_splits::{self, SplitFile};
pub use crate::annotations::mask::resize_mask;
use crate::annotations::mask::Mask;
use crate::annotations::split::{OwnSplit, Part};
use crate::annotations::{labelme, yolo};
use crate::config::{DataConfig, RealKind};
use crate::data::letterbox::Letterbox;
use crate::render::cache::{cache_dir, effective_seed, load_or_render};
use crate::render::export::{annotations, visible_mask, CARCASS_CATEGORY};
use crate::render::{RenderOptions, RenderedSample};

/// One instance of a training sample: class index (0-based, in category order) and its
/// visible mask at the sample's size.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    pub class: usize,
    pub mask: Mask,
}

/// An image at the network input size with its (non-crowd) instances.
#[derive(Clone, Debug)]
pub struct Sample {
    pub image: RgbImage,
    pub instances: Vec<Instance>,
}

/// Render options for a preset at `size`, with the label thresholds scaled to the image
/// area so "too small to be a fair target" means the same at 96 px as at 640 px.
pub fn render_options(proxy: bool, size: u32) -> RenderOptions {
    let mut o = if proxy {
        RenderOptions::proxy_real(size)
    } else {
        RenderOptions::synthetic(size)
    };
    let f = (size as f64 / 640.0).powi(2);
    o.labels.min_visible_px = ((o.labels.min_visible_px as f64 * f).round() as u64).max(4);
    o
}

pub use crate::annotations::image_file::{read_image, to_rgb8};

/// Where the real images come from.
#[derive(Clone, Debug)]
enum RealSource {
    /// Proxy-real renders: image id `k + 1` is render index `k`.
    Proxy {
        opts: RenderOptions,
        seed: u64,
        cache: Option<PathBuf>,
    },
    /// Files; `file_name`s are relative to `root`.
    Files { root: PathBuf },
}

/// The real dataset: COCO ground truth at original size plus a lazy image source.
#[derive(Clone, Debug)]
pub struct RealSet {
    /// Ground truth of every image (original sizes), the evaluator's input.
    pub gt: CocoDataset,
    /// Category ids in class-index order (sorted by id).
    pub cat_ids: Vec<u64>,
    /// True for proxy-real renders (every report must call them a proxy).
    pub proxy: bool,
    /// The split the dataset's files declare (YOLO `train`/`val`/`test`, one COCO file
    /// per split); `None`: the run draws one.
    pub own_split: Option<OwnSplit>,
    source: RealSource,
}

impl RealSet {
    /// Loads (for proxy: renders or reads from the cache `data.cache`) the real set of
    /// `data`; `data.real.limit` keeps only N images (the first by id, or with an own
    /// split the first of each part in turn).
    pub fn load(data: &DataConfig, seed: u64) -> Result<RealSet> {
        let size = data.image_size;
        let limit = data.real.limit;
        let cache_root = Some(data.cache.as_path());
        let real = &data.real;
        let mut own_split = None;
        let (mut gt, source) = match real.kind {
            RealKind::Proxy => {
                let opts = render_options(true, size);
                let cache = match cache_root {
                    Some(r) => Some(cache_dir(r, &opts, seed)?),
                    None => None,
                };
                let n = limit.map_or(real.count, |l| l.min(real.count));
                (
                    proxy_set(&opts, size, seed, n, cache.as_deref())?,
                    RealSource::Proxy { opts, seed, cache },
                )
            }
            RealKind::Coco => match &real.annotations {
                Some(ann) => {
                    let ds = CocoDataset::load(ann)?;
                    let root = match &real.images {
                        Some(d) => d.clone(),
                        None => ann.parent().map(Path::to_path_buf).unwrap_or_default(),
                    };
                    (ds, RealSource::Files { root })
                }
                None => {
                    let (ds, own) = coco_splits::load(&split_files(real)?)?;
                    own_split = Some(own);
                    // file_names include their folders.
                    (
                        ds,
                        RealSource::Files {
                            root: PathBuf::new(),
                        },
                    )
                }
            },
            RealKind::Labelme => {
                let dir = real.dir.as_ref().context("data.real.dir is not set")?;
                let labels = real
                    .labels
                    .as_deref()
                    .map(labelme::read_labels)
                    .transpose()?;
                let ds = labelme::load_dir(dir, labels.as_deref())?;
                (ds, RealSource::Files { root: dir.clone() })
            }
            RealKind::Yolo => {
                let y = real.yaml.as_ref().context("data.real.yaml is not set")?;
                let ds = yolo::load(y)?;
                own_split = ds.own_split;
                (ds.coco, RealSource::Files { root: ds.root })
            }
        };
        gt.validate().context("real dataset")?;
        if let Some(l) = limit {
            let ids = limited_ids(&gt, own_split.as_ref(), l);
            gt.images.retain(|i| ids.binary_search(&i.id).is_ok());
            gt.annotations
                .retain(|a| ids.binary_search(&a.image_id).is_ok());
            if let Some(own) = &mut own_split {
                own.retain(&ids);
            }
        }
        if gt.images.is_empty() {
            bail!("the real dataset has no images");
        }
        if gt.categories.is_empty() {
            bail!("the real dataset has no categories");
        }
        let mut cat_ids: Vec<u64> = gt.categories.iter().map(|c| c.id).collect();
        cat_ids.sort_unstable();
        if let RealSource::Files { root } = &source {
            // Fail early, naming the file, rather than in the middle of epoch 3.
            for im in &gt.images {
                let p = root.join(&im.file_name);
                if !p.exists() {
                    bail!(
                        "image {} of the real dataset (id {}) does not exist",
                        p.display(),
                        im.id
                    );
                }
            }
        }
        Ok(RealSet {
            gt,
            cat_ids,
            proxy: matches!(source, RealSource::Proxy { .. }),
            own_split,
            source,
        })
    }

    pub fn ids(&self) -> Vec<u64> {
        self.gt.images.iter().map(|i| i.id).collect()
    }

    pub fn num_classes(&self) -> usize {
        self.cat_ids.len()
    }

    pub fn class_names(&self) -> Vec<String> {
        self.cat_ids
            .iter()
            .map(|id| {
                self.gt
                    .categories
                    .iter()
                    .find(|c| c.id == *id)
                    .map(|c| c.name.clone())
                    .unwrap_or_default()
            })
            .collect()
    }

    /// The image only, at the network input size, plus its original `(width, height)`.
    pub fn image(&self, id: u64, input: u32) -> Result<(RgbImage, (u32, u32))> {
        let img = self.original(id)?;
        let orig = img.dimensions();
        Ok((Letterbox::new(orig, input).image(&img), orig))
    }

    /// The image at its original size (a file's size is checked against its annotation's;
    /// a proxy-real render is made at it).
    pub fn original(&self, id: u64) -> Result<RgbImage> {
        let im = self
            .gt
            .image(id)
            .with_context(|| format!("image id {id} is not in the real dataset"))?;
        let img = match &self.source {
            RealSource::Proxy { opts, seed, cache } => {
                load_or_render(opts, *seed, id - 1, cache.as_deref())?.image
            }
            RealSource::Files { root } => {
                let p = root.join(&im.file_name);
                let img = read_image(&p)?;
                if img.dimensions() != (im.width, im.height) {
                    bail!(
                        "image {} is {}x{} but its annotation says {}x{}",
                        p.display(),
                        img.width(),
                        img.height(),
                        im.width,
                        im.height
                    );
                }
                img
            }
        };
        Ok(img)
    }

    /// Image and non-crowd instances at the network input size.
    pub fn sample(&self, id: u64, input: u32) -> Result<Sample> {
        let (image, (w, h)) = self.image(id, input)?;
        let mut instances = Vec::new();
        for a in self.gt.annotations.iter().filter(|a| a.image_id == id) {
            if a.iscrowd != 0 {
                continue;
            }
            let class = self.cat_ids.binary_search(&a.category_id).map_err(|_| {
                anyhow::anyhow!("annotation {} has unknown category {}", a.id, a.category_id)
            })?;
            let rle = a
                .segmentation
                .to_rle(h, w)
                .with_context(|| format!("annotation {} of image {id}", a.id))?;
            let mask = Letterbox::new((w, h), input).mask(&rle.decode());
            if mask.area() > 0 {
                instances.push(Instance { class, mask });
            }
        }
        Ok(Sample { image, instances })
    }
}

/// The proxy-real set: `n` renders of `opts` as COCO ground truth (image id `k + 1` is
/// render `k`).
fn proxy_set(
    opts: &RenderOptions,
    size: u32,
    seed: u64,
    n: usize,
    cache: Option<&Path>,
) -> Result<CocoDataset> {
    let anns = render_many(opts, seed, n as u64, cache, "proxy-real", |k, s| {
        let id = k + 1;
        annotations(&s.ids, size, size, &s.instances, id, id * 1000)
    })?;
    let mut ds = CocoDataset {
        info: Some(
            serde_json::json!({"description": "chicktrain proxy-real renders (a stand-in for real photos)"}),
        ),
        licenses: None,
        images: Vec::new(),
        annotations: Vec::new(),
        categories: vec![CocoCategory {
            id: CARCASS_CATEGORY,
            name: "carcass".into(),
            extra: Default::default(),
        }],
    };
    for (k, a) in anns.into_iter().enumerate() {
        let id = k as u64 + 1;
        ds.images.push(CocoImage {
            id,
            file_name: format!("proxy-real/{k:06}.jpg"),
            width: size,
            height: size,
            extra: Default::default(),
        });
        ds.annotations.extend(a);
    }
    Ok(ds)
}

/// `data.real.train`/`val`/`test` as split files, each with its images folder
/// (`data.real.images`, else the file's own folder).
fn split_files(real: &crate::config::RealConfig) -> Result<Vec<SplitFile>> {
    let mut files = Vec::new();
    for (part, f) in [
        (Part::Train, &real.train),
        (Part::Val, &real.val),
        (Part::Test, &real.test),
    ] {
        let Some(f) = f else { continue };
        let images = match &real.images {
            Some(d) => d.clone(),
            None => f.parent().map(Path::to_path_buf).unwrap_or_default(),
        };
        files.push(SplitFile {
            part,
            annotations: f.clone(),
            images,
        });
    }
    if files.len() < 2 {
        bail!("a COCO set split into files needs data.real.train and data.real.val");
    }
    Ok(files)
}

/// The ids `data.real.limit = l` keeps, sorted: the first `l` by id; with an own split,
/// taken in turn from its train, val and test parts (each in id order), so every part
/// keeps images.
fn limited_ids(gt: &CocoDataset, own: Option<&OwnSplit>, l: usize) -> Vec<u64> {
    let mut ids: Vec<u64> = match own {
        None => {
            let mut ids: Vec<u64> = gt.images.iter().map(|i| i.id).collect();
            ids.sort_unstable();
            ids.truncate(l);
            ids
        }
        Some(own) => {
            let parts = [&own.train, &own.val, &own.test];
            let longest = parts.iter().map(|p| p.len()).max().unwrap_or(0);
            (0..longest)
                .flat_map(|k| parts.iter().filter_map(move |p| p.get(k).copied()))
                .take(l)
                .collect()
        }
    };
    ids.sort_unstable();
    ids
}

/// Renders (or reads from `cache`) samples `0..n` in parallel, with a progress bar,
/// keeping only `keep(index, sample)` of each (a 1000-image set at 640 px would not fit
/// in memory as whole samples).
fn render_many<T: Send>(
    opts: &RenderOptions,
    seed: u64,
    n: u64,
    cache: Option<&Path>,
    what: &str,
    keep: impl Fn(u64, RenderedSample) -> T + Sync,
) -> Result<Vec<T>> {
    let bar = crate::util::progress::bar(n, what);
    let out: Result<Vec<T>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let s = load_or_render(opts, seed, i, cache)
                .with_context(|| format!("rendering {what} image {i}"))?;
            bar.inc(1);
            Ok(keep(i, s))
        })
        .collect();
    bar.finish_and_clear();
    out
}

/// A rendered sample → training sample (ignored instances left out, like COCO crowds).
pub fn from_rendered(s: &RenderedSample) -> Sample {
    let (w, h) = s.image.dimensions();
    let instances = s
        .instances
        .iter()
        .filter(|i| !i.ignore)
        .map(|i| Instance {
            class: 0,
            mask: visible_mask(&s.ids, w, h, i.id),
        })
        .collect();
    Sample {
        image: s.image.clone(),
        instances,
    }
}

/// The synthetic source: `count` images of the synthetic preset, a fixed cached set, or
/// fresh renders every epoch.
#[derive(Clone, Debug)]
pub struct SyntheticSet {
    pub count: usize,
    pub fresh: bool,
    opts: RenderOptions,
    seed: u64,
    cache_root: Option<PathBuf>,
}

impl SyntheticSet {
    pub fn new(data: &DataConfig, seed: u64) -> SyntheticSet {
        SyntheticSet {
            count: data.synthetic,
            fresh: data.fresh_synthetic,
            opts: RenderOptions {
                randomize: data.randomize,
                negatives: data.negatives,
                ..render_options(false, data.image_size)
            },
            seed,
            cache_root: Some(data.cache.clone()),
        }
    }

    fn cache_dir(&self, epoch: u64) -> Result<Option<PathBuf>> {
        if self.fresh {
            return Ok(None);
        }
        match &self.cache_root {
            Some(r) => Ok(Some(cache_dir(
                r,
                &self.opts,
                effective_seed(self.seed, epoch, false),
            )?)),
            None => Ok(None),
        }
    }

    /// Renders the fixed set once (no-op for fresh-per-epoch), so epoch 1 is not slow.
    pub fn prepare(&self) -> Result<()> {
        if self.fresh || self.count == 0 || self.cache_root.is_none() {
            return Ok(());
        }
        let dir = self.cache_dir(0)?;
        render_many(
            &self.opts,
            self.seed,
            self.count as u64,
            dir.as_deref(),
            "synthetic",
            |_, _| (),
        )?;
        Ok(())
    }

    /// Sample `index` as seen in `epoch`.
    pub fn sample(&self, index: u64, epoch: u64) -> Result<Sample> {
        let seed = effective_seed(self.seed, epoch, self.fresh);
        let dir = self.cache_dir(epoch)?;
        let s = load_or_render(&self.opts, seed, index, dir.as_deref())
            .with_context(|| format!("rendering synthetic image {index}"))?;
        Ok(from_rendered(&s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resize_mask_nearest() {
        let mut m = Mask::new(2, 2);
        m.set(1, 0, true);
        let r = resize_mask(&m, 4, 4);
        assert_eq!(r.area(), 4);
        assert!(r.get(2, 0) && r.get(3, 1) && !r.get(1, 0));
    }

    #[test]
    fn reads_gray_and_rgba_and_names_bad_files() {
        let dir = std::env::temp_dir().join(format!("ct-ds-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let g = image::GrayImage::from_pixel(3, 2, image::Luma([77]));
        g.save(dir.join("g.png")).unwrap();
        let a = image::RgbaImage::from_pixel(3, 2, image::Rgba([1, 2, 3, 4]));
        a.save(dir.join("a.png")).unwrap();
        let g16 = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(
            2,
            2,
            image::Luma([65535]),
        );
        g16.save(dir.join("g16.png")).unwrap();
        assert_eq!(
            read_image(&dir.join("g.png")).unwrap().get_pixel(0, 0).0,
            [77, 77, 77]
        );
        assert_eq!(
            read_image(&dir.join("a.png")).unwrap().get_pixel(2, 1).0,
            [1, 2, 3]
        );
        assert_eq!(
            read_image(&dir.join("g16.png")).unwrap().get_pixel(1, 1).0,
            [255, 255, 255]
        );
        std::fs::write(dir.join("bad.jpg"), b"not a jpeg").unwrap();
        let e = format!("{:#}", read_image(&dir.join("bad.jpg")).unwrap_err());
        assert!(e.contains("bad.jpg"), "{e}");
        let e = format!("{:#}", read_image(&dir.join("missing.png")).unwrap_err());
        assert!(
            e.contains("missing.png") && e.contains("does not exist"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn tiny_data(dir: &Path, fresh: bool) -> DataConfig {
        let cfg = crate::config::parse(
            crate::config::SHIPPED[0].1,
            "q",
            &[
                format!("data.cache=\"{}\"", dir.display()),
                "data.image_size=64".into(),
                "data.crop=64".into(),
                "data.real.count=4".into(),
                "data.synthetic=2".into(),
                format!("data.fresh_synthetic={fresh}"),
            ],
        )
        .unwrap();
        cfg.data
    }

    #[test]
    fn proxy_real_set_matches_its_ground_truth() {
        let dir = std::env::temp_dir().join(format!("ct-ds-proxy-{}", std::process::id()));
        let data = tiny_data(&dir, false);
        let set = RealSet::load(&data, 5).unwrap();
        assert!(set.proxy);
        assert_eq!(set.ids(), vec![1, 2, 3, 4]);
        assert_eq!(set.cat_ids, vec![CARCASS_CATEGORY]);
        for id in set.ids() {
            let s = set.sample(id, 64).unwrap();
            assert_eq!(s.image.dimensions(), (64, 64));
            let gt: Vec<Mask> = set
                .gt
                .annotations
                .iter()
                .filter(|a| a.image_id == id && a.iscrowd == 0)
                .map(|a| a.segmentation.to_rle(64, 64).unwrap().decode())
                .collect();
            assert_eq!(s.instances.len(), gt.len());
            for (i, g) in s.instances.iter().zip(&gt) {
                assert_eq!(&i.mask, g);
            }
        }
        // Reloading reads the cache and gives the same ground truth.
        let again = RealSet::load(&data, 5).unwrap();
        assert_eq!(again.gt.annotations.len(), set.gt.annotations.len());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn synthetic_fixed_set_repeats_and_fresh_set_changes_per_epoch() {
        let dir = std::env::temp_dir().join(format!("ct-ds-syn-{}", std::process::id()));
        let fixed = SyntheticSet::new(&tiny_data(&dir, false), 5);
        fixed.prepare().unwrap();
        assert_eq!(
            fixed.sample(1, 0).unwrap().image,
            fixed.sample(1, 3).unwrap().image
        );
        let fresh = SyntheticSet::new(&tiny_data(&dir, true), 5);
        assert_ne!(
            fresh.sample(1, 0).unwrap().image,
            fresh.sample(1, 1).unwrap().image
        );
        assert_eq!(
            fresh.sample(1, 2).unwrap().image,
            fresh.sample(1, 2).unwrap().image
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
