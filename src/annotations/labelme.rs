//! LabelMe annotations → COCO, the way the paper's 300 real images were annotated.
//!
//! Follows labelme's own `labelme2coco.py`: shapes sharing a `group_id` (and label) are
//! one instance, ungrouped shapes are instances of their own, rectangles become
//! 4-corner polygons, circles become labelme's n-gon, `__ignore__` and `_background_`
//! are not categories. Masks, areas and boxes are computed with the pycocotools
//! rasteriser (labelme's PIL one differs by a boundary pixel here and there), so the
//! COCO file agrees with what the evaluator sees. Ids start at 1: pycocotools never
//! counts a match with a GT whose id is 0.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use serde_json::Map;

use super::coco::{
    check_polygons, CocoAnnotation, CocoCategory, CocoDataset, CocoImage, Segmentation,
};

#[derive(Deserialize)]
struct LabelmeFile {
    shapes: Vec<LabelmeShape>,
    #[serde(rename = "imagePath")]
    image_path: String,
    #[serde(rename = "imageHeight")]
    image_height: u32,
    #[serde(rename = "imageWidth")]
    image_width: u32,
}

#[derive(Deserialize)]
struct LabelmeShape {
    label: String,
    points: Vec<[f64; 2]>,
    #[serde(default)]
    group_id: Option<i64>,
    #[serde(default = "default_shape_type")]
    shape_type: String,
}

fn default_shape_type() -> String {
    "polygon".into()
}

/// Most vertices of a circle's polygon (labelme's own count up to a radius of ~8.7e8 px).
const MAX_CIRCLE_POINTS: f64 = 65536.0;

/// Labels that mark regions, not objects (labelme's conventions).
const NOT_CATEGORIES: [&str; 2] = ["__ignore__", "_background_"];

/// Reads every `*.json` in `dir` (sorted by name). `labels` fixes the category order
/// (one label per line, as labelme's `labels.txt`); without it the labels found, sorted.
/// Image `file_name`s are relative to `dir`.
pub fn load_dir(dir: &Path, labels: Option<&[String]>) -> Result<CocoDataset> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read LabelMe folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no LabelMe .json files in {}", dir.display());
    }
    let mut parsed = Vec::with_capacity(files.len());
    for f in &files {
        let text = std::fs::read_to_string(f)
            .with_context(|| format!("cannot read LabelMe file {}", f.display()))?;
        parsed.push(parse(&text).with_context(|| format!("in LabelMe file {}", f.display()))?);
    }
    let names = match labels {
        Some(l) => category_names(l.iter()),
        None => category_names(
            parsed
                .iter()
                .flat_map(|lm| lm.shapes.iter().map(|s| &s.label)),
        ),
    };
    let mut ds = dataset_with_categories(names, labels.is_none());
    for (f, lm) in files.iter().zip(parsed) {
        push_file(&mut ds, &lm, f, dir)?;
    }
    ds.validate()?;
    Ok(ds)
}

/// Converts the text of one LabelMe file to COCO, its own labels (sorted) as the
/// categories; `origin` names the file in errors and locates `imagePath` (the image is
/// only checked when it exists). What the fuzz target `labelme_json` drives.
pub fn from_json(text: &str, origin: &Path) -> Result<CocoDataset> {
    let lm = parse(text).with_context(|| format!("in LabelMe file {}", origin.display()))?;
    let names = category_names(lm.shapes.iter().map(|s| &s.label));
    let mut ds = dataset_with_categories(names, true);
    let dir = origin.parent().unwrap_or(Path::new("."));
    push_file(&mut ds, &lm, origin, dir)?;
    ds.validate()?;
    Ok(ds)
}

fn parse(text: &str) -> Result<LabelmeFile> {
    serde_json::from_str(text).context("invalid LabelMe JSON")
}

/// Category names without labelme's region labels; `sort` for labels found in files.
fn category_names<'a>(labels: impl Iterator<Item = &'a String>) -> Vec<String> {
    labels
        .filter(|n| !NOT_CATEGORIES.contains(&n.as_str()))
        .cloned()
        .collect()
}

fn dataset_with_categories(mut names: Vec<String>, sort: bool) -> CocoDataset {
    if sort {
        names.sort();
        names.dedup();
    }
    CocoDataset {
        categories: names
            .iter()
            .enumerate()
            .map(|(i, n)| CocoCategory {
                id: i as u64 + 1,
                name: n.clone(),
                extra: Map::new(),
            })
            .collect(),
        ..Default::default()
    }
}

