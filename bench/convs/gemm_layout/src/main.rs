//! One thread, median of 200 calls per case: the convolution engine's three GEMMs as
//! `vendor/burn-flex/src/ops/conv_engine` makes them, for one tile of `n` output pixels
//! of a layer with `c_out` filters of `k = 9·c_in` taps.
use gemm::{gemm, Parallelism};
use std::time::Instant;

const REPS: usize = 200;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time(f: &mut dyn FnMut()) -> f64 {
    f();
    median((0..REPS).map(|_| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64()
    }).collect())
}

fn main() {
    println!("avx512f: {}", is_x86_feature_detected!("avx512f"));
    println!("| c_out | k | n | forward | input grad | weight grad, stride n | weight grad, stride n + 16 | padded ÷ contiguous |");
    println!("|---|---|---|---|---|---|---|---|");
    let shapes = [(16usize, 144usize, 512usize), (32, 288, 512), (64, 576, 512), (64, 576, 256), (128, 1152, 256), (256, 1152, 64), (32, 576, 512), (64, 144, 2048), (64, 576, 480)];
    for (co, k, n) in shapes {
        let gflop = 2.0 * (co * k * n) as f64 / 1e9;
        let w = vec![0.01f32; co * k];
        let dy = vec![0.1f32; co * n];
        let mut out = vec![0f32; co * n];
        let mut dw = vec![0f32; co * k];
        // forward: out[co, n] += W[co, k] · panel[k, n]
        let panel = vec![0.5f32; k * n];
        let fwd = time(&mut || unsafe {
            gemm(co, n, k, out.as_mut_ptr(), 1, n as isize, true, w.as_ptr(), 1, k as isize,
                 panel.as_ptr(), 1, n as isize, 1.0, 1.0, false, false, false, Parallelism::None)
        });
        // input gradient: panel[k, n] = Wᵀ[k, co] · dY[co, n]
        let mut pan = vec![0f32; k * n];
        let xg = time(&mut || unsafe {
            gemm(k, n, co, pan.as_mut_ptr(), 1, n as isize, false, w.as_ptr(), k as isize, 1,
                 dy.as_ptr(), 1, n as isize, 1.0, 1.0, false, false, false, Parallelism::None)
        });
        // weight gradient: dW[co, k] += dY[co, n] · panelᵀ[n, k], panel rows at stride ld
        let mut wg = |ld: usize| {
            let p = vec![0.5f32; k * ld];
            time(&mut || unsafe {
                gemm(co, k, n, dw.as_mut_ptr(), 1, k as isize, true, dy.as_ptr(), 1, n as isize,
                     p.as_ptr(), ld as isize, 1, 1.0, 1.0, false, false, false, Parallelism::None)
            })
        };
        let (a, b) = (wg(n), wg(n + 16));
        println!("| {co} | {k} | {n} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} |",
                 gflop / fwd, gflop / xg, gflop / a, gflop / b, a / b);
    }
}
