//! The one-batch overfitting scene of the `*_learns` model tests: `BATCH` 64 px images of
//! filled ellipses with their masks, the ground truth and detections in COCO form for
//! the shared evaluator (image ids from 1, category 1), the optimiser loop of the
//! `*_learns` tests ([`overfit`]) and the two checks they make: the logged loss terms fell
//! ([`assert_terms_fell`]) and the eval-mode model overfits the batch ([`assert_overfits`]).

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::annotations::coco::{
    CocoAnnotation, CocoCategory, CocoDataset, CocoImage, Detection as CocoDetection, Segmentation,
};
use chicktrain::annotations::mask::Mask;
use chicktrain::annotations::rle::Rle;
use chicktrain::annotations::targets::ImageTargets;
use chicktrain::eval::coco_eval::{evaluate, IouType};
use chicktrain::model::detection::Detection;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub const SIZE: usize = 64;
pub const BATCH: usize = 2;

/// `BATCH` images with one or two non-overlapping ellipses each (left / right half).
pub fn ellipses(seed: u64) -> (Vec<f32>, Vec<ImageTargets>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = SIZE * SIZE;
    let mut px = vec![0f32; BATCH * 3 * n];
    let mut targets = Vec::new();
    for b in 0..BATCH {
        let mut t = ImageTargets::default();
        for half in 0..1 + b % 2 {
            let rx: f32 = rng.random_range(6.0..13.0);
            let ry: f32 = rng.random_range(6.0..13.0);
            let x0 = half as f32 * 32.0;
            let cx = rng.random_range(x0 + rx..x0 + 32.0 - rx);
            let cy = rng.random_range(ry..SIZE as f32 - ry);
            let mut mask = vec![0u8; n];
            let (mut x1, mut y1, mut x2, mut y2) = (SIZE, SIZE, 0, 0);
            for y in 0..SIZE {
                for x in 0..SIZE {
                    let (dx, dy) = ((x as f32 + 0.5 - cx) / rx, (y as f32 + 0.5 - cy) / ry);
                    if dx * dx + dy * dy <= 1.0 {
                        mask[y * SIZE + x] = 1;
                        (x1, y1, x2, y2) = (x1.min(x), y1.min(y), x2.max(x + 1), y2.max(y + 1));
                        for c in 0..3 {
                            px[(b * 3 + c) * n + y * SIZE + x] = 0.9 - 0.2 * c as f32;
                        }
                    }
                }
            }
            t.boxes.push([x1 as f32, y1 as f32, x2 as f32, y2 as f32]);
            t.classes.push(0);
            t.masks.push(mask);
        }
        targets.push(t);
    }
    (px, targets)
}

fn rle(mask: &[u8]) -> Rle {
    Rle::encode(&Mask::from_row_major(SIZE as u32, SIZE as u32, mask.to_vec()).unwrap())
}

/// Ground truth and results in COCO form (image ids from 1, category 1).
pub fn to_coco(
    targets: &[ImageTargets],
    dets: &[Vec<Detection>],
) -> (CocoDataset, Vec<CocoDetection>) {
    let mut gt = CocoDataset {
        categories: vec![CocoCategory {
            id: 1,
            name: "ellipse".into(),
            extra: Default::default(),
        }],
        ..Default::default()
    };
    let mut dt = Vec::new();
    for (i, (t, d)) in targets.iter().zip(dets).enumerate() {
        let image_id = i as u64 + 1;
        gt.images.push(CocoImage {
            id: image_id,
            file_name: format!("{image_id}.png"),
            width: SIZE as u32,
            height: SIZE as u32,
            extra: Default::default(),
        });
        for (b, m) in t.boxes.iter().zip(&t.masks) {
            gt.annotations.push(CocoAnnotation {
                id: gt.annotations.len() as u64 + 1,
                image_id,
                category_id: 1,
                segmentation: Segmentation::Uncompressed(rle(m)),
                area: m.iter().filter(|&&v| v != 0).count() as f64,
                bbox: [
                    b[0] as f64,
                    b[1] as f64,
                    (b[2] - b[0]) as f64,
                    (b[3] - b[1]) as f64,
                ],
                iscrowd: 0,
                extra: Default::default(),
            });
        }
        for x in d {
            dt.push(CocoDetection {
                image_id,
                category_id: x.class as u64 + 1,
                score: x.score as f64,
                bbox: Some(x.bbox.map(|v| v as f64)),
                segmentation: Some(Segmentation::Uncompressed(rle(&x.input_mask([SIZE, SIZE])))),
            });
        }
    }
    (gt, dt)
}

/// Fails unless each `(k, name)` term of the logged steps fell: its mean over the last
/// three steps below `factor` times its mean over the first three.
pub fn assert_terms_fell<const N: usize>(log: &[[f32; N]], terms: &[(usize, &str)], factor: f32) {
    let mean = |s: &[[f32; N]], k: usize| s.iter().map(|v| v[k]).sum::<f32>() / s.len() as f32;
    let (first, last) = (&log[..3], &log[log.len() - 3..]);
    for &(k, name) in terms {
        let (a, b) = (mean(first, k), mean(last, k));
        assert!(b < factor * a, "{name} fell only from {a} to {b}");
    }
}

/// Fails unless `dets` reach segm AP50 0.9 on the training batch `targets` (the
/// overfitting criterion of the `*_learns` tests).
pub fn assert_overfits(targets: &[ImageTargets], dets: &[Vec<Detection>]) {
    let (gt, dt) = to_coco(targets, dets);
    let segm = evaluate(&gt, &dt, IouType::Segm).unwrap();
    eprintln!(
        "{} detections; segm AP50 {:.3}, AP {:.3}",
        dt.len(),
        segm.stats[1],
        segm.stats[0]
    );
    assert!(
        segm.stats[1] >= 0.9,
        "segm AP50 {} on the training batch",
        segm.stats[1]
    );
}

/// The batch of [`ellipses`]`(11)` on `device`: `[BATCH, 3, SIZE, SIZE]` pixels and targets.
pub fn batch(device: &Device) -> (Tensor<4>, Vec<ImageTargets>) {
    let (px, targets) = ellipses(11);
    let x = Tensor::<4>::from_data(TensorData::new(px, [BATCH, 3, SIZE, SIZE]), device);
    (x, targets)
}

/// `steps` AdamW steps of `model` at learning rate `lr` (no weight decay), then `calib`
/// forward/backward passes without updates, so that BatchNorm's running statistics match
/// the final weights in eval mode. `loss(model, step)` is a step's total and its host
/// terms; returns the terms of the update steps and the model.
pub fn overfit<M: Module, const N: usize>(
    mut model: M,
    (steps, calib, lr): (usize, usize, f64),
    mut loss: impl FnMut(&M, usize) -> (Tensor<1>, [f32; N]),
) -> (Vec<[f32; N]>, M) {
    let mut optim = AdamWConfig::new().with_weight_decay(0.0).init();
    let mut log = Vec::new();
    for step in 0..steps + calib {
        let (total, v) = loss(&model, step);
        let grads = GradientsParams::from_grads(total.backward(), &model);
        if step < steps {
            model = optim.step(lr, model, grads);
            log.push(v);
        }
    }
    (log, model)
}
