//! The few statistics roitrack reports (quantiles of timings and latencies, medians, RMS), defined once.

/// The `q` quantile (0 to 1) of a sorted slice, by nearest rank: `sorted[round((n - 1) q)]`; NaN when empty.
///
/// ```
/// use roitrack_core::stats::quantile;
/// let sorted = [1.0, 2.0, 3.0, 4.0, 5.0];
/// assert_eq!(quantile(&sorted, 0.5), 3.0);
/// assert_eq!(quantile(&sorted, 0.99), 5.0);
/// assert!(quantile(&[], 0.5).is_nan());
/// ```
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// A sorted copy (total order: NaN last).
pub fn sorted(values: &[f64]) -> Vec<f64> {
    let mut s = values.to_vec();
    s.sort_by(f64::total_cmp);
    s
}

/// The median: the middle value, or the mean of the two middle values; NaN when empty.
///
/// ```
/// use roitrack_core::stats::median;
/// assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
/// assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
/// ```
pub fn median(values: &[f64]) -> f64 {
    let s = sorted(values);
    let n = s.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => s[n / 2],
        _ => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// Root mean square; 0 when empty.
///
/// ```
/// use roitrack_core::stats::rms;
/// assert_eq!(rms(&[3.0, -4.0]), (12.5f64).sqrt());
/// ```
pub fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64).sqrt()
}

/// Arithmetic mean; NaN when empty.
pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}
