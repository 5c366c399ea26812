//! Convolution engine: 2D convolutions forward and backward as GEMMs over
//! NCHW tensors, without a whole-tensor layout copy (issue 37 of chicktrain;
//! design note in `CONV_ENGINE.md`, patch record in `PATCH.md`).
//!
//! What it replaces, per pass:
//! - forward: the tiled im2col path of [`super::conv`] converts the whole input
//!   to NHWC, allocates an im2col tile and a GEMM result per tile, and scatters
//!   the result back to NCHW. The engine builds each tile's panel straight from
//!   NCHW into a per-thread buffer, lets the GEMM write the NCHW output rows in
//!   place (the output plane is row-strided), and folds the bias in as the
//!   GEMM's initial accumulator. 1×1 stride-1 layers use the input itself as
//!   the GEMM's right matrix (no panel at all).
//! - input gradient: Burn's default is a transposed convolution; the engine
//!   computes `W^T · dY` per tile (a GEMM reading the weight transposed through
//!   strides) and scatters it back with col2im ([`panel::col2im_rows`]).
//! - weight gradient: Burn's default runs a convolution of the batch-swapped
//!   input with the batch-swapped output gradient as the kernel (two transposed
//!   copies and an im2col as large as the input times the kernel area, one
//!   convolution per group). The engine accumulates `dY_tile · panel^T` per
//!   tile, a GEMM with the tile's pixels as its depth.
//!
//! The old paths stay: forward dispatch ([`prefers_forward`]) sends only the
//! shapes measured faster here; `tests.rs` checks the engine against the old
//! im2col path and Burn's default backward on random shapes.

mod backward;
#[cfg(all(test, feature = "std"))]
mod bench;
pub mod epilogue;
mod forward;
pub mod geometry;
pub(crate) mod panel;
pub mod reference;
#[cfg(test)]
mod tests;
pub mod winograd;

use alloc::vec;
use burn_backend::DType;
use burn_backend::ops::ConvOptions;
use burn_std::{Bytes, Shape, f16};

use crate::{FlexTensor, Layout};
pub use epilogue::Activation;
pub use geometry::Geometry;

/// Element types the engine computes in natively (the `gemm` crate's types).
pub(crate) trait Elem:
    bytemuck::Pod + Copy + Send + Sync + 'static + core::ops::Add<Output = Self> + burn_backend::Element
{
    const ZERO: Self;
    const ONE: Self;

    /// `xs[i] = xs[i] · sigmoid(xs[i])` on this thread ([`Activation::Silu`]).
    fn silu_inplace(xs: &mut [Self]);
}

impl Elem for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;

    fn silu_inplace(xs: &mut [Self]) {
        super::sigmoid::kernels::silu_inplace_serial(xs)
    }
}

impl Elem for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;

    fn silu_inplace(xs: &mut [Self]) {
        for x in xs {
            *x *= 1.0 / (1.0 + (-*x).exp());
        }
    }
}

impl Elem for f16 {
    const ZERO: Self = f16::ZERO;
    const ONE: Self = f16::ONE;

    fn silu_inplace(xs: &mut [Self]) {
        for x in xs {
            *x = f16::from_f32(super::sigmoid::kernels::silu_f32(x.to_f32()));
        }
    }
}

/// A raw output pointer shared by tasks that write disjoint ranges.
#[derive(Clone, Copy)]
pub(crate) struct Shared<T>(pub *mut T);
// SAFETY: every user writes through it only at offsets no other task touches.
unsafe impl<T> Send for Shared<T> {}
unsafe impl<T> Sync for Shared<T> {}

impl<T> Shared<T> {
    /// The pointer `off` elements in (a method, so closures capture the whole
    /// `Send` wrapper rather than its raw-pointer field).
    ///
    /// # Safety
    /// `off` must be within the allocation.
    pub(crate) unsafe fn at(self, off: usize) -> *mut T {
        unsafe { self.0.add(off) }
    }
}

/// Worker threads available to split tiles over.
pub(crate) fn threads() -> usize {
    #[cfg(feature = "rayon")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "rayon"))]
    {
        1
    }
}

