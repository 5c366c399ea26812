//! `export --format onnx` end to end through the binary: a `--smoke` YOLO checkpoint is
//! exported (static and dynamic batch, with the reference file), `predict --onnx` (tract)
//! gives the detections `predict --checkpoint` gives on the same images, and bad input
//! (a non-ONNX file, a missing checkpoint for either format, ONNX options with
//! safetensors) is a clean error. A `--smoke` Mask R-CNN exports its three graphs, which
//! tract runs to the reference file's outputs, and its torchvision-named safetensors.

mod common;

use std::path::{Path, PathBuf};

use chicktrain::annotations::rle::{rle_iou, Rle};
use common::{assert_clean_error, assert_success, export, run, smoke_args, tmp};
use serde_json::Value;

fn results(dir: &Path) -> Vec<Value> {
    serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap()
}

/// Two rendered 160 px piles in `d/imgs` as predict input: real piles, not blank frames.
fn render_inputs(d: &Path) -> PathBuf {
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
    imgs.join("images")
}

/// `predict` on `input` at `--conf conf` with the model given by `args`; its results.json.
fn predict(input: &Path, args: &[&str], conf: &str, out: &Path) -> Vec<Value> {
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
    assert_success(&run(&a));
    results(out)
}

/// A `--conf` between the first two of `dets`' scores more than 1e-3 apart. A smoke
/// model's many low, near-tied scores make NMS order a coin toss between engines that
/// differ by 1e-5, so the engines are compared above a clear gap in the checkpoint's own
/// scores.
fn conf_above_gap(dets: &[Value]) -> Option<String> {
    let mut scores: Vec<f64> = dets.iter().map(|r| r["score"].as_f64().unwrap()).collect();
    scores.sort_by(|a, b| b.total_cmp(a));
    let gap = scores.windows(2).find(|w| w[0] - w[1] > 1e-3)?;
    Some(format!("{}", (gap[0] + gap[1]) / 2.0))
}

/// The same detections in the same order: image, class, score within 1e-4, box within
/// 0.05 px.
fn assert_same_detections(a: &[Value], b: &[Value], conf: &str) {
    assert_eq!(a.len(), b.len(), "at --conf {conf}");
    for (a, b) in a.iter().zip(b) {
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
    }
}

