//! Side-by-side timing of the engine and the paths it replaces on 27 distinct
//! convolution shapes of YOLO11n-seg (ultralytics `yolo11-seg.yaml`, scale n, one
//! class), forward and both gradients, batch 1. The list is not every shape of
//! the model and its counts are approximate, so the TOTAL rows are indicative
//! only; the per-shape ratios are the measurement. Ignored by default (it takes
//! minutes); run with
//! `cargo test --release --lib conv_engine::bench -- --ignored --nocapture`.
//! Old and new calls alternate (old, new, old, new, …) so both see the same
//! machine load; the median of 10 repeats is reported, as GFLOP/s and the
//! ratio old ÷ new.

extern crate std;

use alloc::vec::Vec;
use burn_backend::ops::ConvOptions;
use burn_backend::{DType, TensorData};
use std::println;
use std::time::Instant;

use super::{Geometry, prefers_forward, reference};
use crate::FlexTensor;
use crate::ops::conv::conv2d_f32;

const REPEATS: usize = 10;

/// Distinct YOLO11n-seg convolutions: (c_in, c_out, k, stride, groups, input level, count).
const SHAPES: [(usize, usize, usize, usize, usize, u32, usize); 27] = [
    (3, 16, 3, 2, 1, 0, 1),
    (16, 32, 3, 2, 1, 1, 1),
    (32, 32, 1, 1, 1, 2, 1),
    (16, 16, 3, 1, 1, 2, 2),
    (48, 64, 1, 1, 1, 2, 1),
    (64, 64, 3, 2, 1, 2, 1),
    (64, 64, 3, 1, 1, 2, 1),
    (64, 32, 1, 1, 1, 2, 1),
    (64, 64, 1, 1, 1, 3, 3),
    (32, 32, 3, 1, 1, 3, 4),
    (96, 128, 1, 1, 1, 3, 1),
    (128, 128, 3, 2, 1, 3, 1),
    (64, 64, 3, 1, 1, 3, 3),
    (64, 64, 3, 1, 64, 3, 2),
    (64, 32, 3, 1, 1, 3, 1),
    (128, 128, 1, 1, 1, 4, 1),
    (32, 32, 3, 1, 1, 4, 4),
    (192, 128, 1, 1, 1, 4, 3),
    (128, 256, 3, 2, 1, 4, 1),
    (64, 64, 3, 1, 1, 4, 5),
    (384, 128, 1, 1, 1, 4, 1),
    (128, 128, 3, 1, 128, 4, 1),
    (256, 256, 1, 1, 1, 5, 3),
    (64, 64, 3, 1, 1, 5, 9),
    (384, 256, 1, 1, 1, 5, 3),
    (128, 256, 1, 1, 1, 5, 2),
    (256, 256, 3, 1, 256, 5, 1),
];

fn tensor(shape: [usize; 4], seed: &mut u64) -> FlexTensor {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*seed >> 40) as f32 / (1u64 << 24) as f32) - 0.5
        })
        .collect();
    FlexTensor::from_data(TensorData::new(data, shape))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn interleaved(old: &mut dyn FnMut(), new: &mut dyn FnMut()) -> (f64, f64) {
    old();
    new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..REPEATS {
        let t = Instant::now();
        old();
        a.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        new();
        b.push(t.elapsed().as_secs_f64() * 1e3);
    }
    (median(a), median(b))
}

