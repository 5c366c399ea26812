//! Loss primitives shared by the RPN and the RoI heads: smooth-L1 / L1 on box deltas
//! (detectron2 `fvcore.nn.smooth_l1_loss`, `beta = 0` is plain L1) and softmax
//! cross-entropy against integer labels. BCE-with-logits is the overflow-free one of the
//! YOLO loss.

use burn::tensor::{Device, Tensor, TensorData};

pub use crate::model::loss::bce_with_logits;
use crate::model::loss::log_softmax_stable;

/// Element-wise smooth-L1: `0.5 x²/β` for `|x| < β`, else `|x| − 0.5β`; `β < 1e-5` is L1.
///
/// # Shapes
/// - `pred`, `target`: `[N, 4]` → `[N, 4]`
pub fn smooth_l1(pred: Tensor<2>, target: Tensor<2>, beta: f32) -> Tensor<2> {
    let a = (pred - target).abs();
    if beta < 1e-5 {
        return a;
    }
    let quad = a.clone().powi_scalar(2) * (0.5 / beta);
    let small = a.clone().lower_elem(beta);
    (a - 0.5 * beta).mask_where(small, quad)
}

/// Mean softmax cross-entropy of `logits` against `labels` (each `< K`).
///
/// # Shapes
/// - `logits`: `[N, K]`, `labels.len() == N` → `[1]`
pub fn cross_entropy(logits: Tensor<2>, labels: &[usize]) -> Tensor<1> {
    let device = logits.device();
    let [n, k] = logits.dims();
    assert_eq!(
        labels.len(),
        n,
        "cross_entropy: {} labels for {n} rows",
        labels.len()
    );
    let onehot = one_hot(labels, k, &device);
    (log_softmax_stable(logits, 1) * onehot).sum().neg() / n.max(1) as f64
}

/// `[N, K]` one-hot rows (labels must be `< K`).
pub fn one_hot(labels: &[usize], k: usize, device: &Device) -> Tensor<2> {
    let mut v = vec![0f32; labels.len() * k];
    for (i, &l) in labels.iter().enumerate() {
        assert!(l < k, "one_hot: label {l} at row {i} is not < {k}");
        v[i * k + l] = 1.0;
    }
    Tensor::from_data(TensorData::new(v, [labels.len(), k]), device)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::tensor::{host, to_host};

    #[test]
    fn smooth_l1_hand_values() {
        let d = Device::flex();
        let p = host(vec![0.0, 0.05, 1.0, -2.0], [1, 4], &d);
        let t = Tensor::zeros([1, 4], &d);
        let v = to_host(smooth_l1(p.clone(), t.clone(), 1.0 / 9.0));
        let b = 1.0f32 / 9.0;
        let want = [0.0, 0.5 * 0.0025 / b, 1.0 - 0.5 * b, 2.0 - 0.5 * b];
        for (a, e) in v.iter().zip(want) {
            assert!((a - e).abs() < 1e-6, "{v:?}");
        }
        assert_eq!(to_host(smooth_l1(p, t, 0.0)), vec![0.0, 0.05, 1.0, 2.0]);
    }

    #[test]
    fn cross_entropy_hand_value() {
        let d = Device::flex();
        let l = host(vec![0.0, 0.0, 1000.0, 0.0], [2, 2], &d);
        // Row 0: uniform → ln 2; row 1: saturated correct → 0.
        let v = to_host(cross_entropy(l, &[1, 0]))[0];
        assert!((v - 2f32.ln() / 2.0).abs() < 1e-6, "{v}");
    }
}
