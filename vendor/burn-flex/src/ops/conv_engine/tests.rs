//! The engine against the paths it replaces, on seeded random shapes: the
//! forward against the tiled im2col path (`conv::conv2d_im2col_f32`), the
//! input gradient against Burn's default (a transposed convolution), the
//! weight gradient against Burn's default (a convolution of the batch-swapped
//! tensors, one per group), and all three against a direct f64 loop.
//! Tolerance: max |engine − reference| ≤ 1e-4 · max |reference| per tensor.

use alloc::vec;
use alloc::vec::Vec;
use burn_backend::DType;
use burn_backend::ops::ConvOptions;
use burn_std::{Bytes, Shape};

use super::{Geometry, reference};
use crate::ops::conv;
use crate::{FlexTensor, Layout};

/// One convolution: `[b, c_in, h, w]`, `c_out`, `[kh, kw]`, stride, padding, dilation, groups.
#[derive(Clone, Copy, Debug)]
struct Case {
    x: [usize; 4],
    c_out: usize,
    k: [usize; 2],
    stride: [usize; 2],
    pad: [usize; 2],
    dil: [usize; 2],
    groups: usize,
}

struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn vec(&mut self, len: usize) -> Vec<f32> {
        (0..len)
            .map(|_| self.below(20001) as f32 / 10000.0 - 1.0)
            .collect()
    }
}

fn t4(data: Vec<f32>, s: [usize; 4]) -> FlexTensor {
    let shape = Shape::from(vec![s[0], s[1], s[2], s[3]]);
    FlexTensor::new(
        Bytes::from_elems(data),
        Layout::contiguous(shape),
        DType::F32,
    )
}

fn values(t: &FlexTensor) -> Vec<f32> {
    t.to_contiguous().storage::<f32>().to_vec()
}

fn assert_close(what: &str, case: &Case, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{what} length, {case:?}");
    let scale = want.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-6);
    let err = got
        .iter()
        .zip(want)
        .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        err <= 1e-4 * scale,
        "{what}: max error {err} vs max |ref| {scale}, {case:?}"
    );
}

/// Direct f64 loops: output, input gradient and weight gradient of `case` for
/// input `x`, weight `w` and output gradient `dy`.
fn naive(case: &Case, g: &Geometry, x: &[f32], w: &[f32], dy: &[f32]) -> [Vec<f32>; 3] {
    let mut y = vec![0f64; g.batch * g.c_out * g.out_plane()];
    let mut dx = vec![0f64; x.len()];
    let mut dw = vec![0f64; w.len()];
    for b in 0..g.batch {
        for co in 0..g.c_out {
            let grp = co / g.mpg;
            for c in 0..g.cpg {
                let ci = grp * g.cpg + c;
                for i in 0..g.kh {
                    for j in 0..g.kw {
                        let wi = ((co * g.cpg + c) * g.kh + i) * g.kw + j;
                        for r in 0..g.oh {
                            // Written out rather than `Geometry::input_row`, so a bug
                            // there cannot hide in the reference.
                            let ih = (r * g.sh + i * g.dh).wrapping_sub(g.ph);
                            if ih >= g.h {
                                continue;
                            }
                            for o in 0..g.ow {
                                let iw = (o * g.sw + j * g.dw).wrapping_sub(g.pw);
                                if iw >= g.w {
                                    continue;
                                }
                                let xi = ((b * g.c_in + ci) * g.h + ih) * g.w + iw;
                                let yi = ((b * g.c_out + co) * g.oh + r) * g.ow + o;
                                y[yi] += x[xi] as f64 * w[wi] as f64;
                                dx[xi] += dy[yi] as f64 * w[wi] as f64;
                                dw[wi] += dy[yi] as f64 * x[xi] as f64;
                            }
                        }
                    }
                }
            }
        }
    }
    let _ = case;
    [y, dx, dw].map(|v| v.into_iter().map(|e| e as f32).collect())
}

