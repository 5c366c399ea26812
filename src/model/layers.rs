//! Layer arithmetic both model families use: trainable-parameter counts, convolution
//! output sizes and multiply-accumulates (so printed GFLOPs come from the weights that
//! were built), and the ×2 upsampling both FPNs need.

use burn::module::{Module, ModuleVisitor, Param};
use burn::nn::conv::Conv2d;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::Tensor;

/// Number of trainable scalars of a module: every float parameter except BatchNorm running
/// statistics (which Burn's `num_params` counts too, PyTorch's `parameters()` does not).
pub fn trainable_params<M: Module>(module: &M) -> usize {
    struct Count {
        path: Vec<String>,
        n: usize,
    }
    impl ModuleVisitor for Count {
        fn enter_module(&mut self, name: &str, _container: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let running = self.path.last().is_some_and(|s| s.starts_with("running_"));
            if !running {
                self.n += param.lazy_shape().num_elements();
            }
        }
    }
    let mut c = Count {
        path: Vec::new(),
        n: 0,
    };
    module.visit(&mut c);
    c.n
}

/// Output size of a convolution or pooling with "same"-style padding `k / 2`.
pub fn conv_out(size: usize, kernel: usize, stride: usize) -> usize {
    (size + 2 * (kernel / 2) - kernel) / stride + 1
}

/// Nearest-neighbour ×2 upsampling (the only interpolation whose backward runs on both flex
/// and ndarray, see `shared/notes/burn-0.22.md`).
///
/// # Shapes
/// - `x`: `[B, C, H, W]` → `[B, C, 2H, 2W]`
pub fn upsample2x(x: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([2 * h, 2 * w]),
    )
}

/// MACs of a plain [`Conv2d`] with padding `k/2` for an `[h, w]` input, and its output size.
pub fn conv_macs(conv: &Conv2d, hw: [usize; 2]) -> (u64, [usize; 2]) {
    let [co, ci_g, kh, kw] = conv.weight.dims();
    let oh = conv_out(hw[0], kh, conv.stride[0]);
    let ow = conv_out(hw[1], kw, conv.stride[1]);
    ((co * ci_g * kh * kw * oh * ow) as u64, [oh, ow])
}
