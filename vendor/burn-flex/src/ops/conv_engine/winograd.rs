//! Winograd F(2×2, 3×3) for stride-1, undilated, ungrouped 3×3 convolutions
//! (patch 12), f32 only.
//!
//! Why: the im2col engine spends 9 multiply-adds per input channel per output
//! pixel and first copies every input pixel nine times into a panel. Winograd's
//! minimal filtering (Lavin & Gray, "Fast Algorithms for Convolutional Neural
//! Networks", 2016) computes each 2×2 output tile from a 4×4 input tile with
//! 16 multiply-adds per channel pair instead of 36 (2.25× fewer), as 16
//! independent GEMMs `M_k = U_k · V_k` over the transformed weight `U = G g Gᵀ`
//! and the transformed input tiles `V = Bᵀ d B`; the output is `Y = Aᵀ M A`.
//! F(2, 3) keeps the transforms' constants at 0, ±1 and ½, so its f32 error
//! stays within a few ulps of the direct sum (F(4, 3) trades more of it for
//! 4× fewer multiplies and is not used).
//!
//! Layout: a task is one image and a run of tile rows (≈ [`TILE_TARGET`] tiles,
//! at least two tasks per worker), with per-thread scratch holding `V`
//! `[16, c_in, n]` and `M` `[16, c_out, n]` for its `n` tiles. The transforms
//! run over whole tile rows with the tile index innermost, so they vectorise;
//! the GEMMs are the `gemm` crate's, as in the rest of the engine.

use alloc::vec;
use alloc::vec::Vec;

use super::backward::chunked_sum;
use super::epilogue::Activation;
use super::geometry::{Geometry, rows_per_task};
use super::{Shared, for_each_task, threads};

/// Tiles (GEMM columns) per task: `V` and `M` of a 64-channel layer then
/// take 16 · 64 · 192 · 4 B = 768 KiB each, near a core's L2. Not tuned: no
/// other value was measured.
const TILE_TARGET: usize = 192;

/// Whether Winograd F(2×2, 3×3) computes this convolution.
pub fn takes(g: &Geometry) -> bool {
    g.kh == 3 && g.kw == 3 && g.sh == 1 && g.sw == 1 && g.dh == 1 && g.dw == 1 && g.groups == 1
}

/// `U = G w Gᵀ` for every (output, input) channel pair as 16 matrices
/// `[c_out, c_in]` (index `4i + j` for the 4×4 entry (i, j)); `w(co, ci)`
/// gives the 3×3 filter row-major.
pub(super) fn transform_weight(
    c_out: usize,
    c_in: usize,
    w: impl Fn(usize, usize) -> [f32; 9],
) -> Vec<f32> {
    let plane = c_out * c_in;
    let mut u = vec![0f32; 16 * plane];
    for co in 0..c_out {
        for ci in 0..c_in {
            let f = w(co, ci);
            // G = [[1, 0, 0], [½, ½, ½], [½, −½, ½], [0, 0, 1]]; first G·f (4×3).
            let mut t = [[0f32; 3]; 4];
            for c in 0..3 {
                let (a, b, d) = (f[c], f[3 + c], f[6 + c]);
                t[0][c] = a;
                t[1][c] = 0.5 * (a + b + d);
                t[2][c] = 0.5 * (a - b + d);
                t[3][c] = d;
            }
            for (i, r) in t.iter().enumerate() {
                let (a, b, d) = (r[0], r[1], r[2]);
                let row = [a, 0.5 * (a + b + d), 0.5 * (a - b + d), d];
                for (j, v) in row.into_iter().enumerate() {
                    u[(4 * i + j) * plane + co * c_in + ci] = v;
                }
            }
        }
    }
    u
}

/// The forward weight `[c_out, c_in, 3, 3]` transformed.
pub(super) fn forward_weight(g: &Geometry, ws: &[f32]) -> Vec<f32> {
    transform_weight(g.c_out, g.c_in, |co, ci| {
        ws[(co * g.c_in + ci) * 9..][..9].try_into().unwrap()
    })
}

