//! Timing helper for `chicktrain bench` (not a test): inference ms/image and train-step
//! ms/image of a YOLO-seg model on synthetic input, with the train step split into forward,
//! loss (assigner + losses), backward and optimiser so the report can say where time goes.
//!
//! Also holds [`synthetic_batch`], a procedural scene (filled ellipses on a plain
//! background, with their masks and boxes) used by the benchmark and the learning test.

use std::time::Instant;

use burn::module::Module;
use burn::optim::momentum::MomentumConfig;
use burn::optim::{GradientsParams, SgdConfig};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::loss::{yolo_loss, ImageTargets, LossWeights, YoloTargets};
use super::YoloSegConfig;

/// A batch of procedural images: `[B, 3, size, size]` values in [0, 1] (row-major, channel
/// planes) and their targets. Each image has `objects` filled ellipses of random colour on a
/// plain background; later ellipses occlude earlier ones, and the masks record what stays
/// visible, so masks never overlap.
pub fn synthetic_batch(
    batch: usize,
    size: usize,
    objects: usize,
    seed: u64,
) -> (Vec<f32>, YoloTargets) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pixels = vec![0f32; batch * 3 * size * size];
    let mut images = Vec::with_capacity(batch);
    let s = size as f32;
    for b in 0..batch {
        let bg: [f32; 3] = [
            rng.random_range(0.0..0.3),
            rng.random_range(0.0..0.3),
            rng.random_range(0.0..0.3),
        ];
        let mut owner = vec![0usize; size * size]; // 0 = background, k + 1 = object k
        let mut colours = Vec::new();
        for k in 0..objects {
            let rx = rng.random_range(0.08..0.22) * s;
            let ry = rng.random_range(0.08..0.22) * s;
            let cx = rng.random_range(rx..s - rx);
            let cy = rng.random_range(ry..s - ry);
            colours.push([
                rng.random_range(0.6..1.0),
                rng.random_range(0.4..1.0),
                rng.random_range(0.3..1.0),
            ]);
            for y in 0..size {
                for x in 0..size {
                    let dx = (x as f32 + 0.5 - cx) / rx;
                    let dy = (y as f32 + 0.5 - cy) / ry;
                    if dx * dx + dy * dy <= 1.0 {
                        owner[y * size + x] = k + 1;
                    }
                }
            }
        }
        let mut t = ImageTargets::default();
        for k in 0..objects {
            let mask: Vec<u8> = owner.iter().map(|&o| u8::from(o == k + 1)).collect();
            let (mut x1, mut y1, mut x2, mut y2) = (usize::MAX, usize::MAX, 0, 0);
            for (p, &m) in mask.iter().enumerate() {
                if m != 0 {
                    let (x, y) = (p % size, p / size);
                    x1 = x1.min(x);
                    y1 = y1.min(y);
                    x2 = x2.max(x + 1);
                    y2 = y2.max(y + 1);
                }
            }
            if x1 == usize::MAX {
                continue; // fully occluded
            }
            t.boxes.push([x1 as f32, y1 as f32, x2 as f32, y2 as f32]);
            t.classes.push(0);
            t.masks.push(mask);
        }
        for p in 0..size * size {
            let c = if owner[p] == 0 {
                bg
            } else {
                colours[owner[p] - 1]
            };
            for ch in 0..3 {
                pixels[((b * 3 + ch) * size * size) + p] = c[ch];
            }
        }
        images.push(t);
    }
    (pixels, YoloTargets { images })
}

/// Timings of one configuration, milliseconds per image (median over the timed runs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchResult {
    pub input: usize,
    pub infer_batch: usize,
    pub train_batch: usize,
    /// BatchNorm folded into the convs ([`super::YoloSeg::fuse`]).
    pub infer_ms_per_img: f64,
    /// Same model without folding.
    pub infer_unfused_ms_per_img: f64,
    pub train_ms_per_img: f64,
    /// Split of the train step, ms per image: forward, loss (assigner + losses), backward,
    /// optimiser step.
    pub forward_ms: f64,
    pub loss_ms: f64,
    pub backward_ms: f64,
    pub optim_ms: f64,
}

