//! Side-by-side timing of batch norm in training mode, forward + backward,
//! Burn's defaults ([`super::reference`]) against the fused kernels, on the
//! batch-norm shapes of YOLO11n-seg at batch 8 and 224 px. The shapes are the
//! output channels and levels of the convolutions listed in
//! `conv_engine::bench` (each of YOLO11's Conv blocks is conv + BN + SiLU), so
//! the list and its counts are approximate and the TOTAL row is indicative;
//! the per-shape ratios are the measurement. Ignored by default; run with
//! `cargo test --release --lib batch_norm::bench -- --ignored --nocapture`
//! (prefix `RAYON_NUM_THREADS=1` for one thread, as the quickstart pair runs).
//! Old and new alternate (old, new, old, new, …) so both see the same load;
//! the median of `REPEATS` is reported. Both sides get a shared output
//! gradient, so the fused backward writes a new buffer rather than reusing it.

extern crate std;

use alloc::vec::Vec;
use burn_backend::{DType, TensorData};
use std::println;
use std::time::Instant;

use super::{batch_norm_train, batch_norm_train_backward, reference};
use crate::FlexTensor;

const REPEATS: usize = 11;
const BATCH: usize = 8;
const IMAGE: usize = 224;

/// (channels, level, count): the output side of `conv_engine::bench::SHAPES`,
/// merged; level `l` is `IMAGE / 2^l` pixels square.
const SHAPES: [(usize, u32, usize); 12] = [
    (16, 1, 1),
    (16, 2, 2),
    (32, 2, 3),
    (64, 2, 2),
    (32, 3, 5),
    (64, 3, 9),
    (128, 3, 1),
    (32, 4, 4),
    (64, 4, 5),
    (128, 4, 7),
    (64, 5, 9),
    (256, 5, 10),
];

fn tensor(shape: &[usize], seed: &mut u64) -> FlexTensor {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*seed >> 40) as f32 / (1u64 << 24) as f32) - 0.5
        })
        .collect();
    FlexTensor::from_data(TensorData::new(data, shape.to_vec()))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median milliseconds of `old` and `new`, interleaved.
fn interleaved(old: &dyn Fn(), new: &dyn Fn()) -> (f64, f64) {
    old();
    new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..REPEATS {
        let t = Instant::now();
        old();
        a.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        new();
        b.push(t.elapsed().as_secs_f64() * 1e3);
    }
    (median(a), median(b))
}

#[test]
#[ignore = "timing; run with --ignored --nocapture"]
fn bench_batch_norm_train_yolo11n_224_batch8() {
    let mut seed = 37u64;
    let threads = rayon::current_num_threads();
    println!(
        "batch norm train, forward + backward, batch {BATCH}, {IMAGE} px, {threads} thread(s)"
    );
    println!("| channels | size | count | default ms | fused ms | default ÷ fused |");
    println!("|---|---|---|---|---|---|");
    let (mut total_old, mut total_new) = (0.0, 0.0);
    for (c, level, count) in SHAPES {
        let side = IMAGE >> level;
        let shape = [BATCH, c, side, side];
        let x = tensor(&shape, &mut seed);
        let grad = tensor(&shape, &mut seed);
        let gamma = tensor(&[c], &mut seed);
        let beta = tensor(&[c], &mut seed);
        assert_eq!(x.dtype(), DType::F32);
        let old = || {
            let (_, m, v) =
                reference::batch_norm_train(x.clone(), gamma.clone(), beta.clone(), 1e-3);
            let _ = reference::batch_norm_train_backward(
                x.clone(),
                gamma.clone(),
                m,
                v,
                1e-3,
                grad.clone(),
            );
        };
        let new = || {
            let (_, m, v) = batch_norm_train(x.clone(), gamma.clone(), beta.clone(), 1e-3);
            let _ = batch_norm_train_backward(x.clone(), gamma.clone(), m, v, 1e-3, grad.clone());
        };
        let (t_old, t_new) = interleaved(&old, &new);
        total_old += t_old * count as f64;
        total_new += t_new * count as f64;
        println!(
            "| {c} | {side}×{side} | {count} | {t_old:.2} | {t_new:.2} | {:.2}× |",
            t_old / t_new
        );
    }
    println!(
        "| TOTAL (× count) | | | {total_old:.1} | {total_new:.1} | {:.2}× |",
        total_old / total_new
    );
}
