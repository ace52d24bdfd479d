//! The hand-tuned filters searched: the [`Grid`] of their settings, its coarse stage and pattern-search steps, and
//! the settings at one point ([`HandTuning`]).

use roitrack_estimators::{EstimatorConfig, KalmanTuning, TrackerConfig};
use serde::Serialize;

/// The hand-tuned filters searched: centroid noise (a factor of the true noise) by linear acceleration density
/// ((m/s²)²/Hz) by angular acceleration density ((rad/s²)²/Hz), and how the search goes (see the
/// [module docs](super)). Every axis must hold the told-the-truth value: a noise factor of 1 and the default densities
/// of [`KalmanTuning`].
///
/// ```
/// use roitrack_experiments::adaptive::Grid;
///
/// let grid = Grid::full();
/// assert_eq!(grid.noise_factors, vec![0.5, 0.7, 1.0, 1.4, 2.0]);
/// assert_eq!(grid.linear_accel_psd.len(), 8);
/// assert_eq!(grid.points(), 5 * 8 * 9);
/// assert!(grid.validate().is_ok());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Grid {
    /// The assumed noise as a factor of the true noise.
    pub noise_factors: Vec<f64>,
    /// Linear acceleration densities, increasing.
    pub linear_accel_psd: Vec<f64>,
    /// Angular acceleration densities, increasing.
    pub angular_accel_psd: Vec<f64>,
    /// The coarse stage takes every `coarse_stride`-th density of each axis and the last (and the told-the-truth
    /// point), at the true noise.
    pub coarse_stride: usize,
    /// At most this many rounds of pattern search after the coarse stage (0: the coarse grid alone).
    pub max_rounds: usize,
}

/// A point of the grid: indices into the noise factors, linear and angular densities.
pub(super) type GridIndex = [usize; 3];

impl Grid {
    /// The sweep's grid: noise 0.5, 0.7, 1, 1.4, 2 x the truth; q_a from 1e-4 to 1e3 and q_α from 1e-4 to 1e4, by
    /// factors of 10; coarse stage every other density and the last of each axis (25 points at the true noise, and
    /// the told-the-truth point), then up to 20 rounds of pattern search.
    pub fn full() -> Self {
        Self {
            noise_factors: vec![0.5, 0.7, 1.0, 1.4, 2.0],
            linear_accel_psd: (-4..=3).map(|e| 10f64.powi(e)).collect(),
            angular_accel_psd: (-4..=4).map(|e| 10f64.powi(e)).collect(),
            coarse_stride: 2,
            max_rounds: 20,
        }
    }

    /// A small grid for tests: noise 0.7, 1, 1.4 x the truth; q_a 0.1, 1, 10; q_α 1, 10, 100; one round of pattern
    /// search.
    ///
    /// ```
    /// assert_eq!(roitrack_experiments::adaptive::Grid::quick().points(), 27);
    /// ```
    pub fn quick() -> Self {
        Self {
            noise_factors: vec![0.7, 1.0, 1.4],
            linear_accel_psd: vec![0.1, 1.0, 10.0],
            angular_accel_psd: vec![1.0, 10.0, 100.0],
            coarse_stride: 2,
            max_rounds: 1,
        }
    }

    /// Points in the full grid.
    pub fn points(&self) -> usize {
        self.noise_factors.len() * self.linear_accel_psd.len() * self.angular_accel_psd.len()
    }

    /// Checks that every axis is positive, finite, increasing, and holds its told-the-truth value, and that the
    /// stride is at least 1.
    ///
    /// ```
    /// use roitrack_experiments::adaptive::Grid;
    /// let grid = Grid { linear_accel_psd: vec![0.1, 10.0], ..Grid::quick() };
    /// assert!(grid.validate().unwrap_err().contains("1"));
    /// ```
    pub fn validate(&self) -> Result<(), String> {
        let defaults = KalmanTuning::default();
        for (name, axis, truth) in [
            ("noise_factors", &self.noise_factors, 1.0),
            (
                "linear_accel_psd",
                &self.linear_accel_psd,
                defaults.linear_accel_psd,
            ),
            (
                "angular_accel_psd",
                &self.angular_accel_psd,
                defaults.angular_accel_psd,
            ),
        ] {
            if axis.iter().any(|x| !x.is_finite() || *x <= 0.0)
                || axis.windows(2).any(|w| w[0] >= w[1])
            {
                return Err(format!(
                    "grid axis {name} must be positive, finite and increasing, got {axis:?}"
                ));
            }
            if !axis.contains(&truth) {
                return Err(format!(
                    "grid axis {name} must hold the told-the-truth value {truth}, got {axis:?}"
                ));
            }
        }
        if self.coarse_stride == 0 {
            return Err("the coarse stride must be at least 1".to_string());
        }
        Ok(())
    }

    /// The told-the-truth point: noise factor 1, the default densities.
    pub(super) fn truth_index(&self) -> GridIndex {
        let defaults = KalmanTuning::default();
        let at = |axis: &[f64], x: f64| axis.iter().position(|&a| a == x).unwrap_or(0);
        [
            at(&self.noise_factors, 1.0),
            at(&self.linear_accel_psd, defaults.linear_accel_psd),
            at(&self.angular_accel_psd, defaults.angular_accel_psd),
        ]
    }

