//! Inference over a split of the real set and COCO evaluation of the result: the model in
//! eval mode on the plain device, validation settings (YOLO: conf 0.001, NMS IoU 0.7, 300
//! detections; Mask R-CNN: its own score 0.05, NMS 0.5, 100 detections), boxes mapped
//! back to each image's original size and masks decoded there (inside their boxes only),
//! masks as compressed RLE, then the in-tree pycocotools-exact evaluator for bbox and segm.

use std::borrow::Cow;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;

use super::tta::{fuse, Fused, View, ViewDetection};
use crate::annotations::coco::{CocoDataset, Detection, Segmentation};
use crate::annotations::rle::Rle;
use crate::data::dataset::RealSet;
use crate::data::letterbox::Letterbox;
use crate::eval::{evaluate, IouType};
use crate::model::detection::Detection as RawDetection;

use super::checkpoint::{Checkpoint, Stats};
use super::detector::{Detector, VAL_CONF};
use super::device::device_of;
use crate::annotations::split::Split;
use crate::config::{self, DeviceKind};

/// Images per inference batch.
const EVAL_BATCH: usize = 4;

/// `[1, 3, H, W]`-style planes of an RGB image, values in [0, 1], appended to `out`.
pub fn push_planes(img: &image::RgbImage, out: &mut Vec<f32>) {
    let plane = (img.width() * img.height()) as usize;
    let base = out.len();
    out.resize(base + 3 * plane, 0.0);
    for (p, px) in img.pixels().enumerate() {
        for c in 0..3 {
            out[base + c * plane + p] = px.0[c] as f32 / 255.0;
        }
    }
}

/// Maps one raw detection (at the letterboxed `size × size` input) to a COCO detection
/// of an image of `orig = (width, height)`: the box mapped back through the letterbox,
/// the mask decoded at the original size inside that box (ultralytics'
/// `retina_masks=True`, detectron2's paste into the original image) and run-length
/// encoded from the box window.
pub fn to_coco(
    d: &RawDetection,
    image_id: u64,
    cat_ids: &[u64],
    size: u32,
    orig: (u32, u32),
) -> Detection {
    let lb = Letterbox::new(orig, size);
    let b = d.xyxy().map(|v| v as f64);
    let bx = lb.unbox_xyxy(b).map(|v| v as f32);
    let mask = d.mask_in(lb.orig, bx);
    Detection {
        image_id,
        category_id: cat_ids.get(d.class).copied().unwrap_or(d.class as u64 + 1),
        score: d.score as f64,
        bbox: Some(lb.unbox(b)),
        segmentation: Some(Segmentation::from_rle(&Rle::encode_cropped(&mask))),
    }
}

/// Mask IoU above which detections of two views are one instance (test-time
/// augmentation; NMS's usual 0.5).
pub const TTA_IOU: f64 = 0.5;

/// Test-time augmentation of one image (see [`super::tta`]): `orig` in each of
/// the eight symmetries of the square, letterboxed to `size × size` and handed to `infer`
/// (`[1, 3, size, size]` planes → detections at the input); the detections COCO can read
/// ([`coco_reads`]) of each view are decoded at the view's original size, mapped back to
/// `orig` (a pixel permutation) and fused, at most [`COCO_MAX_DETS`] per class.
pub fn augmented(
    orig: &image::RgbImage,
    size: u32,
    infer: &mut dyn FnMut(Vec<f32>) -> Result<Vec<RawDetection>>,
) -> Result<Vec<Fused>> {
    let mut all = Vec::new();
    for (k, view) in View::ALL.iter().enumerate() {
        let img = view.image(orig);
        let dims = img.dimensions();
        let lb = Letterbox::new(dims, size);
        let mut px = Vec::with_capacity(3 * (size * size) as usize);
        push_planes(&lb.image(&img), &mut px);
        let raw = infer(px)?;
        let keys: Vec<(f32, usize)> = raw.iter().map(|d| (d.score, d.class)).collect();
        let read = coco_reads(&keys, COCO_MAX_DETS);
        let kept: Vec<&RawDetection> = raw.iter().zip(read).filter(|x| x.1).map(|x| x.0).collect();
        all.par_extend(kept.par_iter().map(|d| {
            let bx = lb.unbox_xyxy(d.xyxy().map(|v| v as f64));
            let mask = d.mask_in(lb.orig, bx.map(|v| v as f32));
            ViewDetection {
                view: k,
                class: d.class,
                score: d.score,
                xyxy: view.unmap_box(bx, dims),
                mask: view.unmap_mask(&mask),
            }
        }));
    }
    Ok(fuse(&all, View::ALL.len(), TTA_IOU, COCO_MAX_DETS))
}

