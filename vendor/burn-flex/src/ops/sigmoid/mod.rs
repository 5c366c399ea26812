//! Vectorised f32 sigmoid and sigmoid gradient for Flex (chicktrain issue
//! 37): `ActivationOps::sigmoid` and `sigmoid_backward` send f32 tensors here.
//!
//! Why: YOLO11's SiLU is `x · sigmoid(x)`, composed by Burn, after almost
//! every convolution; upstream computes each sigmoid with one libm `expf`
//! call per element (a scalar loop LLVM cannot vectorise) and the gradient
//! through a generic binary closure. In a `perf record` of the quickstart's
//! training on flex, `expf` and the sigmoid loops were among the largest
//! symbols (chicktrain's `bench/results/convs/profile_0f7e4fd.md`).
//! Here the sigmoid is a branch-free formula over a polynomial `exp`
//! ([`exp`], Cephes' `expf`) that LLVM vectorises, with an AVX2 clone picked
//! at run time ([`kernels`]).
//!
//! What it takes: f32 tensors of any shape and layout (a contiguous view is
//! mapped directly, a tensor whose storage is exactly its permuted view keeps
//! its layout, anything else is copied to contiguous first); the result is
//! written in place when the tensor's buffer is not shared. Other dtypes keep
//! upstream's code in `activation.rs`. Not bit-identical to upstream (a
//! different `exp`): within 3 ulp of the f64 sigmoid for normal results
//! (`tests.rs`).

#[cfg(all(test, feature = "std"))]
mod bench;
pub mod exp;
pub mod kernels;
#[cfg(test)]
mod tests;

use alloc::vec::Vec;
use burn_backend::DType;
use burn_std::Bytes;

use crate::{FlexTensor, Layout};

/// `sigmoid(x)` of an f32 tensor.
///
/// # Panics
/// If the tensor is not f32 (callers route other dtypes elsewhere).
pub fn sigmoid(mut tensor: FlexTensor) -> FlexTensor {
    assert_eq!(tensor.dtype(), DType::F32, "sigmoid: expected f32");
    let layout = tensor.layout().clone();
    let n = layout.num_elements();
    if let Some((start, end)) = layout.contiguous_offsets() {
        if tensor.is_unique() && start == 0 {
            kernels::sigmoid_inplace(&mut tensor.storage_mut::<f32>()[..n]);
            return tensor;
        }
        let out = map_to_vec(&tensor.storage::<f32>()[start..end]);
        return f32_tensor(out, Layout::contiguous(layout.shape().clone()));
    }
    // A permuted view whose storage is exactly its elements (e.g. a
    // transpose): map the storage in order and keep the layout.
    let positive = layout.strides().iter().all(|&s| s > 0);
    if positive && layout.start_offset() == 0 && tensor.storage::<f32>().len() == n {
        if tensor.is_unique() {
            kernels::sigmoid_inplace(tensor.storage_mut::<f32>());
            return tensor;
        }
        let out = map_to_vec(tensor.storage::<f32>());
        return f32_tensor(out, layout);
    }
    sigmoid(tensor.into_contiguous())
}

/// `grad · s · (1 - s)` for an f32 sigmoid output `s` and its gradient, in
/// the gradient's buffer (or the output's) when it is contiguous and not
/// shared. `Err` hands both tensors back when neither can take it (another
/// dtype, different shapes, views, shared buffers): the caller then runs
/// upstream's binary op.
pub fn sigmoid_backward(
    output: FlexTensor,
    grad: FlexTensor,
) -> Result<FlexTensor, (FlexTensor, FlexTensor)> {
    let same = output.dtype() == DType::F32
        && grad.dtype() == DType::F32
        && output.layout().shape() == grad.layout().shape();
    let (Some((s0, s1)), Some((g0, g1))) = (
        output.layout().contiguous_offsets(),
        grad.layout().contiguous_offsets(),
    ) else {
        return Err((output, grad));
    };
    if !same {
        return Err((output, grad));
    }
    if grad.is_unique() && g0 == 0 {
        let mut grad = grad;
        let s = &output.storage::<f32>()[s0..s1];
        kernels::sigmoid_backward_into_grad(s, &mut grad.storage_mut::<f32>()[..g1]);
        return Ok(grad);
    }
    if output.is_unique() && s0 == 0 {
        let mut output = output;
        let g = &grad.storage::<f32>()[g0..g1];
        kernels::sigmoid_backward_into_output(&mut output.storage_mut::<f32>()[..s1], g);
        return Ok(output);
    }
    Err((output, grad))
}

/// The sigmoid of `src` into a new vector (no zero-fill first).
fn map_to_vec(src: &[f32]) -> Vec<f32> {
    let mut out = Vec::with_capacity(src.len());
    kernels::sigmoid_into(src, &mut out.spare_capacity_mut()[..src.len()]);
    // SAFETY: `sigmoid_into` wrote all `src.len()` elements.
    unsafe { out.set_len(src.len()) };
    out
}

fn f32_tensor(values: Vec<f32>, layout: Layout) -> FlexTensor {
    FlexTensor::new(Bytes::from_elems(values), layout, DType::F32)
}