#[test]
#[ignore = "benchmark: minutes; run with --ignored --nocapture"]
fn bench_yolo11n_seg_shapes() {
    println!(
        "| size | shape | ×n | pass | old ms | engine ms | old GFLOP/s | engine GFLOP/s | ratio | fwd→engine |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for size in [256usize, 640] {
        let mut totals = [(0.0f64, 0.0f64); 3];
        for &(c_in, c_out, k, s, groups, level, count) in &SHAPES {
            let hw = size >> level;
            let opts = ConvOptions::new([s; 2], [k / 2; 2], [1, 1], groups);
            let x_shape = [1, c_in, hw, hw];
            let w_shape = [c_out, c_in / groups, k, k];
            let g = Geometry::new(&x_shape, &w_shape, &opts).unwrap();
            let mut seed = 37;
            let x = tensor(x_shape, &mut seed);
            let w = tensor(w_shape, &mut seed);
            let dy = tensor([1, c_out, g.oh, g.ow], &mut seed);
            assert_eq!(x.dtype(), DType::F32);
            let gflop = 2.0 * (c_out * g.oh * g.ow * (c_in / groups) * k * k) as f64 / 1e9;
            let fwd = prefers_forward(&g);
            let timings = [
                interleaved(
                    &mut || drop(conv2d_f32(x.clone(), w.clone(), None, &opts)),
                    &mut || drop(super::conv2d(x.clone(), w.clone(), None, &opts)),
                ),
                interleaved(
                    &mut || {
                        drop(reference::x_backward_f32(
                            &x_shape,
                            w.clone(),
                            dy.clone(),
                            &opts,
                        ))
                    },
                    &mut || {
                        drop(super::conv2d_x_backward(
                            &x_shape,
                            w.clone(),
                            dy.clone(),
                            &opts,
                        ))
                    },
                ),
                interleaved(
                    &mut || {
                        drop(reference::weight_backward_f32(
                            x.clone(),
                            &w_shape,
                            dy.clone(),
                            &opts,
                        ))
                    },
                    &mut || {
                        drop(super::conv2d_weight_backward(
                            x.clone(),
                            &w_shape,
                            dy.clone(),
                            &opts,
                        ))
                    },
                ),
            ];
            for (p, (old, new)) in timings.into_iter().enumerate() {
                let pass = ["forward", "x grad", "weight grad"][p];
                // What conv2d actually runs: the old forward where dispatch keeps it.
                let used = if p == 0 && !fwd { old } else { new };
                totals[p].0 += count as f64 * old;
                totals[p].1 += count as f64 * used;
                println!(
                    "| {size} | {c_in}→{c_out} {k}×{k} s{s} g{groups} @{hw} | {count} | {pass} | {old:.3} | {new:.3} | {:.1} | {:.1} | {:.2} | {fwd} |",
                    gflop / old * 1e3,
                    gflop / new * 1e3,
                    old / new
                );
            }
        }
        for (p, (old, used)) in totals.iter().enumerate() {
            let pass = ["forward", "x grad", "weight grad"][p];
            println!(
                "| {size} | TOTAL (each shape × its count, with dispatch) | | {pass} | {old:.2} | {used:.2} | | | {:.2} | |",
                old / used
            );
        }
    }
}

/// One side-by-side table over the model's shapes at batch 1 / 256 px, batch 1
/// / 640 px and batch 8 / 256 px: `time` gives (`sides[0]` ms, `sides[1]` ms)
/// for a layer's geometry (`None` skips it), and each (batch, size) ends with
/// a TOTAL row weighted by the layer counts.
fn side_by_side(sides: [&str; 2], mut time: impl FnMut(&Geometry) -> Option<(f64, f64)>) {
    println!(
        "| batch | size | shape | ×n | {} ms | {} ms | ratio |",
        sides[0], sides[1]
    );
    println!("|---|---|---|---|---|---|---|");
    for (batch, size) in [(1usize, 256usize), (1, 640), (8, 256)] {
        let (mut before, mut after) = (0.0f64, 0.0f64);
        for &(c_in, c_out, k, s, groups, level, count) in &SHAPES {
            let hw = size >> level;
            let opts = ConvOptions::new([s; 2], [k / 2; 2], [1, 1], groups);
            let w_shape = [c_out, c_in / groups, k, k];
            let g = Geometry::new(&[batch, c_in, hw, hw], &w_shape, &opts).unwrap();
            let Some((a, b)) = time(&g) else {
                continue;
            };
            before += a * count as f64;
            after += b * count as f64;
            println!(
                "| {batch} | {size} | {c_in}→{c_out} {k}×{k} s{s} g{groups} @{hw} | {count} | {a:.3} | {b:.3} | {:.2} |",
                a / b
            );
        }
        println!(
            "| {batch} | {size} | TOTAL | | {before:.2} | {after:.2} | {:.2} |",
            before / after
        );
    }
}

/// Patch 6 alone: the weight gradient with the contiguous panel (before) and
/// the padded one (after), interleaved, on the same shapes at batch 1 and 8.
/// `cargo test --release --lib conv_engine::bench::bench_weight_panel -- --ignored --nocapture`
#[test]
#[ignore = "benchmark: minutes; run with --ignored --nocapture"]
fn bench_weight_panel_layouts() {
    use super::backward::{WeightPanel, weight_grad_with};
    side_by_side(["contiguous", "padded"], |g| {
        let mut seed = 37;
        let x = tensor([g.batch, g.c_in, g.h, g.w], &mut seed);
        let dy = tensor([g.batch, g.c_out, g.oh, g.ow], &mut seed);
        let run = |layout| drop(weight_grad_with::<f32>(g, x.clone(), dy.clone(), layout));
        Some(interleaved(
            &mut || run(WeightPanel::Contiguous),
            &mut || run(WeightPanel::Padded),
        ))
    });
}

