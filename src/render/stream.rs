//! The trainer's streaming source of rendered samples.
//!
//! Worker threads take image indices from a shared counter, render them with
//! [`render_sample`] (deterministic per (seed, index)) and push them into a bounded
//! queue, so rendering runs ahead of training by at most `queue` samples. With a cache
//! directory, each sample is stored once under `<cache>/<key>/<index>.ctr`, the key
//! hashing the renderer version, the scene options and the effective seed: a fixed
//! synthetic set of N images is rendered once and then read back. `fresh_each_epoch`
//! derives a new seed per epoch instead (fresh renders every epoch, never cached twice
//! under the same key).
//!
//! Samples arrive in completion order tagged with their index; content never depends on
//! the order. Images pass through the dataset's file format (JPEG artifacts included),
//! so streamed and written datasets look the same to the model.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;
use std::thread::JoinHandle;

use anyhow::{bail, Context, Result};

use super::noise::mix64;
use super::{
    encode_sample, render_sample, ImageFormat, InstanceLabel, RenderOptions, RenderedSample,
    Timings, RENDERER_VERSION,
};

/// How the stream runs.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamConfig {
    pub workers: usize,
    /// Bounded queue length (samples rendered ahead of the consumer).
    pub queue: usize,
    /// On-disk cache root, e.g. `runs/cache`; None = no cache.
    pub cache_dir: Option<PathBuf>,
    /// New scenes every epoch (seed mixed with the epoch) instead of a fixed set.
    pub fresh_each_epoch: bool,
}

impl Default for StreamConfig {
    fn default() -> Self {
        StreamConfig {
            workers: 2,
            queue: 8,
            cache_dir: Some(PathBuf::from("runs/cache")),
            fresh_each_epoch: false,
        }
    }
}

/// The seed actually rendered for `epoch`.
pub fn effective_seed(seed: u64, epoch: u64, fresh: bool) -> u64 {
    if fresh {
        mix64(seed ^ mix64(epoch.wrapping_add(0xE90C)))
    } else {
        seed
    }
}

/// FNV-1a 64: stable across platforms and Rust versions (std's hashers are not).
fn fnv(h: u64, bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(h, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

/// Cache key: renderer version + scene options (count/seed excluded) + seed, and the
/// bytes of a user carcass file (a replaced file must not reuse stale renders), as hex.
pub fn cache_key(opts: &RenderOptions, seed: u64) -> Result<String> {
    let mut o = opts.clone();
    o.count = 0;
    o.seed = 0;
    let text = format!("{RENDERER_VERSION}\n{}\n{seed}", serde_json::to_string(&o)?);
    let mut h = fnv(0xcbf2_9ce4_8422_2325, text.as_bytes());
    if let Some(path) = &opts.carcass {
        let bytes = std::fs::read(path)
            .with_context(|| format!("cannot read carcass mesh {}", path.display()))?;
        h = fnv(h, &bytes);
    }
    Ok(format!("{:016x}", mix64(h)))
}

/// A running stream of `(index, sample)` pairs.
pub struct SampleStream {
    rx: Option<Receiver<(u64, Result<RenderedSample>)>>,
    stop: Arc<AtomicBool>,
    workers: Vec<JoinHandle<()>>,
    remaining: usize,
}

impl SampleStream {
    /// Streams samples `indices` of `seed` (for `epoch`).
    pub fn new(
        opts: &RenderOptions,
        seed: u64,
        epoch: u64,
        indices: Vec<u64>,
        cfg: &StreamConfig,
    ) -> Result<SampleStream> {
        opts.validate()?;
        if cfg.workers == 0 || cfg.queue == 0 {
            bail!("stream needs at least one worker and a queue of at least 1");
        }
        let seed = effective_seed(seed, epoch, cfg.fresh_each_epoch);
        let dir = match &cfg.cache_dir {
            Some(root) => {
                let d = root.join(cache_key(opts, seed)?);
                std::fs::create_dir_all(&d)
                    .with_context(|| format!("cannot create cache dir {}", d.display()))?;
                Some(d)
            }
            None => None,
        };
        let (tx, rx) = sync_channel(cfg.queue);
        let stop = Arc::new(AtomicBool::new(false));
        let next = Arc::new(AtomicUsize::new(0));
        let indices = Arc::new(indices);
        let opts = Arc::new(opts.clone());
        let mut workers = Vec::new();
        for w in 0..cfg.workers {
            let (tx, stop, next, indices, opts, dir) = (
                tx.clone(),
                stop.clone(),
                next.clone(),
                indices.clone(),
                opts.clone(),
                dir.clone(),
            );
            let h = std::thread::Builder::new()
                .name(format!("render-{w}"))
                .spawn(move || loop {
                    if stop.load(Ordering::Relaxed) {
                        return;
                    }
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&index) = indices.get(k) else { return };
                    let r = load_or_render(&opts, seed, index, dir.as_deref());
                    if tx.send((index, r)).is_err() {
                        return;
                    }
                })
                .context("cannot spawn render worker")?;
            workers.push(h);
        }
        let remaining = indices.len();
        Ok(SampleStream {
            rx: Some(rx),
            stop,
            workers,
            remaining,
        })
    }
}

impl Iterator for SampleStream {
    type Item = (u64, Result<RenderedSample>);

    fn next(&mut self) -> Option<Self::Item> {
        if self.remaining == 0 {
            return None;
        }
        let item = self.rx.as_ref()?.recv().ok()?;
        self.remaining -= 1;
        Some(item)
    }
}

impl Drop for SampleStream {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Dropping the receiver unblocks workers waiting on a full queue.
        self.rx.take();
        for h in self.workers.drain(..) {
            let _ = h.join();
        }
    }
}

