//! Loss primitives both model families use, in their overflow-free forms.

use burn::tensor::activation::relu;
use burn::tensor::Tensor;

/// Overflow-free log-softmax along `dim`.
pub fn log_softmax_stable<const D: usize>(x: Tensor<D>, dim: usize) -> Tensor<D> {
    let m = x.clone().max_dim(dim).detach();
    let z = x - m;
    let lse = z.clone().exp().sum_dim(dim).log();
    z - lse
}

/// Element-wise BCE with logits, `max(x, 0) − x·y + log(1 + e^{−|x|})`.
pub fn bce_with_logits<const D: usize>(x: Tensor<D>, y: Tensor<D>) -> Tensor<D> {
    relu(x.clone()) - x.clone() * y + x.abs().neg().exp().log1p()
}
