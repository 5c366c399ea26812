//! A rendered dataset folder: every image of a seed rendered (in parallel, in a
//! scheduling-independent order) and written as `images/`, COCO `annotations.json`,
//! `preview.png` and `render_meta.json` — what `chicktrain render` writes.

use std::path::Path;

use anyhow::Context;
use image::RgbImage;
use rayon::prelude::*;
use serde_json::json;

use crate::annotations::coco::{CocoCategory, CocoDataset, CocoImage};
use crate::util::png::encode_png;

use super::{asset, encode_sample, export, render_sample, RenderOptions, RENDERER_VERSION};

/// Number of preview tiles in `preview.png`.
pub const PREVIEW_TILES: usize = 16;

/// Renders `opts.count` images of seed `opts.seed` into `out_dir`: `images/NNNNNN.jpg`
/// (or .png), `annotations.json` (COCO; `file_name`s are relative to `out_dir`),
/// `preview.png` (first 16 images, mask overlays and boxes) and `render_meta.json`
/// (renderer version, options, and the proxy flag for the proxy-real preset).
pub fn render_dataset(opts: &RenderOptions, out_dir: &Path, progress: bool) -> anyhow::Result<()> {
    opts.validate()?;
    asset::asset(opts.carcass.as_ref())?;
    let img_dir = out_dir.join("images");
    std::fs::create_dir_all(&img_dir)
        .with_context(|| format!("cannot create {}", img_dir.display()))?;
    let bar = progress_bar(opts.count as u64, progress);
    struct Out {
        image: CocoImage,
        anns: Vec<crate::annotations::coco::CocoAnnotation>,
        tile: Option<RgbImage>,
    }
    let results: Vec<anyhow::Result<Out>> = (0..opts.count as u64)
        .into_par_iter()
        .map(|i| {
            let s = render_sample(opts, opts.seed, i)?;
            let (bytes, ext) = encode_sample(opts, &s)?;
            let name = format!("images/{i:06}.{ext}");
            let path = out_dir.join(&name);
            std::fs::write(&path, bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
            let image_id = i + 1;
            // Annotation ids: image id * 1000 + k keeps them unique and independent of
            // rendering order (at most 64 carcasses per image, validated).
            let anns = export::annotations(
                &s.ids,
                opts.width,
                opts.height,
                &s.instances,
                image_id,
                image_id * 1000,
            );
            let tile = ((i as usize) < PREVIEW_TILES)
                .then(|| export::overlay_tile(&s.image, &s.ids, &s.instances, 320));
            bar.inc(1);
            let mut extra = serde_json::Map::new();
            extra.insert("density".into(), json!(s.density));
            extra.insert("placed".into(), json!(s.placed));
            Ok(Out {
                image: CocoImage {
                    id: image_id,
                    file_name: name,
                    width: opts.width,
                    height: opts.height,
                    extra,
                },
                anns,
                tile,
            })
        })
        .collect();
    bar.finish_and_clear();
    // The data layer's CocoDataset has optional fields (info, licenses) beyond these.
    #[allow(clippy::needless_update)]
    let mut ds = CocoDataset {
        images: Vec::new(),
        annotations: Vec::new(),
        categories: vec![CocoCategory {
            id: export::CARCASS_CATEGORY,
            name: "carcass".into(),
            extra: Default::default(),
        }],
        ..Default::default()
    };
    let mut tiles = Vec::new();
    for r in results {
        let o = r?;
        ds.images.push(o.image);
        ds.annotations.extend(o.anns);
        tiles.extend(o.tile);
    }
    ds.save(&out_dir.join("annotations.json"))?;
    if !tiles.is_empty() {
        let sheet = export::contact_sheet(&tiles, 4);
        let png = encode_png(&sheet)?;
        std::fs::write(out_dir.join("preview.png"), png).context("cannot write preview.png")?;
    }
    write_meta(opts, &ds, out_dir)
}

/// `render_meta.json`: the renderer version, the options, and whether the images are the
/// proxy for real photographs.
fn write_meta(opts: &RenderOptions, ds: &CocoDataset, out_dir: &Path) -> anyhow::Result<()> {
    let meta = json!({
        "renderer_version": RENDERER_VERSION,
        "preset": opts.preset,
        "proxy": opts.is_proxy(),
        "note": if opts.is_proxy() {
            "PROXY for the paper's real photographs (not available): a distinct rendered photographic domain, not real data"
        } else {
            "synthetic rendered data"
        },
        "options": opts,
        "images": ds.images.len(),
        "annotations": ds.annotations.len(),
    });
    std::fs::write(
        out_dir.join("render_meta.json"),
        serde_json::to_vec_pretty(&meta)?,
    )
    .context("cannot write render_meta.json")?;
    Ok(())
}

/// The `render` progress bar, hidden when `show` is false.
fn progress_bar(len: u64, show: bool) -> indicatif::ProgressBar {
    let bar = if show {
        indicatif::ProgressBar::new(len)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("render {bar:40} {pos}/{len} {per_sec} eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::cache;

    /// 3 to 6 carcasses at `size` px, with the randomisation `groups` on.
    fn options(size: u32, groups: &[&str]) -> RenderOptions {
        let mut o = RenderOptions::synthetic(size);
        o.carcasses = [3, 6];
        for g in groups {
            o.randomize = o.randomize.with(g, true).unwrap();
        }
        o
    }

    #[test]
    fn same_seed_gives_byte_identical_files() {
        let base = std::env::temp_dir().join(format!("ct-det-{}", std::process::id()));
        let mut o = options(96, &[]);
        o.count = 3;
        o.seed = 42;
        let (a, b) = (base.join("a"), base.join("b"));
        render_dataset(&o, &a, false).unwrap();
        // Second run on a one-thread pool: scheduling must not matter.
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| render_dataset(&o, &b, false))
            .unwrap();
        for f in [
            "annotations.json",
            "images/000000.jpg",
            "images/000002.jpg",
            "preview.png",
        ] {
            let (x, y) = (
                std::fs::read(a.join(f)).unwrap(),
                std::fs::read(b.join(f)).unwrap(),
            );
            assert!(x == y, "{f} differs between runs");
        }
        // A different seed gives different images.
        o.seed = 43;
        render_dataset(&o, &base.join("c"), false).unwrap();
        assert_ne!(
            std::fs::read(a.join("images/000000.jpg")).unwrap(),
            std::fs::read(base.join("c/images/000000.jpg")).unwrap()
        );
        let _ = std::fs::remove_dir_all(&base);
    }

    #[test]
    fn empty_scenes_have_no_instances_and_a_valid_coco_export() {
        let mut o = options(64, &["scene", "distractors"]);
        o.ranges.p_empty = 1.0;
        let s = render_sample(&o, 1, 0).unwrap();
        assert!(s.instances.is_empty() && s.placed == 0);
        assert!(s.ids.iter().all(|&v| v == 0));
        let dir = std::env::temp_dir().join(format!("ct-empty-{}", std::process::id()));
        o.count = 2;
        render_dataset(&o, &dir, false).unwrap();
        let ds = CocoDataset::load(&dir.join("annotations.json")).unwrap();
        assert_eq!(ds.images.len(), 2);
        assert!(ds.annotations.is_empty());
        // The render cache stores and reads back an image without instances.
        let cache_dir = dir.join("cache");
        std::fs::create_dir_all(&cache_dir).unwrap();
        let first = cache::load_or_render(&o, 1, 0, Some(&cache_dir)).unwrap();
        let again = cache::load_or_render(&o, 1, 0, Some(&cache_dir)).unwrap();
        assert!(first.instances.is_empty() && again.instances.is_empty());
        assert_eq!(first.ids, again.ids);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
