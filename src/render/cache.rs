//! The render cache, the one place rendered samples are stored and read back: each
//! sample lives once under `<root>/<key>/<index>.ctr`, the key hashing the renderer
//! version, the scene options and the effective seed, so a fixed synthetic set of N
//! images is rendered once and then read by every later run and `eval`. A fresh-each-
//! epoch set derives a new seed per epoch ([`effective_seed`]) and is not cached.
//!
//! Images pass through the dataset's file format (JPEG artifacts included), so cached,
//! uncached and written datasets look the same to the model. A torn or stale cache file
//! is re-rendered, never fatal.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::{
    encode_sample, render_sample, ImageFormat, InstanceLabel, RenderOptions, RenderedSample,
    Timings, CLUTTER_VERSION, RANDOMIZE_VERSION, RENDERER_VERSION,
};
use crate::util::hash::{fnv, mix64, FNV_OFFSET};

/// The seed actually rendered for `epoch`.
pub fn effective_seed(seed: u64, epoch: u64, fresh: bool) -> u64 {
    if fresh {
        mix64(seed ^ mix64(epoch.wrapping_add(0xE90C)))
    } else {
        seed
    }
}

/// Cache key: renderer version + scene options (count/seed excluded) + seed, and the
/// bytes of a user carcass file (a replaced file must not reuse stale renders), as hex.
pub fn cache_key(opts: &RenderOptions, seed: u64) -> Result<String> {
    let mut o = opts.clone();
    o.count = 0;
    o.seed = 0;
    // Renders with randomisation groups on carry the groups' version too: caches written
    // before the groups drew anything (same options, base-look pixels) must not be reused.
    // The base look keeps its old key.
    let mut version = if o.randomize.is_off() {
        RENDERER_VERSION.to_string()
    } else {
        format!("{RENDERER_VERSION}+{RANDOMIZE_VERSION}")
    };
    // The same for clutter pictures: a cache of the version before must not be reused.
    if o.negatives.clutter > 0.0 {
        version = format!("{version}+{CLUTTER_VERSION}");
    }
    let text = format!("{version}\n{}\n{seed}", serde_json::to_string(&o)?);
    let mut h = fnv(FNV_OFFSET, text.as_bytes());
    if let Some(path) = &opts.carcass {
        let bytes = std::fs::read(path)
            .with_context(|| format!("cannot read carcass mesh {}", path.display()))?;
        h = fnv(h, &bytes);
    }
    Ok(format!("{:016x}", mix64(h)))
}

/// The cache folder of (`opts`, `seed`) under `root`, created if missing.
pub fn cache_dir(root: &Path, opts: &RenderOptions, seed: u64) -> Result<PathBuf> {
    let d = root.join(cache_key(opts, seed)?);
    std::fs::create_dir_all(&d)
        .with_context(|| format!("cannot create cache folder {}", d.display()))?;
    Ok(d)
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
    fn cache_is_deterministic_and_survives_torn_files() {
        let root = std::env::temp_dir().join(format!("ct-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let o = tiny();
        let dir = cache_dir(&root, &o, 5).unwrap();
        assert_eq!(dir, root.join(cache_key(&o, 5).unwrap()));
        let first: Vec<RenderedSample> = (0..3)
            .map(|i| load_or_render(&o, 5, i, Some(&dir)).unwrap())
            .collect();
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 3);
        // A torn file is re-rendered; every read gives the rendered sample back.
        let torn = dir.join(format!("{:08}.ctr", 1));
        let bytes = std::fs::read(&torn).unwrap();
        std::fs::write(&torn, &bytes[..bytes.len() / 2]).unwrap();
        for (i, a) in first.iter().enumerate() {
            for b in [
                load_or_render(&o, 5, i as u64, Some(&dir)).unwrap(),
                load_or_render(&o, 5, i as u64, None).unwrap(),
            ] {
                assert_eq!(a.image, b.image);
                assert_eq!(a.ids, b.ids);
                assert_eq!(a.instances, b.instances);
            }
        }
        // Fresh-each-epoch uses another seed, hence another cache key.
        assert_ne!(effective_seed(5, 1, true), effective_seed(5, 2, true));
        assert_eq!(effective_seed(5, 1, false), 5);
        assert_ne!(cache_key(&o, 5).unwrap(), cache_key(&o, 6).unwrap());
        let _ = std::fs::remove_dir_all(&root);
    }
}

#[cfg(test)]
mod key_tests {
    use super::*;
    use crate::config::Randomize;

    /// A render with groups on must not reuse a cache written when the groups drew
    /// nothing (same options, base-look pixels), and the base look keeps its key.
    /// The key as it was before any version but the renderer's went into it, at seed 3.
    fn legacy(o: &RenderOptions) -> String {
        let mut c = o.clone();
        c.count = 0;
        c.seed = 0;
        let text = format!(
            "{RENDERER_VERSION}\n{}\n3",
            serde_json::to_string(&c).unwrap()
        );
        format!("{:016x}", mix64(fnv(FNV_OFFSET, text.as_bytes())))
    }

    #[test]
    fn randomised_renders_carry_the_groups_version_in_their_key() {
        let mut o = RenderOptions::synthetic(64);
        let base = cache_key(&o, 3).unwrap();
        assert_eq!(base, legacy(&o));
        o.randomize = Randomize::ALL;
        let on = cache_key(&o, 3).unwrap();
        assert_ne!(on, base);
        assert_ne!(on, legacy(&o));
    }

    /// Renders with clutter pictures carry the clutter version: a cache written by the
    /// flat-shapes-only pictures (the same options) is not reused.
    #[test]
    fn cluttered_renders_carry_the_clutter_version_in_their_key() {
        let mut o = RenderOptions::synthetic(64);
        o.negatives.clutter = 0.1;
        assert_ne!(cache_key(&o, 3).unwrap(), legacy(&o));
    }
}
