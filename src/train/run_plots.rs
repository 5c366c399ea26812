//! The plots ultralytics writes into a run folder after training, beside `plots.png`:
//! `BoxPR_curve.png`, `MaskPR_curve.png`, `BoxF1_curve.png`, `MaskF1_curve.png`
//! ([`crate::eval::curves`]) and `confusion_matrix.png` ([`crate::eval::confusion`]),
//! all from `best.bpk`'s detections on the validation split, scored by the crate's own
//! COCO evaluator (ultralytics draws them from its final validation of `best.pt`).

use std::path::Path;

use anyhow::{Context, Result};

use crate::annotations::coco::{CocoDataset, Detection};
use crate::eval::confusion::{ConfusionMatrix, MATRIX_CONF, MATRIX_IOU};
use crate::eval::curves::write_curves;
use crate::eval::{evaluate, IouType};

/// Writes the curves and the confusion matrix of `dets` against `gt` (the validation
/// images' ground truth) into `dir`; `names`: class names in category order.
pub fn write_val_plots(
    dir: &Path,
    gt: &CocoDataset,
    dets: &[Detection],
    names: &[String],
) -> Result<()> {
    let bbox = evaluate(gt, dets, IouType::Bbox).context("bbox curves")?;
    let segm = evaluate(gt, dets, IouType::Segm).context("segm curves")?;
    write_curves(dir, &bbox, &segm, names)?;
    ConfusionMatrix::count(gt, dets, MATRIX_CONF, MATRIX_IOU).write_png(
        &dir.join("confusion_matrix.png"),
        &format!("val, conf > {MATRIX_CONF}, box IoU > {MATRIX_IOU}"),
    )
}
