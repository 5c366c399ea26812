//! The im2col panel of one tile and its adjoint (col2im).
//!
//! A panel is a row-major `[k, n]` matrix: row `(c, i, j)` (input channel,
//! kernel row, kernel column — the weight's own order) holds, for each of the
//! tile's `n = rows * ow` output pixels, the input value that kernel tap
//! multiplies. It is built straight from the NCHW input (no NHWC copy of the
//! whole tensor) and only for one tile at a time, so it stays in cache between
//! being written and being packed by the GEMM. For stride 1 each panel row is a
//! set of contiguous copies of input rows; padding becomes explicit zeros at
//! the row ends, computed from [`Geometry::valid_cols`] instead of per-element
//! bounds checks.

use super::Elem;
use super::geometry::Geometry;

/// Fill `panel` (`[g.k(), (r1 - r0) * g.ow]`, row `r` starting at `r * ld`,
/// `ld ≥ (r1 - r0) * g.ow`; entries between a row's end and the next row's
/// start are left as they are) from `x_group`, the `g.cpg` input planes of one
/// image and group, for output rows `r0..r1`.
pub(crate) fn im2col_rows<T: Elem>(
    g: &Geometry,
    x_group: &[T],
    r0: usize,
    r1: usize,
    panel: &mut [T],
    ld: usize,
) {
    im2col_rows_with(g, x_group, r0, r1, panel, ld, true);
}