fn check(case: Case, seed: u64) {
    let mut rng = Lcg(seed);
    let opts = ConvOptions::new(case.stride, case.pad, case.dil, case.groups);
    let w_shape = [case.c_out, case.x[1] / case.groups, case.k[0], case.k[1]];
    let g = Geometry::new(&case.x, &w_shape, &opts).expect("test case is a valid convolution");
    let x = rng.vec(case.x.iter().product());
    let w = rng.vec(w_shape.iter().product());
    let bias = rng.vec(case.c_out);
    let dy = rng.vec(g.batch * g.c_out * g.out_plane());
    let y_shape = [g.batch, g.c_out, g.oh, g.ow];
    let [y_ref, dx_ref, dw_ref] = naive(&case, &g, &x, &w, &dy);
    let (xt, wt, dyt) = (t4(x, case.x), t4(w, w_shape), t4(dy, y_shape));
    let bt = FlexTensor::new(
        Bytes::from_elems(bias.clone()),
        Layout::contiguous(Shape::from(vec![case.c_out])),
        DType::F32,
    );

    let y = super::conv2d(xt.clone(), wt.clone(), Some(bt.clone()), &opts).unwrap();
    let old = conv::conv2d_im2col_f32(xt.clone(), wt.clone(), Some(bt), &opts);
    let y_ref: Vec<f32> = y_ref
        .iter()
        .enumerate()
        .map(|(i, v)| v + bias[(i / g.out_plane()) % g.c_out])
        .collect();
    assert_close("forward vs naive", &case, &values(&y), &y_ref);
    assert_close("forward vs im2col", &case, &values(&y), &values(&old));

    let dx = super::conv2d_x_backward(&case.x, wt.clone(), dyt.clone(), &opts).unwrap();
    let dx_old = reference::x_backward_f32(&case.x, wt, dyt.clone(), &opts);
    assert_close("x grad vs naive", &case, &values(&dx), &dx_ref);
    assert_close("x grad vs default", &case, &values(&dx), &values(&dx_old));

    let dw = super::conv2d_weight_backward(xt.clone(), &w_shape, dyt.clone(), &opts).unwrap();
    assert_close("weight grad vs naive", &case, &values(&dw), &dw_ref);
    assert_close(
        "weight grad vs default",
        &case,
        &values(&dw),
        &values(&reference::weight_backward_f32(
            xt.clone(),
            &w_shape,
            dyt.clone(),
            &opts,
        )),
    );
}

fn case(
    x: [usize; 4],
    c_out: usize,
    k: usize,
    stride: usize,
    pad: usize,
    dil: usize,
    groups: usize,
) -> Case {
    Case {
        x,
        c_out,
        k: [k, k],
        stride: [stride; 2],
        pad: [pad; 2],
        dil: [dil; 2],
        groups,
    }
}

#[test]
fn engine_matches_reference_on_listed_shapes() {
    let cases = [
        case([1, 8, 9, 11], 16, 1, 1, 0, 1, 1), // 1×1 stride 1: pointwise GEMM
        case([8, 6, 7, 5], 4, 1, 1, 0, 1, 2),   // 1×1 grouped, batch 8
        case([1, 5, 13, 9], 7, 3, 1, 1, 1, 1),  // 3×3 same padding, odd sizes
        case([8, 4, 8, 8], 8, 3, 2, 1, 1, 1),   // 3×3 stride 2, batch 8
        case([1, 6, 10, 12], 6, 3, 1, 1, 1, 6), // depthwise
        case([2, 8, 9, 9], 4, 3, 1, 2, 2, 2),   // dilation 2, padding 2, groups 2
        case([1, 3, 11, 11], 5, 5, 2, 2, 1, 1), // 5×5 stride 2
        case([1, 4, 6, 6], 3, 3, 1, 0, 1, 1),   // no padding
        case([1, 6, 5, 7], 4, 1, 2, 0, 1, 1),   // 1×1 stride 2 (not pointwise)
        case([1, 2, 1, 9], 3, 3, 1, 1, 1, 1),   // one input row
        case([1, 8, 60, 20], 8, 3, 1, 1, 1, 1), // several rows per tile
    ];
    for (i, c) in cases.into_iter().enumerate() {
        check(c, 1000 + i as u64);
    }
}

