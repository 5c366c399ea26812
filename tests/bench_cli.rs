//! `chicktrain bench models`, `bench ablation` and `sweep` end to end on tiny selections
//! (seconds each): the report files, their columns, resumption, and clean errors.

use std::process::Output;

mod common;
use common::{run, tmp};

fn ok(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "failed: {err}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Timing effort small enough for a test: no warm-up, 2 timed runs, 1 training step of 2.
const FAST_TIMING: [&str; 8] = [
    "--warmup",
    "0",
    "--repeats",
    "2",
    "--train-batch",
    "2",
    "--train-steps",
    "1",
];

fn assert_clean_error(out: &Output, needle: &str) {
    common::assert_clean_error(out, &[needle]);
}

#[test]
fn bench_models_quick_writes_table_and_plot() {
    let d = tmp("models");
    let out = d.join("report");
    let text = ok(&run(&[
        "bench",
        "models",
        "--quick",
        "--variants",
        "yolo-n-p45-w0.25-m4",
        "--sizes",
        "64",
        "--warmup",
        "0",
        "--repeats",
        "3",
        "--train-batch",
        "2",
        "--train-steps",
        "1",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]));
    assert!(text.contains("yolo-n-p45-w0.25-m4"), "{text}");
    let csv = std::fs::read_to_string(out.join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "{csv}");
    let header: Vec<&str> = lines[0].split(',').collect();
    assert_eq!(header, chicktrain::bench::report::COLUMNS);
    let row: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(row.len(), header.len());
    assert_eq!((row[0], row[1]), ("yolo-n-p45-w0.25-m4", "64"));
    for col in [
        "params_M",
        "GFLOPs",
        "latency_ms_median",
        "train_img_s",
        "train_peak_MiB",
    ] {
        let i = header.iter().position(|h| *h == col).unwrap();
        let v: f64 = row[i]
            .parse()
            .unwrap_or_else(|_| panic!("{col} = {:?}", row[i]));
        assert!(v > 0.0, "{col} = {v}");
    }
    // No checkpoints: the AP columns stay empty and no AP plots are written.
    let ap = header.iter().position(|h| *h == "segm_AP").unwrap();
    assert_eq!(row[ap], "");
    assert!(std::fs::read_to_string(out.join("bench.md"))
        .unwrap()
        .contains("| yolo-n-p45-w0.25-m4 | 64 |"));
    assert!(image::open(out.join("speed.png")).is_ok());
    assert!(!out.join("ap_vs_latency.png").exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bench_models_scores_only_the_given_checkpoint() {
    let d = tmp("models_ck");
    let run_dir = d.join("run");
    common::assert_success(&run(&common::smoke_args(&run_dir, &[])));
    let out = d.join("report");
    let ck = run_dir.join("best.bpk");
    let text = ok(&run(&[
        &["bench", "models", "--checkpoints", ck.to_str().unwrap()][..],
        &FAST_TIMING,
        &["--quiet", "--out", out.to_str().unwrap()],
    ]
    .concat()));
    // Checkpoints alone: one row, not the default variant × size grid.
    let csv = std::fs::read_to_string(out.join("bench.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 2, "{csv}\n{text}");
    let header: Vec<&str> = lines[0].split(',').collect();
    let row: Vec<&str> = lines[1].split(',').collect();
    let test: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("test.json")).unwrap()).unwrap();
    for kind in ["bbox", "segm"] {
        let ap: f64 = row[header
            .iter()
            .position(|h| *h == format!("{kind}_AP"))
            .unwrap()]
        .parse()
        .unwrap();
        let want = test[kind]["stats"][0].as_f64().unwrap();
        assert!(
            (ap - want).abs() < 5e-4,
            "{kind} AP {ap} vs test.json {want}"
        );
    }
    assert!(out.join("ap_vs_latency.png").exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bench_models_rejects_bad_variants_and_sizes() {
    assert_clean_error(&run(&["bench", "models", "--variants", "yolo-x"]), "yolo-x");
    assert_clean_error(&run(&["bench", "models", "--sizes", "100"]), "100");
    assert_clean_error(
        &run(&[
            "bench",
            "models",
            "--checkpoints",
            "/no/such/best.bpk",
            "--sizes",
            "64",
            "--variants",
            "yolo-n",
        ]),
        "/no/such/best.bpk",
    );
}

#[test]
fn ablation_times_untrained_variants_without_training() {
    let d = tmp("ablation");
    let text = ok(&run(&[
        &[
            "bench",
            "ablation",
            "--variants",
            "base,no_p3",
            "--set",
            "data.image_size=64",
            "--set",
            "data.crop=64",
            "--no-train",
        ][..],
        &FAST_TIMING,
        &["--quiet", "--out", d.to_str().unwrap()],
    ]
    .concat()));
    assert!(
        text.contains("| base | 64 |") && text.contains("| no_p3 | 64 |"),
        "{text}"
    );
    assert!(!d.join("base").exists(), "--no-train must not train");
    assert_clean_error(
        &run(&[
            "bench",
            "ablation",
            "--variants",
            "base,bogus",
            "--out",
            d.to_str().unwrap(),
        ]),
        "bogus",
    );
    assert_clean_error(
        &run(&[
            "bench",
            "ablation",
            "--train-only",
            "--no-train",
            "--out",
            d.to_str().unwrap(),
        ]),
        "exclude",
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn smoke_sweep_reports_two_settings_and_resumes() {
    let d = tmp("sweep");
    let out = d.join("sweep");
    let cache = format!("data.cache={:?}", d.join("cache").display().to_string());
    let args = [
        "sweep",
        "--config",
        "quickstart.toml",
        "--syn",
        "0,2",
        "--seeds",
        "1",
        "--smoke",
        "--set",
        &cache,
        "--out",
        out.to_str().unwrap(),
    ];
    let text = ok(&run(&[&args[..], &["--quiet"]].concat()));
    assert!(text.contains("| Real baseline | 1 |"), "{text}");
    assert!(text.contains("| Real + 2 syn | 1 |"), "{text}");
    for f in ["sweep.md", "sweep.csv", "runs.csv", "sweep.png"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    assert!(out.join("syn2_seed0/test.json").exists());
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    assert!(csv.starts_with("synthetic,runs,train_minutes,bbox_AP_mean,bbox_AP_std"));
    assert!(csv.lines().nth(2).unwrap().starts_with("2,1,"));
    // Rerun: both settings are read back, not retrained, and the report is the same.
    let again = run(&args);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{err}");
    assert_eq!(err.matches("done, reading it").count(), 2, "{err}");
    assert_eq!(std::fs::read_to_string(out.join("sweep.csv")).unwrap(), csv);
    // --no-train reports the finished runs and names the missing ones without training them.
    let partial = [
        &args[..4],
        &["4,2", "--seeds", "2", "--no-train", "--quiet"],
        &args[7..],
    ];
    let text = ok(&run(&partial.concat()));
    assert!(text.contains("| Real + 2 syn | 1 |"), "{text}");
    assert!(!text.contains("| Real + 4 syn"), "{text}");
    assert!(
        text.contains("syn2_seed1, syn4_seed0, syn4_seed1"),
        "{text}"
    );
    assert!(
        !out.join("syn4_seed0").exists(),
        "--no-train must not train"
    );
    assert_clean_error(
        &run(&[
            "sweep",
            "--config",
            "quickstart.toml",
            "--no-train",
            "--out",
            d.join("empty").to_str().unwrap(),
        ]),
        "no finished run",
    );
    // A setting valid only with synthetic images (train.real_fraction) is checked with each
    // count the sweep runs, not with the config's own data.synthetic.
    let mixed = |syn: &str, out: &str| {
        run(&[
            "sweep",
            "--config",
            "quickstart.toml",
            "--syn",
            syn,
            "--no-train",
            "--set",
            "data.synthetic=0",
            "--set",
            "train.real_fraction=0.5",
            "--out",
            d.join(out).to_str().unwrap(),
        ])
    };
    assert_clean_error(&mixed("2", "mixed"), "no finished run");
    let zero = mixed("2,0", "mixed0");
    common::assert_clean_error(&zero, &["--syn 0", "real_fraction"]);
    assert_clean_error(
        &run(&["sweep", "--config", "quickstart.toml", "--syn", "0,abc"]),
        "abc",
    );
    assert_clean_error(
        &run(&["sweep", "--config", "quickstart.toml", "--seeds", "0"]),
        "--seeds 0",
    );
    let _ = std::fs::remove_dir_all(&d);
}
