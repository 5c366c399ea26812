//! Backward pass: input gradient as `col2im(W_g^T · dY_tile)`, weight gradient
//! as `Σ dY_tile · panel^T`, both GEMMs reading the NCHW tensors and the weight
//! through strides (no transposed copies).
//!
//! Summation order is fixed by the shape alone (never by thread scheduling):
//! the weight gradient splits its (image, tile) list into a fixed number of
//! chunks with tiles cut as for one thread, and adds the chunk sums in order.
//!
//! No zero-filled accumulators (chicktrain patch 5): the output buffers are
//! allocated uninitialised and the first GEMM into each block overwrites it
//! (`read_dst = false`, which the `gemm` crate honours without reading the
//! destination); only col2im, which adds overlapping windows, zeroes its
//! (image, group) block, inside the task that fills it.

use alloc::vec::Vec;

use super::geometry::Geometry;
use super::panel::{col2im_rows, im2col_rows, weight_panel_ld};
use super::{Elem, Shared, for_each_task, threads};
use crate::FlexTensor;

/// Partial sums of the weight gradient computed independently, then added in order.
pub(super) const WEIGHT_GRAD_CHUNKS: usize = 8;

/// Input gradient `[batch, c_in, h, w]` as a flat vector.
pub(super) fn x_grad<T: Elem>(g: &Geometry, weight: FlexTensor, dy: FlexTensor) -> Vec<T> {
    let weight = weight.to_contiguous();
    let dy = dy.to_contiguous();
    let ws: &[T] = weight.storage();
    let dys: &[T] = dy.storage();
    let len = g.batch * g.c_in * g.in_plane();
    let mut dx: Vec<T> = Vec::with_capacity(len);
    let dst = Shared(dx.as_mut_ptr());
    if g.is_pointwise() {
        // Each tile's gradient is a disjoint block of dX: split by tiles.
        let tiles = g.tiles(threads());
        for_each_task(g.batch * tiles.len(), |t, _: &mut Vec<T>| {
            let (r0, r1) = tiles[t % tiles.len()];
            for grp in 0..g.groups {
                // SAFETY: disjoint (image, rows, group) blocks of `dx`.
                unsafe { pointwise_x_tile(g, ws, dys, dst, t / tiles.len(), grp, r0, r1) };
            }
        });
        // SAFETY: the tiles cover every row of every (image, group) block,
        // and each GEMM overwrote its block (`read_dst = false`).
        unsafe { dx.set_len(len) };
        return dx;
    }
    // col2im of neighbouring tiles overlaps in input rows: a task owns a whole
    // (image, group) gradient plane set and walks its tiles in order.
    let tasks = g.batch * g.groups;
    let inner = if tasks < threads() && g.k() * g.mpg * g.out_plane() >= 1 << 21 {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    let tiles = g.tiles(1);
    for_each_task(tasks, |t, panel: &mut Vec<T>| {
        let (b, grp) = (t / g.groups, t % g.groups);
        let off = (b * g.c_in + grp * g.cpg) * g.in_plane();
        // SAFETY: task `t` alone writes this (image, group) block of `dx`;
        // it is zeroed (col2im adds into it) before the slice is made.
        let dx_group = unsafe {
            core::ptr::write_bytes(dst.at(off), 0, g.cpg * g.in_plane());
            core::slice::from_raw_parts_mut(dst.at(off), g.cpg * g.in_plane())
        };
        for &(r0, r1) in &tiles {
            let n = (r1 - r0) * g.ow;
            panel.resize(g.k() * n, T::ZERO);
            let dy_off = (b * g.c_out + grp * g.mpg) * g.out_plane() + r0 * g.ow;
            // panel[k, n] = W_g^T[k, mpg] · dY[mpg, n]; W_g is [mpg, k] row-major.
            unsafe {
                gemm::gemm(
                    g.k(),
                    n,
                    g.mpg,
                    panel.as_mut_ptr(),
                    1,
                    n as isize,
                    false,
                    ws[grp * g.mpg * g.k()..].as_ptr(),
                    g.k() as isize,
                    1,
                    dys[dy_off..].as_ptr(),
                    1,
                    g.out_plane() as isize,
                    T::ZERO,
                    T::ONE,
                    false,
                    false,
                    false,
                    inner,
                );
            }
            col2im_rows(g, &panel[..g.k() * n], r0, r1, dx_group);
        }
    });
    // SAFETY: the (image, group) tasks zeroed and filled every block.
    unsafe { dx.set_len(len) };
    dx
}

/// dX rows `r0..r1` of one image and group of a 1×1 stride-1 convolution:
/// `dX[cpg, n] = W_g^T[cpg, mpg] · dY[mpg, n]`, written in place.
///
/// # Safety
/// `dst` points at the `[batch, c_in, h, w]` gradient and no other thread
/// writes this block concurrently.
#[allow(clippy::too_many_arguments)]
unsafe fn pointwise_x_tile<T: Elem>(
    g: &Geometry,
    ws: &[T],
    dys: &[T],
    dst: Shared<T>,
    b: usize,
    grp: usize,
    r0: usize,
    r1: usize,
) {
    let n = (r1 - r0) * g.ow;
    let dx_off = (b * g.c_in + grp * g.cpg) * g.in_plane() + r0 * g.ow;
    let dy_off = (b * g.c_out + grp * g.mpg) * g.out_plane() + r0 * g.ow;
    unsafe {
        gemm::gemm(
            g.cpg,
            n,
            g.mpg,
            dst.at(dx_off),
            1,
            g.in_plane() as isize,
            false,
            ws[grp * g.mpg * g.cpg..].as_ptr(),
            g.cpg as isize,
            1,
            dys[dy_off..].as_ptr(),
            1,
            g.out_plane() as isize,
            T::ZERO,
            T::ONE,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// How the weight gradient lays out its panel (chicktrain patch 6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum WeightPanel {
    /// Row stride [`weight_panel_ld`]`(n)`: what runs.
    Padded,
    /// Row stride `n`: the layout before patch 6, kept so tests and the bench can
    /// compare the two (same sums, same order).
    #[cfg_attr(not(test), allow(dead_code))]
    Contiguous,
}

/// Weight gradient `[c_out, cpg, kh, kw]` as a flat vector.
pub(super) fn weight_grad<T: Elem>(g: &Geometry, x: FlexTensor, dy: FlexTensor) -> Vec<T> {
    weight_grad_with::<T>(g, x, dy, WeightPanel::Padded)
}

/// [`weight_grad`] with the panel layout chosen.
pub(crate) fn weight_grad_with<T: Elem>(
    g: &Geometry,
    x: FlexTensor,
    dy: FlexTensor,
    layout: WeightPanel,
) -> Vec<T> {
    let x = x.to_contiguous();
    let dy = dy.to_contiguous();
    let xs: &[T] = x.storage();
    let dys: &[T] = dy.storage();
    let len = g.c_out * g.k();
    let tiles = g.tiles(1);
    let tasks = g.batch * tiles.len();
    // SAFETY: a task writes the groups' `[mpg, k]` blocks, which tile the
    // `len` sums of `[c_out, k]`, and nothing else.
    unsafe {
        chunked_sum(tasks, len, |t, acc: Shared<T>, first, panel| {
            let (r0, r1) = tiles[t % tiles.len()];
            for grp in 0..g.groups {
                let acc = acc.at(grp * g.mpg * g.k());
                let tile = Tile {
                    b: t / tiles.len(),
                    grp,
                    r0,
                    r1,
                };
                weight_tile(g, xs, dys, tile, acc, first, panel, layout);
            }
        })
    }
}

/// `len` sums over `tasks` tasks, computed as at most [`WEIGHT_GRAD_CHUNKS`]
/// partial sums in parallel and added in chunk order: the tasks are cut into
/// chunks independently of the thread count, so the result is reproducible.
/// `f(task, acc, first, scratch)` adds the task's terms to the `len` values at
/// `acc`, or writes them there when `first` (the chunk's first task).
///
/// # Safety
/// `f` with `first` writes every one of the `len` values at `acc`, and `f`
/// writes nothing outside them.
pub(super) unsafe fn chunked_sum<T: Elem, F>(tasks: usize, len: usize, f: F) -> Vec<T>
where
    F: Fn(usize, Shared<T>, bool, &mut Vec<T>) + Send + Sync,
{
    let chunks = WEIGHT_GRAD_CHUNKS.min(tasks);
    let mut partials: Vec<T> = Vec::with_capacity(chunks * len);
    let dst = Shared(partials.as_mut_ptr());
    for_each_task(chunks, |c, scratch: &mut Vec<T>| {
        // Every chunk has at least one task (chunks ≤ tasks); its first
        // overwrites the chunk's partial sums, the rest add to them.
        let first = c * tasks / chunks;
        for t in first..(c + 1) * tasks / chunks {
            // SAFETY: chunk `c` alone owns these `len` partial sums.
            f(t, Shared(unsafe { dst.at(c * len) }), t == first, scratch);
        }
    });
    // SAFETY: each chunk's first task wrote all `len` of its sums (the caller's contract).
    unsafe { partials.set_len(chunks * len) };
    let (first, rest) = partials.split_at_mut(len);
    for part in rest.chunks_exact(len) {
        for (a, &p) in first.iter_mut().zip(part) {
            *a = *a + p;
        }
    }
    partials.truncate(len);
    partials
}

/// One (image, group, output rows `r0..r1`) of the weight gradient.
#[derive(Clone, Copy)]
struct Tile {
    b: usize,
    grp: usize,
    r0: usize,
    r1: usize,
}

/// `acc_g[mpg, k] (+)= dY[mpg, n] · panel^T[n, k]` for one tile: overwrites
/// `acc_g` when `first`, adds to it otherwise.
///
/// # Safety
/// `acc_g` points at the group's `[mpg, k]` block of a partial sum that no
/// other thread writes concurrently, initialised unless `first`.
#[allow(clippy::too_many_arguments)]
unsafe fn weight_tile<T: Elem>(
    g: &Geometry,
    xs: &[T],
    dys: &[T],
    tile: Tile,
    acc_g: *mut T,
    first: bool,
    panel: &mut Vec<T>,
    layout: WeightPanel,
) {
    let Tile { b, grp, r0, r1 } = tile;
    let (k, n) = (g.k(), (r1 - r0) * g.ow);
    let x_group = &xs[(b * g.c_in + grp * g.cpg) * g.in_plane()..][..g.cpg * g.in_plane()];
    // panel^T[t, kk] is panel[kk * ld + t]; for 1×1 stride 1 it is x[kk, t],
    // read in place: copying the tile's rows into a padded panel made those
    // layers 0.84× as fast at batch 8 (the copy costs more than the stride).
    let (rhs, rhs_cs) = match layout {
        _ if g.is_pointwise() => (x_group[r0 * g.ow..].as_ptr(), g.in_plane()),
        WeightPanel::Contiguous => {
            panel.resize(k * n, T::ZERO);
            im2col_rows(g, x_group, r0, r1, &mut panel[..k * n], n);
            (panel.as_ptr(), n)
        }
        WeightPanel::Padded => {
            let ld = weight_panel_ld(n);
            panel.resize(k * ld, T::ZERO);
            im2col_rows(g, x_group, r0, r1, &mut panel[..k * ld], ld);
            (panel.as_ptr(), ld)
        }
    };
    let dy_off = (b * g.c_out + grp * g.mpg) * g.out_plane() + r0 * g.ow;
    // SAFETY: all pointers are in bounds of their slices for the given strides.
    unsafe {
        gemm::gemm(
            g.mpg,
            k,
            n,
            acc_g,
            1,
            k as isize,
            !first,
            dys[dy_off..].as_ptr(),
            1,
            g.out_plane() as isize,
            rhs,
            rhs_cs as isize,
            1,
            T::ONE,
            T::ONE,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}
