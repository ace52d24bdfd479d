//! The tracker's options: which estimator runs with which settings ([`EstimatorConfig`]), the options every
//! estimator shares ([`TrackerConfig`]), their ranges and the check that refuses a value outside them.

use thiserror::Error;

use crate::{KalmanTuning, MotionModel, RobustLoss, VvsSettings, WindowMode};
#[cfg(doc)]
use crate::{TrackError, Tracker, track};

/// Which estimator a [`Tracker`] runs, with its own settings.
///
/// ```
/// use roitrack_estimators::{EstimatorConfig, VvsSettings};
/// assert_eq!(EstimatorConfig::default().name(), "kalman");
/// assert_eq!(EstimatorConfig::Vvs(VvsSettings::default()).name(), "vvs");
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EstimatorConfig {
    /// Error-state Kalman filter, constant-velocity model, one update per centroid (the default).
    Kalman(KalmanTuning),
    /// The paper's virtual visual servoing loop.
    Vvs(VvsSettings),
    /// Baseline: Levenberg-Marquardt of the 12 parameters to convergence on the window.
    Batch,
    /// Baseline: static PnP as if the newest centroids were simultaneous; velocity by finite differences.
    Static,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self::Kalman(KalmanTuning::default())
    }
}

impl EstimatorConfig {
    /// A short name: `kalman`, `vvs`, `batch`, `static`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Kalman(_) => "kalman",
            Self::Vvs(_) => "vvs",
            Self::Batch => "batch",
            Self::Static => "static",
        }
    }
}

/// Options of an estimator. `Default` gives the recommended configuration: the Kalman filter that learns the noise
/// and the motion, an estimate every 10 measurements, 0.1 px of centroid noise to start from.
///
/// ```
/// use roitrack_estimators::TrackerConfig;
/// let config = TrackerConfig { every: 1, noise_px: 0.3, ..TrackerConfig::default() };
/// assert!(config.validate().is_ok());
/// assert!(TrackerConfig { every: 0, ..config }.validate().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    /// Which estimator runs, with its own settings (default: the Kalman filter).
    pub estimator: EstimatorConfig,
    /// Which measurements a control step uses (VVS, batch, and the conditioning figure of every estimator).
    pub window: WindowMode,
    /// Control period k: an estimate every `every` measurements (the paper: 10, i.e. 400 Hz at 4 kHz). [`track`]
    /// gives one per frame for measurements that share a time.
    pub every: usize,
    /// Centroid noise standard deviation (px): the covariance scale of the window fits and, for the Kalman filter,
    /// the measurement noise; the default Kalman filter learns the noise online and takes this only as its starting
    /// value ([`KalmanTuning::adapt_noise`]).
    pub noise_px: f64,
    /// Windows whose column-scaled Jacobian has a reciprocal condition number below this are degenerate.
    pub min_inverse_condition: f64,
    /// Median residual (px) above which an estimate counts as bad; 3 bad estimates in a row mean lost.
    pub lost_residual_px: f64,
    /// M-estimator of the window fits (VVS, batch, initialisation): Tukey (default: it rejects gross outliers, which
    /// Huber only down-weights), Huber or none. The Kalman filter has its own ([`KalmanTuning::huber_sigma`],
    /// [`KalmanTuning::gate_sigma`]).
    pub robust: RobustLoss,
    /// The farthest the first pose may put the target's origin (m): a first pose farther away, or behind the
    /// camera, is refused ([`TrackError::ImplausibleFirstPose`]), as it comes from files in the wrong units far more
    /// often than from a real scene (re-initialisations after a lost track are not checked). Default 100 m;
    /// `f64::INFINITY` turns the check off.
    pub max_first_distance_m: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            estimator: EstimatorConfig::default(),
            window: WindowMode::NewestPerPoint,
            every: 10,
            noise_px: 0.1,
            min_inverse_condition: 3e-3,
            lost_residual_px: 5.0,
            robust: RobustLoss::Tukey,
            max_first_distance_m: 100.0,
        }
    }
}

/// The most measurements a window may hold (`window`): 100,000, 25 s at 4 kHz; a window fit is a least-squares
/// problem of twice that many rows, and a longer one is no longer a constant-velocity stretch of any motion.
pub const MAX_WINDOW: usize = 100_000;
/// The most VVS iterations per control step (`iterations`): Gauss-Newton converges in a handful.
pub const MAX_ITERATIONS: usize = 100;
/// The largest centroid noise (`noise_px`, px): more than a ROI's half-width is no centroid.
pub const MAX_NOISE_PX: f64 = 100.0;
/// The range of the Kalman filter's spectral densities (accelerations' and jerks', in their units per Hz): 1e12
/// (m/s²)²/Hz is an acceleration of 20,000 m/s² between estimates at 400 Hz, beyond any tracked target; 1e-12 is no
/// motion at all.
pub const PSD_RANGE: std::ops::RangeInclusive<f64> = 1e-12..=1e12;

