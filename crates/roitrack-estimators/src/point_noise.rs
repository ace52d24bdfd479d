//! Per point: how noisy its centroids are compared with the target's other points, learnt from the Kalman filter's
//! innovations.
//!
//! Blobs of one target are not equally well measured: a small or far blob, one in a shadow or near the image's edge
//! has noisier centroids than the rest. A single noise for all of them lets the noisy ones pull the estimate as much
//! as the good ones, and gates the noisy ones as outliers. The innovations tell them apart, but not directly: a filter
//! that lags a manoeuvre has innovations larger than its noise, and larger for the points the manoeuvre moves most
//! (the far points under a rotation). So each point's innovations are taken in *second differences* over its own
//! successive measurements, `d = ν(k) - 2 ν(k-1) + ν(k-2)`: a lag varies slowly over three cycles of the target and
//! cancels; white innovations of variance `S` per axis give `6 S` per axis, and `|d|²` has the median
//! `12 ln 2 · S`. Each point keeps the running median of `|d|²` (a median, so that outliers, which enter three
//! differences each, move it little), on a logarithmic scale: the logarithm steps up or down by a fixed amount at
//! each sample, which settles where half the samples lie below. `S` is the point's noise variance plus what the
//! state's uncertainty adds (`H P Hᵀ`, larger for some points than others, and while a track converges): each sample
//! is scaled by the noise's share of its variance. A point's noise factor is the square root of its median relative
//! to the others', shrunk towards 1 as far as the medians' own sampling error explains their spread. The target's
//! noise itself is learnt elsewhere (from the window's residual); the factors only share it out, their squares
//! averaging 1 over the points that have learnt theirs (about 1 once clamped).

use nalgebra::Vector2;

use super::track::MIN_NOISE_PX;

/// The step of a median's logarithm per sample once it has settled (before, `2 / (samples + 10)`): its relative
/// error is then about `sqrt(1.4 * step)` in the variance (10 %), and it follows a change within about
/// `1 / (0.69 * step)` samples (200 cycles of the target: 0.8 s at 4 kHz with 16 points).
const MEDIAN_STEP: f64 = 0.007;
/// The sampling variance of a median's logarithm: about `1.4 * step` once settled (`0.72 * step` for independent
/// samples of a 2-dof chi-square, times 1.94 for the correlation of overlapping second differences), and about
/// `4.4 / samples` before (a sample median of the logarithm of a 2-dof chi-square has the variance
/// `1 / (4 f² n) = 2.08 / n`, `f = ln 2 / 2` its density there; the step `2 / n` gives `2.26 / n`; times 1.94).
fn log_median_variance(samples: u32) -> f64 {
    (1.4 * MEDIAN_STEP).max(4.4 / f64::from(samples.max(1)))
}
/// A point measured again more than this long after its measurement before starts its second differences again:
/// a lag cancels over three measurements a few milliseconds apart (ROIs: 4 ms a cycle of 16 points at 4 kHz), not
/// over three frames of a rolling-shutter camera's centroid file (100 ms at 30 Hz).
const MAX_REVISIT_S: f64 = 0.02;

/// Points whose median has fewer samples keep a factor of 1 and do not count: a track's first innovations, while the
/// filter converges, are neither white nor alike across points (measured in docs/results.md, "Design measurements
/// behind the code").
const MIN_SAMPLES: u32 = 20;
/// A second difference this many times the point's median (`|d|²`; a clean one exceeds 20 times the median once in
/// a million) is an outlier's and left out, unless [`MAX_SKIPPED_IN_A_ROW`] were left out before it: then the
/// point's noise itself has grown, and the median follows until a sample comes below again. Outliers on every point
/// alike (10 % of them, 5-20 px) otherwise spread the points' shares by the chance of how many each point got, and
/// the track is worse than with one noise for all points (measured in docs/results.md, "Design measurements behind
/// the code").
const OUTLIER_RATIO: f64 = 20.0;
/// See [`OUTLIER_RATIO`]: an outlier spoils the three second differences it enters.
const MAX_SKIPPED_IN_A_ROW: u8 = 8;
/// Bounds of a point's noise factor.
const FACTOR_RANGE: (f64, f64) = (0.2, 5.0);