/// Patch 7 alone: every im2col panel of a layer (all tiles of all images, as
/// the forward pass builds them) with the loop as it was and with the
/// stride-1 block copy, interleaved, on the same shapes at batch 1 and 8.
/// `cargo test --release --lib conv_engine::bench::bench_im2col -- --ignored --nocapture`
#[test]
#[ignore = "benchmark: minutes; run with --ignored --nocapture"]
fn bench_im2col_block_copy() {
    use super::panel::im2col_rows_with;
    side_by_side(["before", "block copy"], |g| {
        if g.is_pointwise() || g.is_depthwise() {
            return None; // no panel in the forward pass
        }
        let mut seed = 37;
        let x = tensor([g.batch, g.c_in, g.h, g.w], &mut seed);
        let xs: &[f32] = x.storage();
        let tiles = &g.tiles(1);
        let longest = tiles.iter().map(|t| (t.1 - t.0) * g.ow).max().unwrap();
        // Each side fills a panel of its own, as each thread of the engine does.
        let build = |fast: bool| {
            let mut panel = alloc::vec![0.0f32; g.k() * longest];
            move || {
                for b in 0..g.batch {
                    for grp in 0..g.groups {
                        let off = (b * g.c_in + grp * g.cpg) * g.in_plane();
                        let x_group = &xs[off..off + g.cpg * g.in_plane()];
                        for &(r0, r1) in tiles {
                            let n = (r1 - r0) * g.ow;
                            let panel = &mut panel[..g.k() * n];
                            im2col_rows_with(g, x_group, r0, r1, panel, n, fast);
                        }
                    }
                }
                core::hint::black_box(&panel);
            }
        };
        Some(interleaved(&mut build(false), &mut build(true)))
    });
}

/// Patch 10 alone: every col2im of a layer's input gradient (all tiles of all
/// images and groups, as the backward pass scatters them) with the loop as it
/// was and with the stride-2 scatter, interleaved; stride-1 layers take the
/// same code on both sides (a control of the bench's noise).
/// `cargo test --release --lib conv_engine::bench::bench_col2im -- --ignored --nocapture`
#[test]
#[ignore = "benchmark: minutes; run with --ignored --nocapture"]
fn bench_col2im_stride2_scatter() {
    use super::panel::col2im_rows_with;
    side_by_side(["before", "scatter"], |g| {
        if g.is_pointwise() {
            return None; // the input gradient is a GEMM written in place
        }
        let mut seed = 37;
        let tiles = &g.tiles(1);
        // One panel per tile, as the GEMM before each col2im leaves it.
        let panels: Vec<FlexTensor> = tiles
            .iter()
            .map(|t| tensor([1, 1, g.k(), (t.1 - t.0) * g.ow], &mut seed))
            .collect();
        let panels = &panels;
        let run = |fast: bool| {
            let mut dx = alloc::vec![0.0f32; g.batch * g.c_in * g.in_plane()];
            move || {
                dx.fill(0.0);
                for b in 0..g.batch {
                    for grp in 0..g.groups {
                        let off = (b * g.c_in + grp * g.cpg) * g.in_plane();
                        let dx_group = &mut dx[off..off + g.cpg * g.in_plane()];
                        for (&(r0, r1), p) in tiles.iter().zip(panels.iter()) {
                            col2im_rows_with(g, p.storage(), r0, r1, dx_group, fast);
                        }
                    }
                }
                core::hint::black_box(&dx);
            }
        };
        Some(interleaved(&mut run(false), &mut run(true)))
    });
}

