//! The polynomial `exp` and the sigmoid against f64 on dense sweeps and at
//! special values; the dispatched slice kernels against the scalar formula
//! bit for bit (so the AVX2 clone and the baseline build agree); the tensor
//! entry points over every layout path, in place and allocating, and on
//! one versus three threads; the gradient against upstream's formula.

extern crate std;

use alloc::vec;
use alloc::vec::Vec;
use burn_backend::DType;
use burn_std::{Bytes, Shape};

use super::exp::exp_f32;
use super::kernels::{self, sigmoid_f32};
use super::{sigmoid, sigmoid_backward};
use crate::{FlexTensor, Layout};

/// Every `step`-th f32 bit pattern with a value in `[lo, hi]`, both signs.
fn sweep(lo: f32, hi: f32, step: u32) -> impl Iterator<Item = f32> {
    (0..=u32::MAX / step)
        .map(move |i| f32::from_bits(i * step))
        .filter(move |x| *x >= lo && *x <= hi)
}

/// One ulp at `v`'s magnitude (the gap to the next f32 away from zero).
fn ulp(v: f64) -> f64 {
    let f = (v.abs() as f32).max(f32::MIN_POSITIVE);
    (f32::from_bits(f.to_bits() + 1) - f) as f64
}

/// Largest error of `f` against `reference` in ulps over normal results,
/// and the largest absolute error over subnormal results.
fn max_errors(
    xs: impl Iterator<Item = f32>,
    f: fn(f32) -> f32,
    reference: fn(f64) -> f64,
) -> (f64, f64) {
    let (mut ulps, mut sub) = (0f64, 0f64);
    for x in xs {
        let (got, want) = (f(x) as f64, reference(x as f64));
        if want > f32::MAX as f64 {
            assert_eq!(got, f64::INFINITY, "x = {x:e}: want overflow");
        } else if want >= f32::MIN_POSITIVE as f64 {
            ulps = ulps.max((got - want).abs() / ulp(want));
        } else {
            sub = sub.max((got - want).abs());
        }
    }
    (ulps, sub)
}

