//! The renderer's benchmark (`chicktrain bench render`): images/s one at a time and
//! concurrently, and where an image's time goes (scene, physics, BVH build, trace,
//! labels, sensor, encode). Renders in memory, writes nothing.

use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::{asset, encode_sample, family, render_sample, RenderOptions, Timings};

/// Result of [`bench_render`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchReport {
    pub images: usize,
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    /// Wall time of the sequential pass (one image at a time, rows in parallel).
    pub wall: Duration,
    /// Sequential pass: latency-bound rate.
    pub sequential_images_per_sec: f64,
    /// Throughput with images rendered concurrently on the pool (as `render_dataset`
    /// and the loader's workers do): serial stages (BVH build, pile drop) overlap.
    pub images_per_sec: f64,
    /// Mean triangles per image.
    pub triangles: f64,
    /// Mean per-image times (summed over stages that run on all cores).
    pub mean: Timings,
}

impl std::fmt::Display for BenchReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        write!(
            f,
            "{} images {}x{} on {} threads: {:.2} images/s concurrent, {:.2} images/s one at a \
             time ({:.0} ms/image); per image: scene {:.1} ms (physics {:.1} ms), build {:.1} ms, trace {:.1} ms, \
             labels {:.1} ms, sensor {:.1} ms, encode {:.1} ms; {:.0} triangles",
            self.images,
            self.width,
            self.height,
            self.threads,
            self.images_per_sec,
            self.sequential_images_per_sec,
            ms(self.wall) / self.images.max(1) as f64,
            ms(self.mean.scene),
            ms(self.mean.physics),
            ms(self.mean.build),
            ms(self.mean.trace),
            ms(self.mean.labels),
            ms(self.mean.sensor),
            ms(self.mean.encode),
            self.triangles
        )
    }
}

/// Renders and encodes `images` samples (no files written) twice: one after another (each
/// using all cores for its rows; gives the per-stage times) and then concurrently (gives
/// the throughput a dataset render or the training loader sees).
pub fn bench_render(opts: &RenderOptions, images: usize, seed: u64) -> anyhow::Result<BenchReport> {
    opts.validate()?;
    let asset = asset::asset(opts.carcass.as_ref())?;
    // Warm-up (asset parse, family meshes, thread pool start) outside the timed loop.
    if opts.randomize.carcass && opts.carcass.is_none() {
        family::Family::prepare_all();
    }
    render_sample(opts, seed, u64::MAX)?;
    let mut sum = Timings::default();
    let t0 = Instant::now();
    for i in 0..images as u64 {
        let mut s = render_sample(opts, seed, i)?;
        let te = Instant::now();
        encode_sample(opts, &s)?;
        s.timings.encode = te.elapsed();
        sum += s.timings;
    }
    let wall = t0.elapsed();
    // Throughput pass: the same images, several in flight at once.
    let t1 = Instant::now();
    (0..images as u64)
        .into_par_iter()
        .try_for_each(|i| -> anyhow::Result<()> {
            let s = render_sample(opts, seed, i)?;
            encode_sample(opts, &s)?;
            Ok(())
        })?;
    let wall_par = t1.elapsed();
    let n = images.max(1) as u32;
    let mean = Timings {
        scene: sum.scene / n,
        physics: sum.physics / n,
        build: sum.build / n,
        trace: sum.trace / n,
        labels: sum.labels / n,
        sensor: sum.sensor / n,
        encode: sum.encode / n,
    };
    let avg_carcasses = (opts.carcasses[0] + opts.carcasses[1]) as f64 / 2.0;
    Ok(BenchReport {
        images,
        width: opts.width,
        height: opts.height,
        threads: rayon::current_num_threads(),
        wall,
        sequential_images_per_sec: images as f64 / wall.as_secs_f64().max(1e-9),
        images_per_sec: images as f64 / wall_par.as_secs_f64().max(1e-9),
        triangles: avg_carcasses * asset.mesh.triangle_count() as f64,
        mean,
    })
}