/// Output `[batch, c_out, oh, ow]` of the convolution `g` of `xs` with the
/// transformed weight `u` ([`transform_weight`]), plus `bias` per channel,
/// through `act` (applied by each task to the rows it wrote).
pub(super) fn conv2d(
    g: &Geometry,
    xs: &[f32],
    u: &[f32],
    bias: Option<&[f32]>,
    act: Activation,
) -> Vec<f32> {
    debug_assert!(takes(g));
    let (th, tw) = (g.oh.div_ceil(2), g.ow.div_ceil(2));
    let rows = rows_per_task(th, tw, TILE_TARGET, g.batch, threads());
    let chunks = th.div_ceil(rows);
    let len = g.batch * g.c_out * g.out_plane();
    let mut out: Vec<f32> = Vec::with_capacity(len);
    let dst = Shared(out.as_mut_ptr());
    for_each_task(g.batch * chunks, |t, scratch: &mut Vec<f32>| {
        let b = t / chunks;
        let r0 = (t % chunks) * rows;
        let r1 = (r0 + rows).min(th);
        // SAFETY: task (b, r0..r1) writes output rows 2·r0..2·r1 of image b
        // only, and `out` outlives `for_each_task`.
        unsafe { task(g, xs, u, bias, dst, b, r0, r1, scratch) };
        let (y0, y1) = (2 * r0, (2 * r1).min(g.oh));
        let off = b * g.c_out * g.out_plane() + y0 * g.ow;
        // SAFETY: rows `y0..y1` of image b are this task's, written just above.
        unsafe { act.apply_to_planes(dst, off, g.c_out, g.out_plane(), (y1 - y0) * g.ow) };
    });
    // SAFETY: the tasks cover every tile row of every image, and each writes
    // every channel of its output rows (`winograd_matches_reference` runs on NaN-filled
    // freed blocks).
    unsafe { out.set_len(len) };
    out
}

/// Weight gradient `[c_out, c_in, 3, 3]` of the convolution `g` from its input
/// `xs` and output gradient `dys`: `dW = Gᵀ (Σ_tiles (A dY Aᵀ) ⊙ (Bᵀ d B)) G`,
/// the transpose of the forward's chain. Per task, 16 GEMMs
/// `dU_k[c_out, c_in] += dM_k[c_out, n] · V_kᵀ[n, c_in]` with the tiles as
/// depth; tasks are grouped by [`chunked_sum`] into at most 8 partial sums,
/// added in order at the end (the result does not depend on the thread count).
pub(super) fn weight_grad(g: &Geometry, xs: &[f32], dys: &[f32]) -> Vec<f32> {
    debug_assert!(takes(g));
    let (th, tw) = (g.oh.div_ceil(2), g.ow.div_ceil(2));
    let rows = rows_per_task(th, tw, TILE_TARGET, g.batch, 1);
    let per_image = th.div_ceil(rows);
    let tasks = g.batch * per_image;
    let plane = g.c_out * g.c_in;
    // SAFETY: a task writes (first) or adds to the 16 `[c_out, c_in]` blocks of
    // `dU` at `acc` and nothing else.
    let du = unsafe {
        chunked_sum(tasks, 16 * plane, |t, acc: Shared<f32>, first, scratch| {
            let (b, r0) = (t / per_image, (t % per_image) * rows);
            let r1 = (r0 + rows).min(th);
            weight_task(g, xs, dys, acc.0, first, b, r0, r1, scratch);
        })
    };
    // dW = Gᵀ dU G, Gᵀ = [[1, ½, ½, 0], [0, ½, −½, 0], [0, ½, ½, 1]].
    let mut dw = vec![0f32; plane * 9];
    for (at, out) in dw.chunks_exact_mut(9).enumerate() {
        let d = |i: usize, j: usize| du[(4 * i + j) * plane + at];
        // Column j of dU, then t = Gᵀ dU (3×4) one column at a time.
        let cols: [[f32; 4]; 4] = core::array::from_fn(|j| [d(0, j), d(1, j), d(2, j), d(3, j)]);
        let t = [
            cols.map(|c| c[0] + 0.5 * (c[1] + c[2])),
            cols.map(|c| 0.5 * (c[1] - c[2])),
            cols.map(|c| 0.5 * (c[1] + c[2]) + c[3]),
        ];
        for (a, r) in t.iter().enumerate() {
            out[3 * a] = r[0] + 0.5 * (r[1] + r[2]);
            out[3 * a + 1] = 0.5 * (r[1] - r[2]);
            out[3 * a + 2] = 0.5 * (r[1] + r[2]) + r[3];
        }
    }
    dw
}

