//! A tiny Mask2Former (ResNet-18 at quarter width, 64 px, a 32-wide 3-layer decoder with 8
//! queries, procedural filled ellipses with masks drawn here) must learn: over AdamW steps
//! on one batch the total loss falls substantially on flex with every term finite, and the
//! eval-mode model then overfits that batch to segm AP50 ≥ 0.9 under the shared COCO
//! evaluator (issue 17's criterion); a few steps on ndarray run without NaN.

use burn::module::Module;
use burn::tensor::Device;
use chicktrain::model::mask2former::{CriterionConfig, Mask2Former, Mask2FormerConfig};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

mod common;

use common::overfit::{assert_overfits, assert_terms_fell, batch, overfit, BATCH, SIZE};

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
    let model = tiny_config().init(&ad);
    let (x, targets) = batch(&ad);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    overfit(model, (steps, calib, LR), |model: &Mask2Former, step| {
        let losses = model.forward_train(x.clone(), &targets, &mut rng);
        let v = losses.values();
        assert!(
            v.iter().all(|x| x.is_finite()),
            "step {step}: loss terms {v:?}"
        );
        (losses.total, v)
    })
}

const LR: f64 = 1e-3;
const STEPS: usize = 120;

#[test]
fn tiny_model_overfits_one_batch_on_flex() {
    let t = std::time::Instant::now();
    let (log, model) = train(Device::flex(), STEPS, 5);
    eprintln!(
        "first {:?}\nlast {:?}\n{:.1} s",
        &log[..3],
        &log[log.len() - 3..],
        t.elapsed().as_secs_f32()
    );
    assert_terms_fell(&log, &[(3, "total loss")], 0.5);
    assert_terms_fell(&log, &[(0, "cls"), (1, "mask"), (2, "dice")], 0.7);
    let eval = model.valid();
    let (x, targets) = batch(&Device::flex());
    let dets = eval.forward_infer(x);
    assert_eq!(dets.len(), BATCH);
    for d in dets.iter().flatten() {
        assert!(d.score > 0.0 && d.score <= 1.0 && d.class == 0);
        assert!(d.bbox[2] > 0.0 && d.bbox[3] > 0.0 && d.bbox[0] + d.bbox[2] <= SIZE as f32);
    }
    assert_overfits(&targets, &dets);
}

#[test]
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn runs_on_ndarray_without_nan() {
    let (log, _) = train(Device::ndarray(), 2, 0);
    assert_eq!(log.len(), 2);
}
