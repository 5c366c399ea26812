//! The binary end to end: commands, exit codes and bad-input messages (never a panic).

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{assert_clean_error, bin, run, tmp};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/coco")
}

#[test]
fn coco_eval_json_prints_the_12_stats() {
    let gt = fixtures().join("cases/02_gt.json");
    let dt = fixtures().join("cases/02_dt.json");
    let out = run(&[
        "coco-eval",
        "--gt",
        gt.to_str().unwrap(),
        "--dt",
        dt.to_str().unwrap(),
        "--iou-type",
        "segm",
        "--json",
    ]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixtures().join("expected.json")).unwrap())
            .unwrap();
    assert_eq!(v["stats"], expected["02"]["segm"]);
    let text = run(&[
        "coco-eval",
        "--gt",
        gt.to_str().unwrap(),
        "--dt",
        dt.to_str().unwrap(),
        "--iou-type",
        "bbox",
    ]);
    let s = String::from_utf8_lossy(&text.stdout);
    assert_eq!(s.lines().count(), 12);
    assert!(
        s.starts_with(" Average Precision  (AP) @[ IoU=0.50:0.95 | area=   all | maxDets=100 ] = ")
    );
}

#[test]
fn bench_help_names_every_bench_subcommand() {
    let out = run(&["bench", "--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in [
        "models", "engines", "ablation", "transfer", "render", "loader", "coco",
    ] {
        assert!(
            text.contains(&format!("`bench {sub}`")),
            "summary omits {sub}: {text}"
        );
    }
}

#[test]
fn every_subcommand_has_help() {
    for sub in [
        "train",
        "eval",
        "predict",
        "export",
        "render",
        "bench",
        "coco-eval",
        "convert",
        "export",
    ] {
        let out = run(&[sub, "--help"]);
        assert!(out.status.success(), "{sub} --help");
        assert!(!out.stdout.is_empty());
    }
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_string_lossy().into_owned()
}

#[test]
fn bad_coco_inputs_name_the_file_and_entry() {
    let d = tmp("coco");
    let good_gt = std::fs::read_to_string(fixtures().join("cases/01_gt.json")).unwrap();
    let gt = write(&d, "gt.json", &good_gt);
    let dt_ok = r#"[{"image_id": 10, "category_id": 1, "score": 0.5, "bbox": [1, 2, 3, 4]}]"#;
    let cases: Vec<(&str, String, String, Vec<&str>)> = vec![
        ("missing gt", d.join("nope.json").to_string_lossy().into(), dt_ok.into(), vec!["nope.json", "cannot read"]),
        ("truncated gt", write(&d, "t.json", &good_gt[..good_gt.len() / 2]), dt_ok.into(), vec!["t.json", "invalid COCO JSON"]),
        ("gt not an object", write(&d, "arr.json", "[1, 2]"), dt_ok.into(), vec!["arr.json"]),
        ("unknown image in results", gt.clone(), r#"[{"image_id": 999, "category_id": 1, "score": 0.5, "bbox": [1, 2, 3, 4]}]"#.into(), vec!["image_id 999", "not in the ground truth"]),
        ("broken results json", gt.clone(), "[{".into(), vec!["dt.json", "invalid COCO results JSON"]),
        ("results wrong type", gt.clone(), r#"[{"image_id": "ten", "category_id": 1, "score": 0.5}]"#.into(), vec!["dt.json"]),
        ("rle of the wrong size", gt.clone(), r#"[{"image_id": 10, "category_id": 1, "score": 0.5, "segmentation": {"size": [4, 4], "counts": "52203"}}]"#.into(), vec!["detection 0", "disagrees"]),
        ("bad rle string", gt.clone(), r#"[{"image_id": 10, "category_id": 1, "score": 0.5, "segmentation": {"size": [96, 128], "counts": "5 2"}}]"#.into(), vec!["detection 0", "outside the COCO alphabet"]),
        ("polygon of two points", gt.clone(), r#"[{"image_id": 10, "category_id": 1, "score": 0.5, "segmentation": [[1, 1, 5, 5]]}]"#.into(), vec!["detection 0", "at least 3 points"]),
        ("later detection without bbox", gt.clone(), r#"[{"image_id": 10, "category_id": 1, "score": 0.5, "bbox": [1, 2, 3, 4]}, {"image_id": 10, "category_id": 1, "score": 0.4}]"#.into(), vec!["detection 1 has no bbox"]),
    ];
    for (what, gt_path, dt_text, needles) in cases {
        let dt = write(&d, "dt.json", &dt_text);
        let out = run(&[
            "coco-eval",
            "--gt",
            &gt_path,
            "--dt",
            &dt,
            "--iou-type",
            "segm",
        ]);
        eprintln!("case: {what}");
        assert_clean_error(&out, &needles);
    }
    // GT-side problems, made by editing the parsed file
    let edits: Vec<(&str, fn(&mut serde_json::Value), &str)> = vec![
        (
            "unknown category",
            |v| v["annotations"][0]["category_id"] = 42.into(),
            "category_id 42",
        ),
        (
            "negative box",
            |v| v["annotations"][0]["bbox"] = serde_json::json!([1, 1, -5, 3]),
            "negative",
        ),
        (
            "duplicate annotation id",
            |v| {
                let first = v["annotations"][0]["id"].clone();
                v["annotations"][1]["id"] = first;
            },
            "appears twice",
        ),
        (
            "string iscrowd",
            |v| v["annotations"][0]["iscrowd"] = "no".into(),
            "iscrowd",
        ),
        (
            "missing area",
            |v| {
                v["annotations"][0].as_object_mut().unwrap().remove("area");
            },
            "missing field `area`",
        ),
    ];
    for (what, edit, needle) in edits {
        let mut v: serde_json::Value = serde_json::from_str(&good_gt).unwrap();
        edit(&mut v);
        let g = write(&d, "gt_bad.json", &v.to_string());
        let dt = write(&d, "dt.json", dt_ok);
        eprintln!("case: {what}");
        assert_clean_error(
            &run(&["coco-eval", "--gt", &g, "--dt", &dt]),
            &["gt_bad.json", needle],
        );
    }
    // extra fields are fine: real COCO files carry them
    let mut v: serde_json::Value = serde_json::from_str(&good_gt).unwrap();
    v["images"][0]["coco_url"] = "http://x".into();
    v["annotations"][0]["attributes"] = serde_json::json!({"occluded": false});
    let g = write(&d, "gt_extra.json", &v.to_string());
    let dt = write(&d, "dt.json", dt_ok);
    assert!(run(&["coco-eval", "--gt", &g, "--dt", &dt])
        .status
        .success());
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn config_typos_and_bad_values_exit_2_with_the_key() {
    let d = tmp("cfg");
    let base = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("configs/quickstart.toml"),
    )
    .unwrap();
    // The key at the start of its line, not a comment that mentions it.
    let typoed = base.replacen("\nepochs = ", "\nepoch = ", 1);
    assert_ne!(typoed, base, "quickstart.toml has no `epochs = ` line");
    let typo = write(&d, "typo.toml", &typoed);
    assert_clean_error(
        &run(&["--config", &typo]),
        &["typo.toml", "unknown field `epoch`"],
    );
    assert_clean_error(
        &run(&["--config", "no_such_config.toml"]),
        &["no_such_config.toml", "quickstart.toml"],
    );
    assert_clean_error(
        &run(&["--config", "quickstart.toml", "--set", "train.batch=0"]),
        &["train.batch"],
    );
    assert_clean_error(
        &run(&[
            "train",
            "--config",
            "quickstart",
            "--set",
            "data.real.kind=\"coco\"",
        ]),
        &["data.real.annotations"],
    );
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn coco2yolo_writes_normalised_polygons() {
    let d = tmp("yolo");
    let gt = write(
        &d,
        "gt.json",
        r#"{"images": [{"id": 1, "file_name": "imgs/a.jpg", "width": 100, "height": 50}],
            "categories": [{"id": 3, "name": "carcass"}],
            "annotations": [
              {"id": 1, "image_id": 1, "category_id": 3, "segmentation": [[10, 10, 60, 10, 60, 40]], "area": 750, "bbox": [10, 10, 50, 30], "iscrowd": 0},
              {"id": 2, "image_id": 1, "category_id": 3, "segmentation": {"size": [50, 100], "counts": [0, 50, 4950]}, "area": 50, "bbox": [0, 0, 1, 50], "iscrowd": 1}
            ]}"#,
    );
    let out = run(&[
        "convert",
        "coco2yolo",
        &gt,
        "--out",
        d.join("y").to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let txt = std::fs::read_to_string(d.join("y/labels/a.txt")).unwrap();
    assert_eq!(txt, "0 0.1 0.2 0.6 0.2 0.6 0.8\n");
    assert!(std::fs::read_to_string(d.join("y/data.yaml"))
        .unwrap()
        .contains("0: carcass"));
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn render_writes_a_loadable_deterministic_dataset() {
    let d = tmp("render");
    let mut outs = Vec::new();
    for run_name in ["a", "b"] {
        let out = d.join(run_name);
        let o = run(&[
            "render",
            "--count",
            "2",
            "--seed",
            "5",
            "--size",
            "96",
            "--preset",
            "proxy-real",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(String::from_utf8_lossy(&o.stdout).contains("proxy"));
        let ds = chicktrain::annotations::coco::CocoDataset::load(&out.join("annotations.json"))
            .unwrap();
        assert_eq!(ds.images.len(), 2);
        assert!(out.join("preview.png").exists());
        outs.push(out);
    }
    for f in ["annotations.json", "images/000000.jpg", "images/000001.jpg"] {
        assert_eq!(
            std::fs::read(outs[0].join(f)).unwrap(),
            std::fs::read(outs[1].join(f)).unwrap(),
            "{f}"
        );
    }
    let bad = run(&[
        "render",
        "--count",
        "1",
        "--preset",
        "blender",
        "--out",
        d.join("c").to_str().unwrap(),
    ]);
    assert_clean_error(&bad, &["blender"]);
    let glb = write(&d, "broken.glb", "glTF not really");
    let bad = run(&common::render_one(&glb, d.join("c").to_str().unwrap()));
    assert_clean_error(&bad, &["broken.glb"]);
    std::fs::remove_dir_all(&d).unwrap();
}

/// ultralytics' `convert_coco` wrote `tests/fixtures/yolo_export/expected/` from the same
/// COCO file (`make_fixture.py`): multi-part instances, a crowd, a zero-width box.
#[test]
fn coco2yolo_matches_ultralytics_byte_for_byte() {
    let fx = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/yolo_export");
    let d = tmp("yolo-ul");
    let out = run(&[
        "convert",
        "coco2yolo",
        fx.join("coco.json").to_str().unwrap(),
        "--out",
        d.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut n = 0;
    for e in std::fs::read_dir(fx.join("expected")).unwrap() {
        let e = e.unwrap();
        let want = std::fs::read_to_string(e.path()).unwrap();
        let got = std::fs::read_to_string(d.join("labels").join(e.file_name())).unwrap();
        assert_eq!(got, want, "{:?}", e.file_name());
        n += 1;
    }
    assert_eq!(n, 6);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn train_eval_predict_bad_inputs_exit_2_naming_the_file() {
    let d = tmp("trainbad");
    let gt = write(
        &d,
        "gt.json",
        r#"{"images": [{"id": 1, "file_name": "a.jpg", "width": 64, "height": 64},
                       {"id": 2, "file_name": "b.jpg", "width": 64, "height": 64},
                       {"id": 3, "file_name": "c.jpg", "width": 64, "height": 64}],
            "categories": [{"id": 1, "name": "carcass"}],
            "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "segmentation": [[10, 10, 40, 10, 40, 40]], "area": 450, "bbox": [10, 10, 30, 30], "iscrowd": 0}]}"#,
    );
    let cfg = write(
        &d,
        "coco.toml",
        &format!(
            "name = \"bad\"\n[data]\nreal = {{ kind = \"coco\", annotations = {gt:?} }}\nsplit = [0.34, 0.33]\nimage_size = 64\ncrop = 64\n[train]\nepochs = 1\nbatch = 2\n"
        ),
    );
    let run_dir = d.join("run");
    let rd = run_dir.to_str().unwrap();
    // a.jpg is missing.
    assert_clean_error(
        &run(&["--config", &cfg, "--run-dir", rd]),
        &["a.jpg", "does not exist"],
    );
    // All present, but b.jpg is not an image.
    image::RgbImage::new(64, 64).save(d.join("a.jpg")).unwrap();
    image::RgbImage::new(64, 64).save(d.join("c.jpg")).unwrap();
    std::fs::write(d.join("b.jpg"), b"garbage").unwrap();
    assert_clean_error(
        &run(&[
            "train",
            "--config",
            &cfg,
            "--run-dir",
            rd,
            "--set",
            "train.fliplr=0",
        ]),
        &["b.jpg", "decode"],
    );
    assert_clean_error(
        &run(&["eval", "--checkpoint", d.join("none.bpk").to_str().unwrap()]),
        &["none.bpk", "does not exist"],
    );
    let junk = write(&d, "junk.bpk", "not a checkpoint");
    assert_clean_error(
        &run(&["eval", "--checkpoint", &junk]),
        &["junk.bpk", "not a chicktrain checkpoint"],
    );
    assert_clean_error(
        &run(&[
            "predict",
            "--checkpoint",
            &junk,
            "--input",
            ".",
            "--out",
            rd,
        ]),
        &["junk.bpk"],
    );
    let fresh = d.join("fresh");
    assert_clean_error(
        &run(&[
            "--config",
            &cfg,
            "--run-dir",
            fresh.to_str().unwrap(),
            "--resume",
        ]),
        &["last.bpk", "nothing to resume"],
    );
    std::fs::remove_dir_all(&d).unwrap();
}

/// Issue 39: a second run of a config never overwrites `runs/<name>`: it goes to
/// `runs/<name>-2`, then `-3`; `--exist-ok` reuses `runs/<name>`; `--resume` continues
/// the named folder. (The image is missing, so each run stops after claiming its
/// folder and writing config.toml.)
#[test]
fn runs_are_never_overwritten_but_incremented() {
    let d = tmp("increment");
    let gt = write(
        &d,
        "gt.json",
        r#"{"images": [{"id": 1, "file_name": "gone.jpg", "width": 64, "height": 64}],
            "categories": [{"id": 1, "name": "carcass"}], "annotations": []}"#,
    );
    let cfg = write(
        &d,
        "inc.toml",
        &format!("name = \"inc\"\n[data]\nreal = {{ kind = \"coco\", annotations = {gt:?} }}\n"),
    );
    let in_d = |extra: &[&str]| {
        let out = bin()
            .current_dir(&d)
            .args(["train", "--config", &cfg])
            .args(extra)
            .output()
            .unwrap();
        assert_clean_error(&out, &[]);
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let runs = d.join("runs");
    let listing = || {
        let mut v: Vec<String> = std::fs::read_dir(&runs)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    in_d(&[]);
    assert_eq!(listing(), ["inc"]);
    in_d(&[]);
    in_d(&[]);
    assert_eq!(listing(), ["inc", "inc-2", "inc-3"]);
    assert!(runs.join("inc-3/config.toml").is_file());
    in_d(&["--exist-ok"]);
    assert_eq!(
        listing(),
        ["inc", "inc-2", "inc-3"],
        "--exist-ok reuses runs/inc"
    );
    let e = in_d(&["--resume"]);
    assert!(
        e.contains("last.bpk") && e.contains("nothing to resume"),
        "{e}"
    );
    assert!(
        e.contains(&format!(
            "runs{}inc{}",
            std::path::MAIN_SEPARATOR,
            std::path::MAIN_SEPARATOR
        )),
        "{e}"
    );
    assert_eq!(
        listing(),
        ["inc", "inc-2", "inc-3"],
        "--resume names runs/inc"
    );
    std::fs::remove_dir_all(&d).unwrap();
}

/// Ctrl-C during training writes last.bpk and exits 2 saying how to resume; --resume
/// then continues from it.
#[cfg(unix)]
#[test]
fn ctrl_c_saves_last_checkpoint_and_resume_continues() {
    let d = tmp("sigint");
    let run_dir = d.join("run");
    let cache = format!("data.cache=\"{}\"", d.join("cache").display());
    let args = |epochs: &str| -> Vec<String> {
        [
            "--config",
            "quickstart.toml",
            "--run-dir",
            run_dir.to_str().unwrap(),
            "--set",
            &cache,
            "--set",
            "data.image_size=64",
            "--set",
            "data.crop=64",
            "--set",
            "data.real.count=9",
            "--set",
            "data.synthetic=4",
            "--set",
            "train.batch=2",
            "--set",
            epochs,
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let child = bin()
        .args(args("train.epochs=1000"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the first epoch is logged: the loop (and its handler) is running.
    let t0 = std::time::Instant::now();
    while !run_dir.join("metrics.jsonl").exists() {
        assert!(
            t0.elapsed().as_secs() < 120,
            "training never reached epoch 1"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let ok = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
    let out = child.wait_with_output().unwrap();
    assert_clean_error(&out, &["interrupted", "last.bpk", "--resume"]);
    assert!(run_dir.join("last.bpk").is_file());
    // Resume to a short end and finish normally.
    let done = std::fs::read_to_string(run_dir.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .count();
    let mut a = args(&format!("train.epochs={}", done + 1));
    a.push("--resume".into());
    a.push("--quiet".into());
    let out = bin().args(&a).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // --quiet: nothing on stderr (no progress, no per-epoch lines), the summary on stdout.
    assert_eq!(String::from_utf8_lossy(&out.stderr), "");
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(
        summary.contains("trained") && summary.contains("\nARl "),
        "{summary}"
    );
    let lines = std::fs::read_to_string(run_dir.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(lines, done + 1);
    assert!(run_dir.join("test.json").is_file());
    predict_flags_cap_and_save_txt(&run_dir.join("best.bpk"), &d);
    std::fs::remove_dir_all(&d).unwrap();
}

/// `predict --conf 0 --max-det 1 --save-txt` keeps one detection per image and writes
/// its polygon as `class x1 y1 … conf`, normalised, with the score of results.json;
/// `eval --save-json` writes the scored detections.
fn predict_flags_cap_and_save_txt(best: &Path, d: &Path) {
    let imgs = d.join("imgs");
    std::fs::create_dir_all(&imgs).unwrap();
    let img = image::RgbImage::from_fn(96, 64, |x, y| {
        image::Rgb([(x * 2) as u8, (y * 3) as u8, 120])
    });
    img.save(imgs.join("pic.png")).unwrap();
    let out = d.join("pred");
    let o = run(&[
        "predict",
        "--checkpoint",
        best.to_str().unwrap(),
        "--input",
        imgs.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--conf",
        "0",
        "--iou",
        "0.5",
        "--max-det",
        "1",
        "--save-txt",
    ]);
    common::assert_success(&o);
    let dets = chicktrain::annotations::coco::load_results(&out.join("results.json")).unwrap();
    assert_eq!(dets.len(), 1, "--max-det 1 with --conf 0 keeps exactly one");
    let area = dets[0]
        .segmentation
        .as_ref()
        .unwrap()
        .to_rle(64, 96)
        .unwrap()
        .area();
    let txt = std::fs::read_to_string(out.join("labels/pic.txt")).unwrap_or_default();
    if area > 0 {
        let f: Vec<&str> = txt.split_whitespace().collect();
        assert_eq!(txt.lines().count(), 1, "{txt}");
        assert_eq!(f[0], "0");
        assert!(
            f.len() >= 8 && f.len() % 2 == 0,
            "class, ≥ 3 points, conf: {txt}"
        );
        let conf: f64 = f[f.len() - 1].parse().unwrap();
        assert!(
            (conf - dets[0].score).abs() < 1e-5 * dets[0].score.max(1e-3),
            "{txt}"
        );
        for v in &f[1..f.len() - 1] {
            let v: f64 = v.parse().unwrap();
            assert!((0.0..=1.0).contains(&v), "{txt}");
        }
    }
    for (flag, bad) in [("--iou", "7"), ("--conf", "1.5")] {
        let o = run(&[
            "predict",
            "--checkpoint",
            best.to_str().unwrap(),
            "--input",
            imgs.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            flag,
            bad,
        ]);
        assert_clean_error(&o, &[flag, "[0, 1]"]);
    }
    let saved = d.join("dets.json");
    let o = run(&[
        "eval",
        "--checkpoint",
        best.to_str().unwrap(),
        "--split",
        "test",
        "--save-json",
        saved.to_str().unwrap(),
    ]);
    common::assert_success(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    let dets = chicktrain::annotations::coco::load_results(&saved).unwrap();
    assert!(
        text.contains(&format!("{} detections written to", dets.len())),
        "{text}"
    );
}