/// Patch 11 alone: a layer's forward and both gradients through the engine
/// with a fresh scratch buffer per rayon job (as before) and with each
/// thread's buffer kept between calls, interleaved, on the same shapes at
/// batch 1 and 8. The engine's own forward runs for every shape here, the
/// 1×1 and depthwise ones included (their forward is dispatched elsewhere).
/// `cargo test --release --lib --features x86-v4 conv_engine::bench::bench_scratch -- --ignored --nocapture`
#[test]
#[ignore = "benchmark: minutes; run with --ignored --nocapture"]
fn bench_scratch_kept_per_thread() {
    use core::sync::atomic::Ordering;
    side_by_side(["fresh", "kept"], |g| {
        let mut seed = 37;
        let x_shape = [g.batch, g.c_in, g.h, g.w];
        let w_shape = [g.c_out, g.cpg, g.kh, g.kw];
        let x = tensor(x_shape, &mut seed);
        let w = tensor(w_shape, &mut seed);
        let dy = tensor([g.batch, g.c_out, g.oh, g.ow], &mut seed);
        let opts = ConvOptions::new([g.sh, g.sw], [g.ph, g.pw], [g.dh, g.dw], g.groups);
        let (x, w, dy, opts) = (&x, &w, &dy, &opts);
        let step = |fresh: bool| {
            move || {
                super::FRESH_SCRATCH.store(fresh, Ordering::Relaxed);
                drop(super::conv2d(x.clone(), w.clone(), None, opts));
                drop(super::conv2d_x_backward(
                    &x_shape,
                    w.clone(),
                    dy.clone(),
                    opts,
                ));
                drop(super::conv2d_weight_backward(
                    x.clone(),
                    &w_shape,
                    dy.clone(),
                    opts,
                ));
                super::FRESH_SCRATCH.store(false, Ordering::Relaxed);
            }
        };
        Some(interleaved(&mut step(true), &mut step(false)))
    });
}

/// Patch 12 alone: the forward, the input gradient, then the weight gradient of every stride-1
/// 3×3 layer through the im2col engine and through Winograd F(2×2, 3×3),
/// interleaved, at batch 1 and 8 (the weight transform included on the
/// Winograd side, as each call pays it).
/// `cargo test --release --lib conv_engine::bench::bench_winograd -- --ignored --nocapture`
#[test]
#[ignore = "benchmark: minutes; run with --ignored --nocapture"]
fn bench_winograd_forward() {
    side_by_side(["im2col engine", "winograd"], |g| {
        if !super::winograd::takes(g) {
            return None;
        }
        let mut seed = 37;
        let x = tensor([g.batch, g.c_in, g.h, g.w], &mut seed);
        let w = tensor([g.c_out, g.cpg, g.kh, g.kw], &mut seed);
        let b = tensor([1, 1, 1, g.c_out], &mut seed);
        let b = FlexTensor::from_data(TensorData::new(b.storage::<f32>().to_vec(), [g.c_out]));
        let opts = ConvOptions::new([g.sh, g.sw], [g.ph, g.pw], [g.dh, g.dw], g.groups);
        let (x, w, b, opts) = (&x, &w, &b, &opts);
        Some(interleaved(
            &mut || drop(super::conv2d(x.clone(), w.clone(), Some(b.clone()), opts)),
            &mut || {
                drop(super::conv2d_winograd(
                    x.clone(),
                    w.clone(),
                    Some(b.clone()),
                    opts,
                ))
            },
        ))
    });
    side_by_side(["im2col engine x grad", "winograd x grad"], |g| {
        if !super::winograd::takes(g) {
            return None;
        }
        let mut seed = 37;
        let x_shape = [g.batch, g.c_in, g.h, g.w];
        let w = tensor([g.c_out, g.cpg, g.kh, g.kw], &mut seed);
        let dy = tensor([g.batch, g.c_out, g.oh, g.ow], &mut seed);
        let opts = ConvOptions::new([g.sh, g.sw], [g.ph, g.pw], [g.dh, g.dw], g.groups);
        let (w, dy, opts) = (&w, &dy, &opts);
        Some(interleaved(
            &mut || {
                drop(super::conv2d_x_backward(
                    &x_shape,
                    w.clone(),
                    dy.clone(),
                    opts,
                ))
            },
            &mut || {
                drop(super::conv2d_x_backward_winograd(
                    &x_shape,
                    w.clone(),
                    dy.clone(),
                    opts,
                ))
            },
        ))
    });
    side_by_side(["im2col engine w grad", "winograd w grad"], |g| {
        if !super::winograd::takes(g) {
            return None;
        }
        let mut seed = 37;
        let w_shape = [g.c_out, g.cpg, g.kh, g.kw];
        let x = tensor([g.batch, g.c_in, g.h, g.w], &mut seed);
        let dy = tensor([g.batch, g.c_out, g.oh, g.ow], &mut seed);
        let opts = ConvOptions::new([g.sh, g.sw], [g.ph, g.pw], [g.dh, g.dw], g.groups);
        let (x, dy, opts) = (&x, &dy, &opts);
        Some(interleaved(
            &mut || {
                drop(super::conv2d_weight_backward(
                    x.clone(),
                    &w_shape,
                    dy.clone(),
                    opts,
                ))
            },
            &mut || {
                drop(super::conv2d_weight_backward_winograd(
                    x.clone(),
                    &w_shape,
                    dy.clone(),
                    opts,
                ))
            },
        ))
    });
}