#[derive(Debug, Clone, Copy, Default)]
struct PointHistory {
    /// The point's two newest innovations (px), newest last.
    previous: [Option<Vector2<f64>>; 2],
    /// Natural logarithm of the running median of `|d|²` (px²), once `samples > 0`.
    log_median_px2: f64,
    samples: u32,
    /// Second differences left out in a row as outliers'.
    skipped_in_a_row: u8,
    /// The time of the point's newest measurement (s).
    t_s: f64,
    /// `tr(H P Hᵀ) / 2` at the point's two newest measurements, as `previous` (px²).
    previous_predicted_px2: [f64; 2],
}

impl PointHistory {
    /// Moves the median one step towards a sample `log_d2` (the logarithm of a scaled `|d|²`), unless it is an
    /// outlier's (see [`OUTLIER_RATIO`]).
    fn take_sample(&mut self, log_d2: f64) {
        let outlier = log_d2 > self.log_median_px2 + OUTLIER_RATIO.ln();
        if outlier && self.skipped_in_a_row < MAX_SKIPPED_IN_A_ROW {
            self.skipped_in_a_row += 1;
            return;
        }
        if !outlier {
            self.skipped_in_a_row = 0;
        }
        let step = MEDIAN_STEP.max(2.0 / (f64::from(self.samples) + 10.0));
        self.log_median_px2 += if log_d2 > self.log_median_px2 {
            step
        } else {
            -step
        };
        self.samples = self.samples.saturating_add(1);
    }

    /// Moves the newest innovation and its state part into `previous`.
    fn shift(&mut self, innovation_px: Vector2<f64>, predicted_variance_px2: f64) {
        self.previous = [self.previous[1], Some(innovation_px)];
        self.previous_predicted_px2 = [self.previous_predicted_px2[1], predicted_variance_px2];
    }
}

/// The per-point noise factors (see the module's documentation).
#[derive(Debug, Clone, Default)]
pub(crate) struct PointNoise {
    points: Vec<PointHistory>,
    factors: Vec<f64>,
}

impl PointNoise {
    /// Sizes the tables for `point_count` points, keeping what was learnt when the count is unchanged (a new track of
    /// the same target) but not the innovations, which belong to the old track.
    pub(crate) fn restart(&mut self, point_count: usize) {
        if self.points.len() != point_count {
            self.points = vec![PointHistory::default(); point_count];
            self.factors = vec![1.0; point_count];
        }
        for point in &mut self.points {
            point.previous = [None; 2];
        }
    }

    /// The factor on the target's noise for `point` (1 for an unknown point).
    pub(crate) fn factor(&self, point: usize) -> f64 {
        self.factors.get(point).copied().unwrap_or(1.0)
    }

    /// Takes the newest innovation of `point` (px), measured at `t_s`, and the part of its variance per axis that
    /// the state's uncertainty makes (px², `tr(H P Hᵀ) / 2`); `noise_px` is the point's noise as the filter now
    /// takes it. A point's median starts from it: started from its first sample instead, a point whose first sample was an
    /// outlier's kept a factor of 2.7 for half a second.
    pub(crate) fn observe(
        &mut self,
        point: usize,
        t_s: f64,
        innovation_px: Vector2<f64>,
        predicted_variance_px2: f64,
        noise_px: f64,
    ) {
        let Some(history) = self.points.get_mut(point) else {
            return;
        };
        let noise_px2 = noise_px.max(MIN_NOISE_PX).powi(2);
        if history.samples == 0 && history.previous == [None, None] {
            history.log_median_px2 = (12.0 * std::f64::consts::LN_2 * noise_px2).ln();
        }
        if t_s - history.t_s > MAX_REVISIT_S {
            history.previous = [None; 2];
        }
        history.t_s = t_s;
        if let [Some(oldest), Some(middle)] = history.previous {
            // Per axis, d has the variance 6 σ² from the noise and p(k) + 4 p(k-1) + p(k-2) from the state's
            // uncertainty (larger for some points, and while a track converges): scaled by their ratio, the sample
            // is one of the noise alone, at the noise the filter takes for the point now.
            let [p_oldest, p_middle] = history.previous_predicted_px2;
            let from_state_px2 = predicted_variance_px2 + 4.0 * p_middle + p_oldest;
            let from_noise_px2 = 6.0 * noise_px2;
            let d2 = (innovation_px - 2.0 * middle + oldest).norm_squared() * from_noise_px2
                / (from_noise_px2 + from_state_px2.max(0.0));
            if d2 > 0.0 && d2.is_finite() {
                history.take_sample(d2.ln());
            }
        }
        history.shift(innovation_px, predicted_variance_px2);
    }

