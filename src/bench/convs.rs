//! `chicktrain bench convs`: every convolution shape of YOLO11n-seg and of the compact
//! Mask R-CNN R18 ([`super::conv_shapes`]) timed alone on flex, the convolution engine of
//! `vendor/burn-flex` (issue 37; its Winograd path for the large stride-1 3×3 layers where
//! flex's dispatch sends them there) beside the path it replaced, in one process and
//! interleaved (old, new, old, new, …) so both see the same machine load. Three passes per
//! shape: forward (engine vs the old dispatch of `conv::conv2d_f32`: tiled im2col + gemm,
//! or its 1×1 / depthwise / small-channel fast paths), input gradient (engine vs Burn's
//! default transposed convolution) and weight gradient (engine vs Burn's default
//! convolution of the batch-swapped tensors). Reported per row: median ms of each side,
//! GFLOP/s (2 FLOPs per multiply-add), the engine's share of the machine's peak
//! ([`Peak`]) and the ratio old ÷ engine; per model and size, totals weighted by how often
//! each shape occurs. A large square GEMM through flex's matmul is timed too, as the rate
//! a GEMM reaches on this machine. Written as CSV and markdown.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::tensor::ops::ConvOptions;
use burn::tensor::TensorData;
use burn_flex::ops::conv::conv2d_f32;
use burn_flex::ops::conv_engine::{self, reference, Geometry};
use burn_flex::FlexTensor;

use super::conv_shapes::{maskrcnn_r18, yolo11n_seg, ConvShape};
use super::peak::Peak;
use crate::util::write_atomic;

/// Seed of the benchmark's input values (they do not affect the timing).
const SEED: u64 = 37;

/// The three passes timed per shape.
const PASSES: [&str; 3] = ["forward", "x grad", "weight grad"];

/// One (shape, pass): median milliseconds of the old path and of the engine.
#[derive(Debug, Clone)]
pub struct ConvTiming {
    pub size: usize,
    pub shape: ConvShape,
    pub pass: &'static str,
    pub gflop: f64,
    pub old_ms: f64,
    pub new_ms: f64,
    /// Whether `conv2d` dispatches this shape's forward pass to the engine.
    pub engine_forward: bool,
}

impl ConvTiming {
    /// What flex runs now: the engine, except forwards that dispatch keeps on the old path.
    fn used_ms(&self) -> f64 {
        if self.pass == "forward" && !self.engine_forward {
            self.old_ms
        } else {
            self.new_ms
        }
    }
}

fn tensor(shape: &[usize], rng: &mut u64) -> FlexTensor {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|_| {
            *rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*rng >> 40) as f32 / (1u64 << 24) as f32) - 0.5
        })
        .collect();
    FlexTensor::from_data(TensorData::new(data, shape.to_vec()))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Time `old` and `new` alternately, `repeats` times each after one warm-up call of each.
fn interleaved(repeats: usize, old: &dyn Fn(), new: &dyn Fn()) -> (f64, f64) {
    old();
    new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let t = Instant::now();
        old();
        a.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        new();
        b.push(t.elapsed().as_secs_f64() * 1e3);
    }
    (median(a), median(b))
}

/// Time the three passes of one shape at `batch` images.
fn time_shape(size: usize, c: &ConvShape, batch: usize, repeats: usize) -> Vec<ConvTiming> {
    let opts = ConvOptions::new([c.stride; 2], [c.k / 2; 2], [1, 1], c.groups);
    let x_shape = [batch, c.c_in, c.hw, c.hw];
    let w_shape = [c.c_out, c.c_in / c.groups, c.k, c.k];
    let g = Geometry::new(&x_shape, &w_shape, &opts).expect("model shapes are valid");
    let mut rng = SEED;
    let x = tensor(&x_shape, &mut rng);
    let w = tensor(&w_shape, &mut rng);
    let dy = tensor(&[batch, c.c_out, g.oh, g.ow], &mut rng);
    let gflop = 2.0 * (batch as u64 * c.macs()) as f64 / 1e9;
    let (x, w, dy) = (&x, &w, &dy);
    let timings = [
        interleaved(
            repeats,
            &|| drop(conv2d_f32(x.clone(), w.clone(), None, &opts)),
            // The new side runs what flex runs (Winograd for large stride-1 3×3 layers).
            &|| {
                drop(conv_engine::conv2d_preferred(
                    x.clone(),
                    w.clone(),
                    None,
                    &opts,
                    conv_engine::Activation::Identity,
                ))
            },
        ),
        interleaved(
            repeats,
            &|| {
                drop(reference::x_backward_f32(
                    &x_shape,
                    w.clone(),
                    dy.clone(),
                    &opts,
                ))
            },
            &|| {
                drop(conv_engine::conv2d_x_backward_preferred(
                    &x_shape,
                    w.clone(),
                    dy.clone(),
                    &opts,
                ))
            },
        ),
        interleaved(
            repeats,
            &|| {
                drop(reference::weight_backward_f32(
                    x.clone(),
                    &w_shape,
                    dy.clone(),
                    &opts,
                ))
            },
            &|| {
                drop(conv_engine::conv2d_weight_backward_preferred(
                    x.clone(),
                    &w_shape,
                    dy.clone(),
                    &opts,
                ))
            },
        ),
    ];
    timings
        .into_iter()
        .zip(PASSES)
        .map(|((old_ms, new_ms), pass)| ConvTiming {
            size,
            shape: c.clone(),
            pass,
            gflop,
            old_ms,
            new_ms,
            engine_forward: conv_engine::prefers_forward(&g),
        })
        .collect()
}

