//! Burn 0.22.1's default `ModuleOps::batch_norm`, `batch_norm_train` and
//! `batch_norm_train_backward` (burn-backend `src/backend/ops/modules/base.rs`),
//! written out for Flex tensors because the trait defaults cannot be called
//! once Flex overrides them. They serve as the fallback for every dtype the
//! fused kernels do not take (anything but f32), as the reference of the
//! tests and as the "old" side of the benchmark. Same operations in the same
//! order as upstream: swap_dims + reshape + mean_dim for the statistics, one
//! tensor operation per arithmetic step elsewhere.

use alloc::vec;
use burn_backend::Scalar;
use burn_backend::TensorMetadata;
use burn_backend::ops::FloatTensorOps;
use burn_std::Shape;

use crate::{Flex, FlexTensor};

/// Shape `[1, channels, 1, …]` of the input's rank, for broadcasting.
fn per_channel(x_shape: &Shape) -> Shape {
    let mut dims = vec![1; x_shape.num_dims()];
    dims[1] = x_shape[1];
    Shape::from(dims)
}

/// Upstream's `batch_norm`: `(x − mean) / sqrt(var + ε) · γ + β`.
pub fn batch_norm(
    x: FlexTensor,
    gamma: FlexTensor,
    beta: FlexTensor,
    mean: FlexTensor,
    variance: FlexTensor,
    epsilon: f64,
) -> FlexTensor {
    let shape = per_channel(&x.shape());
    let gamma = Flex::float_reshape(gamma, shape.clone());
    let beta = Flex::float_reshape(beta, shape.clone());
    let mean = Flex::float_reshape(mean, shape.clone());
    let variance = Flex::float_reshape(variance, shape);
    let std = Flex::float_sqrt(Flex::float_add_scalar(variance, Scalar::Float(epsilon)));
    let normalized = Flex::float_div(Flex::float_sub(x, mean), std);
    Flex::float_add(Flex::float_mul(normalized, gamma), beta)
}

/// Upstream's `batch_norm_train`: returns `(output, mean, biased variance)`.
pub fn batch_norm_train(
    x: FlexTensor,
    gamma: FlexTensor,
    beta: FlexTensor,
    epsilon: f64,
) -> (FlexTensor, FlexTensor, FlexTensor) {
    let shape = x.shape();
    let channels = shape[1];
    let flattened = Shape::new([channels, shape.num_elements() / channels]);
    let mean = Flex::float_mean_dim(
        Flex::float_reshape(Flex::float_swap_dims(x.clone(), 0, 1), flattened.clone()),
        1,
    );
    let mean = Flex::float_reshape(mean, per_channel(&shape));
    let centered = Flex::float_sub(x.clone(), mean.clone());
    let variance = Flex::float_mean_dim(
        Flex::float_reshape(
            Flex::float_swap_dims(Flex::float_mul(centered.clone(), centered), 0, 1),
            flattened,
        ),
        1,
    );
    let mean = Flex::float_reshape(mean, Shape::new([channels]));
    let variance = Flex::float_reshape(variance, Shape::new([channels]));
    let output = batch_norm(x, gamma, beta, mean.clone(), variance.clone(), epsilon);
    (output, mean, variance)
}

/// Upstream's `batch_norm_train_backward`: returns `(x_grad, gamma_grad, beta_grad)`.
pub fn batch_norm_train_backward(
    x: FlexTensor,
    gamma: FlexTensor,
    mean: FlexTensor,
    variance: FlexTensor,
    epsilon: f64,
    output_grad: FlexTensor,
) -> (FlexTensor, FlexTensor, FlexTensor) {
    let shape = x.shape();
    let channels = shape[1];
    let flattened = Shape::new([channels, shape.num_elements() / channels]);
    let per_channel = per_channel(&shape);
    let inv_std = Flex::float_reshape(
        Flex::float_recip(Flex::float_sqrt(Flex::float_add_scalar(
            variance,
            Scalar::Float(epsilon),
        ))),
        per_channel.clone(),
    );
    let normalized = Flex::float_mul(
        Flex::float_sub(x, Flex::float_reshape(mean, per_channel.clone())),
        inv_std.clone(),
    );
    let output_grad_flat = Flex::float_reshape(
        Flex::float_swap_dims(output_grad.clone(), 0, 1),
        flattened.clone(),
    );
    let normalized_grad_flat = Flex::float_reshape(
        Flex::float_swap_dims(
            Flex::float_mul(output_grad.clone(), normalized.clone()),
            0,
            1,
        ),
        flattened,
    );
    let beta_grad = Flex::float_sum_dim(output_grad_flat.clone(), 1);
    let gamma_grad = Flex::float_sum_dim(normalized_grad_flat.clone(), 1);
    let mean_grad = Flex::float_reshape(
        Flex::float_mean_dim(output_grad_flat, 1),
        per_channel.clone(),
    );
    let mean_normalized_grad = Flex::float_reshape(
        Flex::float_mean_dim(normalized_grad_flat, 1),
        per_channel.clone(),
    );
    let centred_grad = Flex::float_sub(output_grad, mean_grad);
    let projected = Flex::float_mul(normalized, mean_normalized_grad);
    let scale = Flex::float_mul(Flex::float_reshape(gamma, per_channel), inv_std);
    let x_grad = Flex::float_mul(scale, Flex::float_sub(centred_grad, projected));
    (
        x_grad,
        Flex::float_reshape(gamma_grad, Shape::new([channels])),
        Flex::float_reshape(beta_grad, Shape::new([channels])),
    )
}