/// Run `f(task, scratch)` for `0..tasks`, in parallel where rayon is enabled,
/// with a scratch buffer per worker that outlives the call (patch 11).
///
/// `for_each_init` made a fresh buffer for every rayon job, i.e. an allocation
/// and a zero-filling `resize` of a whole panel per tile or two, on every
/// convolution of every step; the panels are then overwritten before they are
/// read. Each thread now keeps its buffer between calls (it only grows, to the
/// largest panel that thread has built), so a panel is zero-filled once.
/// Callers still see a `Vec` whose contents are whatever the previous task
/// left, as with a reused `for_each_init` buffer.
pub(crate) fn for_each_task<T: Elem, F>(tasks: usize, f: F)
where
    F: Fn(usize, &mut alloc::vec::Vec<T>) + Send + Sync,
{
    #[cfg(all(feature = "rayon", feature = "std"))]
    {
        use rayon::prelude::*;
        #[cfg(test)]
        if FRESH_SCRATCH.load(core::sync::atomic::Ordering::Relaxed) {
            (0..tasks)
                .into_par_iter()
                .for_each_init(alloc::vec::Vec::new, |buf, t| f(t, buf));
            return;
        }
        (0..tasks)
            .into_par_iter()
            .for_each(|t| scratch::with(|buf| f(t, buf)));
    }
    #[cfg(all(feature = "rayon", not(feature = "std")))]
    {
        use rayon::prelude::*;
        (0..tasks)
            .into_par_iter()
            .for_each_init(alloc::vec::Vec::new, |buf, t| f(t, buf));
    }
    #[cfg(not(feature = "rayon"))]
    {
        let mut buf = alloc::vec::Vec::new();
        (0..tasks).for_each(|t| f(t, &mut buf));
    }
}

/// The bench's switch back to a fresh buffer per rayon job (as before patch 11).
#[cfg(test)]
pub(crate) static FRESH_SCRATCH: core::sync::atomic::AtomicBool =
    core::sync::atomic::AtomicBool::new(false);

/// Fill every rayon worker's kept scratch buffer of `T` with `len` copies of
/// `value`, as if a task before had left them there (tests of patch 11).
#[cfg(all(test, feature = "rayon", feature = "std"))]
pub(crate) fn poison_scratch<T: Elem>(len: usize, value: T) {
    rayon::broadcast(|_| {
        scratch::with(|buf: &mut alloc::vec::Vec<T>| {
            buf.clear();
            buf.resize(len, value);
        })
    });
}

/// Per-thread scratch buffers of [`for_each_task`], one per element type.
#[cfg(all(feature = "rayon", feature = "std"))]
mod scratch {
    extern crate std;

    use alloc::boxed::Box;
    use alloc::vec::Vec;
    use core::any::{Any, TypeId};
    use core::cell::RefCell;

    std::thread_local! {
        static BUFFERS: RefCell<Vec<(TypeId, Box<dyn Any>)>> = const { RefCell::new(Vec::new()) };
    }

    /// `f` with this thread's buffer of `T`s. The buffer is taken out of the
    /// thread-local for the call, so a task that runs another one on this
    /// thread (rayon steals while a task waits on a nested parallel GEMM)
    /// gets a buffer of its own instead of a second borrow.
    pub(super) fn with<T: 'static, R>(f: impl FnOnce(&mut Vec<T>) -> R) -> R {
        let id = TypeId::of::<T>();
        let taken = BUFFERS.with_borrow_mut(|bufs| {
            let at = bufs.iter().position(|(t, _)| *t == id)?;
            Some(bufs.swap_remove(at).1)
        });
        let mut buf: Vec<T> = taken
            .and_then(|b| b.downcast::<Vec<T>>().ok())
            .map(|b| *b)
            .unwrap_or_default();
        let out = f(&mut buf);
        BUFFERS.with_borrow_mut(|bufs| {
            // A nested task may have put one back meanwhile: keep the larger.
            if let Some(at) = bufs.iter().position(|(t, _)| *t == id) {
                let other_len = bufs[at]
                    .1
                    .downcast_ref::<Vec<T>>()
                    .map_or(0, |v| v.capacity());
                if other_len >= buf.capacity() {
                    return;
                }
                bufs.swap_remove(at);
            }
            bufs.push((id, Box::new(buf)));
        });
        out
    }
}

