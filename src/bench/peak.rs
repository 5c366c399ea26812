//! The machine's peak f32 FLOP/s, the denominator of `bench convs`' "% of peak" (issue 37).
//!
//! Two readings, and the report divides by the larger so a percentage is never flattered:
//! - **nominal**: cores × GHz × f32 lanes × 2 FMA units × 2 FLOPs, with the clock of
//!   `/proc/cpuinfo` (or `--ghz`). A virtual machine often reports the base clock, not the
//!   one the cores run at (a 2-core box here said 2.10 GHz and ran its FMA loop at ~2.7);
//! - **measured**: independent FMA chains on every core, timed, with the widest vectors
//!   flex's GEMM kernels use on this CPU (AVX-512 where present: chicktrain builds the
//!   `gemm` crate with its `x86-v4` kernels, chosen at run time).

use anyhow::{bail, Context, Result};

/// Nominal and measured peak of this machine for the GEMM kernels flex runs.
#[derive(Debug, Clone, Copy)]
pub struct Peak {
    pub cores: usize,
    pub ghz: f64,
    /// f32 lanes of the widest FMA the GEMM kernels use here: 16 (AVX-512), 8 (AVX2 + FMA)
    /// or 4 (other targets, a guess).
    pub lanes: usize,
    /// GFLOP/s of the FMA loop on every core (`None` where there is no x86 FMA).
    pub measured: Option<f64>,
}

impl Peak {
    /// Cores from the OS, GHz from `ghz` or else the first `cpu MHz` of `/proc/cpuinfo`,
    /// lanes from the CPU's features, and the FMA loop timed.
    pub fn detect(ghz: Option<f64>) -> Result<Self> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let ghz = match ghz {
            Some(g) if g.is_finite() && g > 0.0 => g,
            Some(g) => bail!("bench convs: --ghz must be a positive number (got {g})"),
            None => cpuinfo_ghz()
                .context("bench convs: no `cpu MHz` in /proc/cpuinfo; give the clock with --ghz")?,
        };
        let lanes = simd_lanes();
        Ok(Self {
            cores,
            ghz,
            lanes,
            measured: measure_fma(cores, lanes),
        })
    }

    /// cores × GHz × lanes × 2 FMA units × 2 FLOPs.
    pub fn nominal(&self) -> f64 {
        self.cores as f64 * self.ghz * self.lanes as f64 * 2.0 * 2.0
    }

    /// The denominator of "% of peak": the larger of the nominal and the measured peak.
    pub fn gflops(&self) -> f64 {
        self.nominal().max(self.measured.unwrap_or(0.0))
    }

    pub fn describe(&self) -> String {
        let nominal = format!(
            "{} cores × {:.2} GHz × {} f32 lanes × 2 FMA units × 2 FLOPs = {:.1} GFLOP/s",
            self.cores,
            self.ghz,
            self.lanes,
            self.nominal()
        );
        match self.measured {
            Some(m) => format!(
                "{:.1} GFLOP/s, the larger of nominal ({nominal}) and measured (a {}-lane FMA loop on {} threads: {m:.1} GFLOP/s)",
                self.gflops(),
                self.lanes,
                self.cores
            ),
            None => format!("nominal, {nominal}"),
        }
    }
}

fn cpuinfo_ghz() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("cpu MHz"))?;
    let mhz: f64 = line.split(':').nth(1)?.trim().parse().ok()?;
    (mhz > 0.0).then_some(mhz / 1e3)
}

fn simd_lanes() -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx512f") {
            return 16;
        }
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return 8;
        }
    }
    4
}

/// Iterations of the FMA loop per thread: 12 chains × 40 M FMAs, ~0.1–0.3 s.
const FMA_ITERS: usize = 40_000_000;
/// Independent accumulator chains: more than latency × ports (4 × 2), so the loop is
/// throughput-bound.
const CHAINS: usize = 12;

