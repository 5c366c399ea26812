//! The f32 kernels of the fused batch norm: per-channel reductions over a
//! contiguous `[n, c, s]` buffer (`s` = the product of the spatial dims) and
//! one per-channel affine map. Each `(sample, channel)` pair owns one
//! contiguous block of `s` values, so both kernels walk the buffer once, in
//! memory order, with no transposed copy; blocks are spread over the rayon pool
//! when the tensor is large enough to pay for it. Partial sums are combined
//! per channel in sample order on the calling thread, so the result does not
//! depend on the number of threads.

use alloc::vec;
use alloc::vec::Vec;
use core::mem::MaybeUninit;

use burn_backend::DType;
use burn_std::Bytes;

use crate::{FlexTensor, Layout};

/// Independent f32 accumulators per reduction: breaks the add dependency
/// chain so the loop vectorises (four SSE or two AVX registers per sum).
const LANES: usize = 16;

/// Values summed in f32 lanes before each flush into the f64 totals, so each
/// lane adds at most 16 values in f32 (rounding ≤ ~16 ulp of a partial sum,
/// ~1e-6) and the long sums over a channel are f64.
const FLUSH: usize = 16 * LANES;

/// Below this many elements a pass stays on the calling thread.
#[cfg(feature = "rayon")]
const PAR_MIN_ELEMS: usize = 1 << 15;

/// `[n, c, s]` view of a `[n, c, …]` tensor.
#[derive(Clone, Copy, Debug)]
pub(super) struct Dims {
    pub n: usize,
    pub c: usize,
    pub s: usize,
}

impl Dims {
    fn blocks(&self) -> usize {
        self.n * self.c
    }

    /// Values per channel, the `m` of the batch statistics.
    pub fn per_channel(&self) -> usize {
        self.n * self.s
    }
}

/// `out = s1·((a − o1) − lo) + s2·(b − o2) + k` for one channel. `o1 + lo` is
/// an offset split into an f32 and its f32 remainder, so that subtracting a
/// large mean keeps the precision of the f64 statistics.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Affine {
    pub s1: f32,
    pub o1: f32,
    pub lo: f32,
    pub s2: f32,
    pub o2: f32,
    pub k: f32,
}

impl Affine {
    #[inline(always)]
    fn apply(&self, a: f32, b: f32) -> f32 {
        self.s1 * ((a - self.o1) - self.lo) + self.s2 * (b - self.o2) + self.k
    }
}

/// `f(block)` for every `(sample, channel)` block, in block order.
fn per_block<T: Send>(d: Dims, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    #[cfg(feature = "rayon")]
    if d.blocks() * d.s >= PAR_MIN_ELEMS && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        let min_len = 4096usize.div_ceil(d.s);
        return (0..d.blocks())
            .into_par_iter()
            .with_min_len(min_len)
            .map(f)
            .collect();
    }
    (0..d.blocks()).map(f).collect()
}

/// `f(block index, block)` over the `s`-long blocks of `out`.
fn for_blocks<T: Send>(out: &mut [T], d: Dims, f: impl Fn(usize, &mut [T]) + Sync + Send) {
    #[cfg(feature = "rayon")]
    if out.len() >= PAR_MIN_ELEMS && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        let min_len = 4096usize.div_ceil(d.s);
        out.par_chunks_mut(d.s)
            .with_min_len(min_len)
            .enumerate()
            .for_each(|(b, blk)| f(b, blk));
        return;
    }
    out.chunks_mut(d.s)
        .enumerate()
        .for_each(|(b, blk)| f(b, blk));
}

/// Adds per-block pairs into per-channel f64 sums, in sample order.
fn per_channel_sums(partial: &[(f64, f64)], c: usize) -> Vec<(f64, f64)> {
    let mut sums = vec![(0.0f64, 0.0f64); c];
    for (b, &(p, q)) in partial.iter().enumerate() {
        sums[b % c].0 += p;
        sums[b % c].1 += q;
    }
    sums
}

/// `(Σ (x − k), Σ (x − k)²)`: f32 lanes flushed into f64 every `FLUSH` values.
fn shifted_sums(x: &[f32], k: f32) -> (f64, f64) {
    let (mut s, mut q) = (0.0f64, 0.0f64);
    for part in x.chunks(FLUSH) {
        let (mut s32, mut q32) = ([0.0f32; LANES], [0.0f32; LANES]);
        let chunks = part.chunks_exact(LANES);
        let rest = chunks.remainder();
        for ch in chunks {
            for l in 0..LANES {
                let d = ch[l] - k;
                s32[l] += d;
                q32[l] += d * d;
            }
        }
        for (l, &v) in rest.iter().enumerate() {
            let d = v - k;
            s32[l] += d;
            q32[l] += d * d;
        }
        s += s32.iter().map(|&v| v as f64).sum::<f64>();
        q += q32.iter().map(|&v| v as f64).sum::<f64>();
    }
    (s, q)
}

