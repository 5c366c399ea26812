//! COCO → a YOLO-seg dataset (`images/`, `labels/`, `data.yaml`), for users who also
//! train with ultralytics, and for reading back with `kind = "yolo"` ([`super::yolo`]).
//!
//! Labels mirror ultralytics' `convert_coco(use_segments=True)`: crowd and empty boxes
//! are skipped, class = index of the category (sorted by id), coordinates normalised by
//! the image size and printed with `%g`, several polygons of one instance joined into one
//! outline by `merge_multi_segment` (nearest points linked, walked there and back). RLE
//! instances are first traced into polygons.
//!
//! Beyond ultralytics (which writes labels only): the images found beside the COCO file
//! are copied to `images/` (so the folder is a dataset as it stands), and `data.yaml`
//! names the split. One file (no split): `train` and `val` both `images`, which
//! chicktrain reads as "no split of its own". One file per split: `images/<split>/`,
//! `labels/<split>/`, and `train`/`val`/`test` pointing at them. `data.yaml` has no
//! `path`, so the dataset root is its own folder (for ultralytics too) and the folder
//! can be moved.

use std::path::Path;

use anyhow::{bail, Context, Result};

use super::coco::{CocoDataset, Segmentation};
use super::polygon::mask_to_polygons;
use super::split::Part;

/// One COCO set to export: its split (`None`: the dataset has none), the dataset, and
/// the folder its `file_name`s are relative to.
pub struct ExportPart<'a> {
    pub part: Option<Part>,
    pub coco: &'a CocoDataset,
    pub images: &'a Path,
}

/// What [`export`] wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Exported {
    pub labels: usize,
    pub images: usize,
}

/// Writes the dataset of `parts` under `out`: all with `part: None` (one file, one
/// folder each of images and labels) or each with its own split. Categories must be the
/// same in every part.
pub fn export(parts: &[ExportPart], out: &Path) -> Result<Exported> {
    let Some(first) = parts.first() else {
        bail!("nothing to export");
    };
    let split = first.part.is_some();
    if parts.iter().any(|p| p.part.is_some() != split) || (!split && parts.len() > 1) {
        bail!("export either one COCO set without a split or one per split");
    }
    let cats = first.coco.sorted_categories();
    let mut done = Exported::default();
    let mut keys = Vec::new();
    for p in parts {
        if p.coco.sorted_categories() != cats {
            bail!(
                "every split must have the same categories (ids and names) to share class indices"
            );
        }
        let sub = p.part.map(Part::key).unwrap_or("");
        if keys.contains(&sub) {
            bail!("two COCO files for the {sub} split");
        }
        keys.push(sub);
        let images_dir = out.join("images").join(sub);
        done.labels += write_labels(p.coco, &cats, &out.join("labels").join(sub))?;
        done.images += copy_images(p.coco, p.images, &images_dir)?;
    }
    let mut yaml = String::from(
        "# Written by chicktrain convert coco2yolo. No `path`: the dataset root is this\n# file's folder.\n",
    );
    if split {
        for p in Part::ALL {
            if keys.contains(&p.key()) {
                yaml.push_str(&format!("{}: images/{}\n", p.key(), p.key()));
            }
        }
    } else {
        yaml.push_str("# One COCO file, no split of its own: train and val are the same images.\ntrain: images\nval: images\n");
    }
    yaml.push_str("names:\n");
    for (i, c) in cats.iter().enumerate() {
        yaml.push_str(&format!("  {i}: {}\n", yaml_string(&c.1)));
    }
    crate::util::write_atomic(&out.join("data.yaml"), yaml.as_bytes())?;
    Ok(done)
}

/// A class name as a YAML scalar: plain when it is a plain word, else double-quoted
/// (JSON escaping is valid YAML).
fn yaml_string(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_alphanumeric() || c == '_' || c == '-' || c == ' ')
        && !s.starts_with(' ')
        && !s.ends_with(' ')
        && s.parse::<f64>().is_err()
        && !matches!(
            s.to_ascii_lowercase().as_str(),
            "true" | "false" | "null" | "yes" | "no" | "on" | "off" | "~"
        );
    if plain {
        s.to_string()
    } else {
        serde_json::to_string(s).unwrap_or_default()
    }
}