/// One image's tile rows `r0..r1` of the weight gradient, into (or, unless
/// `first`, onto) the `[16, c_out, c_in]` partial sums at `acc`.
///
/// # Safety
/// `acc` points at `16 · c_out · c_in` values no other thread touches,
/// initialised unless `first`.
#[allow(clippy::too_many_arguments)]
unsafe fn weight_task(
    g: &Geometry,
    xs: &[f32],
    dys: &[f32],
    acc: *mut f32,
    first: bool,
    b: usize,
    r0: usize,
    r1: usize,
    scratch: &mut Vec<f32>,
) {
    let tw = g.ow.div_ceil(2);
    let n = (r1 - r0) * tw;
    let (v_len, m_len) = (16 * g.c_in * n, 16 * g.c_out * n);
    let row_len = 2 * tw + 2;
    let need = v_len + m_len + row_len + 16 * tw;
    if scratch.len() < need {
        scratch.resize(need, 0.0);
    }
    let (v, rest) = scratch.split_at_mut(v_len);
    let (dm, rest) = rest.split_at_mut(m_len);
    let (padded, rest) = rest.split_at_mut(row_len);
    let rt = &mut rest[..16 * tw];
    let image = &xs[b * g.c_in * g.in_plane()..][..g.c_in * g.in_plane()];
    kernels::input(g, image, r0, r1, v, padded, rt);
    let dy_image = &dys[b * g.c_out * g.out_plane()..][..g.c_out * g.out_plane()];
    kernels::output_grad(g, dy_image, r0, r1, dm, rt);
    let plane = g.c_out * g.c_in;
    for k in 0..16 {
        // SAFETY: dU_k `[c_out, c_in]` at `acc`, dM_k `[c_out, n]` and V_k
        // `[c_in, n]` (read transposed through its strides) are row-major
        // blocks of `acc`, `dm` and `v`.
        unsafe {
            gemm::gemm(
                g.c_out,
                g.c_in,
                n,
                acc.add(k * plane),
                1,
                g.c_in as isize,
                !first,
                dm.as_ptr().add(k * g.c_out * n),
                1,
                n as isize,
                v.as_ptr().add(k * g.c_in * n),
                n as isize,
                1,
                1.0,
                1.0,
                false,
                false,
                false,
                gemm::Parallelism::None,
            );
        }
    }
}

/// One image's tile rows `r0..r1`: input transform, 16 GEMMs, output transform.
///
/// # Safety
/// `dst` points at the `[batch, c_out, oh, ow]` output and no other thread
/// writes output rows `2·r0..2·r1` of image `b`.
#[allow(clippy::too_many_arguments)]
unsafe fn task(
    g: &Geometry,
    xs: &[f32],
    u: &[f32],
    bias: Option<&[f32]>,
    dst: Shared<f32>,
    b: usize,
    r0: usize,
    r1: usize,
    scratch: &mut Vec<f32>,
) {
    let tw = g.ow.div_ceil(2);
    let n = (r1 - r0) * tw;
    let (v_len, m_len) = (16 * g.c_in * n, 16 * g.c_out * n);
    // Padded input row (2·tw + 2 columns), 16 row-transformed rows of tw
    // (four input rows), and 8 half-transformed output rows of tw.
    let row_len = 2 * tw + 2;
    let need = v_len + m_len + row_len + 16 * tw + 8 * tw;
    if scratch.len() < need {
        scratch.resize(need, 0.0);
    }
    let (v, rest) = scratch.split_at_mut(v_len);
    let (m, rest) = rest.split_at_mut(m_len);
    let (padded, rest) = rest.split_at_mut(row_len);
    let (rt, rest) = rest.split_at_mut(16 * tw);
    let half = &mut rest[..8 * tw];

    let image = &xs[b * g.c_in * g.in_plane()..][..g.c_in * g.in_plane()];
    kernels::input(g, image, r0, r1, v, padded, rt);

    let (cu, ci_n) = (g.c_out * g.c_in, g.c_in);
    for k in 0..16 {
        // SAFETY: M_k `[c_out, n]`, U_k `[c_out, c_in]` and V_k `[c_in, n]` are
        // row-major blocks inside `m`, `u` and `v`.
        unsafe {
            gemm::gemm(
                g.c_out,
                n,
                ci_n,
                m.as_mut_ptr().add(k * g.c_out * n),
                1,
                n as isize,
                false,
                u.as_ptr().add(k * cu),
                1,
                ci_n as isize,
                v.as_ptr().add(k * ci_n * n),
                1,
                n as isize,
                1.0,
                1.0,
                false,
                false,
                false,
                gemm::Parallelism::None,
            );
        }
    }

    // SAFETY: forwarded from the caller.
    unsafe { kernels::output(g, m, bias, dst, b, r0, r1, half) };
}