/// Whether the forward pass of this f32 shape goes to the engine. From the
/// side-by-side bench (`bench.rs`, results in chicktrain's
/// `bench/results/convs/`, loaded 2-core box): k×k and strided convolutions
/// ran 1.2–8× faster through the engine (the stem's 3-input-channel layer
/// included), while 1×1 stride-1 ones were within noise of the old 1×1 GEMM
/// path (0.84–1.15×) and depthwise ones 0.5–0.7× of flex's direct depthwise
/// kernel; those two keep the old forward.
pub fn prefers_forward(g: &Geometry) -> bool {
    !g.is_depthwise() && !g.is_pointwise()
}

fn tensor<T: Elem>(data: alloc::vec::Vec<T>, shape: [usize; 4], dtype: DType) -> FlexTensor {
    FlexTensor::new(
        Bytes::from_elems(data),
        Layout::contiguous(Shape::from(vec![shape[0], shape[1], shape[2], shape[3]])),
        dtype,
    )
}

/// Forward 2D convolution through the engine, for any float dtype (bf16 via
/// f32). `None` when the engine does not take the shape ([`Geometry::new`]).
pub fn conv2d(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    conv2d_activated(x, weight, bias, options, Activation::Identity)
}

/// [`conv2d`] followed by `act`, applied by each task to the output rows it
/// has just written (patch 13; bf16 in f32 before rounding).
pub fn conv2d_activated(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: &ConvOptions<2>,
    act: Activation,
) -> Option<FlexTensor> {
    let g = Geometry::new(x.layout().shape(), weight.layout().shape(), options)?;
    let out = [g.batch, g.c_out, g.oh, g.ow];
    Some(match x.dtype() {
        DType::F32 => tensor(
            forward::conv2d::<f32>(&g, x, weight, bias, act),
            out,
            DType::F32,
        ),
        DType::F64 => tensor(
            forward::conv2d::<f64>(&g, x, weight, bias, act),
            out,
            DType::F64,
        ),
        DType::F16 => tensor(
            forward::conv2d::<f16>(&g, x, weight, bias, act),
            out,
            DType::F16,
        ),
        DType::BF16 => {
            let up = |t: FlexTensor| super::conv_common::convert_bf16_to_f32(&t);
            let y = forward::conv2d::<f32>(&g, up(x), up(weight), bias.map(up), act);
            super::conv_common::convert_f32_to_bf16(&tensor(y, out, DType::F32))
        }
        _ => return None,
    })
}

/// Forward 2D convolution through Winograd F(2×2, 3×3) ([`winograd`], patch
/// 12): f32 stride-1 undilated ungrouped 3×3 convolutions; `None` otherwise.
pub fn conv2d_winograd(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    conv2d_winograd_activated(x, weight, bias, options, Activation::Identity)
}

/// [`conv2d_winograd`] followed by `act`, applied by each task to the output
/// rows it has just written (patch 13).
pub fn conv2d_winograd_activated(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: &ConvOptions<2>,
    act: Activation,
) -> Option<FlexTensor> {
    let g = Geometry::new(x.layout().shape(), weight.layout().shape(), options)?;
    let f32s = [Some(&x), Some(&weight), bias.as_ref()];
    if !winograd::takes(&g) || f32s.iter().flatten().any(|t| t.dtype() != DType::F32) {
        return None;
    }
    let (x, weight) = (x.to_contiguous(), weight.to_contiguous());
    let bias = bias.map(|b| b.to_contiguous());
    let u = winograd::forward_weight(&g, weight.storage());
    let y = winograd::conv2d(&g, x.storage(), &u, bias.as_ref().map(|b| b.storage()), act);
    Some(tensor(y, [g.batch, g.c_out, g.oh, g.ow], DType::F32))
}

