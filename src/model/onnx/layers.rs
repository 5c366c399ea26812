//! Burn layers as ONNX nodes, shared by the models' graph walks (`yolo::onnx`,
//! `maskrcnn::onnx`): a `Conv2d`, a `ConvTranspose2d`, a `Linear`, each with its weights
//! as initializers.

use anyhow::{bail, ensure, Result};
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::nn::{Linear, PaddingConfig2d};

use super::graph::GraphBuilder;
use crate::util::tensor::to_host;

/// Padding of a conv that pads the same on every side.
pub fn symmetric_padding(conv: &Conv2d, scope: &str) -> Result<[usize; 2]> {
    let [_, _, kh, kw] = conv.weight.dims();
    Ok(match &conv.padding {
        PaddingConfig2d::Valid => [0, 0],
        PaddingConfig2d::Explicit(t, l, b, r) if t == b && l == r => [*t, *l],
        PaddingConfig2d::Same if kh % 2 == 1 && kw % 2 == 1 && conv.stride == [1, 1] => {
            [kh / 2, kw / 2]
        }
        p => bail!("{scope}: padding {p:?} has no symmetric ONNX equivalent"),
    })
}

/// A plain `Conv2d` (with its bias if it has one).
pub fn conv2d(g: &mut GraphBuilder, scope: &str, x: &str, conv: &Conv2d) -> Result<String> {
    ensure!(
        conv.dilation == [1, 1],
        "{scope}: dilated convs are not exported (dilation {:?})",
        conv.dilation
    );
    let pad = symmetric_padding(conv, scope)?;
    let dims = conv.weight.dims();
    let w = to_host(conv.weight.val());
    let b = conv.bias.as_ref().map(|b| to_host(b.val()));
    Ok(g.conv(
        scope,
        x,
        (&dims, &w),
        b.as_deref(),
        conv.stride,
        pad,
        conv.groups,
    ))
}

/// A `ConvTranspose2d` without padding, dilation, groups or output padding (the mask
/// head's 2×2 / stride-2 upsampling).
pub fn conv_transpose2d(
    g: &mut GraphBuilder,
    scope: &str,
    x: &str,
    conv: &ConvTranspose2d,
) -> Result<String> {
    ensure!(
        conv.padding == [0, 0]
            && conv.padding_out == [0, 0]
            && conv.dilation == [1, 1]
            && conv.groups == 1,
        "{scope}: only unpadded, undilated, ungrouped transposed convs are exported"
    );
    let dims = conv.weight.dims();
    let w = to_host(conv.weight.val());
    let b = conv.bias.as_ref().map(|b| to_host(b.val()));
    Ok(g.conv_transpose(scope, x, (&dims, &w), b.as_deref(), conv.stride))
}

/// A `Linear` on `[N, in]` rows: `MatMul` by the `[in, out]` weight (Burn's layout, no
/// transpose needed) and `Add` of the bias.
pub fn linear(g: &mut GraphBuilder, scope: &str, x: &str, lin: &Linear) -> Result<String> {
    let [i, o] = lin.weight.dims();
    let w = g.constant_f32(
        &format!("{scope}.weight"),
        &[i, o],
        &to_host(lin.weight.val()),
    );
    let y = g.binary(scope, "MatMul", x, &w);
    Ok(match &lin.bias {
        Some(b) => {
            let b = g.constant_f32(&format!("{scope}.bias"), &[o], &to_host(b.val()));
            g.binary(scope, "Add", &y, &b)
        }
        None => y,
    })
}
