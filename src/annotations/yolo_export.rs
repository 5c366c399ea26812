//! COCO → YOLO-seg label files, for users who also train with ultralytics.
//!
//! Mirrors ultralytics' `convert_coco(use_segments=True)`: crowd and empty boxes are
//! skipped, class = index of the category (sorted by id), coordinates normalised by the
//! image size and printed with `%g`, several polygons of one instance joined into one
//! outline by `merge_multi_segment` (nearest points linked, walked there and back).
//! RLE instances are first traced into polygons.

use std::path::Path;

use anyhow::{Context, Result};

use super::coco::{CocoDataset, Segmentation};
use super::polygon::mask_to_polygons;

/// Writes `labels/<image stem>.txt` per image and `data.yaml` under `out`.
pub fn export(ds: &CocoDataset, out: &Path) -> Result<usize> {
    let labels_dir = out.join("labels");
    std::fs::create_dir_all(&labels_dir)
        .with_context(|| format!("cannot create {}", labels_dir.display()))?;
    let mut cats: Vec<_> = ds.categories.iter().collect();
    cats.sort_by_key(|c| c.id);
    let mut written = 0;
    for im in &ds.images {
        let (w, h) = (im.width as f64, im.height as f64);
        let mut lines: Vec<String> = Vec::new();
        for a in ds.annotations.iter().filter(|a| a.image_id == im.id) {
            if a.iscrowd != 0 || a.bbox[2] <= 0.0 || a.bbox[3] <= 0.0 {
                continue;
            }
            let Some(cls) = cats.iter().position(|c| c.id == a.category_id) else {
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
        let mut text = lines.join("\n");
        if !text.is_empty() {
            text.push('\n');
        }
        crate::util::write_atomic(&labels_dir.join(format!("{stem}.txt")), text.as_bytes())?;
        written += 1;
    }
    let mut yaml = format!(
        "path: {}\ntrain: images\nval: images\nnames:\n",
        out.display()
    );
    for (i, c) in cats.iter().enumerate() {
        yaml.push_str(&format!("  {i}: {}\n", c.name));
    }
    crate::util::write_atomic(&out.join("data.yaml"), yaml.as_bytes())?;
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
