//! Fused batch normalization for Flex (chicktrain issue 37): `batch_norm`
//! (given statistics), `batch_norm_train` (batch statistics) and
//! `batch_norm_train_backward`, which `ModuleOps` for Flex sends here.
//!
//! Why: Burn 0.22.1's defaults build these out of tensor ops — two
//! `swap_dims` copies and a `mean_dim` per statistic, and one full pass per
//! subtraction, division, multiplication and addition — about a dozen passes
//! over the activation forward and backward. In a YOLO11 training step on
//! flex that was ~12 % of all samples. Here each `(sample, channel)` block of
//! an NCHW tensor is contiguous, so the statistics are one pass of per-channel
//! sums (f32 lanes flushed into f64 every 256 values, shifted by the channel's
//! first value so a large mean does not cancel the variance), the normalisation one pass, and the backward one pass
//! for `Σ g` and `Σ g·x̂` and one for the input gradient (in place in the
//! output gradient's buffer when nothing else holds it).
//!
//! What it takes: f32 tensors of rank ≥ 2, `[batch, channels, …]`, any
//! layout (a non-contiguous input is copied once). Other dtypes and empty
//! tensors go through [`reference`], upstream's defaults written out.
//! Not bit-identical to the defaults (different summation order and f64
//! statistics); the tests bound the difference.

#[cfg(all(test, feature = "rayon"))]
mod bench;
mod kernels;
pub mod reference;
#[cfg(test)]
mod tests;

use alloc::vec::Vec;
use burn_backend::DType;
use burn_std::{Bytes, Shape};

use crate::{FlexTensor, Layout};
use kernels::{Affine, Dims};

/// Panics, naming `op` and the shapes, unless `x` is `[batch, channels, …]`
/// and every per-channel tensor is `[channels]`.
fn check_shapes(op: &str, x: &FlexTensor, per_channel: &[(&str, &FlexTensor)]) {
    let shape = x.layout().shape();
    assert!(
        shape.num_dims() >= 2,
        "{op}: input must be [batch, channels, ...], got shape {shape:?}"
    );
    for (name, t) in per_channel {
        let s = t.layout().shape();
        assert!(
            s.num_dims() == 1 && s[0] == shape[1],
            "{op}: {name} must have shape [{}] (the input's channels), got {s:?}",
            shape[1]
        );
    }
}

/// `Some(dims)` when the fused f32 kernels take these tensors.
fn fused_dims(x: &FlexTensor, others: &[&FlexTensor]) -> Option<Dims> {
    let shape = x.layout().shape();
    let f32s = x.dtype() == DType::F32 && others.iter().all(|t| t.dtype() == DType::F32);
    if !f32s || shape.num_elements() == 0 {
        return None;
    }
    Some(Dims {
        n: shape[0],
        c: shape[1],
        s: shape.num_elements() / (shape[0] * shape[1]),
    })
}

fn f32_values(t: FlexTensor) -> Vec<f32> {
    t.into_contiguous().storage::<f32>().to_vec()
}

fn f32_tensor(values: Vec<f32>) -> FlexTensor {
    let shape = Shape::new([values.len()]);
    FlexTensor::new(
        Bytes::from_elems(values),
        Layout::contiguous(shape),
        DType::F32,
    )
}

/// `1 / sqrt(var + ε)` in f64.
fn inv_std(variance: f64, epsilon: f64) -> f64 {
    1.0 / libm::sqrt(variance + epsilon)
}

/// `(x − mean) / sqrt(var + ε) · γ + β` with the given per-channel statistics.
pub fn batch_norm(
    x: FlexTensor,
    gamma: FlexTensor,
    beta: FlexTensor,
    mean: FlexTensor,
    variance: FlexTensor,
    epsilon: f64,
) -> FlexTensor {
    let named = [
        ("gamma", &gamma),
        ("beta", &beta),
        ("mean", &mean),
        ("variance", &variance),
    ];
    check_shapes("batch_norm", &x, &named);
    let Some(d) = fused_dims(&x, &[&gamma, &beta, &mean, &variance]) else {
        return reference::batch_norm(x, gamma, beta, mean, variance, epsilon);
    };
    let (gamma, beta) = (f32_values(gamma), f32_values(beta));
    let (mean, variance) = (f32_values(mean), f32_values(variance));
    let params: Vec<Affine> = (0..d.c)
        .map(|c| Affine {
            s1: (gamma[c] as f64 * inv_std(variance[c] as f64, epsilon)) as f32,
            o1: mean[c],
            k: beta[c],
            ..Affine::default()
        })
        .collect();
    kernels::map_affine(x, None, d, &params)
}