/// The transforms, written so that LLVM vectorises them (the tile index
/// innermost, a few streams per loop), with an AVX2 + FMA clone chosen at run
/// time as in `sigmoid::kernels` (flex is built for baseline x86-64).
mod kernels {
    use super::{Geometry, Shared};

    /// `V = Bᵀ d B` for tile rows `r0..r1` of one image into `v` `[16, c_in, n]`.
    #[inline(always)]
    fn input_body(
        g: &Geometry,
        image: &[f32],
        r0: usize,
        r1: usize,
        v: &mut [f32],
        padded: &mut [f32],
        rt: &mut [f32],
    ) {
        let tw = g.ow.div_ceil(2);
        let n = (r1 - r0) * tw;
        for ci in 0..g.c_in {
            let plane = &image[ci * g.in_plane()..][..g.in_plane()];
            // `slot[i]` is where input row 2r + i's row transform lives; rows
            // 2r + 2 and 2r + 3 are rows 0 and 1 of tile row r + 1.
            let mut slot = [0usize, 1, 2, 3];
            for r in r0..r1 {
                let fresh = if r == r0 { 0 } else { 2 };
                for i in fresh..4 {
                    let q = &mut rt[4 * slot[i] * tw..][..4 * tw];
                    row_transform(g, plane, 2 * r + i, tw, padded, q);
                }
                let col = (r - r0) * tw;
                for j in 0..4 {
                    let a = |i: usize| &rt[(4 * slot[i] + j) * tw..][..tw];
                    let (a0, a1, a2, a3) = (a(0), a(1), a(2), a(3));
                    let at = |i: usize| (4 * i + j) * g.c_in * n + ci * n + col;
                    let v0 = &mut v[at(0)..][..tw];
                    for t in 0..tw {
                        v0[t] = a0[t] - a2[t];
                    }
                    let v1 = &mut v[at(1)..][..tw];
                    for t in 0..tw {
                        v1[t] = a1[t] + a2[t];
                    }
                    let v2 = &mut v[at(2)..][..tw];
                    for t in 0..tw {
                        v2[t] = a2[t] - a1[t];
                    }
                    let v3 = &mut v[at(3)..][..tw];
                    for t in 0..tw {
                        v3[t] = a1[t] - a3[t];
                    }
                }
                slot = [slot[2], slot[3], slot[0], slot[1]];
            }
        }
    }

    /// `q[j][t]` = entry j of `d · B` for tile t, where `d` is padded input
    /// row `y − ph` (zero outside the image), columns `2t − pw .. 2t − pw + 4`.
    #[inline(always)]
    fn row_transform(
        g: &Geometry,
        plane: &[f32],
        y: usize,
        tw: usize,
        padded: &mut [f32],
        q: &mut [f32],
    ) {
        let Some(y) = y.checked_sub(g.ph).filter(|&y| y < g.h) else {
            q.fill(0.0);
            return;
        };
        // Padded column c reads input column c − pw.
        let lo = g.pw.min(padded.len());
        let len = g.w.min(padded.len() - lo);
        padded[..lo].fill(0.0);
        padded[lo..lo + len].copy_from_slice(&plane[y * g.w..][..len]);
        padded[lo + len..].fill(0.0);
        let (q0, rest) = q.split_at_mut(tw);
        let (q1, rest) = rest.split_at_mut(tw);
        let (q2, q3) = rest.split_at_mut(tw);
        let p = &padded[..2 * tw + 2];
        // Bᵀ = [[1, 0, −1, 0], [0, 1, 1, 0], [0, −1, 1, 0], [0, 1, 0, −1]].
        for t in 0..tw {
            let (x0, x1, x2, x3) = (p[2 * t], p[2 * t + 1], p[2 * t + 2], p[2 * t + 3]);
            q0[t] = x0 - x2;
            q1[t] = x1 + x2;
            q2[t] = x2 - x1;
            q3[t] = x1 - x3;
        }
    }

