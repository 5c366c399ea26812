//! One fresh process per measured row: [`measure_in_child`] runs this same binary as
//! `bench model-worker` (hidden) and parses the one JSON [`Measurement`] line it prints;
//! [`worker`] is that child's side. A fresh process keeps one variant's peak-memory
//! high-water mark (`VmHWM`) from including another's, and allocator state from carrying
//! over between rows.

use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::config::DeviceKind;
use crate::infer::device::device_of;

use super::measure::{measure, Effort, Measurement};
use super::variant::Variant;

/// This binary, which runs the per-row worker processes.
pub fn this_exe() -> Result<std::path::PathBuf> {
    std::env::current_exe().map_err(|e| anyhow::anyhow!("cannot locate this binary: {e}"))
}

/// `bench model-worker`: measures one (variant, size) and returns its JSON line.
pub fn worker(variant: &str, size: usize, e: Effort, device: DeviceKind) -> Result<String> {
    let v: Variant = variant.parse()?;
    let m = measure(&v, size, e, &device_of(device)?)?;
    Ok(serde_json::to_string(&m)?)
}

/// The worker's command-line flags for `e`.
fn effort_args(e: Effort) -> Vec<String> {
    vec![
        "--warmup".into(),
        e.warmup.to_string(),
        "--repeats".into(),
        e.repeats.to_string(),
        "--train-batch".into(),
        e.train_batch.to_string(),
        "--train-steps".into(),
        e.train_steps.to_string(),
    ]
}

/// Runs `exe bench model-worker` for one (variant, size) and parses its line.
pub fn measure_in_child(
    exe: &Path,
    variant: &Variant,
    size: usize,
    e: Effort,
    device: DeviceKind,
) -> Result<Measurement> {
    let out = std::process::Command::new(exe)
        .args(["bench", "model-worker", "--variant", &variant.to_string()])
        .args(["--size", &size.to_string(), "--device", &device.to_string()])
        .args(effort_args(e))
        .output()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!(
            "measuring {variant} at {size} px failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let line = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(line)
        .with_context(|| format!("measuring {variant} at {size} px: bad worker output {line:?}"))
}
