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

/// The lower 5 % quantile of the χ² distribution with `dof` degrees of freedom: a χ² variable falls below it one time
/// in twenty, so `cost / chi2_lower_5_percent(dof)` bounds a variance estimated from a residual cost from above with
/// 95 % confidence. Exact for 1 and 2 degrees of freedom, the Wilson-Hilferty cube-root approximation beyond (within
/// 7 % of the exact quantile at 3, 1 % from 15 on; a lower quantile is the safer side here); 0 for none.
///
/// ```
/// use roitrack_core::stats::chi2_lower_5_percent;
/// // Exact: 0.00393 (1 dof), 0.103 (2), 0.352 (3), 7.26 (15), 77.9 (100).
/// for (dof, exact) in [(1.0, 0.00393), (2.0, 0.1026), (3.0, 0.3518), (15.0, 7.261), (100.0, 77.93)] {
///     assert!((chi2_lower_5_percent(dof) - exact).abs() < 0.08 * exact, "{dof}");
/// }
/// ```
pub fn chi2_lower_5_percent(dof: f64) -> f64 {
    // P(χ²₁ < x) = erf(sqrt(x / 2)); P(χ²₂ < x) = 1 - exp(-x / 2).
    const ONE_DOF: f64 = 0.003_932_140;
    const TWO_DOF: f64 = 0.102_586_589;
    const Z_5_PERCENT: f64 = -1.644_853_627;
    if dof <= 0.0 {
        0.0
    } else if dof <= 1.0 {
        ONE_DOF * dof
    } else if dof <= 2.0 {
        ONE_DOF + (TWO_DOF - ONE_DOF) * (dof - 1.0)
    } else {
        let a = 2.0 / (9.0 * dof);
        dof * (1.0 - a + Z_5_PERCENT * a.sqrt()).powi(3)
    }
}