    /// `Y = Aᵀ M A` plus the bias, written into output rows `2·r0..2·r1` of
    /// image `b`.
    ///
    /// # Safety
    /// As [`super::task`].
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn output_body(
        g: &Geometry,
        m: &[f32],
        bias: Option<&[f32]>,
        dst: Shared<f32>,
        b: usize,
        r0: usize,
        r1: usize,
        half: &mut [f32],
    ) {
        let tw = g.ow.div_ceil(2);
        let n = (r1 - r0) * tw;
        let out_image = b * g.c_out * g.out_plane();
        let (sa, sb) = half.split_at_mut(4 * tw);
        for co in 0..g.c_out {
            let beta = bias.map_or(0.0, |bs| bs[co]);
            for r in r0..r1 {
                let col = co * n + (r - r0) * tw;
                let mk = |k: usize| &m[k * g.c_out * n + col..][..tw];
                // Aᵀ = [[1, 1, 1, 0], [0, 1, −1, −1]]: first over the rows of M.
                for j in 0..4 {
                    let (m0, m1, m2, m3) = (mk(j), mk(4 + j), mk(8 + j), mk(12 + j));
                    let (a, bb) = (&mut sa[j * tw..][..tw], &mut sb[j * tw..][..tw]);
                    for t in 0..tw {
                        a[t] = m0[t] + m1[t] + m2[t];
                        bb[t] = m1[t] - m2[t] - m3[t];
                    }
                }
                for (dy, s) in [(0, &*sa), (1, &*sb)] {
                    let oy = 2 * r + dy;
                    if oy >= g.oh {
                        continue;
                    }
                    let off = out_image + co * g.out_plane() + oy * g.ow;
                    // SAFETY: row `oy` of channel `co` of image `b` belongs to
                    // this task (the caller's contract).
                    let row = unsafe { core::slice::from_raw_parts_mut(dst.at(off), g.ow) };
                    let (s0, s1) = (&s[..tw], &s[tw..2 * tw]);
                    let (s2, s3) = (&s[2 * tw..3 * tw], &s[3 * tw..4 * tw]);
                    let pairs = g.ow / 2;
                    let (even, _) = row.split_at_mut(2 * pairs);
                    for t in 0..pairs {
                        even[2 * t] = s0[t] + s1[t] + s2[t] + beta;
                        even[2 * t + 1] = s1[t] - s2[t] - s3[t] + beta;
                    }
                    if g.ow % 2 == 1 {
                        row[g.ow - 1] = s0[pairs] + s1[pairs] + s2[pairs] + beta;
                    }
                }
            }
        }
    }