#[test]
fn export_then_predict_with_tract_matches_checkpoint() {
    let d = tmp("onnx-export");
    let run_dir = d.join("run");
    assert_success(&run(&smoke_args(&run_dir, &[])));
    let best = run_dir.join("best.bpk");
    let best_s = best.to_str().unwrap();

    // Default output path: best.onnx beside best.bpk; the reference file beside it.
    let out = export(best_s, "onnx", &["--reference"]);
    assert_success(&out);
    let onnx = run_dir.join("best.onnx");
    assert!(onnx.is_file());
    let reference = run_dir.join("best.reference.safetensors");
    assert!(reference.is_file());
    let dynamic = d.join("dyn.onnx");
    assert_success(&export(
        best_s,
        "onnx",
        &["--dynamic", "--out", dynamic.to_str().unwrap()],
    ));

    let input = render_inputs(&d);
    let pred = |args: &[&str], conf: &str, out: &str| predict(&input, args, conf, &d.join(out));
    // (The postprocess equivalence itself is a unit test in model::yolo::onnx.)
    let all = pred(&["--checkpoint", best_s], "0.001", "p_all");
    let conf = conf_above_gap(&all).expect("the smoke model's scores have a gap above 1e-3");
    let by_ck = pred(&["--checkpoint", best_s], &conf, "p_ck");
    let by_onnx = pred(&["--onnx", onnx.to_str().unwrap()], &conf, "p_onnx");
    let by_dyn = pred(
        &["--onnx", dynamic.to_str().unwrap(), "--threads", "1"],
        &conf,
        "p_dyn",
    );
    assert!(!by_ck.is_empty());
    for other in [&by_onnx, &by_dyn] {
        assert_same_detections(&by_ck, other, &conf);
        // Masks: the same pixels, up to a few on the threshold (IoU > 0.99).
        for (a, b) in by_ck.iter().zip(other.iter()) {
            let rle = |r: &Value| {
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
    let images: Value =
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
    let out = export(missing.to_str().unwrap(), "onnx", &[]);
    assert_clean_error(&out, &["none.bpk"]);
    assert!(!d.join("none.onnx").exists());
    let out = export(missing.to_str().unwrap(), "safetensors", &[]);
    assert_clean_error(&out, &["none.bpk"]);
    assert!(!d.join("none.safetensors").exists());

    // ONNX-only options with safetensors: a clear error, no file.
    let out = export(missing.to_str().unwrap(), "safetensors", &["--dynamic"]);
    assert_clean_error(
        &out,
        &["--dynamic, --batch and --reference are ONNX options"],
    );
}

/// Mask R-CNN through the binary: `export --format onnx --reference` writes the three
/// graphs and the reference file, and tract runs each graph on the reference inputs to
/// chicktrain's outputs within 1e-4; `--format safetensors` writes torchvision's keys;
/// `predict --onnx` on the export gives `predict --checkpoint`'s detections.
#[test]
fn maskrcnn_exports_three_graphs_that_tract_runs_like_chicktrain() {
    use chicktrain::model::onnx::engine::TractEngine;
    use chicktrain::model::weights::{read_file, snapshot_data};

    let d = tmp("onnx-maskrcnn");
    let mr = d.join("mr");
    let mut a = smoke_args(&mr, &[]);
    a[1] = "maskrcnn_r50_syn250.toml".into();
    assert_success(&run(&a));
    let best = mr.join("best.bpk");
    let out = export(best.to_str().unwrap(), "onnx", &["--reference"]);
    assert_success(&out);
    let reference: std::collections::HashMap<String, (Vec<usize>, Vec<f32>)> =
        read_file(&mr.join("best.reference.safetensors"), &[])
            .unwrap()
            .into_iter()
            .map(|s| {
                let name = s.name.clone();
                let shape = s.shape.to_vec();
                let v = snapshot_data(s).unwrap().try_to_vec::<f32>().unwrap();
                (name, (shape, v))
            })
            .collect();
    let graphs = [
        ("best.onnx", "images"),
        ("best.box_head.onnx", "box_features"),
        ("best.mask_head.onnx", "mask_features"),
    ];
    let mut outputs = 0;
    for (file, input) in graphs {
        let eng = TractEngine::load(&mr.join(file), None).unwrap();
        let (shape, x) = &reference[input];
        let got = eng.run(shape, x).unwrap();
        let g = eng.proto.graph.as_ref().unwrap();
        assert_eq!(got.len(), g.output.len(), "{file}");
        for (o, t) in g.output.iter().zip(&got) {
            let (ws, w) = &reference[&o.name];
            assert_eq!(&t.shape, ws, "{file} {}: shape", o.name);
            let diff = t
                .data
                .iter()
                .zip(w)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            eprintln!("{file} {}: max |tract − chicktrain| = {diff:e}", o.name);
            assert!(diff <= 1e-4, "{file} {}: {diff}", o.name);
            outputs += 1;
        }
    }
    // p2…p6, 5 objectness and 5 delta maps; class logits and deltas; mask logits.
    assert_eq!(outputs, 18);

    let st = mr.join("best.safetensors");
    assert_success(&export(best.to_str().unwrap(), "safetensors", &[]));
    let keys: Vec<String> = read_file(&st, &[])
        .unwrap()
        .into_iter()
        .map(|s| s.name)
        .collect();
    for k in [
        "backbone.body.conv1.weight",
        "backbone.body.layer1.0.bn1.running_var",
        "backbone.fpn.inner_blocks.0.0.weight",
        "rpn.head.conv.0.0.weight",
        "roi_heads.box_head.fc6.weight",
        "roi_heads.box_predictor.cls_score.weight",
        "roi_heads.mask_head.0.0.weight",
        "roi_heads.mask_predictor.mask_fcn_logits.weight",
    ] {
        assert!(keys.iter().any(|x| x == k), "{k} missing");
    }

    // predict --onnx: the graphs through tract, chicktrain's postprocess between them;
    // the same detections as predict --checkpoint above a clear gap in the scores (as
    // for YOLO: near-tied low scores make NMS order a coin toss between engines).
    let input = render_inputs(&d);
    let pred = |args: &[&str], conf: &str, out: &str| predict(&input, args, conf, &d.join(out));
    let best_s = best.to_str().unwrap();
    let onnx = mr.join("best.onnx");
    let all = pred(&["--checkpoint", best_s], "0.05", "p_all");
    let conf = conf_above_gap(&all).unwrap_or_else(|| "0.05".to_string());
    let by_ck = pred(&["--checkpoint", best_s], &conf, "p_ck");
    let by_onnx = pred(&["--onnx", onnx.to_str().unwrap()], &conf, "p_onnx");
    eprintln!(
        "Mask R-CNN predict at --conf {conf}: {} detections by the checkpoint, {} by the ONNX graphs",
        by_ck.len(),
        by_onnx.len()
    );
    assert_same_detections(&by_ck, &by_onnx, &conf);
}
