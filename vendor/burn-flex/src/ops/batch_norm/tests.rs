//! The fused batch norm against Burn's defaults ([`super::reference`]) and
//! against a direct f64 computation, on listed and seeded random shapes
//! (batch 1 and 8, one and many channels, odd spatial sizes, rank 2, 3 and 4).
//!
//! Tolerances, per tensor, as max |fused − reference| ≤ tol · scale, the
//! scale being max |reference| (for the input gradient at least
//! max |γ·inv_std| · max |g|, the size of its terms: with two values per
//! channel the exact gradient is ~0 and only the terms' size is meaningful):
//! - against f64 (every case, also with a mean offset of 10⁴): 1e-5. The
//!   fused kernels add at most 16 values per f32 lane before flushing into
//!   f64 sums, so what remains is f32 rounding of those partial sums and of
//!   the final map (observed ≤ 1.2e-6, mostly ~1e-7); 1e-5 leaves room for
//!   that without hiding a wrong formula (an error in any term moves results
//!   by ≥ 1e-2).
//! - against the defaults (cases with a mean offset ≤ 5): 1e-5. The defaults
//!   sum in f32 over up to ~8 000 values per channel, whose rounding is of
//!   order 1e-6 relative; with an offset of 10⁴ their own error exceeds that,
//!   which the stability case reports instead of comparing.

extern crate std;

use alloc::vec;
use alloc::vec::Vec;
use burn_backend::DType;
use burn_std::{Bytes, Shape};
use std::println;

use super::{batch_norm, batch_norm_train, batch_norm_train_backward, reference};
use crate::{FlexTensor, Layout};

const EPS: f64 = 1e-5;
const TOL: f64 = 1e-5;

struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    /// Uniform in [lo, hi), on a 1e-4 grid.
    fn vec(&mut self, len: usize, lo: f32, hi: f32) -> Vec<f32> {
        (0..len)
            .map(|_| lo + (hi - lo) * (self.below(10000) as f32 / 10000.0))
            .collect()
    }
}

fn tensor(data: Vec<f32>, shape: &[usize]) -> FlexTensor {
    FlexTensor::new(
        Bytes::from_elems(data),
        Layout::contiguous(Shape::from(shape.to_vec())),
        DType::F32,
    )
}

fn values(t: &FlexTensor) -> Vec<f32> {
    t.to_contiguous().storage::<f32>().to_vec()
}

fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |m, x| m.max(x.abs()))
}

/// max |got − want| / max(max |want|, floor) (absolute when both are zero).
fn rel_err(got: &[f32], want: &[f64], floor: f64) -> f64 {
    assert_eq!(got.len(), want.len());
    let diff = max_abs(got.iter().zip(want).map(|(&g, &w)| g as f64 - w));
    diff / max_abs(want.iter().copied()).max(floor).max(1e-30)
}

fn assert_close(what: &str, case: &Case, got: &[f32], want: &[f64], floor: f64) -> f64 {
    let err = rel_err(got, want, floor);
    assert!(
        err <= TOL,
        "{what} {case:?}: relative error {err:e} > {TOL:e}"
    );
    err
}

fn as_f64(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

/// One input: shape `[n, c, …]` and the mean offset added to every value.
#[derive(Clone, Debug)]
struct Case {
    shape: Vec<usize>,
    offset: f32,
}

struct Inputs {
    x: Vec<f32>,
    gamma: Vec<f32>,
    beta: Vec<f32>,
    grad: Vec<f32>,
}

fn inputs(case: &Case, rng: &mut Lcg) -> Inputs {
    let len: usize = case.shape.iter().product();
    let c = case.shape[1];
    let x = rng.vec(len, -1.0, 1.0);
    Inputs {
        x: x.iter().map(|v| v + case.offset).collect(),
        gamma: rng.vec(c, -1.5, 1.5),
        beta: rng.vec(c, -1.0, 1.0),
        grad: rng.vec(len, -1.0, 1.0),
    }
}

/// `(n, c, s)` and the index of element `(i, ch, j)`.
fn ncs(shape: &[usize]) -> (usize, usize, usize) {
    let s = shape[2..].iter().product();
    (shape[0], shape[1], s)
}

/// f64 batch statistics and output: `(output, mean, variance)`.
fn truth_train(case: &Case, inp: &Inputs) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (n, c, s) = ncs(&case.shape);
    let m = (n * s) as f64;
    let at = |i: usize, ch: usize, j: usize| inp.x[(i * c + ch) * s + j] as f64;
    let mut mean = vec![0.0; c];
    let mut var = vec![0.0; c];
    let mut out = vec![0.0; inp.x.len()];
    for ch in 0..c {
        let idx = || (0..n).flat_map(move |i| (0..s).map(move |j| (i, j)));
        mean[ch] = idx().map(|(i, j)| at(i, ch, j)).sum::<f64>() / m;
        var[ch] = idx()
            .map(|(i, j)| (at(i, ch, j) - mean[ch]).powi(2))
            .sum::<f64>()
            / m;
        let inv = 1.0 / (var[ch] + EPS).sqrt();
        for (i, j) in idx() {
            let norm = (at(i, ch, j) - mean[ch]) * inv;
            out[(i * c + ch) * s + j] = norm * inp.gamma[ch] as f64 + inp.beta[ch] as f64;
        }
    }
    (out, mean, var)
}