impl std::fmt::Display for BenchResult {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} px: inference {:.1} ms/img (batch {}, BN folded; {:.1} unfolded); train {:.1} ms/img (batch {}: forward {:.1}, loss {:.1}, backward {:.1}, optimiser {:.1})",
            self.input,
            self.infer_ms_per_img,
            self.infer_batch,
            self.infer_unfused_ms_per_img,
            self.train_ms_per_img,
            self.train_batch,
            self.forward_ms,
            self.loss_ms,
            self.backward_ms,
            self.optim_ms
        )
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Times inference (eval-mode model, no autodiff, `infer_batch` images) and SGD train steps
/// (`train_batch` images, 6 objects each) of `cfg` at `cfg.input_size` on `device` (a plain
/// device: autodiff is added for training). One warm-up, then the median of `runs`.
pub fn bench_yolo(
    cfg: &YoloSegConfig,
    device: &Device,
    infer_batch: usize,
    train_batch: usize,
    runs: usize,
) -> BenchResult {
    let size = cfg.input_size;
    let runs = runs.max(1);
    device.seed(0);
    let ad = device.clone().autodiff();
    let mut model = cfg.init(&ad);

    // Inference, with BatchNorm folded into the convs (as a deployed model runs) and without;
    // the two are interleaved so that load from other processes hits both alike.
    let unfused = model.valid();
    let fused = unfused.clone().fuse();
    let (px, _) = synthetic_batch(infer_batch, size, 6, 1);
    let x = Tensor::<4>::from_data(TensorData::new(px, [infer_batch, 3, size, size]), device);
    let time_infer = |m: &super::YoloSeg| {
        let t0 = Instant::now();
        let out = m.forward(x.clone());
        let _ = super::loss::to_host(out.cls_logits);
        let _ = super::loss::to_host(out.proto);
        t0.elapsed().as_secs_f64() * 1e3 / infer_batch as f64
    };
    let (mut infer, mut infer_unfused) = (Vec::new(), Vec::new());
    for r in 0..=2 * runs {
        let (a, b) = (time_infer(&fused), time_infer(&unfused));
        if r > 0 {
            infer.push(a);
            infer_unfused.push(b);
        }
    }
    drop((fused, unfused));

    // Training.
    let mut optim = SgdConfig::new()
        .with_momentum(Some(
            MomentumConfig::new()
                .with_momentum(0.937)
                .with_dampening(0.0),
        ))
        .init();
    let (px, targets) = synthetic_batch(train_batch, size, 6, 2);
    let x = Tensor::<4>::from_data(TensorData::new(px, [train_batch, 3, size, size]), &ad);
    let w = LossWeights::default();
    let (mut tot, mut fw, mut ls, mut bw, mut op) = (vec![], vec![], vec![], vec![], vec![]);
    let per = |d: std::time::Duration| d.as_secs_f64() * 1e3 / train_batch as f64;
    for r in 0..=runs {
        let t0 = Instant::now();
        let out = model.forward(x.clone());
        let _ = super::loss::to_host(out.cls_logits.clone().detach());
        let t1 = Instant::now();
        let loss = yolo_loss(&out, &targets, &w);
        let _ = loss.values();
        let t2 = Instant::now();
        let grads = loss.total.backward();
        let grads = GradientsParams::from_grads(grads, &model);
        let t3 = Instant::now();
        model = optim.step(0.01, model, grads);
        // Force the update to run before stopping the clock.
        let _ = super::loss::to_host(model.head.boxes[0].out.weight.val().sum());
        let t4 = Instant::now();
        if r > 0 {
            tot.push(per(t4 - t0));
            fw.push(per(t1 - t0));
            ls.push(per(t2 - t1));
            bw.push(per(t3 - t2));
            op.push(per(t4 - t3));
        }
    }
    BenchResult {
        input: size,
        infer_batch,
        train_batch,
        infer_ms_per_img: median(infer),
        infer_unfused_ms_per_img: median(infer_unfused),
        train_ms_per_img: median(tot),
        forward_ms: median(fw),
        loss_ms: median(ls),
        backward_ms: median(bw),
        optim_ms: median(op),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synthetic_masks_are_disjoint_and_boxed() {
        let (px, t) = synthetic_batch(2, 64, 3, 7);
        assert_eq!(px.len(), 2 * 3 * 64 * 64);
        for img in &t.images {
            assert!(!img.boxes.is_empty());
            for p in 0..64 * 64 {
                assert!(img.masks.iter().filter(|m| m[p] != 0).count() <= 1);
            }
            for (b, m) in img.boxes.iter().zip(&img.masks) {
                for (p, &v) in m.iter().enumerate() {
                    if v != 0 {
                        let (x, y) = ((p % 64) as f32, (p / 64) as f32);
                        assert!(x >= b[0] && x < b[2] && y >= b[1] && y < b[3]);
                    }
                }
            }
        }
    }
}
