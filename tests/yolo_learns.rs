//! A tiny YOLO-seg (scale n at half width, 64 px) must actually learn: over a few dozen
//! AdamW steps on one procedural batch (filled ellipses with their masks) the total loss
//! falls substantially on flex; the same steps run on ndarray without NaN.

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::model::yolo::bench::synthetic_batch;
use chicktrain::model::yolo::loss::{yolo_loss, LossWeights};
use chicktrain::model::yolo::postprocess::postprocess;
use chicktrain::model::yolo::{Scale, YoloSegConfig};

const SIZE: usize = 64;
const BATCH: usize = 4;

fn train(dev: Device, steps: usize) -> (Vec<f32>, chicktrain::model::yolo::YoloSeg) {
    dev.seed(42);
    let ad = dev.clone().autodiff();
    let cfg = YoloSegConfig::new(Scale::N, 1)
        .with_input_size(SIZE)
        .with_width_mult(0.5)
        .with_num_masks(8);
    let mut model = cfg.init(&ad);
    let mut optim = AdamWConfig::new().with_weight_decay(0.0).init();
    let (px, targets) = synthetic_batch(BATCH, SIZE, 2, 3);
    let x = Tensor::<4>::from_data(TensorData::new(px, [BATCH, 3, SIZE, SIZE]), &ad);
    let w = LossWeights::default();
    let mut losses = Vec::new();
    for _ in 0..steps {
        let out = model.forward(x.clone());
        let loss = yolo_loss(&out, &targets, &w);
        let v = loss.values();
        assert!(v.iter().all(|x| x.is_finite()), "loss terms {v:?}");
        losses.push(v[4]);
        let grads = GradientsParams::from_grads(loss.total.backward(), &model);
        model = optim.step(2e-3, model, grads);
    }
    (losses, model)
}

#[test]
fn tiny_model_learns_on_flex() {
    let (losses, model) = train(Device::flex(), 40);
    let first: f32 = losses[..3].iter().sum::<f32>() / 3.0;
    let last: f32 = losses[losses.len() - 3..].iter().sum::<f32>() / 3.0;
    eprintln!("loss {first:.2} → {last:.2}: {losses:?}");
    assert!(last < 0.5 * first, "loss fell only from {first} to {last}");
    // The trained model's postprocess runs and returns well-formed detections.
    let eval = model.valid();
    let (px, _) = synthetic_batch(BATCH, SIZE, 2, 3);
    let x = Tensor::<4>::from_data(TensorData::new(px, [BATCH, 3, SIZE, SIZE]), &Device::flex());
    let dets = postprocess(&eval.forward(x), 0.001, 0.7, 50);
    assert_eq!(dets.len(), BATCH);
    for d in dets.iter().flatten() {
        assert_eq!(d.mask.len(), SIZE * SIZE);
        assert!(d.score > 0.001 && d.bbox.iter().all(|v| v.is_finite()));
    }
}

#[test]
#[allow(deprecated)] // Device::ndarray: the trainer must still run there.
fn same_steps_run_on_ndarray() {
    let (losses, _) = train(Device::ndarray(), 3);
    assert!(losses.iter().all(|l| l.is_finite()), "{losses:?}");
}
