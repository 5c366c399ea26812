//! The curve data of a run's PR and F1 plots against pycocotools 2.0.11 on a committed
//! fixture (`tests/fixtures/curves/make_fixture.py` wrote `expected.json` from
//! `gt.json` + `dt.json`): precision at the 101 recall thresholds at IoU 0.5 and the score
//! each is read at (`cocoEval.eval['precision' | 'scores'][0, :, k, 0, 2]`), per
//! category, bbox and segm, within 1e-6.

use std::path::PathBuf;

use chicktrain::annotations::coco::{load_results, CocoDataset};
use chicktrain::eval::curves::{conf_curve, pr_at_50};
use chicktrain::eval::{evaluate, IouType};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/curves")
        .join(name)
}

#[test]
fn pr_points_and_their_scores_match_pycocotools() {
    let gt = CocoDataset::load(&fixture("gt.json")).unwrap();
    let dt = load_results(&fixture("dt.json")).unwrap();
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    let mut compared = 0;
    for (key, iou_type) in [("bbox", IouType::Bbox), ("segm", IouType::Segm)] {
        let res = evaluate(&gt, &dt, iou_type).unwrap();
        let e = &expected[key];
        let cats: Vec<u64> = serde_json::from_value(e["cat_ids"].clone()).unwrap();
        assert_eq!(res.cat_ids, cats);
        let nr = res.rec_thrs.len();
        let (nk, na, nm) = (cats.len(), 4, 3);
        for k in 0..nk {
            let p: Vec<f64> = serde_json::from_value(e["precision"][k].clone()).unwrap();
            let s: Vec<f64> = serde_json::from_value(e["scores"][k].clone()).unwrap();
            assert_eq!(p.len(), nr);
            let ours = pr_at_50(&res, k).expect("both categories have GT");
            for r in 0..nr {
                let (rec, prec) = ours[r];
                let thr = e["rec_thrs"][r].as_f64().unwrap();
                assert!((rec - thr).abs() < 1e-12);
                assert!(
                    (prec - p[r]).abs() < 1e-6,
                    "{key} cat {k} r {r}: {prec} vs {}",
                    p[r]
                );
                let score = res.scores[((r * nk + k) * na) * nm + nm - 1];
                assert!(
                    (score - s[r]).abs() < 1e-6,
                    "{key} cat {k} r {r}: score {score} vs {}",
                    s[r]
                );
                compared += 1;
            }
            // The ranked points the F1 curve reads are the ones the precision came from:
            // scores non-increasing, recall non-decreasing up to pycocotools' last recall.
            let ranked = res.ranked[k].as_ref().unwrap();
            assert!(ranked.scores.windows(2).all(|w| w[0] >= w[1]));
            assert!(ranked.recall.windows(2).all(|w| w[0] <= w[1]));
            let c = conf_curve(ranked);
            assert!(c.f1.iter().all(|v| (0.0..=1.0).contains(v)));
        }
        // Not a vacuous fixture: some precision is neither 0 nor 1, and it falls.
        let p0: Vec<f64> = serde_json::from_value(e["precision"][0].clone()).unwrap();
        assert!(p0.iter().any(|&v| v > 0.0 && v < 1.0) && p0[0] > p0[nr - 1]);
    }
    assert_eq!(compared, 2 * 2 * 101);
}

/// The four curve PNGs and the confusion matrix of the fixture: written, decodable, at
/// their sizes, and not blank (the curves' pixels are not all background).
#[test]
fn curve_and_matrix_pngs_of_the_fixture() {
    use chicktrain::eval::confusion::{ConfusionMatrix, MATRIX_CONF, MATRIX_IOU};
    let gt = CocoDataset::load(&fixture("gt.json")).unwrap();
    let dt = load_results(&fixture("dt.json")).unwrap();
    let dir = std::env::temp_dir().join(format!("ct-curves-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bbox = evaluate(&gt, &dt, IouType::Bbox).unwrap();
    let segm = evaluate(&gt, &dt, IouType::Segm).unwrap();
    let names = vec!["carcass".to_string(), "wing".to_string()];
    chicktrain::eval::curves::write_curves(&dir, &bbox, &segm, &names).unwrap();
    let cm = ConfusionMatrix::count(&gt, &dt, MATRIX_CONF, MATRIX_IOU);
    // Every non-crowd GT lands in exactly one cell of its column.
    let non_crowd = gt.annotations.iter().filter(|a| a.iscrowd == 0).count() as u64;
    let per_true: u64 = (0..2)
        .map(|j| (0..3).map(|i| cm.m[i][j]).sum::<u64>())
        .sum();
    assert_eq!(per_true, non_crowd);
    cm.write_png(&dir.join("confusion_matrix.png"), "fixture")
        .unwrap();
    for f in [
        "BoxPR_curve.png",
        "MaskPR_curve.png",
        "BoxF1_curve.png",
        "MaskF1_curve.png",
        "confusion_matrix.png",
    ] {
        let img = image::open(dir.join(f)).unwrap().to_rgb8();
        let coloured = img
            .pixels()
            .filter(|p| !(p.0[0] == p.0[1] && p.0[1] == p.0[2]))
            .count();
        assert!(coloured > 500, "{f}: {coloured} coloured pixels");
    }
    if std::env::var_os("KEEP_CURVES").is_none() {
        std::fs::remove_dir_all(&dir).unwrap();
    } else {
        eprintln!("curves kept in {}", dir.display());
    }
}
