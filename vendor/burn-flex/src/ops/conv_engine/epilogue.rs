//! A fused epilogue (patch 13): the activation after a convolution, applied by
//! the task that has just written the output rows, while they are in cache.
//!
//! Why: Burn composes YOLO's SiLU as `x · sigmoid(x)` after the convolution,
//! i.e. a fresh tensor for the sigmoid, a second for the product, and two
//! more passes over memory plus two rounds of waking the pool, for every
//! convolution; at batch 1 (a line's usual inference) fusing them made
//! YOLO11n-seg 1.12–1.18× faster (PATCH.md, patch 13). ONNX Runtime (MLAS)
//! fuses bias and activation into its convolution's output tile the same way.
//! Burn has no "convolution with an activation" op, so callers reach this
//! through [`crate::ops::conv2d_activated`] on a tensor they know is flex's
//! (chicktrain does so at inference, where no gradient needs the
//! pre-activation values).

use super::{Elem, Shared};

/// The activation a forward convolution applies to its output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Activation {
    /// The convolution's output as is.
    #[default]
    Identity,
    /// `x · sigmoid(x)`, bit for bit what Burn's `activation::silu` computes
    /// on flex for f32 (the same sigmoid kernel, one multiplication).
    Silu,
}

impl Activation {
    /// Applies the activation, on this thread, to one run of `len` elements in
    /// each of `channels` planes of the output behind `dst`: the runs at
    /// `off + c · plane`, as a task has just written them.
    ///
    /// # Safety
    /// Every run lies inside `dst`'s allocation, is initialised, and belongs
    /// to the calling task alone.
    pub(crate) unsafe fn apply_to_planes<T: Elem>(
        self,
        dst: Shared<T>,
        off: usize,
        channels: usize,
        plane: usize,
        len: usize,
    ) {
        if self == Activation::Identity {
            return;
        }
        for c in 0..channels {
            // SAFETY: the caller's contract.
            let run = unsafe { core::slice::from_raw_parts_mut(dst.at(off + c * plane), len) };
            match self {
                Activation::Identity => {}
                Activation::Silu => T::silu_inplace(run),
            }
        }
    }
}
