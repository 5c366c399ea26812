//! The `chicktrain` binary: flags in, one library call, errors printed once (exit code 2).
//! The command tree and the request structs it fills live in the library
//! (`chicktrain::commands::cli`), so tests walk the same tree the binary parses.

use std::process::ExitCode;

use clap::Parser;

use chicktrain::commands::cli::Cli;

fn main() -> ExitCode {
    keep_freed_tensors();
    match Cli::parse().run() {
        Ok(msg) => {
            if !msg.is_empty() {
                println!("{}", msg.trim_end());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// A forward or training step frees and reallocates tensors of the same sizes
/// every time. glibc hands blocks above its mmap threshold (128 KiB at start)
/// back to the kernel on `free` and trims the heap top above 128 KiB, so every
/// step pays `mmap`/`munmap` and zeroing page faults again. Raising both keeps
/// freed blocks for reuse (the mmap threshold's ceiling is 32 MiB on 64-bit);
/// what this bought and cost: `bench/results/convs/alloc_s2_2026-12-07/` (issue 37).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_tensors() {
    // SAFETY: mallopt only sets allocator parameters; it is called before any
    // other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_tensors() {}
