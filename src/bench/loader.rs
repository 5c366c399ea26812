//! How fast the data side makes training batches: the trainer's own [`Loader`] (reading
//! or rendering each item, augmenting, collating) run alone, with no model, over a
//! config's epoch plans. A device that trains faster than this rate waits for data (the
//! run's `data_wait_s` says by how much); the figure to compare with is the run's
//! `images_per_s`, or `bench models`' training images/s on that device.

use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::annotations::split::Split;
use crate::config::Config;
use crate::data::dataset::{RealSet, SyntheticSet};
use crate::infer::detector::DetectorConfig;
use crate::train::loader::{epoch_batches, Loader, Mix};
use crate::util::stats::median;

/// What one `bench loader` measured.
#[derive(Clone, Debug)]
pub struct LoaderRate {
    /// Batches timed and images in them.
    pub batches: usize,
    pub images: usize,
    /// Wall seconds of the timed batches.
    pub seconds: f64,
    /// Median seconds of one batch.
    pub median_batch: f64,
    /// Threads the batches were built on (the loader's rayon pool).
    pub threads: usize,
    /// Network input size the batches were made for.
    pub input: usize,
    /// Seconds to load the real set and render (or find in the cache) the synthetic one,
    /// before the first batch: what a run pays once, not per epoch.
    pub prepare: f64,
    /// True when `data.fresh_synthetic` renders new images inside the loop.
    pub fresh: bool,
}

impl LoaderRate {
    pub fn images_per_s(&self) -> f64 {
        self.images as f64 / self.seconds.max(1e-9)
    }

    /// The report's lines.
    pub fn report(&self, config: &str) -> String {
        format!(
            "bench loader ({config}): {} batches, {} images at {} px on {} thread{} in {:.2} s: {:.1} images/s (median batch {:.0} ms){}\n\
             data prepared once before training (real set loaded, renders cached) in {:.1} s\n\
             a device that trains faster than {:.1} images/s waits for data (a run's data_wait_s per epoch in metrics.jsonl shows it)",
            self.batches,
            self.images,
            self.input,
            self.threads,
            if self.threads == 1 { "" } else { "s" },
            self.seconds,
            self.images_per_s(),
            1e3 * self.median_batch,
            if self.fresh {
                ", fresh renders every epoch (data.fresh_synthetic) included"
            } else {
                ""
            },
            self.prepare,
            self.images_per_s()
        )
    }
}

/// Builds `batches` training batches of `cfg` exactly as its run would (same split,
/// epoch plans, `train.steps_per_epoch` / `train.real_fraction` mix and augmentations)
/// on `threads` threads (default: every core) and times them.
pub fn bench_loader(cfg: &Config, batches: usize, threads: Option<usize>) -> Result<LoaderRate> {
    if batches == 0 {
        bail!("--batches must be at least 1");
    }
    let t0 = Instant::now();
    let real = RealSet::load(&cfg.data, cfg.seed)?;
    let split = Split::for_training(
        &real.ids(),
        real.own_split.as_ref(),
        cfg.data.split,
        cfg.seed,
        cfg.data.train_limit,
    )?;
    let synthetic = SyntheticSet::new(&cfg.data, cfg.seed);
    synthetic.prepare()?;
    let input = DetectorConfig::from_config(cfg, real.num_classes())?.input_size();
    let fresh = synthetic.fresh && synthetic.count > 0;
    let loader = Loader::for_run(cfg, real, synthetic, input as u32)?;
    let prepare = t0.elapsed().as_secs_f64();

    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        pool = pool.num_threads(n);
    }
    let pool = pool.build().context("starting the loader's threads")?;
    let batch = cfg.train.batch.max(1);
    let mix = Mix::of(&cfg.train);
    let (images, times, seconds) = pool.install(|| -> Result<_> {
        let (mut images, mut times) = (0usize, Vec::with_capacity(batches));
        let t = Instant::now();
        let mut epoch = 0;
        while times.len() < batches {
            let plan = epoch_batches(
                &split.train,
                loader.synthetic.count,
                cfg.seed,
                epoch,
                batch,
                mix,
            )?;
            if plan.is_empty() {
                bail!("the config has no training items (no real train images and data.synthetic = 0)");
            }
            for (b, chunk) in plan.chunks(batch).enumerate() {
                let tb = Instant::now();
                loader
                    .batch(&plan, b * batch, chunk.len(), epoch)
                    .with_context(|| format!("epoch {} batch {}", epoch + 1, b + 1))?;
                times.push(tb.elapsed().as_secs_f64());
                images += chunk.len();
                if times.len() == batches {
                    break;
                }
            }
            epoch += 1;
        }
        Ok((images, times, t.elapsed().as_secs_f64()))
    })?;
    Ok(LoaderRate {
        batches: times.len(),
        images,
        seconds,
        median_batch: median(&times),
        threads: pool.current_num_threads(),
        input,
        prepare,
        fresh,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_the_runs_own_batches_across_epochs() {
        let dir = std::env::temp_dir().join(format!("ct-bench-loader-{}", std::process::id()));
        let cfg = crate::config::load(
            "quickstart.toml",
            &[
                format!("data.cache=\"{}\"", dir.display()),
                "data.image_size=64".into(),
                "data.crop=64".into(),
                "data.real.count=5".into(),
                "data.synthetic=3".into(),
                "train.batch=2".into(),
            ],
        )
        .unwrap();
        // 5 real (split [0.2, 0.2]: 1 train) + 3 renders = 4 items, 2 batches an epoch:
        // 5 batches run into the third epoch.
        let r = bench_loader(&cfg, 5, Some(1)).unwrap();
        assert_eq!((r.batches, r.images, r.threads, r.input), (5, 10, 1, 64));
        assert!(r.seconds > 0.0 && r.images_per_s() > 0.0 && !r.fresh);
        let text = r.report("quickstart.toml");
        assert!(
            text.contains("5 batches, 10 images at 64 px on 1 thread in"),
            "{text}"
        );
        let e = bench_loader(&cfg, 0, None).unwrap_err().to_string();
        assert!(e.contains("--batches"), "{e}");
        let e = bench_loader(&cfg, 1, Some(0)).unwrap_err().to_string();
        assert!(e.contains("--threads"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
