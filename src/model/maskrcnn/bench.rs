//! Timing helper (not a test): inference ms/image and SGD train-step ms/image of a Mask
//! R-CNN on the procedural ellipse scenes of the YOLO benchmark (6 objects per image), with
//! the train step split into forward + losses (the two interleave: proposals and targets
//! are built between the stages), backward and optimiser. Driven by the ignored test
//! `tests/maskrcnn_bench.rs`; `tests/fixtures/maskrcnn/bench_torchvision.py` times
//! torchvision's Mask R-CNN on the same sizes for the ratio.

use std::time::Instant;

use burn::module::Module;
use burn::optim::momentum::MomentumConfig;
use burn::optim::{GradientsParams, SgdConfig};
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::losses::to_vec;
use super::MaskRcnnConfig;
use crate::model::yolo::bench::synthetic_batch;

/// Timings of one configuration, milliseconds per image (median over the timed runs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaskRcnnBench {
    pub depth: usize,
    pub input: usize,
    pub infer_batch: usize,
    pub train_batch: usize,
    pub infer_ms_per_img: f64,
    pub train_ms_per_img: f64,
    pub forward_loss_ms: f64,
    pub backward_ms: f64,
    pub optim_ms: f64,
}

impl std::fmt::Display for MaskRcnnBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "r{} {} px: inference {:.0} ms/img (batch {}); train {:.0} ms/img = {:.2} img/s (batch {}: forward+losses {:.0}, backward {:.0}, optimiser {:.0})",
            self.depth,
            self.input,
            self.infer_ms_per_img,
            self.infer_batch,
            self.train_ms_per_img,
            1e3 / self.train_ms_per_img,
            self.train_batch,
            self.forward_loss_ms,
            self.backward_ms,
            self.optim_ms
        )
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Times inference (eval-mode model, no autodiff) and SGD steps (momentum 0.9, weight
/// decay 1e-4: the paper's protocol) of `cfg` at `cfg.input_size` on `device` (a plain
/// device; autodiff is added for training). One warm-up run each, then the median of `runs`.
pub fn bench_maskrcnn(
    cfg: &MaskRcnnConfig,
    device: &Device,
    infer_batch: usize,
    train_batch: usize,
    runs: usize,
) -> MaskRcnnBench {
    let size = cfg.input_size;
    let runs = runs.max(1);
    device.seed(0);
    let ad = device.clone().autodiff();
    let mut model = cfg.init(&ad);

    let eval = model.valid();
    let (px, _) = synthetic_batch(infer_batch, size, 6, 1);
    let x = Tensor::<4>::from_data(TensorData::new(px, [infer_batch, 3, size, size]), device);
    let mut infer = Vec::new();
    for r in 0..=runs {
        let t0 = Instant::now();
        let dets = eval.forward_infer(x.clone());
        assert_eq!(dets.len(), infer_batch);
        if r > 0 {
            infer.push(t0.elapsed().as_secs_f64() * 1e3 / infer_batch as f64);
        }
    }
    drop(eval);

    let mut optim = SgdConfig::new()
        .with_momentum(Some(
            MomentumConfig::new().with_momentum(0.9).with_dampening(0.0),
        ))
        .with_weight_decay(Some(burn::optim::decay::WeightDecayConfig::new(1e-4)))
        .init();
    let (px, targets) = synthetic_batch(train_batch, size, 6, 2);
    let x = Tensor::<4>::from_data(TensorData::new(px, [train_batch, 3, size, size]), &ad);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let (mut tot, mut fw, mut bw, mut op) = (vec![], vec![], vec![], vec![]);
    let per = |d: std::time::Duration| d.as_secs_f64() * 1e3 / train_batch as f64;
    for r in 0..=runs {
        let t0 = Instant::now();
        let losses = model.forward_train(x.clone(), &targets.images, &mut rng);
        let _ = losses.values();
        let t1 = Instant::now();
        let grads = GradientsParams::from_grads(losses.total.backward(), &model);
        let t2 = Instant::now();
        model = optim.step(0.01, model, grads);
        // Force the update to run before stopping the clock.
        let _ = to_vec(model.box_head.cls_score.weight.val().sum());
        let t3 = Instant::now();
        if r > 0 {
            tot.push(per(t3 - t0));
            fw.push(per(t1 - t0));
            bw.push(per(t2 - t1));
            op.push(per(t3 - t2));
        }
    }
    MaskRcnnBench {
        depth: cfg.depth,
        input: size,
        infer_batch,
        train_batch,
        infer_ms_per_img: median(infer),
        train_ms_per_img: median(tot),
        forward_loss_ms: median(fw),
        backward_ms: median(bw),
        optim_ms: median(op),
    }
}
