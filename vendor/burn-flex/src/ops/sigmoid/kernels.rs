//! Slice kernels for the f32 sigmoid, its gradient and SiLU, built on
//! [`super::exp::exp_f32`], compiled three times on x86-64 (baseline SSE2, an
//! AVX2 clone and an AVX-512 clone picked at run time) and split over the rayon pool for large
//! slices. Every element is computed by the same branch-free formula in
//! every clone and every chunk, so results do not depend on the CPU's
//! features or the thread count.

use core::mem::MaybeUninit;

use super::exp::exp_f32;

/// `1 / (1 + e^-x)` without overflow or cancellation: with `e = e^-|x|`,
/// `1 / (1 + e)` for x ≥ 0 and `e / (1 + e)` for x < 0 (upstream's two
/// branches, as selects). NaN gives NaN.
#[inline(always)]
pub fn sigmoid_f32(x: f32) -> f32 {
    let e = exp_f32(-x.abs());
    let s = 1.0 / (1.0 + e);
    if x >= 0.0 { s } else { e * s }
}

/// The gradient through a sigmoid from its output `s` and the output's
/// gradient `g`: `g · s · (1 - s)` (upstream's formula and order).
#[inline(always)]
fn sigmoid_grad(s: f32, g: f32) -> f32 {
    g * s * (1.0 - s)
}

/// `x · sigmoid(x)`, the product Burn's composed SiLU computes (the same
/// sigmoid, one multiplication), so a fused SiLU equals it bit for bit.
#[inline(always)]
pub fn silu_f32(x: f32) -> f32 {
    x * sigmoid_f32(x)
}

/// `xs[i] = silu(xs[i])` on this thread (a convolution task's epilogue,
/// patch 13: its rows are still in cache and the task is already on a
/// worker).
pub fn silu_inplace_serial(xs: &mut [f32]) {
    dispatch::unary_inplace(xs, silu_f32)
}

/// `xs[i] = silu(xs[i])`, split over the pool like [`sigmoid_inplace`].
pub fn silu_inplace(xs: &mut [f32]) {
    par_chunks(xs.len(), xs, |_, c| dispatch::unary_inplace(c, silu_f32));
}

/// `xs[i] = sigmoid(xs[i])`.
pub fn sigmoid_inplace(xs: &mut [f32]) {
    par_chunks(xs.len(), xs, |_, c| dispatch::unary_inplace(c, sigmoid_f32));
}

/// `dst[i] = sigmoid(src[i])` into uninitialised memory of `src`'s length.
pub fn sigmoid_into(src: &[f32], dst: &mut [MaybeUninit<f32>]) {
    assert_eq!(src.len(), dst.len(), "sigmoid_into: length mismatch");
    par_chunks(dst.len(), dst, |start, c| {
        dispatch::unary_into(&src[start..start + c.len()], c, sigmoid_f32)
    });
}

/// `g[i] = g[i] · s[i] · (1 - s[i])`, in the gradient's buffer.
pub fn sigmoid_backward_into_grad(s: &[f32], g: &mut [f32]) {
    assert_eq!(s.len(), g.len(), "sigmoid_backward: length mismatch");
    par_chunks(g.len(), g, |start, c| {
        dispatch::binary_inplace(c, &s[start..start + c.len()], |g, s| sigmoid_grad(s, g))
    });
}

/// `s[i] = g[i] · s[i] · (1 - s[i])`, in the output's buffer.
pub fn sigmoid_backward_into_output(s: &mut [f32], g: &[f32]) {
    assert_eq!(s.len(), g.len(), "sigmoid_backward: length mismatch");
    par_chunks(s.len(), s, |start, c| {
        dispatch::binary_inplace(c, &g[start..start + c.len()], sigmoid_grad)
    });
}

/// Runs `f(start, chunk)` over `dst` in chunks, on the rayon pool when the
/// slice is large and the pool has more than one thread, with the threshold
/// and chunk length of flex's parallel unary ops (`ops::unary`, patch 1).
fn par_chunks<T, F>(len: usize, dst: &mut [T], f: F)
where
    T: Send,
    F: Fn(usize, &mut [T]) + Send + Sync,
{
    #[cfg(feature = "rayon")]
    if len >= crate::ops::unary::PAR_UNARY_MIN && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        let chunk = crate::ops::unary::par_chunk(len);
        dst.par_chunks_mut(chunk)
            .enumerate()
            .for_each(|(i, c)| f(i * chunk, c));
        return;
    }
    let _ = len;
    f(0, dst);
}

/// The element loops, with AVX2 and AVX-512 clones chosen at run time on
/// x86-64 (flex is built for baseline x86-64, where LLVM vectorises them four
/// lanes wide with SSE2; the clones give eight and sixteen).
pub(crate) mod dispatch {
    use core::mem::MaybeUninit;