/// `(Σ g, Σ g·(x − m))`: f32 lanes flushed into f64 every `FLUSH` values.
fn grad_sums(g: &[f32], x: &[f32], m: f32) -> (f64, f64) {
    let (mut s, mut q) = (0.0f64, 0.0f64);
    for (gp, xp) in g.chunks(FLUSH).zip(x.chunks(FLUSH)) {
        let (mut s32, mut q32) = ([0.0f32; LANES], [0.0f32; LANES]);
        let (gc, xc) = (gp.chunks_exact(LANES), xp.chunks_exact(LANES));
        let (gr, xr) = (gc.remainder(), xc.remainder());
        for (gch, xch) in gc.zip(xc) {
            for l in 0..LANES {
                s32[l] += gch[l];
                q32[l] += gch[l] * (xch[l] - m);
            }
        }
        for (l, (&gv, &xv)) in gr.iter().zip(xr).enumerate() {
            s32[l] += gv;
            q32[l] += gv * (xv - m);
        }
        s += s32.iter().map(|&v| v as f64).sum::<f64>();
        q += q32.iter().map(|&v| v as f64).sum::<f64>();
    }
    (s, q)
}

/// Per-channel `(mean, biased variance)` in f64 of a contiguous `[n, c, s]`
/// buffer. Sums are shifted by each channel's first value (Chan et al.'s
/// shifted data), so a large common offset does not cancel the variance.
pub(super) fn channel_stats(x: &[f32], d: Dims) -> Vec<(f64, f64)> {
    let shift: Vec<f32> = (0..d.c).map(|c| x[c * d.s]).collect();
    let partial = per_block(d, |b| {
        shifted_sums(&x[b * d.s..(b + 1) * d.s], shift[b % d.c])
    });
    let m = d.per_channel() as f64;
    per_channel_sums(&partial, d.c)
        .into_iter()
        .zip(&shift)
        .map(|((s, q), &k)| {
            let mean_shifted = s / m;
            (
                k as f64 + mean_shifted,
                (q / m - mean_shifted * mean_shifted).max(0.0),
            )
        })
        .collect()
}

/// Per-channel `(Σ g, Σ g·(x − mean))` in f64 of two contiguous `[n, c, s]` buffers.
pub(super) fn channel_grad_sums(g: &[f32], x: &[f32], mean: &[f32], d: Dims) -> Vec<(f64, f64)> {
    let partial = per_block(d, |b| {
        let r = b * d.s..(b + 1) * d.s;
        grad_sums(&g[r.clone()], &x[r], mean[b % d.c])
    });
    per_channel_sums(&partial, d.c)
}

fn affine_into(p: Affine, a: &[f32], b: Option<&[f32]>, out: &mut [MaybeUninit<f32>]) {
    // `map_affine` relies on every slot being written.
    assert_eq!(a.len(), out.len(), "batch_norm: block length mismatch");
    match b {
        Some(b) => {
            assert_eq!(b.len(), out.len(), "batch_norm: block length mismatch");
            for ((o, &av), &bv) in out.iter_mut().zip(a).zip(b) {
                o.write(p.apply(av, bv));
            }
        }
        None => {
            for (o, &av) in out.iter_mut().zip(a) {
                o.write(p.apply(av, 0.0));
            }
        }
    }
}

fn affine_in_place(p: Affine, a: &mut [f32], b: Option<&[f32]>) {
    match b {
        Some(b) => {
            for (av, &bv) in a.iter_mut().zip(b) {
                *av = p.apply(*av, bv);
            }
        }
        None => {
            for av in a.iter_mut() {
                *av = p.apply(*av, 0.0);
            }
        }
    }
}

/// `params[channel].apply(a, b)` for every element of the f32 `[n, c, …]`
/// tensor `a` (and of `b`, a contiguous buffer of the same shape, when given).
/// Writes into `a`'s own buffer when it is uniquely owned, else into a new one
/// that is never zero-filled first.
pub(super) fn map_affine(
    a: FlexTensor,
    b: Option<&[f32]>,
    d: Dims,
    params: &[Affine],
) -> FlexTensor {
    let mut a = a.into_contiguous();
    let block_b = |blk: usize| b.map(|b| &b[blk * d.s..(blk + 1) * d.s]);
    if let Some(buf) = a.try_storage_mut::<f32>() {
        for_blocks(buf, d, |blk, vals| {
            affine_in_place(params[blk % d.c], vals, block_b(blk))
        });
        return a;
    }
    let src: &[f32] = a.storage();
    let len = src.len();
    let mut out: Vec<f32> = Vec::with_capacity(len);
    for_blocks(&mut out.spare_capacity_mut()[..len], d, |blk, slots| {
        let vals = &src[blk * d.s..(blk + 1) * d.s];
        affine_into(params[blk % d.c], vals, block_b(blk), slots)
    });
    // SAFETY: `for_blocks` hands every `s`-long chunk of the first `len` slots
    // to `affine_into`, which writes each slot of its chunk (lengths asserted).
    unsafe { out.set_len(len) };
    let shape = a.layout().shape().clone();
    FlexTensor::new(
        Bytes::from_elems(out),
        Layout::contiguous(shape),
        DType::F32,
    )
}
