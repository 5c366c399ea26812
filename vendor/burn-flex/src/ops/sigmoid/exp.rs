//! A branch-free f32 `exp` that LLVM vectorises: Cephes' `expf` (range
//! reduction by `ln 2`, a degree-5 minimax polynomial on `[-ln2/2, ln2/2]`)
//! written with selects, bit tricks and plain multiply-adds only, so a loop
//! over a slice compiles to packed SSE2/AVX2 code instead of one `expf` call
//! per element. Used by the sigmoid kernels beside it; not a general
//! replacement for libm's `expf` (which is correctly rounded more often).
//!
//! Accuracy (checked by `tests.rs` against f64 `exp` on a dense sweep): at
//! most 2 ulp for normal results; results in the subnormal range
//! (x < -87.34) are within one subnormal step (2^-149) plus 2 ulp of the
//! polynomial; `exp(x) = +inf` for x > ln(f32::MAX) ≈ 88.7228, `+inf` for
//! `+inf`, `0` for x < -103.98 and `-inf`, NaN for NaN.
//!
//! No fused multiply-add: the same code runs on baseline x86-64 (where
//! `mul_add` is a libm call) and in an AVX2 clone, and both give the same
//! bits, so results do not depend on the CPU's features.

/// log2(e).
const LOG2E: f32 = core::f32::consts::LOG2_E;
/// ln 2 split in two (Cephes): `LN2_HI` has 9 significant bits, so `n · LN2_HI`
/// is exact for every |n| ≤ 150 and `x - n · LN2_HI` loses nothing.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
/// 1.5 · 2^23: adding it rounds a float of magnitude < 2^22 to the nearest
/// integer (ties to even) and leaves that integer in the low mantissa bits.
const ROUND_MAGIC: f32 = 12_582_912.0;
/// Inputs above this overflow to +inf (2^128 · e^r with r > 0 is past f32::MAX);
/// clamping keeps the exponent arithmetic in range.
const HI: f32 = 89.0;
/// Inputs below this give 0 (e^-104 < 2^-150, half the smallest subnormal).
const LO: f32 = -104.0;

/// Cephes `expf` coefficients for `(e^r - 1 - r) / r^2` on `[-ln2/2, ln2/2]`.
const P: [f32; 6] = [
    1.987_569_2e-4,
    1.398_199_9e-3,
    8.333_452e-3,
    4.166_579_6e-2,
    1.666_666_5e-1,
    5.000_000_1e-1,
];

/// `e^x` for one f32, branch-free (every `if` is a select on the same value),
/// so it inlines into vectorised loops. See the module doc for its accuracy.
#[inline(always)]
pub fn exp_f32(x: f32) -> f32 {
    // Clamp with comparisons that are false for NaN, so NaN passes through
    // (`f32::max`/`min` would replace it).
    let x = if x > HI { HI } else { x };
    let x = if x < LO { LO } else { x };
    // n = round(x / ln 2), as a float and as an integer (|n| ≤ 150).
    let t = x * LOG2E + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    let ni = (t.to_bits() as i32).wrapping_sub(ROUND_MAGIC.to_bits() as i32);
    // r = x - n ln 2 in [-ln2/2, ln2/2] (two steps, the first exact).
    let r = x - n * LN2_HI;
    let r = r - n * LN2_LO;
    let r2 = r * r;
    let mut p = P[0];
    p = p * r + P[1];
    p = p * r + P[2];
    p = p * r + P[3];
    p = p * r + P[4];
    p = p * r + P[5];
    let y = p * r2 + r + 1.0;
    // 2^n as two normal powers of two (n ∈ [-150, 129] does not fit one f32
    // exponent): y · 2^n1 is exact, the second product rounds once, into
    // the subnormals or to +inf where the true result lies.
    let n1 = ni >> 1;
    let n2 = ni.wrapping_sub(n1);
    y * pow2(n1) * pow2(n2)
}

/// `2^n` for `n ∈ [-126, 127]`, built from its exponent bits.
#[inline(always)]
fn pow2(n: i32) -> f32 {
    f32::from_bits((n.wrapping_add(127) as u32).wrapping_shl(23))
}