#[test]
fn engine_matches_reference_on_random_shapes() {
    let mut rng = Lcg(37);
    for i in 0..40 {
        let groups = [1, 1, 2, 3][rng.below(4)];
        let depthwise = rng.below(5) == 0;
        let cpg = 1 + rng.below(5);
        let c_in = if depthwise { groups * 2 } else { groups * cpg };
        let c_out = if depthwise {
            c_in
        } else {
            groups * (1 + rng.below(5))
        };
        let groups = if depthwise { c_in } else { groups };
        let k = [1, 3, 3, 5][rng.below(4)];
        let (stride, pad, dil) = (1 + rng.below(2), rng.below(3), 1 + rng.below(2));
        let batch = [1, 8][rng.below(2)];
        let (h, w) = (k + dil * 2 + rng.below(8), k + dil * 2 + rng.below(8));
        check(
            case([batch, c_in, h, w], c_out, k, stride, pad, dil, groups),
            5000 + i,
        );
    }
}

/// Patch 11: the scratch buffers each worker keeps between calls hold what
/// the last task left there. With every worker's buffer filled with NaN first,
/// the engine's outputs and gradients must still be finite and match the
/// direct loops: no path may read a panel entry it did not write.
#[cfg(all(feature = "rayon", feature = "std"))]
#[test]
fn engine_ignores_what_kept_scratch_buffers_hold() {
    let cases = [
        case([1, 5, 13, 9], 7, 3, 1, 1, 1, 1), // 3×3 same padding: zero columns
        case([2, 3, 6, 40], 4, 3, 2, 1, 1, 1), // stride 2, rows of 20 pixels
        case([1, 4, 6, 6], 3, 3, 1, 0, 1, 1),  // no padding
        case([2, 8, 9, 9], 4, 3, 1, 2, 2, 2),  // dilation, groups
        case([3, 6, 7, 5], 4, 1, 1, 0, 1, 2),  // pointwise, 2 groups
        case([1, 6, 10, 12], 6, 3, 1, 1, 1, 6), // depthwise
        case([1, 8, 60, 20], 8, 3, 1, 1, 1, 1), // several rows per tile
    ];
    for (i, c) in cases.into_iter().enumerate() {
        let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
        let w_shape = [c.c_out, c.x[1] / c.groups, c.k[0], c.k[1]];
        let g = Geometry::new(&c.x, &w_shape, &opts).unwrap();
        let mut rng = Lcg(7000 + i as u64);
        let x = t4(rng.vec(c.x.iter().product()), c.x);
        let w = t4(rng.vec(w_shape.iter().product()), w_shape);
        let dy = t4(
            rng.vec(g.batch * g.c_out * g.out_plane()),
            [g.batch, g.c_out, g.oh, g.ow],
        );
        for pass in ["forward", "x grad", "weight grad"] {
            super::poison_scratch::<f32>(1 << 16, f32::NAN);
            let out = match pass {
                "forward" => super::conv2d(x.clone(), w.clone(), None, &opts),
                "x grad" => super::conv2d_x_backward(&c.x, w.clone(), dy.clone(), &opts),
                _ => super::conv2d_weight_backward(x.clone(), &w_shape, dy.clone(), &opts),
            };
            assert_finite(pass, &c, &values(&out.unwrap()));
        }
        super::poison_scratch::<f32>(1 << 16, f32::NAN);
        check(c, 7100 + i as u64);
    }
}

/// Patch 6: the padded panel changes where the
/// weight gradient's GEMM reads, not what it adds or in which order, so the
/// two layouts give the same bits.
#[test]
fn weight_grad_panel_layouts_are_bit_identical() {
    use super::backward::{WeightPanel, weight_grad_with};
    let cases = [
        case([1, 8, 9, 11], 16, 1, 1, 0, 1, 1), // 1×1 stride 1: in place either way
        case([8, 6, 7, 5], 4, 1, 1, 0, 1, 2),   // 1×1 grouped, batch 8
        case([2, 16, 32, 32], 16, 3, 1, 1, 1, 1), // 512-pixel tiles: power-of-two stride
        case([2, 32, 32, 32], 32, 1, 1, 0, 1, 1), // 1×1 on a 1024-element plane
        case([8, 4, 8, 8], 8, 3, 2, 1, 1, 1),   // stride 2, batch 8
        case([2, 8, 9, 9], 4, 3, 1, 2, 2, 2),   // dilation, groups
        case([1, 8, 60, 20], 8, 3, 1, 1, 1, 1), // several rows per tile
    ];
    for (i, c) in cases.into_iter().enumerate() {
        let mut rng = Lcg(7000 + i as u64);
        let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
        let w_shape = [c.c_out, c.x[1] / c.groups, c.k[0], c.k[1]];
        let g = Geometry::new(&c.x, &w_shape, &opts).unwrap();
        let x = t4(rng.vec(c.x.iter().product()), c.x);
        let dy = t4(
            rng.vec(g.batch * g.c_out * g.out_plane()),
            [g.batch, g.c_out, g.oh, g.ow],
        );
        let padded = weight_grad_with::<f32>(&g, x.clone(), dy.clone(), WeightPanel::Padded);
        let contiguous = weight_grad_with::<f32>(&g, x, dy, WeightPanel::Contiguous);
        let same = padded
            .iter()
            .zip(&contiguous)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same && padded.len() == contiguous.len(), "{c:?}");
    }
}

