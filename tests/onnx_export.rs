//! `export --format onnx` end to end through the binary: a `--smoke` YOLO checkpoint is
//! exported (static and dynamic batch, with the reference file), `predict --onnx` (tract)
//! gives the detections `predict --checkpoint` gives on the same images, and bad input
//! (a Mask R-CNN checkpoint, a non-ONNX file, a missing checkpoint for either format) is a clean error.

mod common;

use std::path::Path;

use chicktrain::annotations::rle::{rle_iou, Rle};
use common::{assert_clean_error, assert_success, run, smoke_args, tmp};

fn results(dir: &Path) -> Vec<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap()
}

#[test]
fn export_then_predict_with_tract_matches_checkpoint() {
    let d = tmp("onnx-export");
    let run_dir = d.join("run");
    assert_success(&run(&smoke_args(&run_dir, &[])));
    let best = run_dir.join("best.bpk");
    let best_s = best.to_str().unwrap();

    // Default output path: best.onnx beside best.bpk; the reference file beside it.
    let out = run(&[
        "export",
        "--checkpoint",
        best_s,
        "--format",
        "onnx",
        "--reference",
    ]);
    assert_success(&out);
    let onnx = run_dir.join("best.onnx");
    assert!(onnx.is_file());
    let reference = run_dir.join("best.reference.safetensors");
    assert!(reference.is_file());
    let dynamic = d.join("dyn.onnx");
    assert_success(&run(&[
        "export",
        "--checkpoint",
        best_s,
        "--format",
        "onnx",
        "--dynamic",
        "--out",
        dynamic.to_str().unwrap(),
    ]));

    // Rendered images of the smoke run's cache as input: real piles, not blank frames.
    let imgs = d.join("imgs");
    assert_success(&run(&[
        "render",
        "--out",
        imgs.to_str().unwrap(),
        "--count",
        "2",
        "--size",
        "160",
    ]));
    let input = imgs.join("images");
    let pred = |args: &[&str], conf: &str, out: &Path| {
        let mut a = vec![
            "predict",
            "--input",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--conf",
            conf,
        ];
        a.extend_from_slice(args);
        let o = run(&a);
        assert_success(&o);
        results(out)
    };
    // A smoke model's many low, near-tied scores make NMS order a coin toss between
    // engines that differ by 1e-5, so compare above a clear gap in the checkpoint's
    // own scores (the postprocess equivalence itself is a unit test in model::yolo::onnx).
    let all = pred(&["--checkpoint", best_s], "0.001", &d.join("p_all"));
    let mut scores: Vec<f64> = all.iter().map(|r| r["score"].as_f64().unwrap()).collect();
    scores.sort_by(|a, b| b.total_cmp(a));
    let gap = scores
        .windows(2)
        .find(|w| w[0] - w[1] > 1e-3)
        .expect("the smoke model's scores have a gap above 1e-3");
    let conf = format!("{}", (gap[0] + gap[1]) / 2.0);
    let by_ck = pred(&["--checkpoint", best_s], &conf, &d.join("p_ck"));
    let by_onnx = pred(
        &["--onnx", onnx.to_str().unwrap()],
        &conf,
        &d.join("p_onnx"),
    );
    let by_dyn = pred(
        &["--onnx", dynamic.to_str().unwrap(), "--threads", "1"],
        &conf,
        &d.join("p_dyn"),
    );
    assert!(!by_ck.is_empty());
    for other in [&by_onnx, &by_dyn] {
        assert_eq!(by_ck.len(), other.len(), "at --conf {conf}");
        for (a, b) in by_ck.iter().zip(other.iter()) {
            assert_eq!(a["image_id"], b["image_id"]);
            assert_eq!(a["category_id"], b["category_id"]);
            let (sa, sb) = (a["score"].as_f64().unwrap(), b["score"].as_f64().unwrap());
            assert!((sa - sb).abs() < 1e-4, "score {sa} vs {sb}");
            for k in 0..4 {
                let (u, v) = (
                    a["bbox"][k].as_f64().unwrap(),
                    b["bbox"][k].as_f64().unwrap(),
                );
                assert!((u - v).abs() < 0.05, "bbox {} vs {}", a["bbox"], b["bbox"]);
            }
            // Masks: the same pixels, up to a few on the threshold (IoU > 0.99).
            let rle = |r: &serde_json::Value| {
                let h = r["segmentation"]["size"][0].as_u64().unwrap() as u32;
                let w = r["segmentation"]["size"][1].as_u64().unwrap() as u32;
                Rle::from_compressed(r["segmentation"]["counts"].as_str().unwrap(), h, w).unwrap()
            };
            let (ra, rb) = (rle(a), rle(b));
            let bb = [0.0, 0.0, 1.0, 1.0];
            let iou = rle_iou(&ra, &bb, &rb, &bb, false);
            assert!(
                ra.area() == 0 && rb.area() == 0 || iou > 0.99,
                "mask IoU {iou}"
            );
        }
    }
    let images: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("p_onnx/images.json")).unwrap())
            .unwrap();
    assert_eq!(images["categories"][0]["name"], "carcass");
}

#[test]
fn export_errors_are_clean() {
    let d = tmp("onnx-errors");
    let junk = d.join("junk.onnx");
    std::fs::write(&junk, b"not a protobuf at all \xff\xff\xff").unwrap();
    let img = d.join("a.png");
    image::RgbImage::new(8, 8).save(&img).unwrap();
    let out = run(&[
        "predict",
        "--onnx",
        junk.to_str().unwrap(),
        "--input",
        img.to_str().unwrap(),
        "--out",
        d.join("p").to_str().unwrap(),
    ]);
    assert_clean_error(&out, &["junk.onnx"]);
    let missing = d.join("none.bpk");
    let out = run(&[
        "export",
        "--checkpoint",
        missing.to_str().unwrap(),
        "--format",
        "onnx",
    ]);
    assert_clean_error(&out, &["none.bpk"]);
    assert!(!d.join("none.onnx").exists());
    let out = run(&[
        "export",
        "--checkpoint",
        missing.to_str().unwrap(),
        "--format",
        "safetensors",
    ]);
    assert_clean_error(&out, &["none.bpk"]);
    assert!(!d.join("none.safetensors").exists());

    // Mask R-CNN: a clear "not yet", no file written.
    let mr = d.join("mr");
    let mut a = smoke_args(&mr, &[]);
    a[1] = "maskrcnn_r50_syn250.toml".into();
    assert_success(&run(&a));
    let out = run(&[
        "export",
        "--checkpoint",
        mr.join("best.bpk").to_str().unwrap(),
        "--format",
        "onnx",
    ]);
    assert_clean_error(&out, &["Mask R-CNN is not implemented yet"]);
    assert!(!mr.join("best.onnx").exists());
}