/// A fused detection of image `image_id` as a COCO result.
pub fn fused_to_coco(f: &Fused, image_id: u64, cat_ids: &[u64]) -> Detection {
    let [x0, y0, x1, y1] = f.xyxy;
    Detection {
        image_id,
        category_id: cat_ids.get(f.class).copied().unwrap_or(f.class as u64 + 1),
        score: f.score as f64,
        bbox: Some([x0, y0, x1 - x0, y1 - y0]),
        segmentation: Some(Segmentation::from_rle(&Rle::encode_cropped(&f.mask))),
    }
}

/// Where the time of an evaluation went, in seconds (wall clock).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EvalTiming {
    pub images: usize,
    /// Reading and letterboxing the images.
    pub load: f64,
    /// The network on the batches ([`Detector::predict_timed`]: YOLO's forward pass;
    /// Mask R-CNN's whole `forward_infer`).
    pub forward: f64,
    /// From the network's output to the detections (YOLO: box decoding, NMS, host copies).
    pub postprocess: f64,
    /// Boxes mapped back, masks decoded at the original size, RLE encoding.
    pub masks: f64,
    /// COCO matching and accumulation, bbox and segm.
    pub coco: f64,
}

impl EvalTiming {
    pub fn total(&self) -> f64 {
        self.load + self.forward + self.postprocess + self.masks + self.coco
    }

    /// `time: 36 images in 2.10 s (1.27× forward): load 0.20, forward 1.50 (41.7 ms/image),
    /// postprocess 0.05, masks + RLE 0.10, COCO 0.25`.
    pub fn line(&self) -> String {
        format!(
            "time: {} images in {:.2} s ({:.2}× forward): load {:.2}, forward {:.2} ({:.1} ms/image), postprocess {:.2}, masks + RLE {:.2}, COCO {:.2}",
            self.images,
            self.total(),
            self.total() / self.forward.max(1e-9),
            self.load,
            self.forward,
            1e3 * self.forward / self.images.max(1) as f64,
            self.postprocess,
            self.masks,
            self.coco
        )
    }
}

/// COCO evaluation reads at most this many detections per image and category
/// (pycocotools' largest `maxDets`).
pub const COCO_MAX_DETS: usize = 100;

/// Which of one image's detections `(score, class)` the COCO evaluator can read: per
/// class the first `n` in a stable sort by descending score — exactly the ones
/// pycocotools keeps (`argsort(-score, kind="mergesort")[:maxDet]` per image and
/// category). The rest cannot change any of the 12 stats, so their masks are never
/// decoded (YOLO validates with up to 300 detections per image).
pub fn coco_reads(dets: &[(f32, usize)], n: usize) -> Vec<bool> {
    let mut order: Vec<usize> = (0..dets.len()).collect();
    order.sort_by(|&a, &b| dets[b].0.total_cmp(&dets[a].0));
    let mut per_class = std::collections::HashMap::new();
    let mut keep = vec![false; dets.len()];
    for i in order {
        let c = per_class.entry(dets[i].1).or_insert(0usize);
        if *c < n {
            *c += 1;
            keep[i] = true;
        }
    }
    keep
}

/// Letterboxed inputs of a fixed list of images, kept between evaluations: per-epoch
/// validation scores the same images every epoch, and reading and letterboxing 640 px
/// sources again each time was ~10 % of its cost. Kept as 8-bit RGB at the input size
/// (a 640 px input is 1.2 MB an image); a set larger than [`InputCache::MAX_BYTES`] is
/// not kept and read each time instead.
#[derive(Debug, Default)]
pub struct InputCache {
    size: u32,
    images: std::collections::HashMap<u64, (image::RgbImage, (u32, u32))>,
}