/// Reads sample `index` from the cache, or renders (and caches) it.
pub fn load_or_render(
    opts: &RenderOptions,
    seed: u64,
    index: u64,
    dir: Option<&Path>,
) -> Result<RenderedSample> {
    let path = dir.map(|d| d.join(format!("{index:08}.ctr")));
    if let Some(p) = &path {
        if p.exists() {
            match read_cached(p) {
                Ok(s) => return Ok(s),
                // A torn or stale file is re-rendered, not fatal.
                Err(_) => {
                    let _ = std::fs::remove_file(p);
                }
            }
        }
    }
    let mut s = render_sample(opts, seed, index)?;
    let (bytes, _) = encode_sample(opts, &s)?;
    if opts.format == ImageFormat::Jpg {
        s.image = image::load_from_memory(&bytes)?.to_rgb8();
    }
    if let Some(p) = &path {
        write_cached(p, &s, &bytes)?;
    }
    Ok(s)
}

const MAGIC: &[u8; 4] = b"CTR1";

/// Cache file: magic, width, height, jpeg quality, density, placed, encoded image,
/// run-length ids (value u16, run u32), labels JSON — each variable part length-prefixed.
fn write_cached(path: &Path, s: &RenderedSample, encoded: &[u8]) -> Result<()> {
    let mut b = Vec::with_capacity(encoded.len() + 4096);
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&s.image.width().to_le_bytes());
    b.extend_from_slice(&s.image.height().to_le_bytes());
    b.push(s.jpeg_quality);
    b.extend_from_slice(&s.density.to_le_bytes());
    b.extend_from_slice(&(s.placed as u32).to_le_bytes());
    b.extend_from_slice(&(encoded.len() as u32).to_le_bytes());
    b.extend_from_slice(encoded);
    let mut runs: Vec<(u16, u32)> = Vec::new();
    for &v in &s.ids {
        match runs.last_mut() {
            Some((last, n)) if *last == v => *n += 1,
            _ => runs.push((v, 1)),
        }
    }
    b.extend_from_slice(&(runs.len() as u32).to_le_bytes());
    for (v, n) in runs {
        b.extend_from_slice(&v.to_le_bytes());
        b.extend_from_slice(&n.to_le_bytes());
    }
    let js = serde_json::to_vec(&s.instances)?;
    b.extend_from_slice(&(js.len() as u32).to_le_bytes());
    b.extend_from_slice(&js);
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, &b).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot move {} into the cache", tmp.display()))?;
    Ok(())
}