/// GFLOP/s of one `n × n × n` f32 matmul through flex (median of `repeats`).
fn gemm_gflops(n: usize, repeats: usize) -> f64 {
    let mut rng = SEED;
    let a = tensor(&[n, n], &mut rng);
    let b = tensor(&[n, n], &mut rng);
    let one = || drop(burn_flex::ops::matmul::matmul(a.clone(), b.clone()));
    one();
    let times = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            one();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    2.0 * (n * n * n) as f64 / median(times) / 1e6
}

/// Options of one `bench convs` run.
#[derive(Debug, Clone)]
pub struct ConvsArgs {
    pub sizes: Vec<usize>,
    pub models: Vec<String>,
    pub batch: usize,
    pub repeats: usize,
    pub ghz: Option<f64>,
}

/// Measure every shape at every size; write `convs.csv` and `convs.md` into `out`.
pub fn run(args: &ConvsArgs, out: &Path) -> Result<String> {
    let ConvsArgs {
        sizes,
        models,
        batch,
        repeats,
        ghz,
    } = args;
    if sizes.is_empty() || sizes.iter().any(|&s| s < 64 || s % 64 != 0) {
        bail!("bench convs: --sizes must be multiples of 64 (got {sizes:?})");
    }
    if *batch == 0 || *repeats == 0 {
        bail!("bench convs: --batch and --repeats must be at least 1");
    }
    if let Some(m) = models
        .iter()
        .find(|m| !["yolo11n-seg", "maskrcnn-r18"].contains(&m.as_str()))
    {
        bail!("bench convs: unknown model {m:?} (known: yolo11n-seg, maskrcnn-r18)");
    }
    let peak = Peak::detect(*ghz)?;
    let mut rows = Vec::new();
    for &size in sizes {
        for model in models {
            let shapes = match model.as_str() {
                "yolo11n-seg" => yolo11n_seg(size),
                _ => maskrcnn_r18(size),
            };
            for c in shapes {
                rows.extend(time_shape(size, &c, *batch, *repeats));
            }
        }
    }
    let gemm = gemm_gflops(1024, (*repeats).max(3));
    let (csv, md) = report(&rows, args, &peak, gemm);
    std::fs::create_dir_all(out)
        .with_context(|| format!("bench convs: cannot create {}", out.display()))?;
    write_atomic(&out.join("convs.csv"), csv.as_bytes())?;
    write_atomic(&out.join("convs.md"), md.as_bytes())?;
    Ok(md)
}

/// CSV (one row per shape and pass) and markdown (the same plus per-model, per-size totals
/// weighted by how often each shape occurs).
fn report(rows: &[ConvTiming], args: &ConvsArgs, peak: &Peak, gemm: f64) -> (String, String) {
    let pk = peak.gflops();
    let mut csv = String::from(
        "model,size,name,c_in,c_out,k,stride,groups,hw,count,pass,gflop,old_ms,new_ms,old_gflops,new_gflops,new_pct_peak,ratio,engine_forward\n",
    );
    let mut md = format!(
        "Batch {}, f32, median of {} interleaved repeats (old, engine, old, …) after one warm-up \
         each. ratio = old ms ÷ engine ms (> 1: the engine is faster). The engine side runs \
         what flex dispatches to: Winograd F(2×2, 3×3) for stride-1 3×3 layers with at least \
         192 output tiles (512 for the weight gradient), the im2col engine otherwise. \
         `fwd→engine`: whether flex's conv2d dispatches this forward to either (otherwise it \
         keeps the old path).\n\n\
         Peak: {}. A 1024³ f32 matmul through flex reached {gemm:.1} GFLOP/s ({:.0} % of it) \
         in the same run.\n\n\
         | model | size | conv | shape | ×n | pass | old ms | engine ms | old GFLOP/s | engine GFLOP/s | engine % peak | ratio | fwd→engine |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        args.batch,
        args.repeats,
        peak.describe(),
        100.0 * gemm / pk
    );
    for r in rows {
        let c = &r.shape;
        let (og, ng) = (r.gflop / r.old_ms * 1e3, r.gflop / r.new_ms * 1e3);
        let ratio = r.old_ms / r.new_ms;
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{},{:.6},{:.4},{:.4},{og:.2},{ng:.2},{:.1},{ratio:.3},{}",
            c.model, r.size, c.name, c.c_in, c.c_out, c.k, c.stride, c.groups, c.hw, c.count,
            r.pass, r.gflop, r.old_ms, r.new_ms, 100.0 * ng / pk, r.engine_forward
        );
        let _ = writeln!(
            md,
            "| {} | {} | {} | {}→{} {}×{} s{} g{} @{} | {} | {} | {:.3} | {:.3} | {og:.1} | {ng:.1} | {:.1} | {ratio:.2} | {} |",
            c.model, r.size, c.name, c.c_in, c.c_out, c.k, c.k, c.stride, c.groups, c.hw,
            c.count, r.pass, r.old_ms, r.new_ms, 100.0 * ng / pk, r.engine_forward
        );
    }
    md.push_str(&totals(rows, pk));
    (csv, md)
}