/// f64 gradients `(x, gamma, beta)` for the given f32 statistics.
fn truth_backward(case: &Case, inp: &Inputs, mean: &[f32], var: &[f32]) -> [Vec<f64>; 3] {
    let (n, c, s) = ncs(&case.shape);
    let m = (n * s) as f64;
    let mut xg = vec![0.0; inp.x.len()];
    let (mut gg, mut bg) = (vec![0.0; c], vec![0.0; c]);
    for ch in 0..c {
        let inv = 1.0 / (var[ch] as f64 + EPS).sqrt();
        let idx = || (0..n).flat_map(move |i| (0..s).map(move |j| (i * c + ch) * s + j));
        let xhat = |k: usize| (inp.x[k] as f64 - mean[ch] as f64) * inv;
        bg[ch] = idx().map(|k| inp.grad[k] as f64).sum();
        gg[ch] = idx().map(|k| inp.grad[k] as f64 * xhat(k)).sum();
        for k in idx() {
            let g = inp.grad[k] as f64;
            xg[k] = inp.gamma[ch] as f64 * inv * (g - bg[ch] / m - xhat(k) * gg[ch] / m);
        }
    }
    [xg, gg, bg]
}

type Five = [Vec<f32>; 5];

/// Forward and backward through `train`/`backward`, as f32 vectors:
/// `[output, mean, variance]` and the three gradients (reusing `[2..5]`).
fn run(case: &Case, inp: &Inputs, fused: bool) -> (Five, Vec<f32>) {
    let t = |v: &Vec<f32>, s: &[usize]| tensor(v.clone(), s);
    let (x, c) = (t(&inp.x, &case.shape), [case.shape[1]]);
    let (gamma, beta) = (t(&inp.gamma, &c), t(&inp.beta, &c));
    let (out, mean, var) = if fused {
        batch_norm_train(x.clone(), gamma.clone(), beta, EPS)
    } else {
        reference::batch_norm_train(x.clone(), gamma.clone(), beta, EPS)
    };
    let grad = t(&inp.grad, &case.shape);
    let (m, v) = (mean.clone(), var.clone());
    let (xg, gg, bg) = if fused {
        batch_norm_train_backward(x, gamma, m, v, EPS, grad)
    } else {
        reference::batch_norm_train_backward(x, gamma, m, v, EPS, grad)
    };
    let fwd = [&out, &mean, &var, &gg, &bg].map(values);
    (fwd, values(&xg))
}

/// Checks one case; returns the fused and default errors against f64 (max over tensors).
fn check(case: &Case, seed: u64) -> (f64, f64) {
    let inp = inputs(case, &mut Lcg(seed));
    let ([out, mean, var, gg, bg], xg) = run(case, &inp, true);
    let (t_out, t_mean, t_var) = truth_train(case, &inp);
    let [t_xg, t_gg, t_bg] = truth_backward(case, &inp, &mean, &var);
    let xg_floor =
        max_abs((0..inp.gamma.len()).map(|c| inp.gamma[c] as f64 / (var[c] as f64 + EPS).sqrt()))
            * max_abs(inp.grad.iter().map(|&g| g as f64));
    let floors = [0.0, 0.0, 0.0, xg_floor, 0.0, 0.0];
    let names = [
        "output",
        "mean",
        "variance",
        "x_grad",
        "gamma_grad",
        "beta_grad",
    ];
    let mut fused_err = 0.0f64;
    let fused = [&out, &mean, &var, &xg, &gg, &bg];
    let truth = [&t_out, &t_mean, &t_var, &t_xg, &t_gg, &t_bg];
    for i in 0..6 {
        let err = assert_close(names[i], case, fused[i], truth[i], floors[i]);
        fused_err = fused_err.max(err);
    }

    let ([d_out, d_mean, d_var, d_gg, d_bg], d_xg) = run(case, &inp, false);
    let default = [&d_out, &d_mean, &d_var, &d_xg, &d_gg, &d_bg];
    let mut default_err = 0.0f64;
    for i in 0..6 {
        default_err = default_err.max(rel_err(default[i], truth[i], floors[i]));
        if case.offset.abs() <= 5.0 {
            let err = rel_err(fused[i], &as_f64(default[i]), floors[i]);
            let name = names[i];
            assert!(
                err <= TOL,
                "{name} {case:?}: fused vs default {err:e} > {TOL:e}"
            );
        }
    }
    (fused_err, default_err)
}