fn read_cached(path: &Path) -> Result<RenderedSample> {
    let b = std::fs::read(path)?;
    let mut at = 0usize;
    let mut take = |n: usize| -> Result<&[u8]> {
        let s = b.get(at..at + n).context("truncated cache file")?;
        at += n;
        Ok(s)
    };
    if take(4)? != MAGIC {
        bail!("not a chicktrain cache file");
    }
    let u32_ = |s: &[u8]| u32::from_le_bytes(s.try_into().expect("4 bytes"));
    let w = u32_(take(4)?);
    let h = u32_(take(4)?);
    let q = take(1)?[0];
    let density = f32::from_le_bytes(take(4)?.try_into()?);
    let placed = u32_(take(4)?) as usize;
    let n = u32_(take(4)?) as usize;
    let image = image::load_from_memory(take(n)?)?.to_rgb8();
    if image.dimensions() != (w, h) {
        bail!("cached image size mismatch");
    }
    let runs = u32_(take(4)?) as usize;
    let mut ids = Vec::with_capacity((w * h) as usize);
    for _ in 0..runs {
        let v = u16::from_le_bytes(take(2)?.try_into()?);
        let k = u32_(take(4)?) as usize;
        ids.extend(std::iter::repeat_n(v, k));
    }
    if ids.len() != (w * h) as usize {
        bail!("cached id buffer size mismatch");
    }
    let n = u32_(take(4)?) as usize;
    let mut instances: Vec<InstanceLabel> = serde_json::from_slice(take(n)?)?;
    // JSON does not round-trip every f64 bit; recompute the ratio exactly as rendered.
    for i in &mut instances {
        i.visib_fract = i.visible_px as f64 / i.amodal_px.max(1) as f64;
    }
    Ok(RenderedSample {
        image,
        ids,
        instances,
        jpeg_quality: q,
        density,
        placed,
        timings: Timings::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> RenderOptions {
        let mut o = RenderOptions::synthetic(64);
        o.carcasses = [2, 4];
        o
    }

    #[test]
    fn stream_is_complete_deterministic_and_cached() {
        let dir = std::env::temp_dir().join(format!("ct-stream-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cfg = StreamConfig {
            workers: 2,
            queue: 2,
            cache_dir: Some(dir.clone()),
            fresh_each_epoch: false,
        };
        let o = tiny();
        let mut first: Vec<(u64, RenderedSample)> =
            SampleStream::new(&o, 5, 0, vec![0, 1, 2], &cfg)
                .unwrap()
                .map(|(i, s)| (i, s.unwrap()))
                .collect();
        first.sort_by_key(|x| x.0);
        assert_eq!(first.iter().map(|x| x.0).collect::<Vec<_>>(), vec![0, 1, 2]);
        let key_dir = dir.join(cache_key(&o, 5).unwrap());
        assert_eq!(std::fs::read_dir(&key_dir).unwrap().count(), 3);
        // Second pass reads the cache and returns identical samples.
        let mut second: Vec<(u64, RenderedSample)> =
            SampleStream::new(&o, 5, 1, vec![2, 1, 0], &cfg)
                .unwrap()
                .map(|(i, s)| (i, s.unwrap()))
                .collect();
        second.sort_by_key(|x| x.0);
        for (a, b) in first.iter().zip(&second) {
            assert_eq!(a.1.image, b.1.image);
            assert_eq!(a.1.ids, b.1.ids);
            assert_eq!(a.1.instances, b.1.instances);
        }
        // Fresh-each-epoch uses another seed, hence another cache key.
        assert_ne!(effective_seed(5, 1, true), effective_seed(5, 2, true));
        assert_eq!(effective_seed(5, 1, false), 5);
        // Dropping a stream early does not hang.
        let mut s = SampleStream::new(
            &o,
            6,
            0,
            (0..50).collect(),
            &StreamConfig {
                cache_dir: None,
                ..cfg.clone()
            },
        )
        .unwrap();
        assert!(s.next().is_some());
        drop(s);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
