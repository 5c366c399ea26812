//! What a training run prints: before step 1 the data, plan and model lines, and after
//! each epoch the epoch line (learning rate, every loss term, time and throughput, loss
//! scale and skipped steps in f16, and the validation stats or why there are none, with
//! the best mark). Only strings: the trainer decides whether to print them (`--quiet`).

use crate::annotations::split::Split;
use crate::config::{Config, Precision};
use crate::data::dataset::RealSet;
use crate::infer::detector::DetectorConfig;

use super::loader::Mix;
use super::run_files::EpochRecord;
use super::state::TrainState;

/// The data line: real images (a proxy said so) and their split, synthetic count, sizes
/// and how long loading took.
pub fn data_line(cfg: &Config, real: &RealSet, split: &Split, seconds: f64) -> String {
    format!(
        "data: {} real images{} ({} train / {} val / {} test), {} synthetic{}, {} px (crop {}), ready in {:.1} s",
        real.gt.images.len(),
        if real.proxy { " [proxy-real renders, not real photos]" } else { "" },
        split.train.len(),
        split.val.len(),
        split.test.len(),
        cfg.data.synthetic,
        if cfg.data.fresh_synthetic { " (fresh each epoch)" } else { "" },
        cfg.data.image_size,
        cfg.data.crop,
        seconds
    )
}

/// The plan line: optimiser steps per epoch and how a batch is made.
pub fn plan_line(cfg: &Config, split: &Split) -> String {
    let m = Mix::of(&cfg.train);
    format!(
        "plan: {} optimiser steps per epoch of batch {}{}",
        m.steps(split.train.len(), cfg.data.synthetic, cfg.train.batch),
        cfg.train.batch,
        match m.real_fraction {
            Some(f) => format!(
                ", {} real per batch (train.real_fraction = {f})",
                (f * cfg.train.batch as f64).round()
            ),
            None => ", real and synthetic in their natural proportion".into(),
        }
    )
}

/// The model line: the model, its size at `input`, the device and the precision.
pub fn model_line(cfg: &Config, mcfg: &DetectorConfig, st: &TrainState, input: usize) -> String {
    format!(
        "model: {}: {} on {:?}{}",
        mcfg.describe(),
        st.model.summary(input),
        cfg.device,
        match cfg.train.precision {
            Precision::F32 => String::new(),
            p => format!(
                " in {} (f32 master weights, EMA and checkpoints{})",
                p.name(),
                if st.scaler.is_some() {
                    ", dynamic loss scaling"
                } else {
                    ""
                }
            ),
        }
    )
}

/// The line printed after an epoch.
pub fn epoch_line(rec: &EpochRecord, epochs: usize, loss_names: &[&str], improved: bool) -> String {
    let val = match &rec.val {
        Some(v) => {
            let (b, s) = (&v.bbox.stats, &v.segm.stats);
            let cost = match &rec.val_time {
                Some(t) => format!(
                    " ({:.1} s, {:.2}× forward)",
                    t.total,
                    t.total / t.forward.max(1e-9)
                ),
                None => String::new(),
            };
            format!(
                "val{cost} bbox AP {:.3} AP50 {:.3}  segm AP {:.3} AP50 {:.3}",
                b[0], b[1], s[0], s[1]
            )
        }
        None => "not validated (train.val_every)".into(),
    };
    let scale = match rec.loss_scale {
        Some(s) => format!(", loss scale {s}, {} skipped", rec.skipped_steps),
        None => String::new(),
    };
    format!(
        "epoch {}/{}  lr {:.2e}  loss {}  {:.1} s ({:.2} img/s, {:.1} s data wait{scale})  {val}{}",
        rec.epoch,
        epochs,
        rec.lr,
        loss_names
            .iter()
            .map(|k| format!("{k} {:.3}", rec.loss[*k]))
            .collect::<Vec<_>>()
            .join(" "),
        rec.time,
        rec.images_per_s,
        rec.data_wait_s,
        if improved { "  *best" } else { "" }
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::run_files::{IouStats, StatsRecord, ValTime};

    #[test]
    fn epoch_line_reports_every_term_and_the_best_mark() {
        let mut segm = [0.0; 12];
        segm[..2].copy_from_slice(&[0.5, 0.75]);
        let rec = EpochRecord {
            data_wait_s: 0.5,
            epoch: 3,
            images_per_s: 6.5,
            loss: [("box".to_string(), 1.25), ("seg".to_string(), 0.5)].into(),
            loss_scale: None,
            lr: 0.01,
            proxy: true,
            skipped_steps: 0,
            steps: 4,
            time: 12.0,
            train_time: 10.0,
            val: Some(StatsRecord {
                bbox: IouStats { stats: [0.25; 12] },
                segm: IouStats { stats: segm },
            }),
            val_time: None,
        };
        let timed = EpochRecord {
            val_time: Some(ValTime {
                total: 1.5,
                forward: 1.25,
            }),
            ..rec.clone()
        };
        assert!(
            epoch_line(&timed, 25, &["box", "seg"], false)
                .contains("val (1.5 s, 1.20× forward) bbox AP 0.250"),
            "{}",
            epoch_line(&timed, 25, &["box", "seg"], false)
        );
        let line = epoch_line(&rec, 25, &["box", "seg"], true);
        assert_eq!(
            line,
            "epoch 3/25  lr 1.00e-2  loss box 1.250 seg 0.500  12.0 s (6.50 img/s, 0.5 s data wait)  val bbox AP 0.250 AP50 0.250  segm AP 0.500 AP50 0.750  *best"
        );
        assert!(!epoch_line(&rec, 25, &["box", "seg"], false).contains("best"));
        let skipped = EpochRecord {
            val: None,
            val_time: None,
            ..rec
        };
        assert_eq!(
            epoch_line(&skipped, 25, &["box", "seg"], false),
            "epoch 3/25  lr 1.00e-2  loss box 1.250 seg 0.500  12.0 s (6.50 img/s, 0.5 s data wait)  not validated (train.val_every)"
        );
        let f16 = EpochRecord {
            loss_scale: Some(16384.0),
            skipped_steps: 2,
            ..skipped
        };
        assert!(
            epoch_line(&f16, 25, &["box", "seg"], false)
                .contains("(6.50 img/s, 0.5 s data wait, loss scale 16384, 2 skipped)"),
            "{}",
            epoch_line(&f16, 25, &["box", "seg"], false)
        );
    }
}