fn listed() -> Vec<Case> {
    let shapes: [&[usize]; 9] = [
        &[1, 1, 5, 7],
        &[8, 1, 33, 29],
        &[8, 16, 7, 9],
        &[1, 64, 13, 11],
        &[8, 32, 28, 28],
        &[2, 3, 1, 1],
        &[8, 5, 33],
        &[1, 7, 1],
        &[8, 12],
    ];
    shapes
        .iter()
        .flat_map(|s| {
            [0.0, 5.0, 1.0e4].map(|offset| Case {
                shape: s.to_vec(),
                offset,
            })
        })
        .collect()
}

#[test]
fn fused_matches_default_and_f64_on_listed_shapes() {
    for (i, case) in listed().iter().enumerate() {
        let (fused, default) = check(case, 1000 + i as u64);
        println!("{case:?}: fused {fused:.2e}, default {default:.2e} (relative to f64)");
    }
}

#[test]
fn fused_matches_default_and_f64_on_random_shapes() {
    let mut rng = Lcg(37);
    for i in 0..40 {
        let n = [1, 8][rng.below(2)];
        let c = 1 + rng.below(40);
        let mut shape = vec![n, c, 1 + rng.below(20)];
        if rng.below(3) > 0 {
            shape.push(1 + rng.below(20));
        }
        let offset = [0.0, 3.0, -2.0e3][rng.below(3)];
        check(&Case { shape, offset }, 2000 + i);
    }
}

#[test]
fn inference_matches_default_and_f64() {
    let mut rng = Lcg(7);
    for shape in [&[8usize, 16, 9, 7][..], &[1, 3, 5], &[4, 6]] {
        let c = shape[1];
        let len: usize = shape.iter().product();
        let x = rng.vec(len, -3.0, 3.0);
        let stats = [rng.vec(c, -1.0, 1.0), rng.vec(c, 0.1, 2.0)];
        let (gamma, beta) = (rng.vec(c, -1.5, 1.5), rng.vec(c, -1.0, 1.0));
        let args = || {
            let t = |v: &Vec<f32>| tensor(v.clone(), &[c]);
            let x = tensor(x.clone(), shape);
            (x, t(&gamma), t(&beta), t(&stats[0]), t(&stats[1]))
        };
        let (a, g, b, m, v) = args();
        let fused = values(&batch_norm(a, g, b, m, v, EPS));
        let (a, g, b, m, v) = args();
        let default = values(&reference::batch_norm(a, g, b, m, v, EPS));
        let s: usize = shape[2..].iter().product();
        let truth: Vec<f64> = (0..len)
            .map(|k| {
                let ch = (k / s) % c;
                let inv = 1.0 / (stats[1][ch] as f64 + EPS).sqrt();
                (x[k] as f64 - stats[0][ch] as f64) * inv * gamma[ch] as f64 + beta[ch] as f64
            })
            .collect();
        let case = Case {
            shape: shape.to_vec(),
            offset: 0.0,
        };
        assert_close("inference output", &case, &fused, &truth, 0.0);
        assert_close(
            "inference vs default",
            &case,
            &fused,
            &as_f64(&default),
            0.0,
        );
    }
}

/// A transposed (non-contiguous) input gives bit-for-bit the contiguous result.
#[test]
fn non_contiguous_input_matches_contiguous() {
    let mut rng = Lcg(11);
    let (n, c, h, w) = (8, 5, 7, 3);
    let data = rng.vec(n * c * h * w, -2.0, 2.0);
    // Stored as [c, n, h, w]; viewed as [n, c, h, w].
    let view = tensor(data, &[c, n, h, w]).transpose(0, 1);
    assert!(!view.is_contiguous());
    let dense = view.to_contiguous();
    let (gamma, beta) = (
        tensor(rng.vec(c, 0.5, 1.5), &[c]),
        tensor(rng.vec(c, -1.0, 1.0), &[c]),
    );
    let (a, am, av) = batch_norm_train(view, gamma.clone(), beta.clone(), EPS);
    let (b, bm, bv) = batch_norm_train(dense, gamma, beta, EPS);
    assert_eq!(values(&a), values(&b));
    assert_eq!(values(&am), values(&bm));
    assert_eq!(values(&av), values(&bv));
}