/// Gradient of a stride-1 3×3 convolution with respect to its input through
/// Winograd (patch 12): `dX = dY ⋆ W'`, a "full" convolution of the output
/// gradient with `W'[ci, co] = W[co, ci]` rotated by 180° at padding `2 − p`.
/// `None` where [`conv2d_winograd`] would decline the forward, or for padding
/// above 2.
pub fn conv2d_x_backward_winograd(
    x_shape: &[usize],
    weight: FlexTensor,
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    let g = Geometry::new(x_shape, weight.layout().shape(), options)?;
    let f32s = weight.dtype() == DType::F32 && output_grad.dtype() == DType::F32;
    if !winograd::takes(&g) || g.ph > 2 || g.pw > 2 || !f32s {
        return None;
    }
    let full = ConvOptions::new([1, 1], [2 - g.ph, 2 - g.pw], [1, 1], 1);
    let gt = Geometry::new(
        &[g.batch, g.c_out, g.oh, g.ow],
        &[g.c_in, g.c_out, 3, 3],
        &full,
    )?;
    debug_assert_eq!((gt.oh, gt.ow), (g.h, g.w));
    let weight = weight.to_contiguous();
    let ws: &[f32] = weight.storage();
    let u = winograd::transform_weight(g.c_in, g.c_out, |ci, co| {
        let f = &ws[(co * g.c_in + ci) * 9..][..9];
        core::array::from_fn(|k| f[8 - k])
    });
    let dy = output_grad.to_contiguous();
    let dx = winograd::conv2d(&gt, dy.storage(), &u, None, Activation::Identity);
    Some(tensor(dx, [g.batch, g.c_in, g.h, g.w], DType::F32))
}

/// Gradient of a stride-1 3×3 convolution with respect to its weight through
/// Winograd (patch 12). `None` where [`conv2d_winograd`] would decline.
pub fn conv2d_weight_backward_winograd(
    x: FlexTensor,
    weight_shape: &[usize],
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    let g = Geometry::new(x.layout().shape(), weight_shape, options)?;
    let f32s = x.dtype() == DType::F32 && output_grad.dtype() == DType::F32;
    if !winograd::takes(&g) || !f32s {
        return None;
    }
    let (x, dy) = (x.to_contiguous(), output_grad.to_contiguous());
    let dw = winograd::weight_grad(&g, x.storage(), dy.storage());
    Some(tensor(dw, [g.c_out, g.c_in, 3, 3], DType::F32))
}

/// Whether Winograd runs this shape's forward and input gradient: 1.06–2.56×
/// the im2col engine's speed at 192 tiles (2×2 output pixels) per call and
/// up, 0.40–1.20× below (`bench.rs`, `bench_winograd`, YOLO11n-seg's layers
/// at batch 1 and 8; chicktrain's `bench/results/convs/winograd_2026-12-07/`):
/// with few tiles its 16 small GEMMs per task cost more than they save.
pub fn prefers_winograd(g: &Geometry) -> bool {
    winograd::takes(g) && winograd_tiles(g) >= 192
}

/// Whether Winograd runs this shape's weight gradient: 1.02–1.61× at 512
/// tiles and up, 0.79–1.68× at 192–511 (same bench); its GEMMs have the tiles
/// as depth and a `[c_out, c_in]` result per task to add up.
pub fn prefers_winograd_weight_grad(g: &Geometry) -> bool {
    winograd::takes(g) && winograd_tiles(g) >= 512
}

fn winograd_tiles(g: &Geometry) -> usize {
    g.batch * g.oh.div_ceil(2) * g.ow.div_ceil(2)
}

/// The forward as flex runs a shape it gives the engine, followed by `act`:
/// Winograd where [`prefers_winograd`] (and it takes the dtypes), the im2col
/// engine otherwise. `None` where [`Geometry::new`] rejects the shape.
pub fn conv2d_preferred(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: &ConvOptions<2>,
    act: Activation,
) -> Option<FlexTensor> {
    let g = Geometry::new(x.layout().shape(), weight.layout().shape(), options)?;
    prefers_winograd(&g)
        .then(|| conv2d_winograd_activated(x.clone(), weight.clone(), bias.clone(), options, act))
        .flatten()
        .or_else(|| conv2d_activated(x, weight, bias, options, act))
}

