//! The velocity lag: the shift that best aligns the estimated linear velocity with the truth (docs/evaluation.md).

use nalgebra::Vector3;

/// The lag of an estimated series behind the true one, in estimator samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Lag {
    /// The integer shift with the highest normalized cross-correlation.
    pub samples: i64,
    /// `samples` refined by a parabola through the peak and its two neighbours.
    pub subsample: f64,
}

/// The shift `s` in `-max_lag..=max_lag` maximising the normalized cross-correlation of `estimate[k]` and
/// `truth[k - s]`; positive `s` means the estimate lags behind the truth.
///
/// Both series hold the same number of samples at the estimator's times. Every shift is scored on the same
/// estimates, all but the first and the last `max_lag`: over the plain overlap of the two series, a shift of `s`
/// drops the first `s` estimates, and when those are a filter's first, converging ones (velocity errors of a metre
/// per second), dropping them raised the normalized correlation enough to report a lag of 2 or 3 samples for a filter
/// whose lag is 1.2. The shift is also kept within a quarter of the series, so that the estimates scored are at least
/// half of it. Each series is mean-removed over the samples scored, and the correlation is summed over x, y and z.
/// Ties (a constant velocity correlates with nothing) go to the smallest |s|.
pub(crate) fn velocity_lag(
    estimate: &[Vector3<f64>],
    truth: &[Vector3<f64>],
    max_lag: usize,
) -> Lag {
    debug_assert_eq!(estimate.len(), truth.len());
    let max_lag = max_lag.min(estimate.len() / 4) as i64;
    let correlations: Vec<f64> = (-max_lag..=max_lag)
        .map(|s| normalized_correlation(estimate, truth, s, max_lag))
        .collect();
    let at = |s: i64| correlations[(s + max_lag) as usize];

    // Visit 0, 1, -1, 2, -2, ... so that only a strictly better correlation moves the peak away from zero.
    let mut best = 0;
    for magnitude in 1..=max_lag {
        for s in [magnitude, -magnitude] {
            if at(s) > at(best) {
                best = s;
            }
        }
    }

    let mut subsample = best as f64;
    if best.abs() < max_lag {
        let (before, peak, after) = (at(best - 1), at(best), at(best + 1));
        let curvature = before - 2.0 * peak + after;
        if curvature < 0.0 {
            subsample += (0.5 * (before - after) / curvature).clamp(-0.5, 0.5);
        }
    }
    Lag {
        samples: best,
        subsample,
    }
}

/// The normalized cross-correlation of `estimate[k]` and `truth[k - shift]` over `k` in `margin..n - margin`, in
/// [-1, 1]; 0 when either series does not vary there. `|shift|` is at most `margin`.
fn normalized_correlation(
    estimate: &[Vector3<f64>],
    truth: &[Vector3<f64>],
    shift: i64,
    margin: i64,
) -> f64 {
    debug_assert!(shift.abs() <= margin);
    let n = estimate.len() as i64;
    let (start, end) = (margin, n - margin);
    if end <= start {
        return 0.0;
    }
    let pairs = || (start..end).map(|k| (&estimate[k as usize], &truth[(k - shift) as usize]));
    let count = (end - start) as f64;
    let (sum_e, sum_t) = pairs().fold((Vector3::zeros(), Vector3::zeros()), |(se, st), (e, t)| {
        (se + e, st + t)
    });
    let (mean_e, mean_t): (Vector3<f64>, Vector3<f64>) = (sum_e / count, sum_t / count);
    let (mut cross, mut energy_e, mut energy_t) = (0.0, 0.0, 0.0);
    for (e, t) in pairs() {
        let (de, dt) = (e - mean_e, t - mean_t);
        cross += de.dot(&dt);
        energy_e += de.norm_squared();
        energy_t += dt.norm_squared();
    }
    let norm = (energy_e * energy_t).sqrt();
    if norm > 0.0 { cross / norm } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A velocity with several incommensurate frequencies, so the correlation has one clear peak.
    fn signal(k: i64) -> Vector3<f64> {
        let t = k as f64 * 0.01;
        Vector3::new(
            (1.3 * t).sin() + 0.5 * (4.1 * t).cos(),
            (2.2 * t).cos(),
            0.3 * (0.7 * t * t).sin(),
        )
    }

    fn shifted(lag: i64, n: i64) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let truth = (0..n).map(signal).collect();
        let estimate = (0..n).map(|k| signal(k - lag)).collect();
        (estimate, truth)
    }

    #[test]
    fn finds_positive_and_negative_lags() {
        for lag in [-7, -1, 0, 2, 5, 12] {
            let (estimate, truth) = shifted(lag, 600);
            let found = velocity_lag(&estimate, &truth, 20);
            assert_eq!(found.samples, lag);
            assert!((found.subsample - lag as f64).abs() < 0.05, "{found:?}");
        }
    }

    #[test]
    fn subsample_refinement_interpolates_fractional_lags() {
        let n = 800;
        let truth: Vec<_> = (0..n).map(signal).collect();
        // A lag of 2.4 samples: sample the signal between the grid points.
        let estimate: Vec<_> = (0..n)
            .map(|k| {
                let t = (k as f64 - 2.4) * 0.01;
                Vector3::new(
                    (1.3 * t).sin() + 0.5 * (4.1 * t).cos(),
                    (2.2 * t).cos(),
                    0.3 * (0.7 * t * t).sin(),
                )
            })
            .collect();
        let found = velocity_lag(&estimate, &truth, 20);
        assert_eq!(found.samples, 2);
        assert!((found.subsample - 2.4).abs() < 0.1, "{found:?}");
    }

    #[test]
    fn a_converging_start_does_not_make_a_lag() {
        // The estimate follows the truth one sample late, but its first 10 samples are far off (a filter's first
        // estimates): dropping them from the overlap must not favour longer shifts.
        for lag in [0, 1] {
            let (mut estimate, truth) = shifted(lag, 600);
            for (k, v) in estimate.iter_mut().take(10).enumerate() {
                *v += Vector3::new(8.0, -6.0, 5.0) * if k % 2 == 0 { 1.0 } else { -0.7 };
            }
            let found = velocity_lag(&estimate, &truth, 20);
            assert_eq!(found.samples, lag, "{found:?}");
        }
    }

    #[test]
    fn lag_beyond_the_search_range_is_clamped_to_the_range() {
        let (estimate, truth) = shifted(30, 600);
        let found = velocity_lag(&estimate, &truth, 10);
        assert_eq!(found.samples, 10);
        assert_eq!(found.subsample, 10.0);
    }

    #[test]
    fn constant_or_tiny_series_give_zero() {
        let constant = vec![Vector3::new(1.0, 2.0, 3.0); 50];
        assert_eq!(
            velocity_lag(&constant, &constant, 10),
            Lag {
                samples: 0,
                subsample: 0.0
            }
        );
        let one = [Vector3::new(1.0, 0.0, 0.0)];
        assert_eq!(velocity_lag(&one, &one, 10).samples, 0);
    }
}