    #[inline(always)]
    fn unary_inplace_body(xs: &mut [f32], f: impl Fn(f32) -> f32) {
        for x in xs.iter_mut() {
            *x = f(*x);
        }
    }

    #[inline(always)]
    fn unary_into_body(src: &[f32], dst: &mut [MaybeUninit<f32>], f: impl Fn(f32) -> f32) {
        for (d, &s) in dst.iter_mut().zip(src) {
            d.write(f(s));
        }
    }

    #[inline(always)]
    fn binary_inplace_body(xs: &mut [f32], ys: &[f32], f: impl Fn(f32, f32) -> f32) {
        for (x, &y) in xs.iter_mut().zip(ys) {
            *x = f(*x, y);
        }
    }

    /// Whether the AVX2 clones may run (std caches the CPUID answer).
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[inline(always)]
    fn has_avx2() -> bool {
        std::arch::is_x86_feature_detected!("avx2")
    }

    /// Whether the AVX-512 clones may run (patch 13: sixteen lanes; the loops
    /// are bound by `vdivps`, whose 512-bit form does twice the work per
    /// instruction on the CPUs that have it).
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[inline(always)]
    fn has_avx512() -> bool {
        std::arch::is_x86_feature_detected!("avx512f")
    }

    // The same loops with AVX-512 enabled. No FMA is formed (Rust does not
    // contract `a * b + c`), so every clone gives the same bits.
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx512f")]
    fn unary_inplace_avx512(xs: &mut [f32], f: impl Fn(f32) -> f32) {
        unary_inplace_body(xs, f)
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx512f")]
    fn unary_into_avx512(src: &[f32], dst: &mut [MaybeUninit<f32>], f: impl Fn(f32) -> f32) {
        unary_into_body(src, dst, f)
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx512f")]
    fn binary_inplace_avx512(xs: &mut [f32], ys: &[f32], f: impl Fn(f32, f32) -> f32) {
        binary_inplace_body(xs, ys, f)
    }

    /// The in-place loop through one named clone: `"avx512"`, `"avx2"`, or
    /// anything else for the baseline build whatever the CPU (the tests hold
    /// every clone to its bits; the clone bench times them). `false` when the
    /// CPU lacks the clone.
    #[cfg(test)]
    pub(crate) fn unary_inplace_with_clone(
        xs: &mut [f32],
        clone: &str,
        f: impl Fn(f32) -> f32,
    ) -> bool {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        match clone {
            "avx512" if has_avx512() => {
                // SAFETY: the CPU supports AVX-512F (checked just above).
                unsafe { unary_inplace_avx512(xs, f) };
                return true;
            }
            "avx2" if has_avx2() => {
                // SAFETY: the CPU supports AVX2 (checked just above).
                unsafe { unary_inplace_avx2(xs, f) };
                return true;
            }
            _ => {}
        }
        if clone == "avx512" || clone == "avx2" {
            return false;
        }
        unary_inplace_body(xs, f);
        true
    }

    // One AVX2 clone per loop; `f` is inlined into it, so LLVM vectorises
    // the loop eight lanes wide. The `has_avx2` check is in the caller.
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn unary_inplace_avx2(xs: &mut [f32], f: impl Fn(f32) -> f32) {
        unary_inplace_body(xs, f)
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn unary_into_avx2(src: &[f32], dst: &mut [MaybeUninit<f32>], f: impl Fn(f32) -> f32) {
        unary_into_body(src, dst, f)
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn binary_inplace_avx2(xs: &mut [f32], ys: &[f32], f: impl Fn(f32, f32) -> f32) {
        binary_inplace_body(xs, ys, f)
    }

    pub(super) fn unary_inplace(xs: &mut [f32], f: impl Fn(f32) -> f32) {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F (checked just above).
            return unsafe { unary_inplace_avx512(xs, f) };
        }
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { unary_inplace_avx2(xs, f) };
        }
        unary_inplace_body(xs, f)
    }

    pub(super) fn unary_into(src: &[f32], dst: &mut [MaybeUninit<f32>], f: impl Fn(f32) -> f32) {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F (checked just above).
            return unsafe { unary_into_avx512(src, dst, f) };
        }
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { unary_into_avx2(src, dst, f) };
        }
        unary_into_body(src, dst, f)
    }

    pub(super) fn binary_inplace(xs: &mut [f32], ys: &[f32], f: impl Fn(f32, f32) -> f32) {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F (checked just above).
            return unsafe { binary_inplace_avx512(xs, ys, f) };
        }
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { binary_inplace_avx2(xs, ys, f) };
        }
        binary_inplace_body(xs, ys, f)
    }
}