/// Patches 7, 8 and 10: the stride-1 block copy and the stride-2 gather build
/// the same panel as the loop before them, and the stride-2 scatter adds a
/// panel back onto the input gradient bit for bit as the loop did, on listed
/// shapes and 60 seeded random ones (every tile of every image; a third of
/// them stride 2, as wide as 48 columns so that rows reach the 16-pixel
/// threshold of the stride-2 paths).
#[test]
fn fast_panels_equal_the_row_loop() {
    use super::panel::{col2im_rows_with, im2col_rows_with};
    let mut rng = Lcg(91);
    let mut cases = vec![
        case([1, 5, 13, 9], 7, 3, 1, 1, 1, 1),
        case([2, 8, 9, 9], 4, 3, 1, 2, 2, 2),
        case([1, 8, 60, 20], 8, 3, 1, 1, 1, 1),
        case([1, 2, 1, 9], 3, 3, 1, 1, 1, 1),
        case([1, 3, 11, 11], 5, 5, 1, 2, 1, 1),
        case([8, 4, 8, 8], 8, 3, 2, 1, 1, 1), // stride 2, rows of 4 pixels: the loop
        case([1, 3, 11, 11], 5, 5, 2, 2, 1, 1), // 5×5 stride 2
        case([2, 3, 6, 40], 4, 3, 2, 1, 1, 1), // stride 2, rows of 20: gather and scatter
        case([1, 2, 5, 37], 3, 3, 2, 0, 1, 1), // no padding, odd width: 18 pixels
        case([1, 2, 7, 45], 3, 5, 2, 2, 1, 1), // 5×5 stride 2, 23 pixels
    ];
    for _ in 0..60 {
        let k = [1, 3, 3, 5][rng.below(4)];
        let dil = 1 + rng.below(2);
        // Mostly "same" padding (the block copy's case), sometimes not.
        let pad = if rng.below(4) == 0 {
            rng.below(3)
        } else {
            dil * (k / 2)
        };
        let stride = [1, 1, 2][rng.below(3)];
        let h = 1 + rng.below(12);
        let w = if stride == 2 {
            1 + rng.below(48)
        } else {
            1 + rng.below(12)
        };
        cases.push(case(
            [1 + rng.below(2), 1 + rng.below(4), h, w],
            2,
            k,
            stride,
            pad,
            dil,
            1,
        ));
    }
    let (mut fast_hits, mut stride2_hits) = (0, 0);
    for (ci, c) in cases.into_iter().enumerate() {
        let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
        let w_shape = [c.c_out, c.x[1] / c.groups, c.k[0], c.k[1]];
        let Some(g) = Geometry::new(&c.x, &w_shape, &opts) else {
            continue; // a kernel larger than the padded input
        };
        fast_hits += usize::from(g.ow == g.w && g.sw == 1);
        // A row of enough valid pixels takes the stride-2 gather and scatter.
        stride2_hits += usize::from(
            g.sw == 2
                && (0..g.kw).any(|j| {
                    let (lo, hi) = g.valid_cols(j);
                    hi >= lo + super::panel::PAIRS_MIN_PIXELS
                }),
        );
        let mut rng = Lcg(ci as u64);
        let x = rng.vec(c.x.iter().product());
        let plane_len = g.cpg * g.in_plane();
        for b in 0..g.batch {
            let x_group = &x[b * g.c_in * g.in_plane()..][..plane_len];
            for (r0, r1) in g.tiles(1).into_iter().chain(g.tiles(4)) {
                let n = (r1 - r0) * g.ow;
                let ld = n + 3;
                let mut a = vec![f32::NAN; g.k() * ld];
                let mut bl = vec![f32::NAN; g.k() * ld];
                im2col_rows_with(&g, x_group, r0, r1, &mut a, ld, false);
                im2col_rows_with(&g, x_group, r0, r1, &mut bl, ld, true);
                for row in 0..g.k() {
                    let (ra, rb) = (&a[row * ld..row * ld + n], &bl[row * ld..row * ld + n]);
                    assert!(
                        ra.iter().zip(rb).all(|(p, q)| p.to_bits() == q.to_bits()),
                        "{c:?} rows {r0}..{r1} panel row {row}"
                    );
                }
                // The adjoint: a random panel added onto a random gradient.
                let panel = rng.vec(g.k() * n);
                let dx0 = rng.vec(plane_len);
                let (mut da, mut db) = (dx0.clone(), dx0);
                col2im_rows_with(&g, &panel, r0, r1, &mut da, false);
                col2im_rows_with(&g, &panel, r0, r1, &mut db, true);
                assert!(
                    da.iter().zip(&db).all(|(p, q)| p.to_bits() == q.to_bits()),
                    "{c:?} rows {r0}..{r1}: col2im differs"
                );
            }
        }
    }
    assert!(
        fast_hits >= 20 && stride2_hits >= 10,
        "only {fast_hits} cases took the block copy, {stride2_hits} the stride-2 paths"
    );
}