impl InputCache {
    /// The most memory a cache may take (values beyond it are read each evaluation).
    pub const MAX_BYTES: usize = 1 << 30;

    /// Reads and letterboxes `ids` of `set` to `input` in parallel; `None` when they would
    /// take more than [`InputCache::MAX_BYTES`].
    pub fn load(set: &RealSet, ids: &[u64], input: usize) -> Result<Option<InputCache>> {
        if ids.len().saturating_mul(3 * input * input) > Self::MAX_BYTES {
            return Ok(None);
        }
        let images = ids
            .par_iter()
            .map(|&id| Ok((id, set.image(id, input as u32)?)))
            .collect::<Result<_>>()?;
        Ok(Some(InputCache {
            size: input as u32,
            images,
        }))
    }

    /// Image `id` letterboxed to `input` and its original size: borrowed from the cache
    /// when it holds it at that size, else read from `set`.
    fn image<'a>(
        cache: Option<&'a InputCache>,
        set: &RealSet,
        id: u64,
        input: u32,
    ) -> Result<(Cow<'a, image::RgbImage>, (u32, u32))> {
        match cache
            .filter(|c| c.size == input)
            .and_then(|c| c.images.get(&id))
        {
            Some((img, orig)) => Ok((Cow::Borrowed(img), *orig)),
            None => set
                .image(id, input)
                .map(|(img, orig)| (Cow::Owned(img), orig)),
        }
    }
}

/// Runs `model` on the real images `ids`, letterboxed to its `input` size (from `cache`
/// where it holds them); returns the detections COCO evaluation reads ([`coco_reads`])
/// and where the time went. With `augment`, each image is seen in eight views and the
/// detections fused ([`augmented`]; the cache is not used).
pub fn predict_ids(
    model: &Detector,
    set: &RealSet,
    ids: &[u64],
    input: usize,
    device: &Device,
    cache: Option<&InputCache>,
    augment: bool,
) -> Result<(Vec<Detection>, EvalTiming)> {
    let size = input;
    let mut dets = Vec::new();
    let mut t = EvalTiming {
        images: ids.len(),
        ..Default::default()
    };
    if augment {
        for &id in ids {
            let t0 = Instant::now();
            let orig = set.original(id)?;
            let t1 = Instant::now();
            let mut forward = 0.0;
            let fused = augmented(&orig, size as u32, &mut |px| {
                let x = Tensor::<4>::from_data(TensorData::new(px, [1, 3, size, size]), device);
                let (mut raw, f) = model.predict_timed(x, VAL_CONF);
                forward += f;
                Ok(raw.swap_remove(0))
            })?;
            dets.extend(fused.iter().map(|f| fused_to_coco(f, id, &set.cat_ids)));
            t.load += (t1 - t0).as_secs_f64();
            t.forward += forward;
            t.masks += t1.elapsed().as_secs_f64() - forward;
        }
        return Ok((dets, t));
    }
    for chunk in ids.chunks(EVAL_BATCH) {
        let t0 = Instant::now();
        let mut px = Vec::with_capacity(chunk.len() * 3 * size * size);
        let mut origs = Vec::new();
        for &id in chunk {
            let (img, orig) = InputCache::image(cache, set, id, size as u32)?;
            push_planes(&img, &mut px);
            origs.push(orig);
        }
        let x = Tensor::<4>::from_data(TensorData::new(px, [chunk.len(), 3, size, size]), device);
        let t1 = Instant::now();
        let (raw, forward) = model.predict_timed(x, VAL_CONF);
        let t2 = Instant::now();
        for ((&id, orig), per) in chunk.iter().zip(&origs).zip(&raw) {
            let keys: Vec<(f32, usize)> = per.iter().map(|d| (d.score, d.class)).collect();
            let read = coco_reads(&keys, COCO_MAX_DETS);
            let kept: Vec<&RawDetection> =
                per.iter().zip(read).filter(|x| x.1).map(|x| x.0).collect();
            dets.par_extend(
                kept.par_iter()
                    .map(|d| to_coco(d, id, &set.cat_ids, size as u32, *orig)),
            );
        }
        t.load += (t1 - t0).as_secs_f64();
        t.forward += forward;
        t.postprocess += (t2 - t1).as_secs_f64() - forward;
        t.masks += t2.elapsed().as_secs_f64();
    }
    Ok((dets, t))
}