    /// The coarse stage: the true noise, every `coarse_stride`-th density and the last, and the told-the-truth point.
    pub(super) fn coarse(&self) -> Vec<GridIndex> {
        let truth = self.truth_index();
        let strided = |len: usize| {
            let mut indices: Vec<usize> = (0..len).step_by(self.coarse_stride).collect();
            if indices.last() != Some(&(len - 1)) {
                indices.push(len - 1);
            }
            indices
        };
        let mut out = vec![truth];
        for l in strided(self.linear_accel_psd.len()) {
            for a in strided(self.angular_accel_psd.len()) {
                if [truth[0], l, a] != truth {
                    out.push([truth[0], l, a]);
                }
            }
        }
        out
    }

    /// The points one step from `at` along each axis.
    pub(super) fn neighbours(&self, at: GridIndex) -> Vec<GridIndex> {
        let lens = [
            self.noise_factors.len(),
            self.linear_accel_psd.len(),
            self.angular_accel_psd.len(),
        ];
        let mut out = Vec::new();
        for axis in 0..3 {
            if at[axis] > 0 {
                let mut p = at;
                p[axis] -= 1;
                out.push(p);
            }
            if at[axis] + 1 < lens[axis] {
                let mut p = at;
                p[axis] += 1;
                out.push(p);
            }
        }
        out
    }

    /// Whether `at` lies on the boundary of the grid along some axis: the best there may lie beyond the grid.
    pub(super) fn on_edge(&self, at: GridIndex) -> bool {
        let lens = [
            self.noise_factors.len(),
            self.linear_accel_psd.len(),
            self.angular_accel_psd.len(),
        ];
        (0..3).any(|axis| at[axis] == 0 || at[axis] + 1 == lens[axis])
    }

    /// The hand-tuned settings at `at` for a true noise of `noise_px`.
    pub(super) fn tuning(&self, at: GridIndex, noise_px: f64) -> HandTuning {
        HandTuning {
            noise_factor: self.noise_factors[at[0]],
            noise_px: noise_px * self.noise_factors[at[0]],
            linear_accel_psd: self.linear_accel_psd[at[1]],
            angular_accel_psd: self.angular_accel_psd[at[2]],
        }
    }
}

/// The settings of a hand-tuned filter: `adapt_noise` and `adapt_motion` off, the rest of [`KalmanTuning`] and
/// [`TrackerConfig`] at their defaults.
///
/// ```
/// use roitrack_estimators::EstimatorConfig;
/// use roitrack_experiments::adaptive::HandTuning;
///
/// let tuning = HandTuning { noise_factor: 1.4, noise_px: 0.14, linear_accel_psd: 10.0, angular_accel_psd: 100.0 };
/// let config = tuning.config();
/// assert_eq!(config.noise_px, 0.14);
/// let EstimatorConfig::Kalman(kalman) = config.estimator else { unreachable!() };
/// assert!(!kalman.adapt_noise && !kalman.adapt_motion);
/// assert_eq!((kalman.linear_accel_psd, kalman.angular_accel_psd), (10.0, 100.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HandTuning {
    /// `noise_px` over the true noise.
    pub noise_factor: f64,
    /// The assumed centroid noise (px).
    pub noise_px: f64,
    /// q_a ((m/s²)²/Hz).
    pub linear_accel_psd: f64,
    /// q_α ((rad/s²)²/Hz).
    pub angular_accel_psd: f64,
}

impl HandTuning {
    /// The tracker configuration.
    pub fn config(&self) -> TrackerConfig {
        TrackerConfig {
            estimator: EstimatorConfig::Kalman(KalmanTuning {
                linear_accel_psd: self.linear_accel_psd,
                angular_accel_psd: self.angular_accel_psd,
                adapt_noise: false,
                adapt_motion: false,
                ..KalmanTuning::default()
            }),
            noise_px: self.noise_px,
            ..TrackerConfig::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_coarse_stage_and_the_neighbours_stay_on_the_grid() {
        let grid = Grid::full();
        let coarse = grid.coarse();
        assert_eq!(coarse.len(), 26);
        assert_eq!(coarse[0], grid.truth_index());
        let t = grid.tuning(grid.truth_index(), 0.3);
        assert_eq!(
            (t.noise_px, t.linear_accel_psd, t.angular_accel_psd),
            (0.3, 1.0, 10.0)
        );
        assert_eq!(grid.neighbours([0, 0, 0]).len(), 3);
        assert_eq!(grid.neighbours([2, 3, 3]).len(), 6);
        assert!(
            grid.neighbours([4, 7, 8])
                .iter()
                .all(|p| p[0] < 5 && p[1] < 8 && p[2] < 9)
        );
        assert!(grid.on_edge([4, 3, 3]) && grid.on_edge([2, 0, 3]) && !grid.on_edge([2, 3, 3]));
        assert_eq!(Grid::quick().coarse().len(), 5);
    }
}
