//! Training: the loop ([`trainer`]) over the trainable models ([`detector`]), learning-rate schedule ([`schedule`]), optimisers and
//! global-norm clipping ([`optim`]), weight EMA ([`ema`]), checkpoint files
//! ([`checkpoint`]), per-epoch COCO evaluation ([`evaluate`]), plots ([`plot`]) and
//! progress bars ([`progress`]). The commands built on it (`train`, `eval`, `predict`)
//! live in [`commands`].

pub mod checkpoint;
pub mod commands;
pub mod detector;
pub mod divergence;
pub mod ema;
pub mod evaluate;
pub mod interrupt;
pub mod optim;
pub mod plot;
pub mod progress;
pub mod schedule;
pub mod trainer;

use burn::tensor::Tensor;

/// First element of a tensor as f32 (syncs the device).
pub fn scalar<const D: usize>(t: &Tensor<D>) -> f32 {
    t.clone()
        .into_data_as::<f32>()
        .try_into_vec::<f32>()
        .map(|v| v.first().copied().unwrap_or(f32::NAN))
        .unwrap_or(f32::NAN)
}