/// Per (model, size, pass): ms summed over the model's layers (each shape × its count),
/// old path vs what flex runs now, and the GFLOP/s and % of peak of the latter.
fn totals(rows: &[ConvTiming], peak: f64) -> String {
    let mut md = String::from(
        "\nTotals over each model's layers (each shape × its count; `now` = what flex runs: \
         the engine, or the old forward where dispatch keeps it):\n\n\
         | model | size | pass | old ms | now ms | ratio | now GFLOP/s | now % peak |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let mut keys: Vec<(&str, usize)> = Vec::new();
    for r in rows {
        if !keys.contains(&(r.shape.model, r.size)) {
            keys.push((r.shape.model, r.size));
        }
    }
    for (model, size) in keys {
        for pass in PASSES {
            let sel = rows
                .iter()
                .filter(|r| r.shape.model == model && r.size == size && r.pass == pass);
            let (old, now, gflop) = sel.fold((0.0, 0.0, 0.0), |(a, b, f), r| {
                let n = r.shape.count as f64;
                (a + n * r.old_ms, b + n * r.used_ms(), f + n * r.gflop)
            });
            let rate = gflop / now * 1e3;
            let _ = writeln!(
                md,
                "| {model} | {size} | {pass} | {old:.2} | {now:.2} | {:.2} | {rate:.1} | {:.1} |",
                old / now,
                100.0 * rate / peak
            );
        }
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_arguments_are_errors() {
        let args = |sizes: Vec<usize>, models: &[&str], batch| ConvsArgs {
            sizes,
            models: models.iter().map(|m| m.to_string()).collect(),
            batch,
            repeats: 1,
            ghz: Some(2.0),
        };
        let out = Path::new("unused");
        let e = run(&args(vec![100], &["yolo11n-seg"], 1), out).unwrap_err();
        assert!(e.to_string().contains("multiples of 64"), "{e}");
        let e = run(&args(vec![64], &["yolo"], 1), out).unwrap_err();
        assert!(e.to_string().contains("unknown model \"yolo\""), "{e}");
        let e = run(&args(vec![64], &["yolo11n-seg"], 0), out).unwrap_err();
        assert!(e.to_string().contains("at least 1"), "{e}");
        let mut a = args(vec![64], &["yolo11n-seg"], 1);
        a.ghz = Some(-1.0);
        assert!(run(&a, out).unwrap_err().to_string().contains("--ghz"));
    }

    #[test]
    fn one_tiny_shape_is_timed_and_reported() {
        let c = ConvShape {
            model: "yolo11n-seg",
            name: "t".to_string(),
            c_in: 4,
            c_out: 8,
            k: 3,
            stride: 2,
            groups: 1,
            hw: 8,
            count: 2,
        };
        let rows = time_shape(64, &c, 1, 1);
        assert_eq!(rows.len(), 3);
        assert!(rows.iter().all(|r| r.old_ms > 0.0 && r.new_ms > 0.0));
        let args = ConvsArgs {
            sizes: vec![64],
            models: vec!["yolo11n-seg".into()],
            batch: 1,
            repeats: 1,
            ghz: Some(2.0),
        };
        let p = Peak::detect(Some(2.0)).unwrap();
        let (csv, md) = report(&rows, &args, &p, 10.0);
        assert_eq!(csv.lines().count(), 4);
        assert!(md.contains("| yolo11n-seg | 64 | weight grad |"), "{md}");
    }
}