    /// `dM = A dY Aᵀ` for tile rows `r0..r1` of one image's output gradient
    /// into `dm` `[16, c_out, n]`, zero beyond the output's last row and
    /// column; `rows` is scratch for 12 rows of `tw`.
    #[inline(always)]
    fn output_grad_body(
        g: &Geometry,
        dy: &[f32],
        r0: usize,
        r1: usize,
        dm: &mut [f32],
        rows: &mut [f32],
    ) {
        let tw = g.ow.div_ceil(2);
        let n = (r1 - r0) * tw;
        let (y0, rest) = rows.split_at_mut(2 * tw);
        let (y1, rest) = rest.split_at_mut(2 * tw);
        let (h0, rest) = rest.split_at_mut(4 * tw);
        let h1 = &mut rest[..4 * tw];
        for co in 0..g.c_out {
            let plane = &dy[co * g.out_plane()..][..g.out_plane()];
            for r in r0..r1 {
                // A = [[1, 0], [1, 1], [1, −1], [0, −1]]: first h_i = (A · row i
                // of the 2×2 tile) for both rows, as four rows of tw each.
                for (dy_row, y, h) in [(0, &mut *y0, &mut *h0), (1, &mut *y1, &mut *h1)] {
                    let oy = 2 * r + dy_row;
                    if oy < g.oh {
                        y[..g.ow].copy_from_slice(&plane[oy * g.ow..][..g.ow]);
                        y[g.ow..].fill(0.0);
                    } else {
                        y.fill(0.0);
                    }
                    let (q0, rest) = h.split_at_mut(tw);
                    let (q1, rest) = rest.split_at_mut(tw);
                    let (q2, q3) = rest.split_at_mut(tw);
                    let y = &y[..2 * tw];
                    for t in 0..tw {
                        let (a, b) = (y[2 * t], y[2 * t + 1]);
                        q0[t] = a;
                        q1[t] = a + b;
                        q2[t] = a - b;
                        q3[t] = -b;
                    }
                }
                let col = co * n + (r - r0) * tw;
                let at = |i: usize, j: usize| (4 * i + j) * g.c_out * n + col;
                // Then down the columns: dM[i][j] = (A · (h_0[j], h_1[j]))[i].
                for j in 0..4 {
                    let (a, b) = (&h0[j * tw..][..tw], &h1[j * tw..][..tw]);
                    dm[at(0, j)..][..tw].copy_from_slice(a);
                    let d1 = &mut dm[at(1, j)..][..tw];
                    for t in 0..tw {
                        d1[t] = a[t] + b[t];
                    }
                    let d2 = &mut dm[at(2, j)..][..tw];
                    for t in 0..tw {
                        d2[t] = a[t] - b[t];
                    }
                    let d3 = &mut dm[at(3, j)..][..tw];
                    for t in 0..tw {
                        d3[t] = -b[t];
                    }
                }
            }
        }
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    fn output_grad_avx2(
        g: &Geometry,
        dy: &[f32],
        r0: usize,
        r1: usize,
        dm: &mut [f32],
        rows: &mut [f32],
    ) {
        output_grad_body(g, dy, r0, r1, dm, rows)
    }

    pub(super) fn output_grad(
        g: &Geometry,
        dy: &[f32],
        r0: usize,
        r1: usize,
        dm: &mut [f32],
        rows: &mut [f32],
    ) {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { output_grad_avx2(g, dy, r0, r1, dm, rows) };
        }
        output_grad_body(g, dy, r0, r1, dm, rows)
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    fn input_avx2(
        g: &Geometry,
        image: &[f32],
        r0: usize,
        r1: usize,
        v: &mut [f32],
        padded: &mut [f32],
        rt: &mut [f32],
    ) {
        input_body(g, image, r0, r1, v, padded, rt)
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn output_avx2(
        g: &Geometry,
        m: &[f32],
        bias: Option<&[f32]>,
        dst: Shared<f32>,
        b: usize,
        r0: usize,
        r1: usize,
        half: &mut [f32],
    ) {
        unsafe { output_body(g, m, bias, dst, b, r0, r1, half) }
    }

    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    fn has_avx2() -> bool {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }

    pub(super) fn input(
        g: &Geometry,
        image: &[f32],
        r0: usize,
        r1: usize,
        v: &mut [f32],
        padded: &mut [f32],
        rt: &mut [f32],
    ) {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { input_avx2(g, image, r0, r1, v, padded, rt) };
        }
        input_body(g, image, r0, r1, v, padded, rt)
    }

    /// # Safety
    /// As [`super::task`].
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn output(
        g: &Geometry,
        m: &[f32],
        bias: Option<&[f32]>,
        dst: Shared<f32>,
        b: usize,
        r0: usize,
        r1: usize,
        half: &mut [f32],
    ) {
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 and FMA; the rest is the caller's.
            return unsafe { output_avx2(g, m, bias, dst, b, r0, r1, half) };
        }
        unsafe { output_body(g, m, bias, dst, b, r0, r1, half) }
    }
}