/// `<image stem>.txt` per image of `ds` under `dir`, classes indexed by `cats`.
fn write_labels(ds: &CocoDataset, cats: &[(u64, String)], dir: &Path) -> Result<usize> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut stems = std::collections::HashSet::new();
    let mut written = 0;
    for im in &ds.images {
        let (w, h) = (im.width as f64, im.height as f64);
        let mut lines: Vec<String> = Vec::new();
        for a in ds.annotations.iter().filter(|a| a.image_id == im.id) {
            if a.iscrowd != 0 || a.bbox[2] <= 0.0 || a.bbox[3] <= 0.0 {
                continue;
            }
            let Some(cls) = cats.iter().position(|c| c.0 == a.category_id) else {
                continue;
            };
            let polys = match &a.segmentation {
                Segmentation::Polygons(p) => p.clone(),
                other => mask_to_polygons(&other.to_rle(im.height, im.width)?.decode()),
            };
            let Some(line) = polygon_line(cls, &polys, (w, h)) else {
                continue;
            };
            if !lines.contains(&line) {
                lines.push(line);
            }
        }
        let stem = Path::new(&im.file_name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| im.id.to_string());
        if !stems.insert(stem.clone()) {
            bail!(
                "two images have the file name stem {stem:?} (the second: {}); YOLO label files are named by it",
                im.file_name
            );
        }
        let mut text = lines.join("\n");
        if !text.is_empty() {
            text.push('\n');
        }
        crate::util::write_atomic(&dir.join(format!("{stem}.txt")), text.as_bytes())?;
        written += 1;
    }
    Ok(written)
}

/// One YOLO-seg label line, `class x1 y1 x2 y2 …`: the instance's polygons (flat pixel
/// `[x0, y0, x1, y1, …]`, several joined by [`merge_multi_segment`]) normalised by the
/// image's `(width, height)` and printed with `%g`. None without a polygon.
pub fn polygon_line(cls: usize, polys: &[Vec<f64>], (w, h): (f64, f64)) -> Option<String> {
    let points: Vec<[f64; 2]> = match polys.len() {
        0 => return None,
        1 => pairs(&polys[0]),
        _ => merge_multi_segment(&polys.iter().map(|p| pairs(p)).collect::<Vec<_>>()),
    };
    let mut line = format!("{cls}");
    for [x, y] in points {
        line.push(' ');
        line.push_str(&fmt_g(x / w));
        line.push(' ');
        line.push_str(&fmt_g(y / h));
    }
    Some(line)
}

