//! Conv + SiLU in one pass on the flex backend at inference (burn-flex patch 13).
//!
//! Why: Burn composes SiLU as `x · sigmoid(x)`, so at inference every YOLO conv is followed
//! by two more ops, each a fresh tensor, a pass over memory and a wake-up of the thread
//! pool. burn-flex applies the activation to each output tile while it is still in cache,
//! as ONNX Runtime does: batch-1 latency 1.12–1.18× faster
//! (`bench/results/convs/fused_silu_2026-12-07/`). Burn has no op for a convolution with an
//! activation, so this reaches into flex's primitives where the tensors are flex's, f32 and
//! outside autodiff (a training step keeps Burn's ops: its backward needs the
//! pre-activation values). The SiLU is Burn's composition bit for bit on the same
//! convolution route (burn-flex `fused_silu_equals_conv_then_composed_silu`); 1×1 layers
//! now take the engine's row tiles, whose GEMMs may sum in another order than flex's old
//! 1×1 path (`fused_conv_silu_equals_composed` here finds the same bits on its shapes).

use burn::nn::conv::Conv2d;
use burn::nn::PaddingConfig2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{DType, Tensor};
use burn_flex::ops::conv_engine::Activation;
use burn_flex::Flex;

/// `silu(conv.forward(x))` in one flex convolution with a SiLU epilogue; `Err(x)` when `x`
/// or the conv's parameters are not f32 flex tensors outside autodiff, or the padding is
/// not explicit (the caller then composes it with Burn's ops).
pub fn conv_silu(conv: &Conv2d, x: Tensor<4>) -> Result<Tensor<4>, Tensor<4>> {
    let PaddingConfig2d::Explicit(top, left, bottom, right) = conv.padding else {
        return Err(x);
    };
    let Ok(weight) = conv.weight.val().try_into_primitive::<Flex>() else {
        return Err(x);
    };
    let bias = match &conv.bias {
        Some(b) => match b.val().try_into_primitive::<Flex>() {
            Ok(b) => Some(b),
            Err(_) => return Err(x),
        },
        None => None,
    };
    // A clone shares the buffer; the original is dropped once the primitive is out.
    let Ok(input) = x.clone().try_into_primitive::<Flex>() else {
        return Err(x);
    };
    let f32s = [Some(&input), Some(&weight), bias.as_ref()];
    if f32s.iter().flatten().any(|t| t.dtype() != DType::F32) {
        return Err(x);
    }
    drop(x);
    let options = ConvOptions::new_with_padding(
        conv.stride,
        [(top, bottom), (left, right)],
        conv.dilation,
        conv.groups,
    );
    let y = burn_flex::ops::conv2d_activated(input, weight, bias, options, Activation::Silu);
    Ok(Tensor::from_primitive::<Flex>(y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::conv::Conv2dConfig;
    use burn::tensor::activation::silu;
    use burn::tensor::{Device, Distribution};

    use crate::util::tensor::to_host;

    fn conv(c_in: usize, c_out: usize, k: usize, s: usize, groups: usize, dev: &Device) -> Conv2d {
        let p = k / 2;
        Conv2dConfig::new([c_in, c_out], [k, k])
            .with_stride([s, s])
            .with_groups(groups)
            .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
            .init(dev)
    }

    /// Every kind of YOLO conv (3×3 with Winograd's tile count, 3×3 stride 2, 1×1,
    /// depthwise) takes the fused path on flex and equals Burn's composition bit for bit.
    #[test]
    fn fused_conv_silu_equals_composed() {
        let dev = Device::flex();
        dev.seed(5);
        for (c_in, c_out, k, s, groups, hw) in [
            (8, 16, 3, 1, 1, 40),
            (8, 16, 3, 2, 1, 21),
            (16, 24, 1, 1, 1, 13),
            (12, 12, 3, 1, 12, 10),
        ] {
            let conv = conv(c_in, c_out, k, s, groups, &dev);
            let x = Tensor::<4>::random([1, c_in, hw, hw], Distribution::Normal(0.0, 3.0), &dev);
            let want = to_host(silu(conv.forward(x.clone())));
            let got = to_host(conv_silu(&conv, x).expect("flex f32 takes the fused path"));
            assert_eq!(got.len(), want.len());
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(
                same,
                "fused differs for {c_in}->{c_out} k{k} s{s} g{groups}"
            );
        }
    }

    /// Other backends and autodiff tensors get their input back untouched.
    #[test]
    fn other_backends_and_autodiff_hand_the_input_back() {
        for dev in [Device::ndarray(), Device::flex().autodiff()] {
            let conv = conv(4, 6, 3, 1, 1, &dev);
            let x = Tensor::<4>::random([1, 4, 9, 9], Distribution::Default, &dev);
            let back = conv_silu(&conv, x.clone()).expect_err("not fused off flex inference");
            assert_eq!(to_host(back), to_host(x));
        }
    }
}