/// Writing the input gradient into the output gradient's own buffer (when it
/// is not shared) gives the same bits as writing a new buffer.
#[test]
fn in_place_and_fresh_buffers_agree() {
    let case = Case {
        shape: vec![8, 4, 9, 9],
        offset: 0.5,
    };
    let inp = inputs(&case, &mut Lcg(5));
    let x = tensor(inp.x.clone(), &case.shape);
    let gamma = tensor(inp.gamma.clone(), &[4]);
    let beta = tensor(inp.beta.clone(), &[4]);
    let (out_unique, m, v) = batch_norm_train(x.clone(), gamma.clone(), beta.clone(), EPS);
    let x_unique = tensor(inp.x.clone(), &case.shape);
    let (out_fresh, _, _) = batch_norm_train(x_unique, gamma.clone(), beta, EPS);
    assert_eq!(values(&out_unique), values(&out_fresh));
    let grad = tensor(inp.grad.clone(), &case.shape);
    let held = grad.clone();
    let (shared, _, _) =
        batch_norm_train_backward(x.clone(), gamma.clone(), m.clone(), v.clone(), EPS, grad);
    let unique = tensor(inp.grad.clone(), &case.shape);
    let (owned, _, _) = batch_norm_train_backward(x, gamma, m, v, EPS, unique);
    assert_eq!(values(&shared), values(&owned));
    assert_eq!(
        values(&held),
        inp.grad,
        "a shared output gradient must not be overwritten"
    );
}

/// Partial sums are combined in a fixed order: 1 and 3 threads agree bit for bit.
#[cfg(feature = "rayon")]
#[test]
fn results_do_not_depend_on_thread_count() {
    let case = Case {
        shape: vec![8, 8, 32, 33],
        offset: 2.0,
    };
    let inp = inputs(&case, &mut Lcg(3));
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| run(&case, &inp, true))
    };
    let (a, axg) = on(1);
    let (b, bxg) = on(3);
    assert_eq!(a, b);
    assert_eq!(axg, bxg);
}

#[test]
fn f64_tensors_take_the_default_path() {
    let x = FlexTensor::from_data(burn_backend::TensorData::new(
        vec![1.0f64, 2.0, 4.0, 8.0, -1.0, 0.0],
        [3, 2],
    ));
    let gamma = FlexTensor::from_data(burn_backend::TensorData::new(vec![1.0f64, 2.0], [2]));
    let beta = FlexTensor::from_data(burn_backend::TensorData::new(vec![0.0f64, 1.0], [2]));
    let (out, mean, var) = batch_norm_train(x, gamma, beta, 0.0);
    assert_eq!(out.dtype(), DType::F64);
    let mean: Vec<f64> = mean.into_data().try_to_vec::<f64>().unwrap();
    let var: Vec<f64> = var.into_data().try_to_vec::<f64>().unwrap();
    let out: Vec<f64> = out.into_data().try_to_vec::<f64>().unwrap();
    // Channel 0: 1, 4, -1 → mean 4/3; channel 1: 2, 8, 0 → mean 10/3.
    assert!((mean[0] - 4.0 / 3.0).abs() < 1e-12 && (mean[1] - 10.0 / 3.0).abs() < 1e-12);
    let var0 = [1.0f64, 4.0, -1.0]
        .iter()
        .map(|v| (v - 4.0 / 3.0).powi(2))
        .sum::<f64>()
        / 3.0;
    assert!((var[0] - var0).abs() < 1e-12);
    assert!((out[0] - (1.0 - 4.0 / 3.0) / var0.sqrt()).abs() < 1e-12);
}

#[test]
#[should_panic(
    expected = "batch_norm_train: gamma must have shape [4] (the input's channels), got Shape { dims: [3] }"
)]
fn wrong_gamma_length_names_the_shapes() {
    let x = tensor(vec![0.0; 2 * 4 * 3], &[2, 4, 3]);
    let gamma = tensor(vec![1.0; 3], &[3]);
    let beta = tensor(vec![0.0; 4], &[4]);
    let _ = batch_norm_train(x, gamma, beta, EPS);
}

#[test]
#[should_panic(expected = "batch_norm_train_backward: output_grad must have the input's shape")]
fn wrong_gradient_shape_is_rejected() {
    let x = tensor(vec![0.0; 8], &[2, 4]);
    let c = || tensor(vec![1.0; 4], &[4]);
    let grad = tensor(vec![0.0; 8], &[4, 2]);
    let _ = batch_norm_train_backward(x, c(), c(), c(), EPS, grad);
}