/// Batch norm with the batch's own statistics: `(output, mean, biased variance)`.
pub fn batch_norm_train(
    x: FlexTensor,
    gamma: FlexTensor,
    beta: FlexTensor,
    epsilon: f64,
) -> (FlexTensor, FlexTensor, FlexTensor) {
    check_shapes(
        "batch_norm_train",
        &x,
        &[("gamma", &gamma), ("beta", &beta)],
    );
    let Some(d) = fused_dims(&x, &[&gamma, &beta]) else {
        return reference::batch_norm_train(x, gamma, beta, epsilon);
    };
    let x = x.into_contiguous();
    let stats = kernels::channel_stats(x.storage::<f32>(), d);
    let (gamma, beta) = (f32_values(gamma), f32_values(beta));
    let params: Vec<Affine> = stats
        .iter()
        .enumerate()
        .map(|(c, &(mean, var))| {
            let hi = mean as f32;
            Affine {
                s1: (gamma[c] as f64 * inv_std(var, epsilon)) as f32,
                o1: hi,
                lo: (mean - hi as f64) as f32,
                k: beta[c],
                ..Affine::default()
            }
        })
        .collect();
    let output = kernels::map_affine(x, None, d, &params);
    let mean = stats.iter().map(|&(m, _)| m as f32).collect();
    let variance = stats.iter().map(|&(_, v)| v as f32).collect();
    (output, f32_tensor(mean), f32_tensor(variance))
}

/// Gradients of [`batch_norm_train`]: `(x_grad, gamma_grad, beta_grad)`, with
/// `x̂ = (x − mean)·inv_std`, `β' = Σ g`, `γ' = Σ g·x̂` and
/// `x' = γ·inv_std·(g − β'/m − x̂·γ'/m)` (`m` values per channel).
pub fn batch_norm_train_backward(
    x: FlexTensor,
    gamma: FlexTensor,
    mean: FlexTensor,
    variance: FlexTensor,
    epsilon: f64,
    output_grad: FlexTensor,
) -> (FlexTensor, FlexTensor, FlexTensor) {
    let named = [("gamma", &gamma), ("mean", &mean), ("variance", &variance)];
    check_shapes("batch_norm_train_backward", &x, &named);
    assert_eq!(
        x.layout().shape(),
        output_grad.layout().shape(),
        "batch_norm_train_backward: output_grad must have the input's shape"
    );
    let Some(d) = fused_dims(&x, &[&gamma, &mean, &variance, &output_grad]) else {
        return reference::batch_norm_train_backward(
            x,
            gamma,
            mean,
            variance,
            epsilon,
            output_grad,
        );
    };
    let (x, g) = (x.into_contiguous(), output_grad.into_contiguous());
    let (gamma, mean) = (f32_values(gamma), f32_values(mean));
    let variance = f32_values(variance);
    let xs: &[f32] = x.storage();
    let sums = kernels::channel_grad_sums(g.storage::<f32>(), xs, &mean, d);
    let m = d.per_channel() as f64;
    let (mut gamma_grad, mut beta_grad) = (Vec::with_capacity(d.c), Vec::with_capacity(d.c));
    let mut params = Vec::with_capacity(d.c);
    for (c, &(sum_g, sum_gx)) in sums.iter().enumerate() {
        let inv = inv_std(variance[c] as f64, epsilon);
        let dgamma = sum_gx * inv;
        let scale = gamma[c] as f64 * inv;
        gamma_grad.push(dgamma as f32);
        beta_grad.push(sum_g as f32);
        params.push(Affine {
            s1: scale as f32,
            o1: (sum_g / m) as f32,
            s2: -(scale * inv * dgamma / m) as f32,
            o2: mean[c],
            ..Affine::default()
        });
    }
    let x_grad = kernels::map_affine(g, Some(xs), d, &params);
    (x_grad, f32_tensor(gamma_grad), f32_tensor(beta_grad))
}
