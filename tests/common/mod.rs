//! Helpers shared by the test crates: running the binary (here), the `--smoke` scenario
//! of the `train_*` tests ([`smoke`]), the one-batch scene of the `*_learns` tests
//! ([`overfit`]), the tiny Mask R-CNN of the model tests ([`tiny`]) and the JSON fixtures
//! ([`json`]).
#![allow(dead_code)] // each test crate uses its own subset

pub mod json;
pub mod overfit;
pub mod smoke;
pub mod tiny;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_chicktrain"))
}

/// A fresh, empty temp folder for test `name`.
pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ct-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn run<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Output {
    bin().args(args).output().unwrap()
}

/// `render` of one 64 px image of the carcass mesh `carcass` into `out` (the arguments).
pub fn render_one<'a>(carcass: &'a str, out: &'a str) -> [&'a str; 9] {
    [
        "render",
        "--count",
        "1",
        "--size",
        "64",
        "--carcass",
        carcass,
        "--out",
        out,
    ]
}

/// `chicktrain export --checkpoint CHECKPOINT --format FORMAT` and `extra` flags.
pub fn export(checkpoint: &str, format: &str, extra: &[&str]) -> Output {
    let mut args = vec!["export", "--checkpoint", checkpoint, "--format", format];
    args.extend_from_slice(extra);
    run(&args)
}

/// Fails unless the command exited 2 with an error naming every needle, and no panic.
pub fn assert_clean_error(out: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    for n in needles {
        assert!(err.contains(n), "{err:?} should mention {n:?}");
    }
}

pub fn assert_success(out: &Output) {
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `--config quickstart.toml --smoke` into `run_dir` (render cache beside it) plus `--set`s.
pub fn smoke_args(run_dir: &Path, sets: &[&str]) -> Vec<String> {
    let cache = run_dir.with_extension("cache");
    let mut a: Vec<String> = [
        "--config",
        "quickstart.toml",
        "--smoke",
        "--run-dir",
        run_dir.to_str().unwrap(),
        "--set",
        &format!("data.cache=\"{}\"", cache.display()),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for s in sets {
        a.push("--set".into());
        a.push(s.to_string());
    }
    a
}