/// The input gradient as flex runs it: Winograd where [`prefers_winograd`]
/// (and it takes the padding and dtypes), the engine otherwise.
pub fn conv2d_x_backward_preferred(
    x_shape: &[usize],
    weight: FlexTensor,
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    let g = Geometry::new(x_shape, weight.layout().shape(), options)?;
    prefers_winograd(&g)
        .then(|| conv2d_x_backward_winograd(x_shape, weight.clone(), output_grad.clone(), options))
        .flatten()
        .or_else(|| conv2d_x_backward(x_shape, weight, output_grad, options))
}

/// The weight gradient as flex runs it: Winograd where
/// [`prefers_winograd_weight_grad`] (and it takes the dtypes), the engine
/// otherwise.
pub fn conv2d_weight_backward_preferred(
    x: FlexTensor,
    weight_shape: &[usize],
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    let g = Geometry::new(x.layout().shape(), weight_shape, options)?;
    prefers_winograd_weight_grad(&g)
        .then(|| {
            conv2d_weight_backward_winograd(x.clone(), weight_shape, output_grad.clone(), options)
        })
        .flatten()
        .or_else(|| conv2d_weight_backward(x, weight_shape, output_grad, options))
}

/// Gradient of a 2D convolution with respect to its input `[b, c_in, h, w]`
/// (`x_shape`), from the weight and the output gradient. Symmetric padding
/// only (the caller pads asymmetric inputs explicitly); `None` otherwise.
pub fn conv2d_x_backward(
    x_shape: &[usize],
    weight: FlexTensor,
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    let g = Geometry::new(x_shape, weight.layout().shape(), options)?;
    let shape = [g.batch, g.c_in, g.h, g.w];
    Some(match output_grad.dtype() {
        DType::F32 => tensor(
            backward::x_grad::<f32>(&g, weight, output_grad),
            shape,
            DType::F32,
        ),
        DType::F64 => tensor(
            backward::x_grad::<f64>(&g, weight, output_grad),
            shape,
            DType::F64,
        ),
        DType::F16 => tensor(
            backward::x_grad::<f16>(&g, weight, output_grad),
            shape,
            DType::F16,
        ),
        DType::BF16 => {
            let up = |t: FlexTensor| super::conv_common::convert_bf16_to_f32(&t);
            let dx = backward::x_grad::<f32>(&g, up(weight), up(output_grad));
            super::conv_common::convert_f32_to_bf16(&tensor(dx, shape, DType::F32))
        }
        _ => return None,
    })
}

/// Gradient of a 2D convolution with respect to its weight
/// `[c_out, c_in / groups, kh, kw]` (`weight_shape`), from the input and the
/// output gradient. Symmetric padding only; `None` otherwise.
pub fn conv2d_weight_backward(
    x: FlexTensor,
    weight_shape: &[usize],
    output_grad: FlexTensor,
    options: &ConvOptions<2>,
) -> Option<FlexTensor> {
    let g = Geometry::new(x.layout().shape(), weight_shape, options)?;
    let shape = [g.c_out, g.cpg, g.kh, g.kw];
    Some(match x.dtype() {
        DType::F32 => tensor(
            backward::weight_grad::<f32>(&g, x, output_grad),
            shape,
            DType::F32,
        ),
        DType::F64 => tensor(
            backward::weight_grad::<f64>(&g, x, output_grad),
            shape,
            DType::F64,
        ),
        DType::F16 => tensor(
            backward::weight_grad::<f16>(&g, x, output_grad),
            shape,
            DType::F16,
        ),
        DType::BF16 => {
            let up = |t: FlexTensor| super::conv_common::convert_bf16_to_f32(&t);
            let dw = backward::weight_grad::<f32>(&g, up(x), up(output_grad));
            super::conv_common::convert_f32_to_bf16(&tensor(dw, shape, DType::F32))
        }
        _ => return None,
    })
}
