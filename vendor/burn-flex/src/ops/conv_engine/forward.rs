//! Forward pass: per (image, tile of output rows, group), one GEMM
//! `out[mpg, n] (+)= W_g[mpg, k] · panel[k, n]` written straight into the NCHW
//! output, with the bias as the GEMM's initial accumulator. Layers too small to
//! give every thread two row tiles also split their output channels
//! ([`Geometry::forward_split`]); then each panel is built once and shared by
//! the channel chunks' GEMMs.

use alloc::vec;
use alloc::vec::Vec;

use super::geometry::{ForwardSplit, Geometry};
use super::panel::im2col_rows;
use super::{Elem, Shared, for_each_task, threads};
use crate::FlexTensor;

/// Output `[batch, c_out, oh, ow]` as a flat vector.
pub(super) fn conv2d<T: Elem>(
    g: &Geometry,
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
) -> Vec<T> {
    conv2d_split(g, x, weight, bias, &g.forward_split(threads()))
}

/// [`conv2d`] cut into the tasks of `split` (the bench and tests pass other
/// splits than [`Geometry::forward_split`]'s; every split gives the same sums).
pub(super) fn conv2d_split<T: Elem>(
    g: &Geometry,
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    split: &ForwardSplit,
) -> Vec<T> {
    let x = x.to_contiguous();
    let weight = weight.to_contiguous();
    let xs: &[T] = x.storage();
    let ws: &[T] = weight.storage();
    let plane = g.out_plane();
    let mut out = vec![T::ZERO; g.batch * g.c_out * plane];
    let with_bias = bias.is_some();
    if let Some(bias) = bias {
        let bias = bias.to_contiguous();
        let bs: &[T] = bias.storage();
        for (i, chunk) in out.chunks_exact_mut(plane).enumerate() {
            chunk.fill(bs[i % g.c_out]);
        }
    }
    let dst = Shared(out.as_mut_ptr());
    let rows = &split.rows;
    let k = g.k();
    if let [whole] = split.channels[..] {
        for_each_task(g.batch * rows.len(), |t, panel: &mut Vec<T>| {
            let (r0, r1) = rows[t % rows.len()];
            let b = t / rows.len();
            for grp in 0..g.groups {
                let n = (r1 - r0) * g.ow;
                let rhs = if g.is_pointwise() {
                    Rhs::input(g, xs, b, grp, r0)
                } else {
                    panel.resize(k * n, T::ZERO);
                    im2col_rows(g, x_group(g, xs, b, grp), r0, r1, &mut panel[..k * n], n);
                    Rhs {
                        ptr: panel.as_ptr(),
                        row_stride: n,
                    }
                };
                // SAFETY: tasks write disjoint (image, row-range) blocks of
                // `out`, which outlives `for_each_task`.
                unsafe { gemm_block(g, ws, dst, b, grp, whole, (r0, r1), rhs, with_bias) };
            }
        });
        return out;
    }
    // Few tasks by rows: build each (image, row tile, group) panel once, then
    // let the channel chunks' GEMMs share it.
    let slot = k * rows
        .iter()
        .map(|&(r0, r1)| (r1 - r0) * g.ow)
        .max()
        .unwrap_or(0);
    let slots = g.batch * rows.len() * g.groups;
    let mut panels = Vec::new();
    if !g.is_pointwise() {
        panels = vec![T::ZERO; slots * slot];
        let base = Shared(panels.as_mut_ptr());
        for_each_task(slots, |s, _: &mut Vec<T>| {
            let (b, tile, grp) = (
                s / (rows.len() * g.groups),
                (s / g.groups) % rows.len(),
                s % g.groups,
            );
            let (r0, r1) = rows[tile];
            let n = (r1 - r0) * g.ow;
            // SAFETY: slot `s` is written by this task only; `panels` outlives it.
            let panel = unsafe { core::slice::from_raw_parts_mut(base.at(s * slot), k * n) };
            im2col_rows(g, x_group(g, xs, b, grp), r0, r1, panel, n);
        });
    }
    let chunks = &split.channels;
    let per_image = rows.len() * chunks.len();
    for_each_task(g.batch * per_image, |t, _: &mut Vec<T>| {
        let (b, tile, chunk) = (
            t / per_image,
            (t / chunks.len()) % rows.len(),
            t % chunks.len(),
        );
        let (r0, r1) = rows[tile];
        for grp in 0..g.groups {
            let rhs = if g.is_pointwise() {
                Rhs::input(g, xs, b, grp, r0)
            } else {
                let s = (b * rows.len() + tile) * g.groups + grp;
                Rhs {
                    ptr: panels[s * slot..].as_ptr(),
                    row_stride: (r1 - r0) * g.ow,
                }
            };
            // SAFETY: tasks write disjoint (image, row-range, channel-range)
            // blocks of `out`, which outlives `for_each_task`.
            unsafe { gemm_block(g, ws, dst, b, grp, chunks[chunk], (r0, r1), rhs, with_bias) };
        }
    });
    out
}

/// The `g.cpg` input planes of image `b`, group `grp`.
fn x_group<'a, T: Elem>(g: &Geometry, xs: &'a [T], b: usize, grp: usize) -> &'a [T] {
    &xs[(b * g.c_in + grp * g.cpg) * g.in_plane()..][..g.cpg * g.in_plane()]
}

/// The GEMM's right matrix `[k, n]`: a panel, or for 1×1 stride-1 layers the
/// NCHW input itself (rows are channels, one plane apart).
#[derive(Clone, Copy)]
struct Rhs<T> {
    ptr: *const T,
    row_stride: usize,
}

impl<T: Elem> Rhs<T> {
    fn input(g: &Geometry, xs: &[T], b: usize, grp: usize, r0: usize) -> Self {
        Rhs {
            ptr: x_group(g, xs, b, grp)[r0 * g.ow..].as_ptr(),
            row_stride: g.in_plane(),
        }
    }
}

/// `out[m0..m1, r0..r1 rows] (+)= W[m0..m1] · rhs` for image `b`, group `grp`.
///
/// # Safety
/// `dst` points at the `[batch, c_out, oh, ow]` output, `rhs` at a `[k, n]`
/// matrix that lives through the call, and no other thread writes this block.
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_block<T: Elem>(
    g: &Geometry,
    ws: &[T],
    dst: Shared<T>,
    b: usize,
    grp: usize,
    (m0, m1): (usize, usize),
    (r0, r1): (usize, usize),
    rhs: Rhs<T>,
    accumulate: bool,
) {
    let k = g.k();
    let n = (r1 - r0) * g.ow;
    let out_off = (b * g.c_out + grp * g.mpg + m0) * g.out_plane() + r0 * g.ow;
    unsafe {
        gemm::gemm(
            m1 - m0,
            n,
            k,
            dst.at(out_off),
            1,
            g.out_plane() as isize,
            accumulate,
            ws[(grp * g.mpg + m0) * k..].as_ptr(),
            1,
            k as isize,
            rhs.ptr,
            1,
            rhs.row_stride as isize,
            T::ONE,
            T::ONE,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}
