//! Summary statistics shared by the divergence guard, the benches and the reports.

/// Mean and sample standard deviation (n − 1; 0 for a single value; NaN when empty).
pub fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

/// Nearest-rank percentile `p` (0–100) of `v` (NaN when empty).
pub fn percentile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * s.len() as f64).ceil() as usize;
    s[rank.clamp(1, s.len()) - 1]
}

/// Median in f32 arithmetic (mean of the two middle values for an even count, NaN when
/// empty), sorted by `total_cmp`: the divergence guard's reference level.
pub fn median_f32(v: impl IntoIterator<Item = f32>) -> f32 {
    let mut s: Vec<f32> = v.into_iter().collect();
    s.sort_by(f32::total_cmp);
    let n = s.len();
    match n {
        0 => f32::NAN,
        _ if n % 2 == 1 => s[n / 2],
        _ => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// Median of timings or metrics: the nearest-rank 50th percentile (NaN when empty).
pub fn median(v: &[f64]) -> f64 {
    percentile(v, 50.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_match_hand_values() {
        let (m, s) = mean_std(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m, 2.5);
        assert!((s - 1.2909944487358056).abs() < 1e-12);
        assert_eq!(mean_std(&[0.7]), (0.7, 0.0));
        let v: Vec<f64> = (1..=10).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), 5.0);
        assert_eq!(percentile(&v, 10.0), 1.0);
        assert_eq!(percentile(&v, 90.0), 9.0);
        assert_eq!(percentile(&v, 100.0), 10.0);
        assert!(percentile(&[], 50.0).is_nan());
        assert_eq!(median(&v), 5.0);
        assert_eq!(median_f32([3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median_f32([4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median_f32([]).is_nan());
    }
}