#[test]
fn geometry_rejects_asymmetric_padding_and_bad_channels() {
    let asym = ConvOptions::new_with_padding([1, 1], [(0, 1), (1, 1)], [1, 1], 1);
    assert!(Geometry::new(&[1, 2, 5, 5], &[2, 2, 3, 3], &asym).is_none());
    let opts = ConvOptions::new([1, 1], [0, 0], [1, 1], 2);
    assert!(Geometry::new(&[1, 3, 5, 5], &[2, 1, 3, 3], &opts).is_none());
    let big = ConvOptions::new([1, 1], [0, 0], [1, 1], 1);
    assert!(Geometry::new(&[1, 1, 2, 2], &[1, 1, 3, 3], &big).is_none());
}

/// Drops a NaN-filled buffer of `len` f32, so that glibc's allocator hands
/// the same block to the next allocation of that size: an output element
/// the operation forgot to write then reads NaN instead of a fresh zero.
fn poison(len: usize) {
    drop(core::hint::black_box(vec![f32::NAN; len]));
}

fn assert_finite(what: &str, case: &Case, v: &[f32]) {
    let bad = v.iter().filter(|x| !x.is_finite()).count();
    assert_eq!(bad, 0, "{what}: {bad} unwritten (NaN) elements, {case:?}");
}

/// Patches 5 and 9: the gradients' and the forward output's buffers are not
/// zero-filled, so every element must be written. Small shapes (glibc serves
/// them from its free lists, not fresh zeroed pages), checked for NaN and
/// against the direct f64 loop.
#[test]
fn engine_writes_every_element_of_unzeroed_buffers() {
    let cases = [
        case([2, 8, 9, 11], 16, 1, 1, 0, 1, 1), // pointwise: GEMM overwrites dX
        case([3, 6, 7, 5], 4, 1, 1, 0, 1, 2),   // pointwise, 2 groups
        case([2, 5, 13, 9], 7, 3, 1, 1, 1, 1),  // col2im: zeroed per (image, group)
        case([3, 4, 8, 8], 6, 3, 2, 1, 1, 2),   // stride 2, 2 groups
        case([1, 6, 5, 7], 4, 1, 2, 0, 1, 1),   // 1×1 stride 2 (col2im path)
    ];
    for (i, c) in cases.into_iter().enumerate() {
        let mut rng = Lcg(9000 + i as u64);
        let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
        let w_shape = [c.c_out, c.x[1] / c.groups, c.k[0], c.k[1]];
        let g = Geometry::new(&c.x, &w_shape, &opts).expect("valid convolution");
        let x = rng.vec(c.x.iter().product());
        let w = rng.vec(w_shape.iter().product());
        let dy = rng.vec(g.batch * g.c_out * g.out_plane());
        let [y_ref, dx_ref, dw_ref] = naive(&c, &g, &x, &w, &dy);
        let y_shape = [g.batch, g.c_out, g.oh, g.ow];
        let (xt, wt, dyt) = (t4(x, c.x), t4(w, w_shape), t4(dy, y_shape));
        poison(y_ref.len());
        let y = super::conv2d(xt.clone(), wt.clone(), None, &opts).unwrap();
        assert_finite("forward", &c, &values(&y));
        assert_close("forward vs naive", &c, &values(&y), &y_ref);
        poison(dx_ref.len());
        let dx = super::conv2d_x_backward(&c.x, wt, dyt.clone(), &opts).unwrap();
        assert_finite("x grad", &c, &values(&dx));
        assert_close("x grad vs naive", &c, &values(&dx), &dx_ref);
        let tasks = g.batch * g.tiles(1).len();
        poison(super::backward::WEIGHT_GRAD_CHUNKS.min(tasks) * dw_ref.len());
        let dw = super::conv2d_weight_backward(xt, &w_shape, dyt, &opts).unwrap();
        assert_finite("weight grad", &c, &values(&dw));
        assert_close("weight grad vs naive", &c, &values(&dw), &dw_ref);
    }
}

