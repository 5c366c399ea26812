//! The data commands: `render`, `convert`, `coco-eval`, `bench coco`, `bench render`
//! (none needs Burn).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use crate::annotations::coco::{load_results, CocoDataset};
use crate::annotations::{labelme, yolo_export};
use crate::config::Randomize;
use crate::eval::{evaluate, IouType};

/// `chicktrain coco-eval`: the pycocotools summary (or one JSON object) for a GT/DT pair.
pub fn coco_eval(gt: &Path, dt: &Path, iou_type: IouType, json: bool) -> Result<String> {
    let gt = CocoDataset::load(gt)?;
    let dets = load_results(dt)?;
    let res =
        evaluate(&gt, &dets, iou_type).with_context(|| format!("evaluating {}", dt.display()))?;
    Ok(if json {
        res.to_json().to_string()
    } else {
        res.summary()
    })
}

/// `chicktrain convert labelme DIR --out coco.json`.
pub fn convert_labelme(dir: &Path, labels: Option<&Path>, out: &Path) -> Result<String> {
    let labels = labels.map(labelme::read_labels).transpose()?;
    let ds = labelme::load_dir(dir, labels.as_deref())?;
    ds.save(out)?;
    Ok(format!(
        "wrote {}: {} images, {} instances, {} categories (image file_names are relative to {})",
        out.display(),
        ds.images.len(),
        ds.annotations.len(),
        ds.categories.len(),
        dir.display()
    ))
}

/// `chicktrain convert coco2yolo coco.json --out DIR`.
pub fn convert_coco2yolo(coco: &Path, out: &Path) -> Result<String> {
    let ds = CocoDataset::load(coco)?;
    let n = yolo_export::export(&ds, out)?;
    Ok(format!(
        "wrote {n} label files under {} and {}",
        out.join("labels").display(),
        out.join("data.yaml").display()
    ))
}

/// `chicktrain bench coco`: load + evaluate + accumulate time, median of `repeats`.
pub fn bench_coco(gt: &Path, dt: &Path, repeats: usize) -> Result<String> {
    let mut out = String::new();
    for iou_type in [IouType::Bbox, IouType::Segm] {
        let mut times = Vec::with_capacity(repeats);
        let mut stats = [0.0; 12];
        for _ in 0..repeats.max(1) {
            let t0 = Instant::now();
            let g = CocoDataset::load(gt)?;
            let d = load_results(dt)?;
            stats = evaluate(&g, &d, iou_type)?.stats;
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(|a, b| a.total_cmp(b));
        out.push_str(&format!(
            "{:?}: median {:.4} s, min {:.4} s, max {:.4} s over {} runs (AP {:.4})\n",
            iou_type,
            times[times.len() / 2],
            times[0],
            times[times.len() - 1],
            times.len(),
            stats[0]
        ));
    }
    Ok(out)
}

/// Options of `preset` at `size` with the `--randomize` groups on (proxy-real never
/// randomises: it stands in for real photographs).
fn preset_with(preset: &str, size: u32, randomize: &str) -> Result<crate::render::RenderOptions> {
    let mut opts = crate::render::RenderOptions::preset(preset, size)?;
    opts.randomize = parse_randomize(randomize)?;
    anyhow::ensure!(
        !opts.is_proxy() || opts.randomize.is_off(),
        "--randomize {randomize}: the proxy-real preset never randomises (it stands in for \
         real photos); use --preset synthetic"
    );
    Ok(opts)
}

/// The `--randomize` flag: `none`, `all`, or a comma list of group names.
pub fn parse_randomize(list: &str) -> Result<Randomize> {
    Randomize::parse_list(list).context("--randomize")
}

/// `chicktrain render`: a rendered, auto-labelled dataset with a preview sheet.
pub fn render(
    out: &Path,
    count: u32,
    seed: u64,
    size: u32,
    preset: &str,
    carcass: Option<PathBuf>,
    randomize: &str,
) -> Result<String> {
    let mut opts = preset_with(preset, size, randomize)?;
    opts.count = count;
    opts.seed = seed;
    opts.carcass = carcass;
    crate::render::render_dataset(&opts, out, true)?;
    let proxy = if opts.is_proxy() {
        " (proxy-real: a rendered stand-in for real photos, not real data)"
    } else {
        ""
    };
    Ok(format!(
        "wrote {count} {preset} images{proxy} to {}: images/, annotations.json, preview.png",
        out.display()
    ))
}

/// `chicktrain bench render`.
pub fn bench_render(
    size: u32,
    images: usize,
    preset: &str,
    seed: u64,
    randomize: &str,
) -> Result<String> {
    let opts = preset_with(preset, size, randomize)?;
    Ok(crate::render::bench_render(&opts, images, seed)?.to_string())
}

#[cfg(test)]
mod randomize_flag_tests {
    use super::*;

    #[test]
    fn randomize_flag_parses_lists_and_refuses_unknown_groups_and_proxy() {
        assert!(parse_randomize("none").unwrap().is_off());
        assert_eq!(parse_randomize("all").unwrap(), Randomize::ALL);
        let r = parse_randomize("carcass, lighting").unwrap();
        assert!(r.carcass && r.lighting && !r.scene);
        let e = format!("{:#}", parse_randomize("carcass,colour").unwrap_err());
        assert!(e.contains("--randomize") && e.contains("colour"), "{e}");
        let e = preset_with("proxy-real", 64, "carcass")
            .unwrap_err()
            .to_string();
        assert!(e.contains("proxy-real"), "{e}");
        assert!(
            preset_with("synthetic", 64, "carcass")
                .unwrap()
                .randomize
                .carcass
        );
    }
}