/// Copies the images of `ds` (relative to `root`) into `dir` under their file names.
/// None found: labels only (0, as ultralytics' converter); some found but not all: an
/// error naming a missing one.
fn copy_images(ds: &CocoDataset, root: &Path, dir: &Path) -> Result<usize> {
    let found = ds
        .images
        .iter()
        .filter(|im| root.join(&im.file_name).is_file())
        .count();
    if found == 0 {
        return Ok(0);
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for im in &ds.images {
        let src = root.join(&im.file_name);
        if !src.is_file() {
            bail!(
                "image {} (id {}) does not exist, though {found} other images of the set do",
                src.display(),
                im.id
            );
        }
        let name = src
            .file_name()
            .context("an image file_name without a name")?;
        let dst = dir.join(name);
        let bytes =
            std::fs::read(&src).with_context(|| format!("cannot read {}", src.display()))?;
        crate::util::write_atomic(&dst, &bytes)?;
    }
    Ok(found)
}

fn pairs(p: &[f64]) -> Vec<[f64; 2]> {
    p.chunks_exact(2).map(|c| [c[0], c[1]]).collect()
}

/// Indices (i in a, j in b) of the closest pair of points (first minimum in C order).
fn min_index(a: &[[f64; 2]], b: &[[f64; 2]]) -> (usize, usize) {
    let mut best = (f64::INFINITY, 0, 0);
    for (i, p) in a.iter().enumerate() {
        for (j, q) in b.iter().enumerate() {
            let d = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
            if d < best.0 {
                best = (d, i, j);
            }
        }
    }
    (best.1, best.2)
}

/// ultralytics' `merge_multi_segment` (8.4.190): one outline through all parts of an
/// instance, each part entered and left at its points nearest the neighbouring parts.
pub fn merge_multi_segment(segments: &[Vec<[f64; 2]>]) -> Vec<[f64; 2]> {
    let n = segments.len();
    let mut segs: Vec<Vec<[f64; 2]>> = segments.to_vec();
    let mut idx_list: Vec<Vec<usize>> = vec![Vec::new(); n];
    for i in 1..n {
        let (i1, i2) = min_index(&segs[i - 1], &segs[i]);
        idx_list[i - 1].push(i1);
        idx_list[i].push(i2);
    }
    let mut s: Vec<Vec<[f64; 2]>> = Vec::new();
    for (i, idx0) in idx_list.iter().enumerate() {
        let mut idx = idx0.clone();
        let len = segs[i].len();
        if idx.len() == 2 && idx[0] > idx[1] {
            // walk a middle part backwards, with its link points mapped into that order
            idx = idx.iter().map(|&x| len - 1 - x).collect();
            segs[i].reverse();
        }
        segs[i].rotate_left(idx[0] % len);
        let first = segs[i][0];
        segs[i].push(first);
        if i == 0 || i == n - 1 {
            s.push(segs[i].clone());
        } else {
            let end = idx[1] - idx[0];
            s.push(segs[i][0..=end].to_vec());
        }
    }
    for i in (0..n).rev() {
        if i != 0 && i != n - 1 {
            let idx = &idx_list[i];
            let nidx = idx[1].abs_diff(idx[0]);
            s.push(segs[i][nidx..].to_vec());
        }
    }
    s.concat()
}

/// C's `%g`: 6 significant digits, trailing zeros dropped, exponent outside 1e-4..1e6.
pub fn fmt_g(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let exp = v.abs().log10().floor() as i32;
    // Round to 6 significant digits first; rounding can bump the exponent.
    let sci = format!("{:.5e}", v);
    let (mant, e) = sci.split_once('e').unwrap_or((&sci, "0"));
    let e: i32 = e.parse().unwrap_or(exp);
    if !(-4..6).contains(&e) {
        let mant = trim_zeros(mant);
        let sign = if e < 0 { '-' } else { '+' };
        format!("{mant}e{sign}{:02}", e.abs())
    } else {
        let decimals = (5 - e).max(0) as usize;
        trim_zeros(&format!("{:.*}", decimals, v)).to_string()
    }
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_g_matches_c() {
        for (v, want) in [
            (0.5, "0.5"),
            (0.123456789, "0.123457"),
            (1.0, "1"),
            (0.000123456, "0.000123456"),
            (0.0000123456, "1.23456e-05"),
            (123456789.0, "1.23457e+08"),
            (0.9999999, "1"),
        ] {
            assert_eq!(fmt_g(v), want, "{v}");
        }
    }

    #[test]
    fn merge_links_parts_there_and_back() {
        let a = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
        let b = vec![[5.0, 0.0], [6.0, 0.0], [6.0, 1.0]];
        let m = merge_multi_segment(&[a, b]);
        // a rolled to its point nearest b (1,0) and closed, then b from (5,0), closed
        assert_eq!(
            m,
            vec![
                [1.0, 0.0],
                [1.0, 1.0],
                [0.0, 0.0],
                [1.0, 0.0],
                [5.0, 0.0],
                [6.0, 0.0],
                [6.0, 1.0],
                [5.0, 0.0]
            ]
        );
    }
}
