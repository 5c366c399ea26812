//! `plots.png` of a run: two panels drawn with [`crate::eval::plots`]. Left, the model's
//! training losses per epoch (mean per step; YOLO: box, cls, dfl, seg; Mask R-CNN:
//! rpn_cls, rpn_box, cls, box, mask); right, validation
//! bbox/segm AP and AP50 per validated epoch (`train.val_every`) on a 0–1 axis. The
//! numbers are in `results.csv`.

use std::path::Path;

use anyhow::Result;

use crate::eval::plots::{write_png, Panel, Series, PALETTE};

use super::run_files::EpochRecord;

/// The panels of a run's plot from its per-epoch metric records.
pub fn run_panels(records: &[EpochRecord], loss_names: &[&str]) -> [Panel; 2] {
    let curve = |f: &dyn Fn(&EpochRecord) -> Option<f64>| -> Vec<(f64, f64)> {
        records
            .iter()
            .filter_map(|r| Some((r.epoch as f64, f(r)?)))
            .collect()
    };
    let mut losses = Panel::new("training losses", "epoch", "loss (mean per step)");
    for (i, &k) in loss_names.iter().enumerate() {
        losses = losses.push(Series::new(
            k,
            curve(&|r| r.loss.get(k).copied()),
            PALETTE[i % 6],
        ));
    }
    let mut ap = Panel::new("validation", "epoch", "COCO AP").y_range(0.0, 1.0);
    for (i, (t, s, name)) in [
        ("bbox", 0, "bbox AP"),
        ("bbox", 1, "bbox AP50"),
        ("segm", 0, "segm AP"),
        ("segm", 1, "segm AP50"),
    ]
    .into_iter()
    .enumerate()
    {
        ap = ap.push(Series::new(
            name,
            curve(&|r| {
                let val = r.val.as_ref()?;
                let v = if t == "bbox" { &val.bbox } else { &val.segm };
                Some(v.stats[s])
            }),
            PALETTE[6 + i],
        ));
    }
    [losses, ap]
}

/// Writes `<dir>/plots.png` from the per-epoch metric records (`loss.<name>` for each of
/// `loss_names`).
pub fn write_plots(dir: &Path, records: &[EpochRecord], loss_names: &[&str]) -> Result<()> {
    write_png(
        &dir.join("plots.png"),
        &run_panels(records, loss_names),
        2,
        420,
        300,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::run_files::{IouStats, StatsRecord};

    #[test]
    fn run_plot_has_every_curve() {
        let recs: Vec<EpochRecord> = (1..=3)
            .map(|e| {
                let mut bbox = [0.0; 12];
                bbox[..2].copy_from_slice(&[0.1 * e as f64, 0.2]);
                let mut segm = [0.0; 12];
                segm[..2].copy_from_slice(&[0.05, 0.1]);
                EpochRecord {
                    data_wait_s: 0.0,
                    epoch: e,
                    images_per_s: 1.0,
                    loss: [
                        ("box", 1.0 / e as f64),
                        ("cls", 2.0),
                        ("dfl", 1.5),
                        ("seg", 3.0),
                    ]
                    .map(|(k, v)| (k.to_string(), v))
                    .into(),
                    loss_scale: None,
                    lr: 0.01,
                    proxy: true,
                    skipped_steps: 0,
                    steps: 2,
                    time: 1.0,
                    train_time: 1.0,
                    // Epoch 2 was not validated (train.val_every = 2 would skip 1 and 3;
                    // any gap must just leave its points out).
                    val: (e != 2).then_some(StatsRecord {
                        bbox: IouStats { stats: bbox },
                        segm: IouStats { stats: segm },
                    }),
                    val_time: None,
                }
            })
            .collect();
        let names = ["box", "cls", "dfl", "seg"];
        let [l, a] = run_panels(&recs, &names);
        assert_eq!(l.series.len(), 4);
        assert_eq!(a.series.len(), 4);
        assert!(l.series.iter().all(|s| s.points.len() == 3));
        assert!(a.series.iter().all(|s| s.points.len() == 2));
        assert_eq!(a.series[0].points[0].0, 1.0);
        assert_eq!(a.series[0].points[1], (3.0, 0.30000000000000004));
        let dir = std::env::temp_dir().join(format!("ct-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write_plots(&dir, &recs, &names).unwrap();
        let img = image::open(dir.join("plots.png")).unwrap();
        assert_eq!((img.width(), img.height()), (840, 300));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
