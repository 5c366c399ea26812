//! Host copies of tensors: the one place that turns device data into `Vec<f32>`.

use burn::tensor::{Device, Tensor, TensorData};

/// All elements of `t` as f32, row-major (syncs the device).
pub fn to_host<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data_as::<f32>()
        .try_into_vec::<f32>()
        .expect("f32 tensor data")
}

/// First element of a tensor as f32 (syncs the device); NaN for an empty tensor.
pub fn scalar<const D: usize>(t: &Tensor<D>) -> f32 {
    t.clone()
        .into_data_as::<f32>()
        .try_into_vec::<f32>()
        .map(|v| v.first().copied().unwrap_or(f32::NAN))
        .unwrap_or(f32::NAN)
}

/// Host `f32` values → a tensor of `shape` on `device`.
pub fn host<const D: usize>(v: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(v, shape), device)
}