/// Appends the image of LabelMe file `f` (parsed as `lm`) and its instances to `ds`.
fn push_file(ds: &mut CocoDataset, lm: &LabelmeFile, f: &Path, dir: &Path) -> Result<()> {
    let cat_of: HashMap<&str, u64> = ds
        .categories
        .iter()
        .map(|c| (c.name.as_str(), c.id))
        .collect();
    let image_id = ds.images.len() as u64 + 1;
    let json_dir = f.parent().unwrap_or(Path::new("."));
    let image_file = json_dir.join(&lm.image_path);
    let file_name = relative_to(&image_file, dir);
    if let Ok((w, h)) = super::image_file::image_dimensions(&image_file) {
        if (w, h) != (lm.image_width, lm.image_height) {
            bail!(
                "{}: imageWidth×imageHeight {}×{} disagrees with {} ({}×{})",
                f.display(),
                lm.image_width,
                lm.image_height,
                image_file.display(),
                w,
                h
            );
        }
    }
    let mut annotations = Vec::new();
    // Instances keyed by (label, group), in order of first appearance.
    let mut order: Vec<(String, Option<i64>, usize)> = Vec::new();
    let mut polys: Vec<Vec<Vec<f64>>> = Vec::new();
    for (si, shape) in lm.shapes.iter().enumerate() {
        let poly = shape_polygon(shape)
            .with_context(|| format!("{}: shape {si} ({:?})", f.display(), shape.label))?;
        let Some(poly) = poly else {
            eprintln!(
                "warning: {}: shape {si} is a {:?}, which has no area; skipped",
                f.display(),
                shape.shape_type
            );
            continue;
        };
        let slot = match shape.group_id {
            Some(g) => order
                .iter()
                .position(|(l, gg, _)| *l == shape.label && *gg == Some(g)),
            None => None,
        };
        match slot {
            Some(s) => polys[order[s].2].push(poly),
            None => {
                order.push((shape.label.clone(), shape.group_id, polys.len()));
                polys.push(vec![poly]);
            }
        }
    }
    for (label, _, idx) in order {
        let Some(&category_id) = cat_of.get(label.as_str()) else {
            if !NOT_CATEGORIES.contains(&label.as_str()) {
                bail!("{}: label {label:?} is not in the labels list", f.display());
            }
            continue;
        };
        let segmentation = Segmentation::Polygons(std::mem::take(&mut polys[idx]));
        // The COCO checks, extent included: a vertex far off the image would make the
        // rasteriser walk billions of points (found by the `labelme_json` fuzz target).
        let rle = segmentation
            .to_rle(lm.image_height, lm.image_width)
            .with_context(|| format!("{}: instance {label:?}", f.display()))?;
        annotations.push(CocoAnnotation {
            id: (ds.annotations.len() + annotations.len()) as u64 + 1,
            image_id,
            category_id,
            area: rle.area() as f64,
            bbox: rle.bbox(),
            segmentation,
            iscrowd: 0,
            extra: Map::new(),
        });
    }
    ds.images.push(CocoImage {
        id: image_id,
        file_name,
        width: lm.image_width,
        height: lm.image_height,
        extra: Map::new(),
    });
    ds.annotations.extend(annotations);
    Ok(())
}

/// A shape's outline as a flat polygon; `None` for shapes without area (points, lines).
fn shape_polygon(s: &LabelmeShape) -> Result<Option<Vec<f64>>> {
    if s.points.iter().flatten().any(|v| !v.is_finite()) {
        bail!("has a non-finite point");
    }
    let poly = match s.shape_type.as_str() {
        "polygon" => {
            let p: Vec<f64> = s.points.iter().flatten().copied().collect();
            check_polygons(std::slice::from_ref(&p))?;
            p
        }
        "rectangle" => {
            let [[x1, y1], [x2, y2]] = two_points(s)?;
            let (x1, x2) = (x1.min(x2), x1.max(x2));
            let (y1, y2) = (y1.min(y2), y1.max(y2));
            vec![x1, y1, x2, y1, x2, y2, x1, y2]
        }
        "circle" => {
            let [[x1, y1], [x2, y2]] = two_points(s)?;
            let r = ((x2 - x1).powi(2) + (y2 - y1).powi(2)).sqrt();
            if r <= 0.0 {
                bail!("circle has zero radius");
            }
            // labelme's vertex count, capped: it grows as π·sqrt(r/2) and is infinite once
            // 1 − 1/r rounds to 1 (a huge radius from the `labelme_json` fuzz target).
            let n = (std::f64::consts::PI / (1.0 - 1.0 / r).acos()).min(MAX_CIRCLE_POINTS);
            let n = (n as usize).max(12);
            (0..n)
                .flat_map(|i| {
                    let a = 2.0 * std::f64::consts::PI / n as f64 * i as f64;
                    [x1 + r * a.sin(), y1 + r * a.cos()]
                })
                .collect()
        }
        "point" | "line" | "linestrip" | "points" => return Ok(None),
        other => bail!("shape_type {other:?} is not supported (polygon, rectangle, circle)"),
    };
    Ok(Some(poly))
}

fn two_points(s: &LabelmeShape) -> Result<[[f64; 2]; 2]> {
    match s.points.as_slice() {
        [a, b] => Ok([*a, *b]),
        p => bail!("{} needs exactly 2 points, has {}", s.shape_type, p.len()),
    }
}

/// `path` relative to `base` when it lies below it, else as given.
fn relative_to(path: &Path, base: &Path) -> String {
    let norm = |p: &Path| {
        p.components()
            .filter(|c| c.as_os_str() != ".")
            .collect::<PathBuf>()
    };
    let (p, b) = (norm(path), norm(base));
    p.strip_prefix(&b)
        .map(Path::to_path_buf)
        .unwrap_or(p)
        .to_string_lossy()
        .into_owned()
}

/// Reads a labelme `labels.txt` (one label per line).
pub fn read_labels(path: &Path) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read labels file {}", path.display()))?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(String::from)
        .collect())
}
