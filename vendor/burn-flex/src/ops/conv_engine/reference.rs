//! The paths the engine replaces, kept callable as references for its tests
//! and for `chicktrain bench convs`: the tiled im2col forward
//! ([`crate::ops::conv::conv2d_im2col_f32`]) and Burn 0.22.1's default
//! `conv2d_x_backward` / `conv2d_weight_backward` (burn-backend
//! `src/backend/ops/modules/conv.rs`), written out here for f32 Flex tensors
//! with symmetric padding because the trait defaults cannot be called once
//! Flex overrides them.

use alloc::vec::Vec;
use burn_backend::ops::conv::calculate_padding_out;
use burn_backend::ops::{ConvOptions, ConvTransposeOptions};
use burn_std::{Bytes, Shape, Slice};

use crate::ops::{conv, conv_transpose, slice::slice};
use crate::{FlexTensor, Layout};

/// Burn's default input gradient: a transposed convolution of the output
/// gradient with the weight. `x_shape` is the input's `[b, c_in, h, w]`.
pub fn x_backward_f32(
    x_shape: &[usize],
    weight: FlexTensor,
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> FlexTensor {
    let k = weight.layout().shape().clone();
    let y = output_grad.layout().shape().clone();
    let pad = options.padding_begin();
    let pad_out = [0, 1].map(|d| {
        let (kd, s, dil) = (k[d + 2], options.stride[d], options.dilation[d]);
        calculate_padding_out(kd, s, pad[d], dil, x_shape[d + 2], y[d + 2])
    });
    let t = ConvTransposeOptions::new(
        options.stride,
        pad,
        pad_out,
        options.dilation,
        options.groups,
    );
    conv_transpose::conv_transpose2d_f32(output_grad, weight, None, &t)
}

/// Burn's default weight gradient: per group, a convolution of the
/// batch-swapped input with the batch-swapped output gradient as the kernel,
/// swapped back and cropped to the kernel size.
pub fn weight_backward_f32(
    x: FlexTensor,
    weight_shape: &[usize],
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> FlexTensor {
    let groups = options.groups;
    let [c_out, cpg, kh, kw] = [0, 1, 2, 3].map(|d| weight_shape[d]);
    let mpg = c_out / groups;
    let opts = ConvOptions::new(options.dilation, options.padding_begin(), options.stride, 1);
    let xs = x.transpose(0, 1);
    let dys = output_grad.transpose(0, 1);
    let mut out: Vec<f32> = Vec::with_capacity(c_out * cpg * kh * kw);
    for grp in 0..groups {
        let xg = slice(xs.clone(), &[Slice::from(grp * cpg..(grp + 1) * cpg)]);
        let dyg = slice(dys.clone(), &[Slice::from(grp * mpg..(grp + 1) * mpg)]);
        let wg = conv::conv2d_f32(xg, dyg, None, &opts).transpose(0, 1);
        let ranges = [0..mpg, 0..cpg, 0..kh, 0..kw].map(Slice::from);
        let wg = slice(wg, &ranges).to_contiguous();
        out.extend_from_slice(wg.storage::<f32>());
    }
    let shape = Shape::from(alloc::vec![c_out, cpg, kh, kw]);
    FlexTensor::new(
        Bytes::from_elems(out),
        Layout::contiguous(shape),
        burn_backend::DType::F32,
    )
}