/// Patch 12: Winograd F(2×2, 3×3) forward, input and weight gradients against
/// the direct f64 loop (the forward also against the im2col engine), with a bias, on odd and even sizes, paddings 0–2, one-row and
/// one-column images, batches 1–8 and channel counts around the GEMM's
/// register tiles; every scratch buffer and freed block NaN-filled first, so
/// an unwritten output element or an unwritten transform entry fails.
#[test]
fn winograd_matches_reference() {
    let mut cases = vec![
        case([1, 5, 13, 9], 7, 3, 1, 1, 1, 1),
        case([2, 16, 8, 8], 16, 3, 1, 1, 1, 1),
        case([1, 3, 1, 9], 4, 3, 1, 1, 1, 1),
        case([1, 3, 9, 1], 4, 3, 1, 1, 1, 1),
        case([3, 4, 6, 7], 5, 3, 1, 0, 1, 1),
        case([1, 6, 5, 4], 3, 3, 1, 2, 1, 1),
        case([8, 9, 12, 10], 17, 3, 1, 1, 1, 1),
        case([1, 33, 40, 24], 31, 3, 1, 1, 1, 1),
    ];
    let mut rng = Lcg(77);
    for _ in 0..24 {
        let (h, w) = (1 + rng.below(14), 1 + rng.below(14));
        let pad = rng.below(3);
        if h + 2 * pad < 3 || w + 2 * pad < 3 {
            continue;
        }
        let (c_in, c_out) = (1 + rng.below(20), 1 + rng.below(20));
        cases.push(case([1 + rng.below(4), c_in, h, w], c_out, 3, 1, pad, 1, 1));
    }
    for (i, c) in cases.into_iter().enumerate() {
        let mut rng = Lcg(12000 + i as u64);
        let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
        let w_shape = [c.c_out, c.x[1], 3, 3];
        let g = Geometry::new(&c.x, &w_shape, &opts).expect("valid convolution");
        assert!(super::winograd::takes(&g));
        let x = rng.vec(c.x.iter().product());
        let w = rng.vec(w_shape.iter().product());
        let bias = rng.vec(c.c_out);
        let dy = rng.vec(g.batch * g.c_out * g.out_plane());
        let [y_ref, dx_ref, dw_ref] = naive(&c, &g, &x, &w, &dy);
        let y_ref: Vec<f32> = y_ref
            .iter()
            .enumerate()
            .map(|(i, v)| v + bias[(i / g.out_plane()) % g.c_out])
            .collect();
        let (xt, wt) = (t4(x, c.x), t4(w, w_shape));
        let bt = FlexTensor::new(
            Bytes::from_elems(bias),
            Layout::contiguous(Shape::from(vec![c.c_out])),
            DType::F32,
        );
        #[cfg(all(feature = "rayon", feature = "std"))]
        super::poison_scratch(1 << 16, f32::NAN);
        poison(y_ref.len());
        let y = super::conv2d_winograd(xt.clone(), wt.clone(), Some(bt.clone()), &opts).unwrap();
        assert_finite("winograd", &c, &values(&y));
        assert_close("winograd vs naive", &c, &values(&y), &y_ref);
        let engine = super::conv2d(xt.clone(), wt.clone(), Some(bt), &opts).unwrap();
        assert_close("winograd vs engine", &c, &values(&y), &values(&engine));
        poison(y_ref.len());
        let y = super::conv2d_winograd(xt.clone(), wt.clone(), None, &opts).unwrap();
        assert_finite("winograd, no bias", &c, &values(&y));
        let dyt = t4(dy, [g.batch, g.c_out, g.oh, g.ow]);
        poison(dx_ref.len());
        let dx = super::conv2d_x_backward_winograd(&c.x, wt, dyt.clone(), &opts).unwrap();
        assert_finite("winograd x grad", &c, &values(&dx));
        assert_close("winograd x grad vs naive", &c, &values(&dx), &dx_ref);
        poison(16 * super::backward::WEIGHT_GRAD_CHUNKS * dw_ref.len());
        let dw = super::conv2d_weight_backward_winograd(xt, &w_shape, dyt, &opts).unwrap();
        assert_finite("winograd weight grad", &c, &values(&dw));
        assert_close("winograd weight grad vs naive", &c, &values(&dw), &dw_ref);
    }
}