    /// Recomputes the factors from the medians (see the module's documentation). The logarithms of the points' noise
    /// variances, taken from their mean, are shrunk towards 0 by the share of their spread that their own sampling
    /// error does not explain (an empirical Bayes estimate): equally noisy points, whose medians differ by their
    /// sampling error alone, all get factors near 1 (weighting them by that error cost about 1 % of position RMSE), a
    /// point far noisier than the others keeps its factor. Points with fewer than [`MIN_SAMPLES`] keep 1.
    pub(crate) fn update_factors(&mut self) {
        let learnt = || self.points.iter().filter(|p| p.samples >= MIN_SAMPLES);
        let count = learnt().count();
        if count < 2 {
            return;
        }
        let n = count as f64;
        let mean_log = learnt().map(|p| p.log_median_px2).sum::<f64>() / n;
        let spread = learnt()
            .map(|p| (p.log_median_px2 - mean_log).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        let sampling = learnt()
            .map(|p| log_median_variance(p.samples))
            .sum::<f64>()
            / n;
        let between = (spread - sampling).max(0.0);
        let mut sum_squares = 0.0;
        for (factor, point) in self.factors.iter_mut().zip(&self.points) {
            *factor = if point.samples >= MIN_SAMPLES {
                let shrink = between / (between + log_median_variance(point.samples));
                // A variance's logarithm: the factor on the noise is its square root.
                let f = (0.5 * shrink * (point.log_median_px2 - mean_log)).exp();
                sum_squares += f * f;
                f
            } else {
                1.0
            };
        }
        // The learnt points' squares averaging 1: they share the target's noise out.
        let rms = (sum_squares / n).sqrt();
        for (factor, point) in self.factors.iter_mut().zip(&self.points) {
            if point.samples >= MIN_SAMPLES {
                *factor = (*factor / rms).clamp(FACTOR_RANGE.0, FACTOR_RANGE.1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Standard normal samples from a fixed linear congruential generator (Box-Muller): the test needs no crate.
    fn normals(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        move || (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos()
    }

    /// Innovations of `points` points in turn, point `i` with noise `sigmas[i]`, plus a slow drift per point that a
    /// lagging filter leaves (larger for some points than for others).
    fn learn(sigmas: &[f64], cycles: usize, drift_px: f64) -> PointNoise {
        let mut noise = PointNoise::default();
        noise.restart(sigmas.len());
        let mut normal = normals(7);
        for k in 0..cycles {
            for (i, sigma) in sigmas.iter().enumerate() {
                let slow = drift_px * (i as f64 + 1.0) * (k as f64 * 0.01).sin();
                let innovation = Vector2::new(sigma * normal() + slow, sigma * normal() - slow);
                noise.observe(i, k as f64 * 1e-3, innovation, 0.0, 0.1);
            }
            noise.update_factors();
        }
        noise
    }

    #[test]
    fn equally_noisy_points_get_factors_near_one_even_with_a_lag_larger_than_the_noise() {
        let noise = learn(&[0.1; 16], 2000, 0.05);
        for i in 0..16 {
            let f = noise.factor(i);
            assert!((0.85..1.15).contains(&f), "point {i}: {f}");
        }
    }

    #[test]
    fn noisier_points_get_their_share_of_the_noise() {
        let mut sigmas = [0.1; 16];
        sigmas[3] = 0.4;
        sigmas[12] = 0.2;
        let noise = learn(&sigmas, 2000, 0.02);
        // The mean variance is (14 * 0.01 + 0.16 + 0.04) / 16 = 0.02125 px²: factors sqrt(σ² / 0.02125).
        let expected = |s: f64| (s * s / 0.02125f64).sqrt();
        for (i, &s) in sigmas.iter().enumerate() {
            let f = noise.factor(i);
            assert!(
                (f / expected(s) - 1.0).abs() < 0.15,
                "point {i}: {f} against {}",
                expected(s)
            );
        }
    }

    #[test]
    fn outliers_shared_by_all_points_leave_the_factors_near_one() {
        let mut noise = PointNoise::default();
        noise.restart(8);
        let mut normal = normals(3);
        for k in 0..2000 {
            for i in 0..8 {
                // One measurement in ten (a normal beyond 1.28) is 15 px off, on every point alike.
                let outlier = if normal() > 1.2816 { 15.0 } else { 0.0 };
                noise.observe(
                    i,
                    k as f64 * 1e-3,
                    Vector2::new(0.1 * normal() + outlier, 0.1 * normal()),
                    0.0,
                    0.1,
                );
            }
            noise.update_factors();
        }
        for i in 0..8 {
            assert!((0.9..1.1).contains(&noise.factor(i)), "{}", noise.factor(i));
        }
    }

    /// Innovations of 4 points at 0.1 px, point 0's with `extra_px2` more variance per axis, the state's share of
    /// its variance said to be `predicted_px2`, measured `dt_s` apart; a noise that grows `growth` times for point 0
    /// halfway through.
    fn learn_four(extra_px2: f64, predicted_px2: f64, dt_s: f64, growth: f64) -> PointNoise {
        let mut noise = PointNoise::default();
        noise.restart(4);
        let mut normal = normals(5);
        for k in 0..3000 {
            for i in 0..4 {
                let mut sigma = (0.01 + if i == 0 { extra_px2 } else { 0.0 }).sqrt();
                if i == 0 && k >= 1500 {
                    sigma *= growth;
                }
                let innovation = Vector2::new(sigma * normal(), sigma * normal());
                let predicted = if i == 0 { predicted_px2 } else { 0.0 };
                noise.observe(i, k as f64 * dt_s, innovation, predicted, 0.1);
            }
            noise.update_factors();
        }
        noise
    }

    #[test]
    fn what_the_states_uncertainty_adds_is_taken_away() {
        // Point 0's innovations are wider by what the state's uncertainty adds there, not by its noise.
        let noise = learn_four(0.02, 0.02, 1e-3, 1.0);
        assert!((0.9..1.1).contains(&noise.factor(0)), "{}", noise.factor(0));
        // Not said, it looks sqrt(3) times noisier than the others.
        let naive = learn_four(0.02, 0.0, 1e-3, 1.0);
        assert!(naive.factor(0) > 1.3, "{}", naive.factor(0));
    }

    #[test]
    fn points_measured_frames_apart_learn_nothing() {
        let noise = learn_four(0.08, 0.0, 0.033, 1.0);
        assert!((0..4).all(|i| noise.factor(i) == 1.0));
        assert!(noise.points.iter().all(|p| p.samples == 0));
    }

    #[test]
    fn a_point_whose_noise_grows_thirty_six_fold_is_followed() {
        // 0.1 to 0.6 px: every second difference is first beyond the outlier ratio.
        let noise = learn_four(0.0, 0.0, 1e-3, 6.0);
        // sqrt(0.36 / ((0.36 + 0.03) / 4)) = 1.92.
        assert!((noise.factor(0) - 1.92).abs() < 0.2, "{}", noise.factor(0));
    }

    #[test]
    fn a_first_innovation_far_off_does_not_make_its_point_noisy() {
        let mut noise = PointNoise::default();
        noise.restart(4);
        let mut normal = normals(11);
        for k in 0..200 {
            for i in 0..4 {
                let off = if k == 2 && i == 0 { 20.0 } else { 0.0 };
                noise.observe(
                    i,
                    k as f64 * 1e-3,
                    Vector2::new(0.1 * normal() + off, 0.1 * normal()),
                    0.0,
                    0.1,
                );
            }
            noise.update_factors();
        }
        for i in 0..4 {
            assert!(
                (0.85..1.15).contains(&noise.factor(i)),
                "point {i}: {}",
                noise.factor(i)
            );
        }
    }

    #[test]
    fn a_new_track_keeps_the_factors_but_not_the_innovations() {
        let mut sigmas = [0.1; 4];
        sigmas[0] = 0.5;
        let mut noise = learn(&sigmas, 1000, 0.0);
        // sqrt(0.25 / ((0.25 + 3 * 0.01) / 4)) = 1.89.
        let before = noise.factor(0);
        assert!((before - 1.89).abs() < 0.2, "{before}");
        noise.restart(4);
        assert_eq!(noise.factor(0), before);
        assert!(noise.points.iter().all(|p| p.previous == [None, None]));
        // Another target: everything starts again.
        noise.restart(5);
        assert_eq!(noise.factor(0), 1.0);
        assert_eq!(noise.factor(99), 1.0);
    }
}