/// [`im2col_rows`] with patch 7's stride-1 block copy ([`contiguous_rows`])
/// and patch 8's stride-2 gather ([`every_other`]) on or off (`fast`; off: the
/// loop as it was, kept for the test and the bench that compare the two). A
/// `step_by` gather for stride 2 was tried first and measured 0.47–0.79× as
/// fast as the indexed loop.
pub(crate) fn im2col_rows_with<T: Elem>(
    g: &Geometry,
    x_group: &[T],
    r0: usize,
    r1: usize,
    panel: &mut [T],
    ld: usize,
    fast: bool,
) {
    let n = (r1 - r0) * g.ow;
    debug_assert!(ld >= n);
    let plane = g.in_plane();
    for c in 0..g.cpg {
        let x_plane = &x_group[c * plane..(c + 1) * plane];
        for i in 0..g.kh {
            for j in 0..g.kw {
                let row_idx = (c * g.kh + i) * g.kw + j;
                let row = &mut panel[row_idx * ld..row_idx * ld + n];
                let (lo, hi) = g.valid_cols(j);
                if fast && g.sw == 1 && g.sh == 1 && g.ow == g.w {
                    contiguous_rows(g, x_plane, r0, r1, i, j, row);
                    continue;
                }
                for (t, r) in (r0..r1).enumerate() {
                    let seg = &mut row[t * g.ow..(t + 1) * g.ow];
                    let Some(ih) = g.input_row(r, i) else {
                        seg.fill(T::ZERO);
                        continue;
                    };
                    let src = &x_plane[ih * g.w..(ih + 1) * g.w];
                    seg[..lo].fill(T::ZERO);
                    seg[hi..].fill(T::ZERO);
                    if hi > lo {
                        let first = lo * g.sw + j * g.dw - g.pw;
                        if g.sw == 1 {
                            seg[lo..hi].copy_from_slice(&src[first..first + (hi - lo)]);
                        } else if fast && g.sw == 2 && hi - lo >= PAIRS_MIN_PIXELS {
                            every_other(&src[first..], &mut seg[lo..hi]);
                        } else {
                            for (o, v) in seg[lo..hi].iter_mut().enumerate() {
                                *v = src[first + o * g.sw];
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Shortest stride-2 row (valid pixels) that [`every_other`] and
/// [`add_every_other`] take; shorter rows keep the indexed loop.
pub(crate) const PAIRS_MIN_PIXELS: usize = 16;

/// `out[o] = src[2 o]`: stride-2 columns (the downsampling 3×3 layers) as
/// pairs of `src`, a loop the compiler vectorises with shuffles, where the
/// general loop's `src[first + o * sw]` with a run-time stride is scalar.
/// Rows shorter than 16 keep that loop: 8-pixel rows ran 0.8× as fast here.
fn every_other<T: Elem>(src: &[T], out: &mut [T]) {
    let Some(last) = out.len().checked_sub(1) else {
        return;
    };
    for (v, pair) in out[..last].iter_mut().zip(src[..2 * last].chunks_exact(2)) {
        *v = pair[0];
    }
    out[last] = src[2 * last];
}

/// One panel row of [`im2col_rows`] for stride 1 in both directions and output
/// rows as wide as the input's (`ow == w`, "same" padding): the valid output
/// rows `t0..t1` then read consecutive input rows at the same column offset,
/// so their values are one contiguous run of the input plane. One copy of that
/// run (chicktrain patch 7), then the padding columns of each row set to zero,
/// instead of a copy and two fills per output row; same values as the general
/// loop.
fn contiguous_rows<T: Elem>(
    g: &Geometry,
    x_plane: &[T],
    r0: usize,
    r1: usize,
    i: usize,
    j: usize,
    row: &mut [T],
) {
    let ow = g.ow;
    let (lo, hi) = g.valid_cols(j);
    // Valid output rows form one range: ih = r + i·dh − ph must lie in 0..h.
    let valid = |r: usize| g.input_row(r, i).is_some();
    let Some(t0) = (r0..r1).position(valid) else {
        row.fill(T::ZERO);
        return;
    };
    let t1 = t0 + (r0 + t0..r1).take_while(|&r| valid(r)).count();
    row[..t0 * ow].fill(T::ZERO);
    row[t1 * ow..].fill(T::ZERO);
    if hi <= lo {
        row[t0 * ow..t1 * ow].fill(T::ZERO);
        return;
    }
    let ih0 = g.input_row(r0 + t0, i).expect("t0 is a valid row");
    // seg(t)[lo..hi] = x[ih0 + (t − t0), first..first + (hi − lo)], first = lo + j·dw − pw;
    // with w == ow these runs are one slice of the plane.
    let first = lo + j * g.dw - g.pw;
    let len = (t1 - t0 - 1) * ow + (hi - lo);
    let src = ih0 * g.w + first;
    row[t0 * ow + lo..t0 * ow + lo + len].copy_from_slice(&x_plane[src..src + len]);
    for t in t0..t1 {
        row[t * ow..t * ow + lo].fill(T::ZERO);
        row[t * ow + hi..(t + 1) * ow].fill(T::ZERO);
    }
}

/// Adjoint of [`im2col_rows`]: add every panel entry back onto the input
/// position it was read from (`dx_group`, the `g.cpg` gradient planes of one
/// image and group). Entries that came from padding are dropped.
pub(crate) fn col2im_rows<T: Elem>(
    g: &Geometry,
    panel: &[T],
    r0: usize,
    r1: usize,
    dx_group: &mut [T],
) {
    col2im_rows_with(g, panel, r0, r1, dx_group, true);
}

/// [`col2im_rows`] with patch 10's stride-2 scatter ([`add_every_other`]) on
/// or off (`fast`; off: the loop as it was, kept for the test and the bench
/// that compare the two). Each input position receives its additions in the
/// same order either way (one panel row adds at most once to a position), so
/// the two agree bit for bit.
pub(crate) fn col2im_rows_with<T: Elem>(
    g: &Geometry,
    panel: &[T],
    r0: usize,
    r1: usize,
    dx_group: &mut [T],
    fast: bool,
) {
    let n = (r1 - r0) * g.ow;
    let plane = g.in_plane();
    for c in 0..g.cpg {
        let dx_plane = &mut dx_group[c * plane..(c + 1) * plane];
        for i in 0..g.kh {
            for j in 0..g.kw {
                let row_idx = (c * g.kh + i) * g.kw + j;
                let row = &panel[row_idx * n..(row_idx + 1) * n];
                let (lo, hi) = g.valid_cols(j);
                if hi <= lo {
                    continue;
                }
                for (t, r) in (r0..r1).enumerate() {
                    let Some(ih) = g.input_row(r, i) else {
                        continue;
                    };
                    let seg = &row[t * g.ow + lo..t * g.ow + hi];
                    let dst = &mut dx_plane[ih * g.w..(ih + 1) * g.w];
                    let first = lo * g.sw + j * g.dw - g.pw;
                    if g.sw == 1 {
                        for (d, &v) in dst[first..first + (hi - lo)].iter_mut().zip(seg) {
                            *d = *d + v;
                        }
                    } else if fast && g.sw == 2 && hi - lo >= PAIRS_MIN_PIXELS {
                        add_every_other(seg, &mut dst[first..]);
                    } else {
                        for (o, &v) in seg.iter().enumerate() {
                            let d = &mut dst[first + o * g.sw];
                            *d = *d + v;
                        }
                    }
                }
            }
        }
    }
}

/// `dst[2 o] += src[o]`: the adjoint of [`every_other`], for the input
/// gradient of stride-2 layers, as pairs of `dst` (the general loop's
/// `dst[first + o * sw]` with a run-time stride is scalar).
fn add_every_other<T: Elem>(src: &[T], dst: &mut [T]) {
    let Some(last) = src.len().checked_sub(1) else {
        return;
    };
    for (pair, &v) in dst[..2 * last].chunks_exact_mut(2).zip(&src[..last]) {
        pair[0] = pair[0] + v;
    }
    dst[2 * last] = dst[2 * last] + src[last];
}

/// Row stride of the weight gradient's panel for tiles of `n` pixels: `n`
/// plus 16 elements. The weight gradient's GEMM reads the panel transposed
/// (its pixels are the GEMM's depth), i.e. as a column-major right-hand side,
/// which the `gemm` crate does not repack for small left-hand sides; with a
/// power-of-two stride (tiles are often 256 or 512 pixels) the columns it
/// reads side by side fall into the same cache sets. 16 more elements break that
/// and keep rows 64-byte aligned: the GEMM alone ran 1.4–1.9× faster at
/// 512-pixel tiles (PATCH.md, patch 6).
pub(crate) fn weight_panel_ld(n: usize) -> usize {
    n + 16
}