/// Winograd takes only what it computes: no stride, dilation, group or other
/// kernel size, no dtype but f32, and (input gradient) no padding above 2.
#[test]
fn winograd_declines_other_shapes() {
    let x = t4(vec![0.5; 2 * 4 * 6 * 6], [2, 4, 6, 6]);
    let w3 = t4(vec![0.5; 4 * 4 * 9], [4, 4, 3, 3]);
    let declined = [
        ConvOptions::new([2, 2], [1, 1], [1, 1], 1),
        ConvOptions::new([1, 1], [2, 2], [2, 2], 1),
        ConvOptions::new([1, 1], [1, 1], [1, 1], 2),
    ];
    for opts in declined {
        let w = if opts.groups == 2 {
            t4(vec![0.5; 4 * 2 * 9], [4, 2, 3, 3])
        } else {
            w3.clone()
        };
        assert!(
            super::conv2d_winograd(x.clone(), w, None, &opts).is_none(),
            "{opts:?}"
        );
    }
    let w1 = t4(vec![0.5; 16], [4, 4, 1, 1]);
    let opts = ConvOptions::new([1, 1], [0, 0], [1, 1], 1);
    assert!(super::conv2d_winograd(x.clone(), w1, None, &opts).is_none());
    let opts = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
    let x64 = FlexTensor::new(
        Bytes::from_elems(vec![0.5f64; 2 * 4 * 6 * 6]),
        Layout::contiguous(Shape::from(vec![2, 4, 6, 6])),
        DType::F64,
    );
    assert!(super::conv2d_winograd(x64, w3.clone(), None, &opts).is_none());
    let opts = ConvOptions::new([1, 1], [3, 3], [1, 1], 1);
    let dy = t4(vec![0.5; 2 * 4 * 10 * 10], [2, 4, 10, 10]);
    assert!(super::conv2d_winograd(x.clone(), w3.clone(), None, &opts).is_some());
    assert!(super::conv2d_x_backward_winograd(&[2, 4, 6, 6], w3, dy, &opts).is_none());
}