/// The ground truth of `ids` only.
pub fn gt_subset(gt: &CocoDataset, ids: &[u64]) -> CocoDataset {
    let mut sorted = ids.to_vec();
    sorted.sort_unstable();
    let keep = |id: &u64| sorted.binary_search(id).is_ok();
    let mut g = gt.clone();
    g.images.retain(|i| keep(&i.id));
    g.annotations.retain(|a| keep(&a.image_id));
    g
}

/// A model scored on some images: the COCO stats, the detections they came from and
/// where the time went.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub stats: Stats,
    pub detections: Vec<Detection>,
    pub timing: EvalTiming,
}

/// bbox and segm COCO stats of `model` (input size `input`) on the real images `ids`
/// (inputs from `cache` where it holds them; with `augment`, test-time augmentation).
pub fn evaluate_ids(
    model: &Detector,
    set: &RealSet,
    ids: &[u64],
    input: usize,
    device: &Device,
    cache: Option<&InputCache>,
    augment: bool,
) -> Result<Evaluation> {
    let (detections, mut timing) = predict_ids(model, set, ids, input, device, cache, augment)?;
    let t0 = Instant::now();
    let gt = gt_subset(&set.gt, ids);
    let bbox = evaluate(&gt, &detections, IouType::Bbox).context("bbox evaluation")?;
    let segm = evaluate(&gt, &detections, IouType::Segm).context("segm evaluation")?;
    timing.coco = t0.elapsed().as_secs_f64();
    Ok(Evaluation {
        stats: Stats {
            bbox: bbox.stats,
            segm: segm.stats,
        },
        detections,
        timing,
    })
}

/// Which split of a real set to score.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SplitName {
    Train,
    Val,
    Test,
}

/// A checkpoint scored on a split.
#[derive(Clone, Debug)]
pub struct Score {
    pub stats: Stats,
    /// The square size the images were letterboxed to.
    pub input: usize,
    /// Epochs the checkpoint had completed.
    pub epoch: usize,
    pub images: usize,
    /// True when the scored images are proxy-real renders.
    pub proxy: bool,
    /// Where the images came from, for messages.
    pub origin: String,
    pub timing: EvalTiming,
    /// The scored detections (COCO results, the real set's image ids).
    pub detections: Vec<Detection>,
}

/// The square size images are letterboxed to for inference: the checkpoint's training
/// input size, or `imgsz` (ultralytics' `val imgsz=` / `predict imgsz=`) where given. The
/// networks are convolutional, so any multiple of their largest stride (32) runs; objects
/// then appear `imgsz / trained` times their training size in pixels, which is what a
/// user scoring photos of another resolution or camera height asks for.
pub fn inference_size(trained: usize, imgsz: Option<usize>) -> Result<usize> {
    match imgsz {
        None => Ok(trained),
        Some(s) if (64..=2048).contains(&s) && s % 32 == 0 => Ok(s),
        Some(s) => bail!(
            "--imgsz {s}: give a multiple of 32 (the largest stride) from 64 to 2048 (the checkpoint was trained at {trained})"
        ),
    }
}