/// GFLOP/s of `threads` threads each running [`CHAINS`] independent FMA chains of `lanes`
/// f32 lanes (best of three runs). `None` without x86 FMA.
fn measure_fma(threads: usize, lanes: usize) -> Option<f64> {
    #[cfg(target_arch = "x86_64")]
    {
        if lanes < 8 {
            return None;
        }
        let mut best = 0.0f64;
        for _ in 0..3 {
            let t0 = std::time::Instant::now();
            let handles: Vec<_> = (0..threads)
                .map(|_| std::thread::spawn(move || fma_chains(lanes, FMA_ITERS)))
                .collect();
            let mut sink = 0.0f32;
            for h in handles {
                sink += h.join().unwrap_or(0.0);
            }
            let secs = t0.elapsed().as_secs_f64();
            std::hint::black_box(sink);
            let flops = (threads * FMA_ITERS * CHAINS * lanes * 2) as f64;
            best = best.max(flops / secs / 1e9);
        }
        Some(best)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (threads, lanes);
        None
    }
}

#[cfg(target_arch = "x86_64")]
fn fma_chains(lanes: usize, iters: usize) -> f32 {
    // SAFETY: each kernel runs only after its target features were detected at run time
    // (`simd_lanes` returned its lane count from `is_x86_feature_detected!`).
    unsafe {
        if lanes == 16 {
            fma512(iters)
        } else {
            fma256(iters)
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma256(iters: usize) -> f32 {
    use std::arch::x86_64::*;
    let mut acc = [_mm256_set1_ps(0.0); CHAINS];
    let a = _mm256_set1_ps(std::hint::black_box(0.999_999));
    let b = _mm256_set1_ps(std::hint::black_box(1e-7));
    for _ in 0..iters {
        for r in acc.iter_mut() {
            *r = _mm256_fmadd_ps(*r, a, b);
        }
    }
    // Every chain feeds the result, so none is optimised away.
    let mut sum = 0.0;
    for r in acc {
        let mut lane = [0f32; 8];
        _mm256_storeu_ps(lane.as_mut_ptr(), r);
        sum += lane.iter().sum::<f32>();
    }
    sum
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn fma512(iters: usize) -> f32 {
    use std::arch::x86_64::*;
    let mut acc = [_mm512_set1_ps(0.0); CHAINS];
    let a = _mm512_set1_ps(std::hint::black_box(0.999_999));
    let b = _mm512_set1_ps(std::hint::black_box(1e-7));
    for _ in 0..iters {
        for r in acc.iter_mut() {
            *r = _mm512_fmadd_ps(*r, a, b);
        }
    }
    acc.iter().map(|r| _mm512_reduce_add_ps(*r)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nominal_is_the_product_of_its_factors_and_the_larger_reading_wins() {
        let mut p = Peak {
            cores: 2,
            ghz: 2.5,
            lanes: 8,
            measured: None,
        };
        assert_eq!(p.nominal(), 160.0);
        assert_eq!(p.gflops(), 160.0);
        assert!(
            p.describe().ends_with("= 160.0 GFLOP/s"),
            "{}",
            p.describe()
        );
        p.measured = Some(175.0);
        assert_eq!(p.gflops(), 175.0);
        assert!(
            p.describe().starts_with("175.0 GFLOP/s"),
            "{}",
            p.describe()
        );
        p.measured = Some(100.0);
        assert_eq!(p.gflops(), 160.0);
    }

    #[test]
    fn the_fma_loop_counts_every_chain() {
        // A short loop: the rate must be positive and finite where x86 FMA exists; the
        // result depends on every chain (12 chains × 8 or 16 lanes, each ≈ 1e-7·n).
        #[cfg(target_arch = "x86_64")]
        if simd_lanes() >= 8 {
            let s = fma_chains(simd_lanes(), 1000);
            let per_lane = s / (CHAINS * simd_lanes()) as f32;
            assert!(per_lane > 0.5e-4 && per_lane < 2e-4, "{per_lane}");
            let m = measure_fma(1, simd_lanes()).unwrap();
            assert!(m.is_finite() && m > 0.0, "{m}");
        }
    }
}