/// Patch 12's dispatch: flex's conv2d and both gradients, for a shape with
/// enough tiles that dispatch prefers Winograd for all three, match the direct
/// loop.
#[test]
fn backend_ops_route_large_3x3_layers_through_winograd() {
    use crate::Flex;
    use burn_backend::ops::ModuleOps;
    let c = case([2, 6, 32, 33], 5, 3, 1, 1, 1, 1);
    let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
    let w_shape = [c.c_out, c.x[1], 3, 3];
    let g = Geometry::new(&c.x, &w_shape, &opts).unwrap();
    assert!(super::prefers_winograd(&g) && super::prefers_winograd_weight_grad(&g));
    let mut rng = Lcg(31);
    let x = rng.vec(c.x.iter().product());
    let w = rng.vec(w_shape.iter().product());
    let dy = rng.vec(g.batch * g.c_out * g.out_plane());
    let [y_ref, dx_ref, dw_ref] = naive(&c, &g, &x, &w, &dy);
    let (xt, wt) = (t4(x, c.x), t4(w, w_shape));
    let dyt = t4(dy, [g.batch, g.c_out, g.oh, g.ow]);
    let y = Flex::conv2d(xt.clone(), wt.clone(), None, opts.clone());
    assert_close("conv2d", &c, &values(&y), &y_ref);
    let dx = Flex::conv2d_x_backward(xt.clone(), wt.clone(), dyt.clone(), opts.clone());
    assert_close("conv2d_x_backward", &c, &values(&dx), &dx_ref);
    let dw = Flex::conv2d_weight_backward(xt, wt, dyt, opts);
    assert_close("conv2d_weight_backward", &c, &values(&dw), &dw_ref);
}

/// Patch 13: a convolution with a fused SiLU equals the convolution followed
/// by Burn's composed SiLU (`x · sigmoid(x)` as two flex ops) bit for bit, on
/// each route: Winograd, the im2col engine (k×k, strided, 1×1 with an
/// activation) and the old direct paths (depthwise, then SiLU in place), with
/// and without a bias, batch 1 and 3, every output element written.
#[test]
fn fused_silu_equals_conv_then_composed_silu() {
    use crate::Flex;
    use crate::ops::conv2d_activated;
    use burn_backend::ops::{ActivationOps, FloatTensorOps, ModuleOps};
    let cases = [
        case([1, 6, 32, 33], 5, 3, 1, 1, 1, 1), // Winograd (≥ 192 tiles)
        case([1, 6, 9, 7], 5, 3, 1, 1, 1, 1),   // engine, few tiles
        case([3, 4, 17, 16], 8, 3, 2, 1, 1, 1), // stride 2
        case([1, 16, 12, 13], 24, 1, 1, 0, 1, 1), // 1×1: engine only with the activation
        case([3, 12, 10, 10], 12, 3, 1, 1, 1, 12), // depthwise: old path + in place
        case([2, 8, 11, 9], 6, 3, 1, 1, 1, 2),  // grouped
    ];
    let mut rng = Lcg(13);
    for c in cases {
        let opts = ConvOptions::new(c.stride, c.pad, c.dil, c.groups);
        let w_shape = [c.c_out, c.x[1] / c.groups, c.k[0], c.k[1]];
        let g = Geometry::new(&c.x, &w_shape, &opts).expect("valid convolution");
        let (x, w) = (
            rng.vec(c.x.iter().product()),
            rng.vec(w_shape.iter().product()),
        );
        // Scaled up so that the SiLU sees large negative and positive inputs.
        let x: Vec<f32> = x.iter().map(|v| 4.0 * v).collect();
        let (xt, wt) = (t4(x, c.x), t4(w, w_shape));
        for with_bias in [false, true] {
            let bias = with_bias.then(|| {
                FlexTensor::new(
                    Bytes::from_elems(rng.vec(c.c_out)),
                    Layout::contiguous(Shape::from(vec![c.c_out])),
                    DType::F32,
                )
            });
            // What the fused call must equal: the same route without an
            // activation (the engine for 1×1 too), then Burn's SiLU.
            let plain = if super::prefers_forward(&g) || g.is_pointwise() {
                let b = bias.clone();
                super::conv2d_preferred(
                    xt.clone(),
                    wt.clone(),
                    b,
                    &opts,
                    super::Activation::Identity,
                )
                .unwrap()
            } else {
                Flex::conv2d(xt.clone(), wt.clone(), bias.clone(), opts.clone())
            };
            let want = values(&Flex::float_mul(plain.clone(), Flex::sigmoid(plain)));
            #[cfg(all(feature = "rayon", feature = "std"))]
            super::poison_scratch(1 << 16, f32::NAN);
            poison(want.len());
            let got = conv2d_activated(
                xt.clone(),
                wt.clone(),
                bias,
                opts.clone(),
                super::Activation::Silu,
            );
            let got = values(&got);
            assert_finite("fused silu", &c, &got);
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(
                same && got.len() == want.len(),
                "fused silu differs, bias {with_bias}, {c:?}"
            );
        }
    }
}
