//! Forward pass: per (image, tile of output rows, group), one GEMM
//! `out[mpg, n] (+)= W_g[mpg, k] · panel[k, n]` written straight into the NCHW
//! output, with the bias as the GEMM's initial accumulator and the activation
//! applied to the rows it wrote ([`Activation`], patch 13).

use alloc::vec::Vec;

use super::epilogue::Activation;
use super::geometry::Geometry;
use super::panel::im2col_rows;
use super::{Elem, Shared, for_each_task, threads};
use crate::FlexTensor;

/// Output `[batch, c_out, oh, ow]` as a flat vector.
pub(super) fn conv2d<T: Elem>(
    g: &Geometry,
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    act: Activation,
) -> Vec<T> {
    let x = x.to_contiguous();
    let weight = weight.to_contiguous();
    let xs: &[T] = x.storage();
    let ws: &[T] = weight.storage();
    let plane = g.out_plane();
    let len = g.batch * g.c_out * plane;
    // Not zero-filled (patch 9): with a bias every plane starts as its bias
    // value, which the GEMMs add to; without one the first and only GEMM into
    // each element writes it with `read_dst = false` (the tiles cover every
    // row of every (image, group) block).
    let mut out: Vec<T> = Vec::with_capacity(len);
    let with_bias = bias.is_some();
    if let Some(bias) = bias {
        let bias = bias.to_contiguous();
        let bs: &[T] = bias.storage();
        for i in 0..g.batch * g.c_out {
            out.extend(core::iter::repeat_n(bs[i % g.c_out], plane));
        }
    }
    let tiles = g.tiles(threads());
    let dst = Shared(out.as_mut_ptr());
    for_each_task(g.batch * tiles.len(), |t, panel: &mut Vec<T>| {
        let (r0, r1) = tiles[t % tiles.len()];
        let b = t / tiles.len();
        for grp in 0..g.groups {
            // SAFETY: tasks write disjoint (image, row-range) blocks of `out`,
            // which outlives `for_each_task`.
            unsafe { tile(g, xs, ws, dst, b, grp, r0, r1, with_bias, act, panel) };
        }
    });
    // SAFETY: every element is initialised, by the bias fill or by the GEMMs
    // (`engine_writes_every_element_of_unzeroed_buffers`).
    unsafe { out.set_len(len) };
    out
}

/// One (image, group, row range) GEMM.
///
/// # Safety
/// `dst` points at the `[batch, c_out, oh, ow]` output, and no other thread
/// writes rows `r0..r1` of image `b`, group `grp` concurrently.
#[allow(clippy::too_many_arguments)]
unsafe fn tile<T: Elem>(
    g: &Geometry,
    xs: &[T],
    ws: &[T],
    dst: Shared<T>,
    b: usize,
    grp: usize,
    r0: usize,
    r1: usize,
    accumulate: bool,
    act: Activation,
    panel: &mut Vec<T>,
) {
    let k = g.k();
    let n = (r1 - r0) * g.ow;
    let x_group = &xs[(b * g.c_in + grp * g.cpg) * g.in_plane()..][..g.cpg * g.in_plane()];
    let (rhs, rhs_rs) = if g.is_pointwise() {
        (x_group[r0 * g.ow..].as_ptr(), g.in_plane())
    } else {
        panel.resize(k * n, T::ZERO);
        im2col_rows(g, x_group, r0, r1, &mut panel[..k * n], n);
        (panel.as_ptr(), n)
    };
    let out_off = (b * g.c_out + grp * g.mpg) * g.out_plane() + r0 * g.ow;
    unsafe {
        gemm::gemm(
            g.mpg,
            n,
            k,
            dst.at(out_off),
            1,
            g.out_plane() as isize,
            accumulate,
            ws[grp * g.mpg * k..].as_ptr(),
            1,
            k as isize,
            rhs,
            1,
            rhs_rs as isize,
            T::ONE,
            T::ONE,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
    // SAFETY: rows `r0..r1` of this (image, group)'s channels are this task's
    // (the caller's contract), written just above.
    unsafe { act.apply_to_planes(dst, out_off, g.mpg, g.out_plane(), n) };
}
