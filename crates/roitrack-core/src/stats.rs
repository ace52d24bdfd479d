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

/// The upper `p` quantile of Fisher's F distribution with `dof` degrees of freedom in numerator and denominator: the
/// ratio of two independent residual costs of `dof` degrees of freedom each, under the same noise, exceeds it with
/// probability `1 - p`. So a fit whose cost is more than this many times another's, on as many degrees of freedom,
/// fits worse than noise explains at that confidence. Computed from `F = q / (1 - q)` with `q` the quantile of the
/// Beta(dof/2, dof/2) distribution, found on its numerically integrated distribution function (to about 1e-4 in
/// `q`); `dof` below 2 is taken as 2, where it is exact: `p / (1 - p)`.
///
/// ```
/// use roitrack_core::stats::f_equal_dof_upper_quantile;
/// // Exact values: 99 (2, 2 dof, 99 %), 15.98 (4), 4.85 (10), 1.60 (100).
/// for (dof, exact) in [(2.0, 99.0), (4.0, 15.98), (10.0, 4.849), (100.0, 1.598)] {
///     let f = f_equal_dof_upper_quantile(dof, 0.99);
///     assert!((f - exact).abs() < 0.01 * exact, "{dof}: {f}");
/// }
/// ```
pub fn f_equal_dof_upper_quantile(dof: f64, p: f64) -> f64 {
    const STEPS: usize = 8192;
    let a = 0.5 * dof.max(2.0);
    let p = p.clamp(0.5, 1.0 - 1e-9);
    if a == 1.0 {
        return p / (1.0 - p);
    }
    // The density (x (1 - x))^(a - 1) up to a constant, on the midpoints of STEPS cells; normalised by its sum.
    let log_density = |x: f64| (a - 1.0) * (x * (1.0 - x)).ln();
    let peak = log_density(0.5);
    let weights: Vec<f64> = (0..STEPS)
        .map(|k| (log_density((k as f64 + 0.5) / STEPS as f64) - peak).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    let mut below = 0.0;
    for (k, w) in weights.iter().enumerate() {
        let next = below + w / total;
        if next >= p {
            let q = (k as f64 + (p - below) / (next - below)) / STEPS as f64;
            return q / (1.0 - q);
        }
        below = next;
    }
    f64::INFINITY
}

/// The upper 0.1 % point of the chi-square distribution with `dof` degrees of freedom: a residual cost of `dof`
/// degrees of freedom over the noise variance exceeds it once in a thousand. Exact for 1 and 2 degrees of freedom,
/// the Wilson-Hilferty cube-root approximation beyond (within 1 % of the exact quantile); 0 for none.
///
/// ```
/// use roitrack_core::stats::chi2_upper_0_1_percent;
/// // Exact: 10.83 (1 dof), 13.82 (2), 29.59 (10), 149.4 (100).
/// for (dof, exact) in [(1.0, 10.83), (2.0, 13.82), (10.0, 29.59), (100.0, 149.4)] {
///     assert!((chi2_upper_0_1_percent(dof) - exact).abs() < 0.01 * exact, "{dof}");
/// }
/// ```
pub fn chi2_upper_0_1_percent(dof: f64) -> f64 {
    const Z_0_1_PERCENT: f64 = 3.090_232_306;
    // P(χ²₁ > x) = erfc(sqrt(x / 2)); P(χ²₂ > x) = exp(-x / 2).
    const ONE_DOF: f64 = 10.827_566;
    const TWO_DOF: f64 = 13.815_511;
    if dof <= 0.0 {
        return 0.0;
    } else if dof <= 1.0 {
        return ONE_DOF * dof;
    } else if dof <= 2.0 {
        return ONE_DOF + (TWO_DOF - ONE_DOF) * (dof - 1.0);
    }
    chi2_upper_quantile(dof, Z_0_1_PERCENT)
}

/// The upper point of the chi-square distribution with `dof` degrees of freedom that has the tail of a standard
/// Gaussian beyond `z` standard deviations (`z` = 2: exceeded with probability 2.3 %), by the Wilson-Hilferty
/// cube-root approximation (within 1 % of the exact quantile from 2 degrees of freedom for `z` from 1 to 3.1); 0 for none. It says how large a sum of `dof` squared independent errors can be at the confidence
/// that `z` sigmas give one error.
///
/// ```
/// use roitrack_core::stats::chi2_upper_quantile;
/// // Exact upper 2.275 % points (z = 2): 7.566 (2 dof), 11.37 (4), 20.77 (10), 130.2 (100).
/// for (dof, exact) in [(2.0, 7.566), (4.0, 11.37), (10.0, 20.77), (100.0, 130.2)] {
///     assert!((chi2_upper_quantile(dof, 2.0) - exact).abs() < 0.01 * exact, "{dof}");
/// }
/// ```
pub fn chi2_upper_quantile(dof: f64, z: f64) -> f64 {
    if dof <= 0.0 {
        return 0.0;
    }
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).max(0.0).powi(3)
}
