//! `confusion_matrix.png` of a run: detections against ground truth per class, with
//! background, as ultralytics' `ConfusionMatrix` for detection counts them
//! (`ultralytics/utils/metrics.py`): detections above `conf` are matched one-to-one to
//! ground-truth boxes of the same image with box IoU above `iou` (pairs taken by IoU,
//! highest first, each detection and each ground truth once); a matched pair counts at
//! (predicted class, true class), an unmatched ground truth at (background, its class)
//! (missed), an unmatched detection at (its class, background) (a false positive).
//! Crowd regions are not instances and are left out. Drawn as counts and as each true
//! class's share (columns summing to 1), side by side.

use std::collections::HashMap;
use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::plots::{register_font, FAMILY};
use crate::annotations::coco::{CocoDataset, Detection};

/// ultralytics' confusion-matrix defaults: detections above 0.25, matched at IoU 0.45.
pub const MATRIX_CONF: f64 = 0.25;
pub const MATRIX_IOU: f64 = 0.45;

/// `(nc + 1) × (nc + 1)` counts, `m[predicted][true]`, index `nc` = background.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfusionMatrix {
    pub names: Vec<String>,
    pub m: Vec<Vec<u64>>,
}

fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let iw = ((a[0] + a[2]).min(b[0] + b[2]) - a[0].max(b[0])).max(0.0);
    let ih = ((a[1] + a[3]).min(b[1] + b[3]) - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let union = a[2] * a[3] + b[2] * b[3] - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

impl ConfusionMatrix {
    /// Counts `dets` against `gt` (class = index of the category in `gt`'s categories
    /// sorted by id, which is how the models number them).
    pub fn count(gt: &CocoDataset, dets: &[Detection], conf: f64, iou_thr: f64) -> Self {
        let mut cats: Vec<(u64, String)> = gt
            .categories
            .iter()
            .map(|c| (c.id, c.name.clone()))
            .collect();
        cats.sort_by_key(|c| c.0);
        let nc = cats.len();
        let class: HashMap<u64, usize> = cats.iter().enumerate().map(|(i, c)| (c.0, i)).collect();
        let mut m = vec![vec![0u64; nc + 1]; nc + 1];
        for im in &gt.images {
            let g: Vec<([f64; 4], usize)> = gt
                .annotations
                .iter()
                .filter(|a| a.image_id == im.id && a.iscrowd == 0)
                .filter_map(|a| Some((a.bbox, *class.get(&a.category_id)?)))
                .collect();
            let d: Vec<([f64; 4], usize)> = dets
                .iter()
                .filter(|d| d.image_id == im.id && d.score > conf)
                .filter_map(|d| Some((d.bbox?, *class.get(&d.category_id)?)))
                .collect();
            let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
            for (gi, gb) in g.iter().enumerate() {
                for (di, db) in d.iter().enumerate() {
                    let v = iou(gb.0, db.0);
                    if v > iou_thr {
                        pairs.push((v, gi, di));
                    }
                }
            }
            pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
            let (mut g_used, mut d_used) = (vec![false; g.len()], vec![false; d.len()]);
            for (_, gi, di) in pairs {
                if !g_used[gi] && !d_used[di] {
                    g_used[gi] = true;
                    d_used[di] = true;
                    m[d[di].1][g[gi].1] += 1;
                }
            }
            for (gi, used) in g_used.iter().enumerate() {
                if !used {
                    m[nc][g[gi].1] += 1;
                }
            }
            for (di, used) in d_used.iter().enumerate() {
                if !used {
                    m[d[di].1][nc] += 1;
                }
            }
        }
        let mut names: Vec<String> = cats.into_iter().map(|c| c.1).collect();
        names.push("background".into());
        ConfusionMatrix { names, m }
    }

    /// Each true class's column divided by its sum (0 for an empty column).
    pub fn normalized(&self) -> Vec<Vec<f64>> {
        let n = self.m.len();
        let col: Vec<u64> = (0..n).map(|j| (0..n).map(|i| self.m[i][j]).sum()).collect();
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| {
                        if col[j] > 0 {
                            self.m[i][j] as f64 / col[j] as f64
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// Writes the counts and the normalised matrix side by side to `path` (PNG).
    pub fn write_png(&self, path: &Path, title: &str) -> Result<()> {
        register_font();
        let (pw, ph) = (560u32, 520u32);
        let (w, h) = (2 * pw, ph);
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            let halves = root.split_evenly((1, 2));
            let norm = self.normalized();
            let counts: Vec<Vec<f64>> = self
                .m
                .iter()
                .map(|r| r.iter().map(|&v| v as f64).collect())
                .collect();
            self.draw(&halves[0], &counts, &format!("{title}: counts"), false)?;
            self.draw(&halves[1], &norm, &format!("{title}: normalised"), true)?;
            root.present()
                .map_err(|e| anyhow!("finishing {}: {e:?}", path.display()))?;
        }
        let png =
            crate::util::png::encode_rgb8(&buf, w, h, image::codecs::png::CompressionType::Best)?;
        crate::util::write_atomic(path, &png)
    }

    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, plotters::coord::Shift>,
        v: &[Vec<f64>],
        title: &str,
        fraction: bool,
    ) -> Result<()>
    where
        DB::ErrorType: 'static,
    {
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing {title:?}: {e:?}");
        let n = v.len();
        let max = v
            .iter()
            .flatten()
            .copied()
            .fold(0.0f64, f64::max)
            .max(1e-12);
        let names = self.names.clone();
        let mut chart = ChartBuilder::on(area)
            .caption(title, (FAMILY, 16))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(90)
            // A segmented `0..k` has k + 1 cells (its end included): `0..n - 1` is n cells.
            .build_cartesian_2d((0..n - 1).into_segmented(), (0..n - 1).into_segmented())
            .map_err(err)?;
        // Rows are drawn top-down (predicted class 0 first), as ultralytics lays them out.
        let label_x = |v: &SegmentValue<usize>| match v {
            SegmentValue::CenterOf(i) => names.get(*i).cloned().unwrap_or_default(),
            _ => String::new(),
        };
        let label_y = |v: &SegmentValue<usize>| match v {
            SegmentValue::CenterOf(i) if *i < n => names[n - 1 - i].clone(),
            _ => String::new(),
        };
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("true")
            .y_desc("predicted")
            .x_labels(n)
            .y_labels(n)
            .x_label_formatter(&label_x)
            .y_label_formatter(&label_y)
            .label_style((FAMILY, 14))
            .draw()
            .map_err(err)?;
        let centre = Pos::new(HPos::Center, VPos::Center);
        for (i, row) in v.iter().enumerate() {
            for (j, &x) in row.iter().enumerate() {
                let t = x / max;
                let shade = (255.0 * (1.0 - 0.85 * t)) as u8;
                let y = n - 1 - i;
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [
                            (SegmentValue::Exact(j), SegmentValue::Exact(y)),
                            (SegmentValue::Exact(j + 1), SegmentValue::Exact(y + 1)),
                        ],
                        RGBColor(shade, shade, 255).filled(),
                    )))
                    .map_err(err)?;
                let text = if fraction {
                    format!("{x:.2}")
                } else {
                    format!("{}", x as u64)
                };
                let color = if t > 0.6 { WHITE } else { BLACK };
                chart
                    .draw_series(std::iter::once(Text::new(
                        text,
                        (SegmentValue::CenterOf(j), SegmentValue::CenterOf(y)),
                        (FAMILY, 18).into_font().color(&color).pos(centre),
                    )))
                    .map_err(err)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gt() -> CocoDataset {
        serde_json::from_str(
            r#"{"images": [{"id": 1, "file_name": "a.png", "width": 100, "height": 100}],
            "categories": [{"id": 5, "name": "carcass"}],
            "annotations": [
              {"id": 1, "image_id": 1, "category_id": 5, "bbox": [0, 0, 10, 10], "area": 100, "iscrowd": 0, "segmentation": [[0, 0, 10, 0, 10, 10]]},
              {"id": 2, "image_id": 1, "category_id": 5, "bbox": [50, 50, 10, 10], "area": 100, "iscrowd": 0, "segmentation": [[50, 50, 60, 50, 60, 60]]},
              {"id": 3, "image_id": 1, "category_id": 5, "bbox": [80, 0, 10, 10], "area": 100, "iscrowd": 1, "segmentation": [[80, 0, 90, 0, 90, 10]]}]}"#,
        )
        .unwrap()
    }

    fn det(b: [f64; 4], score: f64) -> Detection {
        Detection {
            image_id: 1,
            category_id: 5,
            score,
            bbox: Some(b),
            segmentation: None,
        }
    }

    #[test]
    fn hits_misses_and_false_positives_land_in_their_cells() {
        let dets = [
            det([0.0, 0.0, 10.0, 10.0], 0.9),   // hit on GT 1
            det([1.0, 0.0, 10.0, 10.0], 0.8),   // duplicate of GT 1: a false positive
            det([30.0, 30.0, 10.0, 10.0], 0.7), // nothing there: a false positive
            det([50.0, 50.0, 10.0, 10.0], 0.1), // would hit GT 2, but below conf
        ];
        let c = ConfusionMatrix::count(&gt(), &dets, MATRIX_CONF, MATRIX_IOU);
        assert_eq!(c.names, ["carcass", "background"]);
        // [pred][true]: 1 hit, 2 false positives, GT 2 missed, the crowd box not counted.
        assert_eq!(c.m, vec![vec![1, 2], vec![1, 0]]);
        assert_eq!(c.normalized(), vec![vec![0.5, 1.0], vec![0.5, 0.0]]);
    }
}
