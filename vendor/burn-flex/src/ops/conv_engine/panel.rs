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

/// Row stride of the weight gradient's panel for tiles of `n` pixels: `n`
/// plus 16 elements. The weight gradient's GEMM reads the panel transposed
/// (its pixels are the GEMM's depth), i.e. as a column-major right-hand side,
/// which the `gemm` crate does not repack for small left-hand sides; with a
/// power-of-two stride (tiles are often 256 or 512 pixels) the columns it
/// reads side by side fall into the same cache sets. 16 more elements break that
/// and keep rows 64-byte aligned: the GEMM alone ran 1.3–2× faster on
/// YOLO11n-seg's 3×3 shapes (PATCH.md, patch 6).
pub(crate) fn weight_panel_ld(n: usize) -> usize {
    n + 16
}