/// Scores `checkpoint`'s weights on `split` of the data it was trained with, rebuilt from
/// its header; with `data`, on the real set of that config instead (e.g. your photos),
/// split as `Split::for_dataset` decides (its own split, else by its `data.split` and
/// seed; `[0, 0]`: every image is test) and letterboxed
/// to the checkpoint's input size (or `imgsz`, see [`inference_size`]); with `augment`,
/// by test-time augmentation ([`augmented`]).
pub fn score_checkpoint(
    checkpoint: &Path,
    split: SplitName,
    data: Option<&str>,
    device: Option<DeviceKind>,
    imgsz: Option<usize>,
    augment: bool,
) -> Result<Score> {
    let ck = Checkpoint::load(checkpoint)?;
    let input = inference_size(ck.header.model.input_size(), imgsz)?;
    let dev = device_of(device.unwrap_or(ck.header.config.device))?;
    let (real, split_ids, origin) = match data {
        None => {
            let cfg = &ck.header.config;
            let real = RealSet::load(&cfg.data, cfg.seed)
                .with_context(|| format!("rebuilding the data of {}", checkpoint.display()))?;
            (
                real,
                ck.header.split.clone(),
                checkpoint.display().to_string(),
            )
        }
        Some(name) => {
            let cfg = config::load(name, &[])?;
            let real = RealSet::load(&cfg.data, cfg.seed)?;
            let split = Split::for_dataset(
                &real.ids(),
                real.own_split.as_ref(),
                cfg.data.split,
                cfg.seed,
            )?;
            (real, split, format!("the data of {name}"))
        }
    };
    if real.cat_ids != ck.header.category_ids {
        bail!(
            "the categories of {origin} {:?} differ from the checkpoint's {:?}",
            real.cat_ids,
            ck.header.category_ids
        );
    }
    let ids = match split {
        SplitName::Train => &split_ids.train,
        SplitName::Val => &split_ids.val,
        SplitName::Test => &split_ids.test,
    };
    if ids.is_empty() {
        bail!("the {split:?} split of {origin} is empty");
    }
    let model = ck
        .model("ema", &dev)
        .with_context(|| format!("in checkpoint {}", checkpoint.display()))?;
    let ev = evaluate_ids(&model, &real, ids, input, &dev, None, augment)?;
    Ok(Score {
        stats: ev.stats,
        timing: ev.timing,
        detections: ev.detections,
        input,
        epoch: ck.header.epoch,
        images: ids.len(),
        proxy: real.proxy,
        origin,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::detection::MaskSource;

    /// A "detector" that finds the one bright rectangle of its input exactly: its tight
    /// box, a full-box mask, score 0.9.
    fn bright_box(px: Vec<f32>, size: usize) -> Vec<RawDetection> {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..size {
            for x in 0..size {
                if px[y * size + x] > 0.9 {
                    (x0, y0) = (x0.min(x), y0.min(y));
                    (x1, y1) = (x1.max(x + 1), y1.max(y + 1));
                }
            }
        }
        vec![RawDetection {
            bbox: [x0 as f32, y0 as f32, (x1 - x0) as f32, (y1 - y0) as f32],
            score: 0.9,
            class: 0,
            mask: MaskSource::RoiProbs {
                probs: vec![1.0; 28 * 28],
                size: 28,
                threshold: 0.5,
            },
        }]
    }

    #[test]
    fn augmented_views_map_back_onto_the_image() {
        // An off-centre rectangle in a 32 × 16 image, letterboxed to 32 without
        // resampling (the turned views are 16 × 32, padded left and right): every view
        // finds it, and all eight map back onto the same pixels, fused into one.
        let (w, h) = (32u32, 16u32);
        let rect = |x: u32, y: u32| (4..12).contains(&x) && (2..6).contains(&y);
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            image::Rgb(if rect(x, y) { [255; 3] } else { [0; 3] })
        });
        let mut calls = 0;
        let fused = augmented(&img, 32, &mut |px| {
            calls += 1;
            Ok(bright_box(px, 32))
        })
        .unwrap();
        assert_eq!(calls, 8);
        assert_eq!(fused.len(), 1, "{fused:?}");
        let f = &fused[0];
        assert_eq!(f.members, 8);
        assert!((f.score - 0.9).abs() < 1e-6);
        for (got, want) in f.xyxy.iter().zip([4.0, 2.0, 12.0, 6.0]) {
            assert!((got - want).abs() < 1e-9, "{:?}", f.xyxy);
        }
        let full = f.mask.full();
        assert_eq!((full.width, full.height), (w, h));
        for y in 0..h {
            for x in 0..w {
                assert_eq!(full.get(x, y), rect(x, y), "pixel ({x}, {y})");
            }
        }
        let coco = fused_to_coco(f, 7, &[3]);
        assert_eq!((coco.image_id, coco.category_id), (7, 3));
        assert_eq!(
            coco.bbox.map(|b| b.map(|v| v.round())),
            Some([4.0, 2.0, 8.0, 4.0])
        );
    }

    #[test]
    fn inference_size_takes_multiples_of_32_only() {
        assert_eq!(inference_size(256, None).unwrap(), 256);
        assert_eq!(inference_size(256, Some(640)).unwrap(), 640);
        assert_eq!(inference_size(256, Some(64)).unwrap(), 64);
        for bad in [0, 32, 100, 330, 2080] {
            let e = inference_size(256, Some(bad)).unwrap_err().to_string();
            assert!(
                e.contains(&format!("--imgsz {bad}")) && e.contains("trained at 256"),
                "{e}"
            );
        }
    }

    /// Two images with a few GT boxes and 250 detections each (two categories, scores
    /// with many ties): the stats of the detections `coco_reads` keeps equal the stats of
    /// all of them, and nothing past 100 per image and category is kept.
    #[test]
    fn detections_past_max_dets_never_change_the_stats() {
        let gt: CocoDataset = serde_json::from_str(
            r#"{"images": [{"id": 1, "file_name": "a", "width": 60, "height": 50},
                           {"id": 2, "file_name": "b", "width": 60, "height": 50}],
                "categories": [{"id": 1, "name": "x"}, {"id": 2, "name": "y"}],
                "annotations": [
                  {"id": 1, "image_id": 1, "category_id": 1, "bbox": [5, 5, 20, 15], "segmentation": [[5, 5, 25, 5, 25, 20, 5, 20]], "area": 300, "iscrowd": 0},
                  {"id": 2, "image_id": 1, "category_id": 2, "bbox": [30, 20, 20, 25], "segmentation": [[30, 20, 50, 20, 50, 45, 30, 45]], "area": 500, "iscrowd": 0},
                  {"id": 3, "image_id": 2, "category_id": 1, "bbox": [10, 10, 30, 30], "segmentation": [[10, 10, 40, 10, 40, 40, 10, 40]], "area": 900, "iscrowd": 0},
                  {"id": 4, "image_id": 2, "category_id": 1, "bbox": [40, 5, 15, 10], "segmentation": [[40, 5, 55, 5, 55, 15, 40, 15]], "area": 150, "iscrowd": 0}]}"#,
        )
        .unwrap();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move |m: u64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % m
        };
        let (mut all, mut kept) = (Vec::new(), Vec::new());
        for image_id in [1u64, 2] {
            let dets: Vec<Detection> = (0..250)
                .map(|_| {
                    let (x, y) = (next(40) as f64, next(35) as f64);
                    let (w, h) = (5.0 + next(25) as f64, 5.0 + next(20) as f64);
                    Detection {
                        image_id,
                        category_id: 1 + next(2),
                        score: next(8) as f64 / 8.0 + 0.01,
                        bbox: Some([x, y, w, h]),
                        segmentation: None,
                    }
                })
                .collect();
            let keys: Vec<(f32, usize)> = dets
                .iter()
                .map(|d| (d.score as f32, d.category_id as usize))
                .collect();
            let read = coco_reads(&keys, COCO_MAX_DETS);
            for c in [1, 2] {
                let n = read
                    .iter()
                    .zip(&keys)
                    .filter(|(r, k)| **r && k.1 == c)
                    .count();
                assert_eq!(n, COCO_MAX_DETS, "image {image_id} class {c}");
            }
            kept.extend(dets.iter().zip(&read).filter(|x| *x.1).map(|x| x.0.clone()));
            all.extend(dets);
        }
        let full = evaluate(&gt, &all, IouType::Bbox).unwrap().stats;
        let cut = evaluate(&gt, &kept, IouType::Bbox).unwrap().stats;
        assert_eq!(full, cut);
        assert!(full[0] > 0.0 && full[0] < 1.0, "{full:?}");
    }
}
