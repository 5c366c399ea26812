//! Side-by-side timing of the f32 sigmoid forward and its gradient, upstream's
//! scalar closures (libm `expf` per element; the gradient through the generic
//! binary op) against this module's kernels, on YOLO11n-seg's SiLU shapes at
//! batch 8 and 224 px (the output side of the Conv blocks listed in
//! `batch_norm::bench`, each conv + BN + SiLU). The forward gets a shared
//! input as SiLU's `x · sigmoid(x)` does (so both sides allocate), the
//! gradient a unique one as autodiff hands it over. Ignored by default; run
//! with `RAYON_NUM_THREADS=1 cargo test --release --lib sigmoid::bench --
//! --ignored --nocapture`. Old and new alternate; medians of `REPEATS`.

extern crate std;

use alloc::vec::Vec;
use burn_backend::TensorData;
use std::println;
use std::time::Instant;

use crate::FlexTensor;
use crate::ops::binary::binary_op;
use crate::ops::unary::unary_op;

const REPEATS: usize = 11;
const BATCH: usize = 8;
const IMAGE: usize = 224;

/// (channels, level, count) as in `batch_norm::bench::SHAPES`.
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

/// Upstream's f32 sigmoid (`activation.rs` before this patch).
fn upstream_sigmoid(x: f32) -> f32 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

fn tensor(shape: &[usize], seed: &mut u64, scale: f32) -> FlexTensor {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (((*seed >> 40) as f32 / (1u64 << 24) as f32) - 0.5) * scale
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
fn bench_sigmoid_yolo11n_224_batch8() {
    let mut seed = 37u64;
    println!(
        "sigmoid f32, batch {BATCH}, {IMAGE} px, {} thread(s)",
        threads()
    );
    println!(
        "| channels | size | count | fwd upstream ms | fwd new ms | ratio | bwd upstream ms | bwd new ms | ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut totals = [0.0f64; 4];
    for (c, level, count) in SHAPES {
        let side = IMAGE >> level;
        let shape = [BATCH, c, side, side];
        let x = tensor(&shape, &mut seed, 12.0);
        let s = super::sigmoid(x.clone());
        let g = tensor(&shape, &mut seed, 1.0);
        let g_values: Vec<f32> = g.storage::<f32>().to_vec();
        let unique_g = || FlexTensor::from_data(TensorData::new(g_values.clone(), shape.to_vec()));
        let (f_old, f_new) = interleaved(
            &|| drop(unary_op(x.clone(), upstream_sigmoid, |v: f64| v)),
            &|| drop(super::sigmoid(x.clone())),
        );
        // A unique gradient each time (a copy), as autodiff hands it over;
        // both sides pay for the same copy.
        let (b_old, b_new) = interleaved(
            &|| {
                let g = unique_g();
                drop(binary_op(
                    s.clone(),
                    g,
                    |s, g| g * s * (1.0 - s),
                    |s, g| g * s * (1.0 - s),
                    None,
                ))
            },
            &|| {
                let g = unique_g();
                drop(super::sigmoid_backward(s.clone(), g).ok().expect("fused"))
            },
        );
        for (t, v) in totals.iter_mut().zip([f_old, f_new, b_old, b_new]) {
            *t += v * count as f64;
        }
        println!(
            "| {c} | {side}×{side} | {count} | {f_old:.3} | {f_new:.3} | {:.2}× | {b_old:.3} | {b_new:.3} | {:.2}× |",
            f_old / f_new,
            b_old / b_new
        );
    }
    let [fo, fnew, bo, bnew] = totals;
    println!(
        "| TOTAL (× count) | | | {fo:.1} | {fnew:.1} | {:.2}× | {bo:.1} | {bnew:.1} | {:.2}× |",
        fo / fnew,
        bo / bnew
    );
}

fn threads() -> usize {
    #[cfg(feature = "rayon")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "rayon"))]
    {
        1
    }
}

/// Patch 13's AVX-512 clone against the AVX2 one and the baseline build: the
/// SiLU loop on one thread over a 64-channel 32×32 tile (256 KiB, in L2, as
/// the convolution epilogue sees its rows), clones interleaved, medians of 31.
/// `cargo test --release --lib sigmoid::bench::bench_silu_clones -- --ignored --nocapture`
#[cfg(target_arch = "x86_64")]
#[test]
#[ignore = "timing; run with --ignored --nocapture"]
fn bench_silu_clones() {
    use super::kernels::dispatch::unary_inplace_with_clone;
    use super::kernels::silu_f32;
    let mut seed = 7u64;
    let src = tensor(&[64, 32, 32], &mut seed, 8.0);
    let src: Vec<f32> = src.storage::<f32>().to_vec();
    let clones = ["baseline", "avx2", "avx512"];
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); clones.len()];
    let mut buf = src.clone();
    for _ in 0..31 {
        for (i, c) in clones.iter().enumerate() {
            buf.copy_from_slice(&src);
            let t = Instant::now();
            for _ in 0..20 {
                if !unary_inplace_with_clone(core::hint::black_box(&mut buf), c, silu_f32) {
                    break;
                }
            }
            times[i].push(t.elapsed().as_secs_f64() / 20.0);
        }
    }
    for (c, mut t) in clones.iter().zip(times) {
        t.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let med = t[t.len() / 2];
        println!(
            "silu {c:>8}: {:8.1} µs per {} elements, {:.2} ns/element",
            med * 1e6,
            src.len(),
            med * 1e9 / src.len() as f64
        );
    }
}
