//! A tiny Mask2Former (ResNet-18 at quarter width, 64 px, a 32-wide 3-layer decoder with 8
//! queries, procedural filled ellipses with masks drawn here) must learn: over AdamW steps
//! on one batch the total loss falls substantially on flex with every term finite, and the
//! eval-mode model then overfits that batch to segm AP50 ≥ 0.9 under the shared COCO
//! evaluator (issue 17's criterion); a few steps on ndarray run without NaN.

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::annotations::coco::{
    CocoAnnotation, CocoCategory, CocoDataset, CocoImage, Detection as CocoDetection, Segmentation,
};
use chicktrain::annotations::mask::Mask;
use chicktrain::annotations::rle::Rle;
use chicktrain::data::targets::ImageTargets;
use chicktrain::eval::coco_eval::{evaluate, IouType};
use chicktrain::model::detection::Detection;
use chicktrain::model::mask2former::{CriterionConfig, Mask2Former, Mask2FormerConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIZE: usize = 64;
const BATCH: usize = 2;

/// `BATCH` images with one or two non-overlapping ellipses each (left / right half).
fn ellipses(seed: u64) -> (Vec<f32>, Vec<ImageTargets>) {
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

fn tiny_config() -> Mask2FormerConfig {
    Mask2FormerConfig {
        width_mult: 0.25,
        input_size: SIZE,
        conv_dim: 32,
        mask_dim: 32,
        hidden_dim: 32,
        heads: 4,
        ffn_dim: 64,
        dec_layers: 3,
        queries: 8,
        top_k: 8,
        criterion: CriterionConfig {
            points: 256,
            ..CriterionConfig::paper()
        },
        ..Mask2FormerConfig::new(18, 1)
    }
}

/// `steps` AdamW steps, then `calib` forward/backward passes without updates so that
/// BatchNorm's running statistics match the final weights in eval mode.
fn train(dev: Device, steps: usize, calib: usize) -> (Vec<[f32; 4]>, Mask2Former) {
    dev.seed(7);
    let ad = dev.clone().autodiff();
    let mut model = tiny_config().init(&ad);
    let mut optim = AdamWConfig::new().with_weight_decay(0.0).init();
    let (px, targets) = ellipses(11);
    let x = Tensor::<4>::from_data(TensorData::new(px, [BATCH, 3, SIZE, SIZE]), &ad);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut log = Vec::new();
    for step in 0..steps + calib {
        let losses = model.forward_train(x.clone(), &targets, &mut rng);
        let v = losses.values();
        assert!(
            v.iter().all(|x| x.is_finite()),
            "step {step}: loss terms {v:?}"
        );
        let grads = GradientsParams::from_grads(losses.total.backward(), &model);
        if step < steps {
            model = optim.step(LR, model, grads);
            log.push(v);
        }
    }
    (log, model)
}

const LR: f64 = 1e-3;
const STEPS: usize = 120;

#[test]
fn tiny_model_overfits_one_batch_on_flex() {
    let t = std::time::Instant::now();
    let (log, model) = train(Device::flex(), STEPS, 5);
    let mean = |s: &[[f32; 4]], k: usize| s.iter().map(|v| v[k]).sum::<f32>() / s.len() as f32;
    let (first, last) = (&log[..3], &log[log.len() - 3..]);
    eprintln!(
        "first {first:?}\nlast {last:?}\n{:.1} s",
        t.elapsed().as_secs_f32()
    );
    let (t0, t1) = (mean(first, 3), mean(last, 3));
    assert!(t1 < 0.5 * t0, "total loss fell only from {t0} to {t1}");
    for (k, name) in ["cls", "mask", "dice"].iter().enumerate() {
        assert!(
            mean(last, k) < 0.7 * mean(first, k),
            "{name} fell only from {} to {}",
            mean(first, k),
            mean(last, k)
        );
    }
    let eval = model.valid();
    let (px, targets) = ellipses(11);
    let x = Tensor::<4>::from_data(TensorData::new(px, [BATCH, 3, SIZE, SIZE]), &Device::flex());
    let dets = eval.forward_infer(x);
    assert_eq!(dets.len(), BATCH);
    for d in dets.iter().flatten() {
        assert!(d.score > 0.0 && d.score <= 1.0 && d.class == 0);
        assert!(d.bbox[2] > 0.0 && d.bbox[3] > 0.0 && d.bbox[0] + d.bbox[2] <= SIZE as f32);
    }
    let (gt, dt) = to_coco(&targets, &dets);
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

fn rle(mask: &[u8]) -> Rle {
    Rle::encode(&Mask::from_row_major(SIZE as u32, SIZE as u32, mask.to_vec()).unwrap())
}

/// Ground truth and results in COCO form (image ids from 1, category 1).
fn to_coco(targets: &[ImageTargets], dets: &[Vec<Detection>]) -> (CocoDataset, Vec<CocoDetection>) {
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

#[test]
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn runs_on_ndarray_without_nan() {
    let (log, _) = train(Device::ndarray(), 2, 0);
    assert_eq!(log.len(), 2);
}