impl TrackerConfig {
    /// Checks every option, those of the estimator included, against its range: [`MAX_WINDOW`],
    /// [`MAX_ITERATIONS`], [`MAX_NOISE_PX`], [`PSD_RANGE`] and the ranges named in the errors. `every` has no upper
    /// bound: a huge one (`usize::MAX`) is a filter that gives no estimate after its first, as benchmarks use.
    ///
    /// ```
    /// use roitrack_estimators::{TrackerConfig, WindowMode};
    ///
    /// let huge = TrackerConfig { window: WindowMode::Last(4_000_000_000), ..TrackerConfig::default() };
    /// assert!(huge.validate().unwrap_err().to_string().starts_with("window must be from 4 to 100000"));
    /// ```
    pub fn validate(&self) -> Result<(), ConfigError> {
        let check = |field, value: f64, expected, ok: bool| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(ConfigError::Invalid {
                    field,
                    expected,
                    value,
                })
            }
        };
        check("every", self.every as f64, "at least 1", self.every >= 1)?;
        check(
            "noise_px",
            self.noise_px,
            "positive, at most 100 px",
            self.noise_px > 0.0 && self.noise_px <= MAX_NOISE_PX,
        )?;
        check(
            "min_inverse_condition",
            self.min_inverse_condition,
            "in [0, 1)",
            (0.0..1.0).contains(&self.min_inverse_condition),
        )?;
        check(
            "lost_residual_px",
            self.lost_residual_px,
            "positive",
            self.lost_residual_px > 0.0,
        )?;
        if let WindowMode::Last(n) = self.window {
            check(
                "window",
                n as f64,
                "from 4 to 100000 measurements",
                (4..=MAX_WINDOW).contains(&n),
            )?;
        }
        // Infinity is allowed here: it turns the check off.
        if self.max_first_distance_m.is_nan() || self.max_first_distance_m <= 0.0 {
            return Err(ConfigError::Invalid {
                field: "max_first_distance_m",
                expected: "positive (or infinite)",
                value: self.max_first_distance_m,
            });
        }
        match self.estimator {
            EstimatorConfig::Kalman(k) => {
                check(
                    "kalman.linear_accel_psd",
                    k.linear_accel_psd,
                    "from 1e-12 to 1e12",
                    PSD_RANGE.contains(&k.linear_accel_psd),
                )?;
                check(
                    "kalman.angular_accel_psd",
                    k.angular_accel_psd,
                    "from 1e-12 to 1e12",
                    PSD_RANGE.contains(&k.angular_accel_psd),
                )?;
                if let MotionModel::ConstantAcceleration {
                    linear_jerk_psd,
                    angular_jerk_psd,
                } = k.motion_model
                {
                    check(
                        "kalman.linear_jerk_psd",
                        linear_jerk_psd,
                        "from 1e-12 to 1e12",
                        PSD_RANGE.contains(&linear_jerk_psd),
                    )?;
                    check(
                        "kalman.angular_jerk_psd",
                        angular_jerk_psd,
                        "from 1e-12 to 1e12",
                        PSD_RANGE.contains(&angular_jerk_psd),
                    )?;
                }
                check(
                    "kalman.gate_sigma",
                    k.gate_sigma,
                    "positive",
                    k.gate_sigma > 0.0,
                )?;
                if k.huber_sigma.is_nan() || k.huber_sigma <= 0.0 {
                    return Err(ConfigError::Invalid {
                        field: "kalman.huber_sigma",
                        expected: "positive (infinite turns it off)",
                        value: k.huber_sigma,
                    });
                }
            }
            EstimatorConfig::Vvs(v) => {
                check("gain", v.gain, "in (0, 2]", v.gain > 0.0 && v.gain <= 2.0)?;
                check(
                    "iterations",
                    v.iterations as f64,
                    "from 1 to 100",
                    (1..=MAX_ITERATIONS).contains(&v.iterations),
                )?;
            }
            EstimatorConfig::Batch | EstimatorConfig::Static => {}
        }
        Ok(())
    }
}

/// Why a configuration is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    /// An option is outside its range.
    #[error("{field} must be {expected}, got {value}")]
    Invalid {
        /// The option's field: a [`TrackerConfig`] one (`noise_px`, ...), a [`KalmanTuning`] one after `kalman.`
        /// (`kalman.gate_sigma`, ...) or a [`VvsSettings`] one (`gain`, `iterations`).
        field: &'static str,
        /// The range it must be in.
        expected: &'static str,
        /// The value given (a count converted to a number).
        value: f64,
    },
}
