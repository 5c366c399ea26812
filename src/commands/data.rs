//! The data commands: `render`, `convert`, `coco-eval`, `bench coco`, `bench render`
//! (none needs Burn).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use crate::annotations::coco::{load_results, CocoDataset};
use crate::annotations::{coco_splits, labelme, yolo_export};
use crate::config::Randomize;
use crate::eval::{evaluate, IouType};

/// `coco-eval` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct CocoEvalRequest {
    /// Ground-truth COCO instances file.
    #[arg(long)]
    pub gt: PathBuf,
    /// Detections (COCO results JSON: a list of detections).
    #[arg(long)]
    pub dt: PathBuf,
    /// bbox or segm.
    #[arg(long, default_value = "segm")]
    pub iou_type: IouType,
    /// Print one JSON object with "stats" (the 12 numbers in pycocotools order).
    #[arg(long)]
    pub json: bool,
}

/// `chicktrain coco-eval`: the pycocotools summary (or one JSON object) for a GT/DT pair.
pub fn coco_eval(r: &CocoEvalRequest) -> Result<String> {
    let gt = CocoDataset::load(&r.gt)?;
    let dets = load_results(&r.dt)?;
    let res = evaluate(&gt, &dets, r.iou_type)
        .with_context(|| format!("evaluating {}", r.dt.display()))?;
    Ok(if r.json {
        res.to_json().to_string()
    } else {
        res.summary()
    })
}

/// `convert labelme` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct LabelmeRequest {
    /// Folder of LabelMe .json files (with their images beside them).
    pub dir: PathBuf,
    /// The COCO instances file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// labelme's labels.txt (one label per line) to fix the category order.
    #[arg(long)]
    pub labels: Option<PathBuf>,
}

/// `chicktrain convert labelme DIR --out coco.json`.
pub fn convert_labelme(r: &LabelmeRequest) -> Result<String> {
    let (dir, out) = (&r.dir, &r.out);
    let labels = r.labels.as_deref().map(labelme::read_labels).transpose()?;
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

/// `convert coco2yolo` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct Coco2yoloRequest {
    /// COCO instances file(s): one file, or one per split named for it (train.json
    /// val.json test.json); the images beside each file are copied too.
    #[arg(required = true, num_args = 1..=3)]
    pub coco: Vec<PathBuf>,
    /// Output folder: images/, labels/<image stem>.txt and data.yaml are written here.
    #[arg(long)]
    pub out: PathBuf,
}

/// `chicktrain convert coco2yolo coco.json --out DIR`, or one file per split
/// (`train.json val.json test.json`, each split named by its file, see
/// [`coco_splits::part_of_file`]): labels, the images found beside each file, and
/// `data.yaml` (see [`yolo_export`]).
pub fn convert_coco2yolo(r: &Coco2yoloRequest) -> Result<String> {
    let (coco, out) = (&r.coco, &r.out);
    let mut sets = Vec::with_capacity(coco.len());
    for f in coco {
        let part = match coco.len() {
            1 => None,
            _ => Some(coco_splits::part_of_file(f)?),
        };
        let images = f.parent().map(Path::to_path_buf).unwrap_or_default();
        sets.push((part, CocoDataset::load(f)?, images));
    }
    let parts: Vec<yolo_export::ExportPart> = sets
        .iter()
        .map(|(part, coco, images)| yolo_export::ExportPart {
            part: *part,
            coco,
            images,
        })
        .collect();
    let n = yolo_export::export(&parts, out)?;
    let images = match n.images {
        0 => format!(
            "no images found beside the COCO file{}: put them under {}",
            if coco.len() > 1 { "s" } else { "" },
            out.join("images").display()
        ),
        k => format!("{k} images under {}", out.join("images").display()),
    };
    Ok(format!(
        "wrote {} label files under {}, {images}, and {}",
        n.labels,
        out.join("labels").display(),
        out.join("data.yaml").display()
    ))
}

/// `bench coco` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchCocoRequest {
    /// Ground-truth COCO instances file.
    #[arg(long)]
    pub gt: PathBuf,
    /// Detections (COCO results JSON).
    #[arg(long)]
    pub dt: PathBuf,
    /// Timed runs per IoU type; the median is reported.
    #[arg(long, default_value_t = 21)]
    pub repeats: usize,
}

/// `chicktrain bench coco`: load + evaluate + accumulate time, median of `repeats`.
pub fn bench_coco(r: &BenchCocoRequest) -> Result<String> {
    let (gt, dt, repeats) = (&r.gt, &r.dt, r.repeats);
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

/// The scene flags `render` and `bench render` share.
#[derive(Clone, Debug, clap::Args)]
pub struct SceneFlags {
    /// Image side in pixels.
    #[arg(long, default_value_t = 640)]
    pub size: u32,
    /// `synthetic` (training renders) or `proxy-real` (the stand-in for real photos).
    #[arg(long, default_value = "synthetic")]
    pub preset: String,
    /// Seed of the scenes (image k is drawn from (seed, k)).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Domain-randomisation groups to switch on: a comma list of carcass, scene,
    /// distractors, lighting, camera, physics, or `all` / `none`.
    #[arg(long, default_value = "none")]
    pub randomize: String,
}

/// `render` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct RenderRequest {
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of images.
    #[arg(long, default_value_t = 16)]
    pub count: u32,
    /// A carcass mesh (.glb, skinned or rigid) instead of the embedded one.
    #[arg(long)]
    pub carcass: Option<PathBuf>,
    #[command(flatten)]
    pub scene: SceneFlags,
}

/// `chicktrain render`: a rendered, auto-labelled dataset with a preview sheet.
pub fn render(r: &RenderRequest) -> Result<String> {
    let (out, count, preset) = (&r.out, r.count, &r.scene.preset);
    let mut opts = preset_with(preset, r.scene.size, &r.scene.randomize)?;
    opts.count = count;
    opts.seed = r.scene.seed;
    opts.carcass = r.carcass.clone();
    crate::render::dataset::render_dataset(&opts, out, true)?;
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

/// `bench render` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchRenderRequest {
    /// Images to render and time.
    #[arg(long, default_value_t = 12)]
    pub images: usize,
    #[command(flatten)]
    pub scene: SceneFlags,
}

/// `chicktrain bench render`.
pub fn bench_render(r: &BenchRenderRequest) -> Result<String> {
    let s = &r.scene;
    let opts = preset_with(&s.preset, s.size, &s.randomize)?;
    Ok(crate::render::bench::bench_render(&opts, r.images, s.seed)?.to_string())
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