fn sigmoid_f64(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

#[test]
fn exp_within_two_ulp_over_the_whole_range() {
    let (ulps, sub) = max_errors(sweep(-110.0, 90.0, 251), exp_f32, f64::exp);
    std::println!("exp: max {ulps:.3} ulp (normal), {sub:e} (subnormal)");
    assert!(ulps <= 2.0, "exp: {ulps} ulp");
    assert!(
        sub <= 2.0 * f32::from_bits(1) as f64,
        "exp subnormal error {sub:e}"
    );
}

#[test]
fn exp_special_values() {
    assert_eq!(exp_f32(0.0), 1.0);
    assert_eq!(exp_f32(-0.0), 1.0);
    assert_eq!(exp_f32(f32::INFINITY), f32::INFINITY);
    assert_eq!(exp_f32(f32::NEG_INFINITY), 0.0);
    assert!(exp_f32(f32::NAN).is_nan());
    assert!(exp_f32(-f32::NAN).is_nan());
    assert_eq!(exp_f32(f32::MAX), f32::INFINITY);
    assert_eq!(exp_f32(f32::MIN), 0.0);
    // Around ln(f32::MAX) = 88.72283905…: the largest finite result, then +inf.
    assert!(exp_f32(88.722_83).is_finite());
    assert_eq!(exp_f32(88.722_84), f32::INFINITY);
    assert_eq!(exp_f32(88.0).to_bits(), (88f64.exp() as f32).to_bits());
    // Gradual underflow down to the smallest subnormal, then zero.
    let tiny = exp_f32(-103.0);
    assert!(tiny > 0.0 && tiny < f32::MIN_POSITIVE, "{tiny:e}");
    assert!(exp_f32(-87.3) >= f32::MIN_POSITIVE, "e^-87.3 is normal");
    assert_eq!(exp_f32(-104.5), 0.0);
}

#[test]
fn sigmoid_within_1e6_of_f64_and_3_ulp_for_normal_results() {
    let xs = || sweep(-120.0, 120.0, 199);
    let (ulps, sub) = max_errors(xs(), sigmoid_f32, sigmoid_f64);
    std::println!("sigmoid: max {ulps:.3} ulp (normal), {sub:e} (subnormal)");
    assert!(ulps <= 3.0, "sigmoid: {ulps} ulp");
    assert!(sub <= 2.0 * f32::from_bits(1) as f64);
    for x in xs() {
        let (got, want) = (sigmoid_f32(x) as f64, sigmoid_f64(x as f64));
        assert!(
            (got - want).abs() <= 1e-6 * want.max(1e-30),
            "x = {x:e}: {got} vs {want}"
        );
    }
}

#[test]
fn sigmoid_special_values() {
    assert_eq!(sigmoid_f32(0.0), 0.5);
    assert_eq!(sigmoid_f32(-0.0), 0.5);
    assert_eq!(sigmoid_f32(f32::INFINITY), 1.0);
    assert_eq!(sigmoid_f32(f32::NEG_INFINITY), 0.0);
    assert_eq!(sigmoid_f32(100.0), 1.0);
    assert!(
        sigmoid_f32(-100.0) > 0.0,
        "sigmoid(-100) = 3.7e-44 is a subnormal, not 0"
    );
    assert!(sigmoid_f32(f32::NAN).is_nan());
    assert!(sigmoid_f32(-f32::NAN).is_nan());
}

fn values(n: usize) -> Vec<f32> {
    // Deterministic, spread over [-30, 30] with some specials mixed in.
    let mut v: Vec<f32> = (0..n)
        .map(|i| ((i as f32 * 0.618_034).fract() - 0.5) * 60.0)
        .collect();
    for (i, s) in [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        0.0,
        -0.0,
        90.0,
        -110.0,
    ]
    .into_iter()
    .enumerate()
    {
        v[i * 3] = s;
    }
    v
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn slice_kernels_match_the_scalar_formula_bit_for_bit() {
    // Odd lengths: vector body plus scalar tail; the AVX2 clone runs here
    // on CPUs that have it, the scalar calls below are baseline code.
    for n in [1, 7, 8, 9, 33, 1000, 70_001] {
        let v = values(n.max(21))[..n].to_vec();
        let want: Vec<f32> = v.iter().map(|&x| sigmoid_f32(x)).collect();
        let mut inplace = v.clone();
        kernels::sigmoid_inplace(&mut inplace);
        assert_eq!(bits(&inplace), bits(&want), "in place, n = {n}");
        let mut out = Vec::with_capacity(n);
        kernels::sigmoid_into(&v, &mut out.spare_capacity_mut()[..n]);
        // SAFETY: sigmoid_into wrote all n elements.
        unsafe { out.set_len(n) };
        assert_eq!(bits(&out), bits(&want), "into, n = {n}");
        let g: Vec<f32> = v.iter().map(|x| x.sin()).collect();
        let s = want;
        let want_g: Vec<f32> = s.iter().zip(&g).map(|(&s, &g)| g * s * (1.0 - s)).collect();
        let mut into_g = g.clone();
        kernels::sigmoid_backward_into_grad(&s, &mut into_g);
        assert_eq!(bits(&into_g), bits(&want_g), "backward into grad, n = {n}");
        let mut into_s = s.clone();
        kernels::sigmoid_backward_into_output(&mut into_s, &g);
        assert_eq!(
            bits(&into_s),
            bits(&want_g),
            "backward into output, n = {n}"
        );
    }
}

fn tensor(data: Vec<f32>, shape: &[usize]) -> FlexTensor {
    FlexTensor::new(
        Bytes::from_elems(data),
        Layout::contiguous(Shape::from(shape.to_vec())),
        DType::F32,
    )
}

/// The tensor's elements in logical (row-major) order.
fn logical(t: &FlexTensor) -> Vec<u32> {
    bits(t.to_contiguous().storage::<f32>())
}

#[test]
fn tensor_sigmoid_over_every_layout_path() {
    let shape = [3, 5, 7, 11];
    let v = values(3 * 5 * 7 * 11);
    let want = |t: &FlexTensor| -> Vec<u32> {
        let c = t.to_contiguous();
        bits(
            &c.storage::<f32>()
                .iter()
                .map(|&x| sigmoid_f32(x))
                .collect::<Vec<_>>(),
        )
    };
    // Unique contiguous: in place, same buffer.
    let x = tensor(v.clone(), &shape);
    let expect = want(&x);
    let ptr = x.storage::<f32>().as_ptr();
    let y = sigmoid(x);
    assert_eq!(y.storage::<f32>().as_ptr(), ptr, "unique input is reused");
    assert_eq!(logical(&y), expect);
    // Shared contiguous (SiLU's case): allocating, the input untouched.
    let x = tensor(v.clone(), &shape);
    let y = sigmoid(x.clone());
    assert_eq!(logical(&y), expect);
    assert_eq!(bits(x.storage::<f32>()), bits(&v));
    // Offset view, permuted views (shared and unique), a strided narrow.
    let views = [
        x.narrow(0, 1, 2),
        x.transpose(1, 3),
        x.permute(&[2, 0, 3, 1]),
        x.narrow(3, 2, 5),
    ];
    for view in views {
        let expect = want(&view);
        assert_eq!(logical(&sigmoid(view.clone())), expect);
        let unique = tensor(v.clone(), &shape).transpose(1, 3);
        let expect_unique = want(&unique);
        assert_eq!(logical(&sigmoid(unique)), expect_unique);
    }
}

#[cfg(feature = "rayon")]
#[test]
fn tensor_sigmoid_does_not_depend_on_thread_count() {
    let v = values(8 * 16 * 56 * 56);
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        let x = tensor(v.clone(), &[8, 16, 56, 56]);
        pool.install(|| (logical(&sigmoid(x.clone())), logical(&sigmoid(x))))
    };
    assert_eq!(on(1), on(3));
}

#[test]
fn tensor_sigmoid_backward_in_place_or_declined() {
    let v = values(2 * 3 * 9);
    let s: Vec<f32> = v.iter().map(|&x| sigmoid_f32(x)).collect();
    let g: Vec<f32> = v.iter().map(|x| x.cos()).collect();
    let want: Vec<u32> = bits(
        &s.iter()
            .zip(&g)
            .map(|(&s, &g)| g * s * (1.0 - s))
            .collect::<Vec<_>>(),
    );
    let shape = [2, 3, 9];
    // Unique gradient: written in its buffer.
    let grad = tensor(g.clone(), &shape);
    let ptr = grad.storage::<f32>().as_ptr();
    let out = sigmoid_backward(tensor(s.clone(), &shape), grad)
        .ok()
        .expect("fused");
    assert_eq!(out.storage::<f32>().as_ptr(), ptr);
    assert_eq!(logical(&out), want);
    // Shared gradient, unique output: written in the output's buffer.
    let grad = tensor(g.clone(), &shape);
    let out = sigmoid_backward(tensor(s.clone(), &shape), grad.clone())
        .ok()
        .expect("fused");
    assert_eq!(logical(&out), want);
    assert_eq!(bits(grad.storage::<f32>()), bits(&g));
    // Both shared, a view, or a broadcast shape: declined, inputs handed back.
    let (so, go) = (tensor(s.clone(), &shape), tensor(g.clone(), &shape));
    assert!(sigmoid_backward(so.clone(), go.clone()).is_err());
    assert!(sigmoid_backward(so.transpose(0, 2), go.transpose(0, 2)).is_err());
    let row = tensor(g[..9].to_vec(), &[1, 1, 9]);
    let (s_back, g_back) = sigmoid_backward(so, row).err().expect("declined");
    assert_eq!(s_back.layout().shape(), &Shape::from(vec![2, 3, 9]));
    assert_eq!(g_back.layout().shape(), &Shape::from(vec![1, 1, 9]));
}

#[test]
fn backend_hooks_route_f32_here_and_keep_upstream_for_f64() {
    use burn_backend::ops::ActivationOps;
    let v = values(64);
    let y = <crate::Flex as ActivationOps<crate::Flex>>::sigmoid(tensor(v.clone(), &[64]));
    let want: Vec<f32> = v.iter().map(|&x| sigmoid_f32(x)).collect();
    assert_eq!(logical(&y), bits(&want));
    let v64: Vec<f64> = (0..64).map(|i| i as f64 / 4.0 - 8.0).collect();
    let x64 = FlexTensor::new(
        Bytes::from_elems(v64.clone()),
        Layout::contiguous(Shape::from(vec![64])),
        DType::F64,
    );
    let y64 = <crate::Flex as ActivationOps<crate::Flex>>::sigmoid(x64);
    for (&got, &x) in y64.storage::<f64>().iter().zip(&v64) {
        assert!((got - sigmoid_f64(x)).abs() <= 1e-15, "{x}: {got}");
    }
    // The gradient hook, including a broadcast gradient (upstream's path).
    let s = tensor(want.clone(), &[8, 8]);
    let g = tensor(vec![2.0; 8], &[1, 8]);
    let dx = <crate::Flex as ActivationOps<crate::Flex>>::sigmoid_backward(s, g);
    let got = dx.to_contiguous().storage::<f32>().to_vec();
    for (i, &d) in got.iter().enumerate() {
        let s = want[i];
        assert_eq!(d.to_bits(), (2.0 * s * (1.0 - s)).to_bits(), "element {i}");
    }
}

/// Patch 13: every clone this CPU has (AVX-512, AVX2), and the dispatch that
/// picks the widest, gives the baseline build's bits for the sigmoid and SiLU
/// slice kernels, on a sweep over ±120 plus the special values, at lengths that
/// leave a remainder after every vector width.
#[test]
fn every_clone_gives_the_baseline_bits() {
    let mut xs: Vec<f32> = sweep(-120.0, 120.0, 997).collect();
    xs.extend([
        0.0,
        -0.0,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
        88.72,
        -103.9,
    ]);
    for len in [xs.len(), 1, 7, 15, 17, 33] {
        let src = &xs[..len];
        for (name, f) in [
            ("sigmoid", sigmoid_f32 as fn(f32) -> f32),
            ("silu", kernels::silu_f32 as fn(f32) -> f32),
        ] {
            let mut want = src.to_vec();
            assert!(kernels::dispatch::unary_inplace_with_clone(
                &mut want, "baseline", f
            ));
            let want = bits(&want);
            for clone in ["avx2", "avx512"] {
                let mut got = src.to_vec();
                if kernels::dispatch::unary_inplace_with_clone(&mut got, clone, f) {
                    assert_eq!(bits(&got), want, "{name} {clone} clone, len {len}");
                }
            }
            let mut got = src.to_vec();
            if name == "sigmoid" {
                kernels::sigmoid_inplace(&mut got);
            } else {
                kernels::silu_inplace(&mut got);
                let mut serial = src.to_vec();
                kernels::silu_inplace_serial(&mut serial);
                assert_eq!(bits(&serial), want, "silu_inplace_serial, len {len}");
            }
            assert_eq!(bits(&got), want, "{name} through the dispatch, len {len}");
        }
    }
}
