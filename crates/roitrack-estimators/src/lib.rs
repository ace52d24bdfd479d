//! # roitrack-estimators
//!
//! The 12-dof pose and velocity estimators and their baselines, behind one trait, on the model of `roitrack-core`;
//! pure math, no I/O and no threads.
//!
//! Every estimator is an [`Estimator`]: it takes raw centroids one at a time ([`Estimator::push`]), undistorts them,
//! initialises itself from the first two cycles with no prior (a static pose, then a 12-dof fit of the two cycles so
//! that a target already moving starts with its velocity), then every `every` measurements emits an [`Estimate`] at
//! the time of the newest measurement, with a status, a residual, a conditioning figure and, where it has one, a
//! covariance. Each lives in its own module:
//!
//! - [`KalmanEstimator`] (default, [`kalman`]): an error-state Kalman filter with a constant-velocity model; every
//!   centroid updates the state once, at its own time.
//! - [`VvsEstimator`] ([`vvs`]): the paper's virtual visual servoing loop: predict with the current twist, then
//!   `iterations` steps `δ = -λ L⁺ e` on the window, with the exact or the paper's interaction matrix.
//! - [`BatchEstimator`] ([`batch`]): baseline, Levenberg-Marquardt of the 12 parameters to convergence on the window.
//! - [`StaticEstimator`] ([`static_baseline`]): baseline, static PnP as if the newest centroids were simultaneous,
//!   velocity by finite differences.
//!
//! [`Tracker`] is the one to use when the estimator is chosen at run time ([`TrackerConfig::estimator`]); [`track`]
//! runs one over a stream of measurements. The window fits share one [`WindowProblem`] and the
//! [`solver`](roitrack_core::solver); the static pose ([`solve_static_pose`]) also serves the full-frame initialisation.
//!
//! Every estimator refuses to update on a degenerate window (reciprocal condition number of the column-scaled
//! Jacobian below [`TrackerConfig::min_inverse_condition`]), flags the estimate, and widens its window.
//!
//! ```
//! use roitrack_estimators::{Estimator, TrackStatus, Tracker, TrackerConfig};
//! use roitrack_core::roi_order::bit_reversed_indices;
//! use roitrack_core::{CameraModel, Measurement, MotionState, Target};
//! use nalgebra::Vector3;
//!
//! let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
//! // A target 0.6 m away moving at 0.1 m/s along x, seen one point every 250 µs in the bit-reversed order.
//! let mut truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
//! truth.velocity_mps = Vector3::new(0.1, 0.0, 0.0);
//! let order = bit_reversed_indices(16);
//! let mut tracker = Tracker::new(camera.clone(), target.clone(), TrackerConfig::default()).unwrap();
//! let mut last = None;
//! for k in 0..400 {
//!     let t_s = k as f64 * 250e-6;
//!     let point = &target.points()[order[k % 16]];
//!     let px = camera.raw_pixel_from_cam(&truth.point_in_cam_at(&point.point_in_obj_m, t_s)).unwrap();
//!     let m = Measurement { t_s, id: point.id, u_px: px.x, v_px: px.y };
//!     if let Some(estimate) = tracker.push(&m).unwrap() {
//!         last = Some(estimate);
//!     }
//! }
//! let last = last.unwrap();
//! assert_eq!(last.status, TrackStatus::Tracking);
//! assert!((last.state.velocity_mps - truth.velocity_mps).norm() < 1e-6);
//! ```
#![deny(missing_docs)]

pub mod batch;
mod calibration;
pub mod kalman;
mod model_error;
mod options;
mod point_noise;
mod problem;
pub mod rig;
pub mod rolling_refit;
pub mod static_baseline;
mod static_pose;
mod track;
pub mod vvs;
mod window;

use thiserror::Error;

pub use batch::BatchEstimator;
pub use kalman::{
    KNOWN_ACCELERATION_CAPACITY, KalmanEstimator, KalmanTuning, KnownAccelerationError, Matrix12,
    MotionModel, NoiseSample,
};
pub use model_error::{MODEL_UNCERTAINTY, ModelEffect, ModelResidual, ModelUncertainty};
pub use options::{
    Adaptation, EstimatorKind, MotionModelKind, OptionConflict, TrackerOptions, UnknownName,
};
pub use problem::{Observation, RobustLoss, WindowProblem};
use roitrack_core::{CameraModel, Measurement, MotionState, Target};
pub use rolling_refit::{
    MAX_STENCIL_POSES, PoseRefit, StencilMotion, TimedPose, pose_residuals, refit_pose,
    stencil_motion, stencil_motion_at_start,
};
pub use static_baseline::StaticEstimator;
pub use static_pose::{
    AMBIGUITY_CHI2, InitError, MAX_STATIC_POSES, MODEL_SPREAD_SIGMAS, PixelNoise, PoseFit,
    StaticPoses, best_static_pose, is_rival, refine_static_pose, relabelling_is_rival,
    solve_static_pose, static_model_residual,
};
pub use vvs::{VvsEstimator, VvsSettings};
pub use window::WindowMode;

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

/// The state of a track, as told by each estimate. Only `Converging` and `Tracking` estimates are vouched for.
///
/// ```
/// use roitrack_estimators::TrackStatus;
/// assert_eq!(TrackStatus::Disputed.name(), "disputed");
/// assert!(TrackStatus::Tracking.is_vouched_for() && !TrackStatus::Degenerate.is_vouched_for());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackStatus {
    /// Just initialised: the first estimates after (re)initialisation.
    Converging,
    /// Normal operation.
    Tracking,
    /// The window was degenerate: the update was not applied (the state was only predicted).
    Degenerate,
    /// The residual stayed too large: the tracker drops this track and re-initialises from the next measurements.
    Lost,
    /// The newest measurement disagreed with the track beyond the outlier gate and was rejected (Kalman) or weighed
    /// nothing (robust window fits): the estimate rests on the earlier measurements. It is right if that measurement
    /// was an outlier and out of date if the target has just jumped; one measurement cannot tell which, so the
    /// estimate is not vouched for.
    Disputed,
}

impl TrackStatus {
    /// Every status, in the order of [`StatusCounts`].
    pub const ALL: [Self; 5] = [
        Self::Converging,
        Self::Tracking,
        Self::Degenerate,
        Self::Disputed,
        Self::Lost,
    ];

    /// The name used in diagnostics files and reports.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Converging => "converging",
            Self::Tracking => "tracking",
            Self::Degenerate => "degenerate",
            Self::Lost => "lost",
            Self::Disputed => "disputed",
        }
    }

    /// Whether an estimate with this status is presented as valid (`converging` or `tracking`).
    pub fn is_vouched_for(&self) -> bool {
        matches!(self, Self::Converging | Self::Tracking)
    }
}

/// One output of an estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Reference time (s): the time of the newest measurement used (the frame tracker moves its estimates to the
    /// mean time of each frame's measurements).
    pub t_ref_s: f64,
    /// The pose and twist at `t_ref_s`, camera frame.
    pub state: MotionState,
    /// RMS of the window's reprojection residual at the emitted state (px, per coordinate); for the Kalman filter,
    /// of the innovations of the measurements since the previous estimate (each against the prediction from the
    /// measurement before it).
    pub residual_rms_px: f64,
    /// Reciprocal condition number of the window's column-scaled Jacobian (1 perfect, 0 singular).
    pub inverse_condition: f64,
    /// Measurements in the window.
    pub measurements_used: usize,
    /// Iterations (or Kalman updates since the last estimate).
    pub iterations: usize,
    /// What the track is doing, and whether the estimate is vouched for ([`TrackStatus::is_vouched_for`]).
    pub status: TrackStatus,
    /// Covariance of the error state (v, w, dV, dW) where the estimator has one (Kalman; batch and VVS give the
    /// Gauss-Newton covariance σ² (JᵀJ)⁻¹ of the window).
    pub covariance: Option<Matrix12>,
    /// The centroid noise (px, standard deviation per coordinate) the estimate was computed with: the adaptive
    /// Kalman filter's online estimate, else [`TrackerConfig::noise_px`].
    pub noise_px: f64,
    /// The accelerations at `t_ref_s`, when the estimator has them in its state (the Kalman filter with
    /// [`MotionModel::ConstantAcceleration`]).
    pub acceleration: Option<roitrack_core::Acceleration>,
}

impl Estimate {
    /// An estimate of the bench pose ([`MotionState::bench`]) at 1 s, tracking, with a covariance of 1e-6 on the
    /// diagonal: the fixture of the benchmarks and tests that hand estimates around.
    ///
    /// ```
    /// use roitrack_estimators::{Estimate, TrackStatus};
    /// let estimate = Estimate::bench();
    /// assert_eq!(estimate.status, TrackStatus::Tracking);
    /// assert!(estimate.covariance.is_some());
    /// ```
    pub fn bench() -> Self {
        Self {
            t_ref_s: 1.0,
            state: MotionState::bench(),
            residual_rms_px: 0.0,
            inverse_condition: 1.0,
            measurements_used: 16,
            iterations: 1,
            status: TrackStatus::Tracking,
            covariance: Some(Matrix12::identity() * 1e-6),
            noise_px: 0.1,
            acceleration: None,
        }
    }

    /// The state `dt_s` after `t_ref_s` (before, if negative): with the accelerations when the estimate has them
    /// ([`roitrack_core::Acceleration::predicted`]), else under its constant twist ([`MotionState::predicted`]).
    pub fn state_at(&self, dt_s: f64) -> MotionState {
        match &self.acceleration {
            Some(acceleration) => acceleration.predicted(&self.state, dt_s),
            None => self.state.predicted(dt_s),
        }
    }

    /// 1-sigma standard deviations of the covariance, in the order (v, w, dV, dW); NaN without a covariance.
    pub fn standard_deviations(&self) -> [f64; 12] {
        self.covariance
            .map_or([f64::NAN; 12], |c| standard_deviations(&c))
    }
}

/// Why a measurement was refused. The estimator's state is unchanged by a refused measurement.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrackError {
    /// The time or a pixel coordinate is NaN or infinite.
    #[error("measurement at t = {t_s} s: {field} is not finite ({value})")]
    NotFinite {
        /// The measurement's time (s).
        t_s: f64,
        /// `t`, `u` or `v`.
        field: &'static str,
        /// The value given.
        value: f64,
    },
    /// The measurement is older than the one before it: the estimators move forward in time only.
    #[error(
        "measurement at t = {t_s} s is older than the previous one ({previous_s} s): times must not decrease"
    )]
    TimeOutOfOrder {
        /// The measurement's time (s).
        t_s: f64,
        /// The time of the measurement accepted before it (s).
        previous_s: f64,
    },
    /// The measurement's point id is not one of the target's.
    #[error("measurement at t = {t_s} s: point id {id} is not in the target")]
    UnknownId {
        /// The measurement's time (s).
        t_s: f64,
        /// The id given.
        id: u32,
    },
    /// The raw pixel could not be undistorted ([`roitrack_core::CameraError::UndistortionDiverged`]).
    #[error("measurement at t = {t_s} s: {source}")]
    Undistortion {
        /// The measurement's time (s).
        t_s: f64,
        /// The camera's refusal.
        #[source]
        source: roitrack_core::CameraError,
    },
    /// The first pose of a track is farther than [`TrackerConfig::max_first_distance_m`] or behind the camera.
    #[error(
        "the first pose (t = {t_s} s) puts the target's origin at ({x_m:.3}, {y_m:.3}, {z_m:.3}) m, {distance_m:.1} m \
         from the camera{}: check the units of the target file (a target in millimetres or centimetres needs \
         --target-units mm or cm) and that the camera file matches the camera that took the measurements",
        if *z_m <= 0.0 { ", behind it".to_string() } else { format!(", more than {max_m} m away") }
    )]
    ImplausibleFirstPose {
        /// The time of the first estimate (s).
        t_s: f64,
        /// The target origin's x in the camera frame (m).
        x_m: f64,
        /// The target origin's y in the camera frame (m).
        y_m: f64,
        /// The target origin's z in the camera frame (m): depth, negative behind the camera.
        z_m: f64,
        /// The target origin's distance from the camera (m).
        distance_m: f64,
        /// The farthest allowed ([`TrackerConfig::max_first_distance_m`], m).
        max_m: f64,
    },
}

/// When [`Estimator::push_batch`] gives an estimate.
///
/// ```
/// use roitrack_estimators::{Emit, Estimator, Tracker, TrackerConfig};
/// use roitrack_core::{CameraModel, Measurement, MotionState, Target};
/// use nalgebra::Vector3;
///
/// // A global-shutter camera: the 16 blobs of each frame share the frame's time; one estimate per frame.
/// let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
/// let truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
/// let mut tracker = Tracker::new(camera.clone(), target.clone(), TrackerConfig::default()).unwrap();
/// let mut estimates = 0;
/// for k in 0..5 {
///     let t_s = k as f64 / 30.0;
///     let frame: Vec<Measurement> = target.points().iter().map(|p| {
///         let px = camera.raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, t_s)).unwrap();
///         Measurement { t_s, id: p.id, u_px: px.x, v_px: px.y }
///     }).collect();
///     if let Some(e) = tracker.push_batch(&frame, Emit::EachBatch).unwrap() {
///         assert_eq!(e.t_ref_s, t_s);
///         estimates += 1;
///     }
/// }
/// // The first frame alone cannot initialise (two cycles over the points are needed); every later frame gives one.
/// assert_eq!(estimates, 4);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Emit {
    /// One estimate after every batch (a frame camera: one estimate per frame).
    EachBatch,
    /// As [`Estimator::push`]: once `every` measurements have come since the previous estimate, but only after the
    /// batch's last measurement.
    #[default]
    Every,
    /// None yet: more measurements of the same readout follow. A later batch (an empty one will do) closes the
    /// readout and gives the estimate that is due.
    Hold,
}

/// Estimates counted by status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StatusCounts {
    /// Estimates with [`TrackStatus::Converging`].
    pub converging: usize,
    /// Estimates with [`TrackStatus::Tracking`].
    pub tracking: usize,
    /// Estimates with [`TrackStatus::Degenerate`].
    pub degenerate: usize,
    /// Estimates with [`TrackStatus::Disputed`].
    pub disputed: usize,
    /// Estimates with [`TrackStatus::Lost`].
    pub lost: usize,
}

impl StatusCounts {
    /// How many estimates had `status`.
    pub fn get(&self, status: TrackStatus) -> usize {
        match status {
            TrackStatus::Converging => self.converging,
            TrackStatus::Tracking => self.tracking,
            TrackStatus::Degenerate => self.degenerate,
            TrackStatus::Disputed => self.disputed,
            TrackStatus::Lost => self.lost,
        }
    }

    /// Counts one more estimate with `status`.
    pub fn add(&mut self, status: TrackStatus) {
        *self.count_mut(status) += 1;
    }

    fn count_mut(&mut self, status: TrackStatus) -> &mut usize {
        match status {
            TrackStatus::Converging => &mut self.converging,
            TrackStatus::Tracking => &mut self.tracking,
            TrackStatus::Degenerate => &mut self.degenerate,
            TrackStatus::Disputed => &mut self.disputed,
            TrackStatus::Lost => &mut self.lost,
        }
    }

    /// Every estimate counted.
    pub fn total(&self) -> usize {
        TrackStatus::ALL.iter().map(|&s| self.get(s)).sum()
    }

    /// The statuses of `estimates`, counted.
    pub fn of(estimates: &[Estimate]) -> Self {
        let mut counts = Self::default();
        for e in estimates {
            counts.add(e.status);
        }
        counts
    }
}

/// Why the newest attempt to start a track from the measurements started none ([`EstimatorReport::start_failure`]).
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum StartFailure {
    /// No static pose from the newest centroid of each point.
    #[error("{0}")]
    NoPose(InitError),
    /// Several poses fit the measurements as well as the best, within the noise: a target of 3 points, a symmetric
    /// layout, or a small target far away whose tilt the view cannot tell from its mirror tilt. The track waits for
    /// measurements that decide.
    #[error(
        "{poses} poses fit the measurements equally well within the noise (3 points, a symmetric target, or a small \
         target far away whose tilt cannot be told from its mirror tilt)"
    )]
    Ambiguous {
        /// How many poses fit equally well (the best and its rivals).
        poses: usize,
    },
    /// A pose decided with little margin over a rival was not decided the same way by the cycle before: the track
    /// waits for views that agree.
    #[error(
        "a pose that fits only a little better than a second one was not confirmed by the cycle before"
    )]
    Unconfirmed,
    /// The 12-dof fit of the first cycles left residuals above the noise (a wrong correspondence, or bad data).
    #[error("the first cycles fit no motion: median residual {median_px:.2} px")]
    Residual {
        /// The median residual norm of the fit (px), over the bound set by the noise.
        median_px: f64,
    },
}

/// What an estimator has done since it was built.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstimatorReport {
    /// Measurements accepted.
    pub measurements: usize,
    /// Measurements refused ([`TrackError`]), which left the estimator as it was.
    pub refused: usize,
    /// Estimates emitted, by status.
    pub estimates: StatusCounts,
    /// Tracks started: initialisations from the measurements and starts from a given state.
    pub initialisations: usize,
    /// Why the newest attempt to start a track from the measurements started none (`None` once one has started).
    pub start_failure: Option<StartFailure>,
    /// Kalman: measurements rejected by the innovation gate.
    pub gated: usize,
    /// Kalman: covariance resets after runs of gated measurements.
    pub covariance_resets: usize,
}

impl EstimatorReport {
    /// Why no track started, for a run that gave no estimate: the reason of the newest failed start, or the wait for
    /// two cycles over every point when no start was tried.
    pub fn why_no_start(&self) -> String {
        match self.start_failure {
            Some(failure) => format!("the tracker could not initialise: {failure}"),
            None => "the tracker could not initialise: it needs two cycles over every target point"
                .to_string(),
        }
    }

    fn count(&mut self, status: TrackStatus) {
        self.estimates.add(status);
    }

    /// Takes back an estimate counted but not given (a first pose refused).
    fn uncount(&mut self, status: TrackStatus) {
        let count = self.estimates.count_mut(status);
        *count = count.saturating_sub(1);
    }
}

/// A streaming pose-and-velocity estimator (see the [module documentation](self)).
pub trait Estimator: Send + std::fmt::Debug {
    /// Takes one raw centroid (times must not decrease); returns an estimate every `every` measurements once
    /// initialised. A refused measurement leaves the estimator as it was.
    fn push(&mut self, m: &Measurement) -> Result<Option<Estimate>, TrackError>;

    /// Takes the measurements of one readout at once (the blobs of a frame, in time order: one time for a global
    /// shutter, one per row for a rolling shutter) and returns at most one estimate, at the newest measurement's time,
    /// after the last of them (see [`Emit`]). Each measurement updates the state at its own time, as with
    /// [`Self::push`]; the Kalman filter then fits a readout of three or more together, iterated, and may use blobs
    /// its updates one by one had rejected ([`KalmanEstimator`]). Measurements that share a time are one readout,
    /// never an error. Every measurement is checked before any is used: a refused batch leaves the estimator as it
    /// was.
    fn push_batch(
        &mut self,
        measurements: &[Measurement],
        emit: Emit,
    ) -> Result<Option<Estimate>, TrackError>;

    /// Which measurement of `measurements` [`Self::push_batch`] would refuse first (its offset in them), and why;
    /// `None` if it would take them all. Takes nothing and counts nothing. [`track`] names a refused measurement of
    /// a readout by it; an estimator that cannot tell (the default) leaves it the readout's first.
    ///
    /// ```
    /// use roitrack_estimators::{Estimator, Tracker, TrackerConfig, TrackError};
    /// use roitrack_core::{CameraModel, Measurement, Target};
    ///
    /// let tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
    /// let good = Measurement { t_s: 0.0, id: 0, u_px: 500.0, v_px: 400.0 };
    /// let readout = [good, Measurement { id: 1, ..good }, Measurement { id: 99, ..good }];
    /// assert!(matches!(tracker.first_refused(&readout), Some((2, TrackError::UnknownId { id: 99, .. }))));
    /// assert!(tracker.first_refused(&readout[..2]).is_none());
    /// ```
    fn first_refused(&self, _measurements: &[Measurement]) -> Option<(usize, TrackError)> {
        None
    }

    /// Drops the current track: the next measurements initialise a new one (after a re-initialisation from a full
    /// frame, say). Measurement times must still not decrease.
    fn reset(&mut self);

    /// Starts tracking from a known state at time `t_s` (e.g. a static pose from a full frame, velocity zero) with
    /// its covariance (error-state order v, w, dV, dW), instead of initialising from the first two cycles. The new
    /// track takes measurements from `t_s` on, even if the old one had later ones.
    fn start_from(&mut self, t_s: f64, state: MotionState, covariance: Option<Matrix12>);

    /// The current state and its time (that of the newest measurement processed), once initialised.
    fn state(&self) -> Option<(f64, MotionState)>;

    /// The current state predicted to `t_s`, once initialised, with its covariance (pose and twist, error-state
    /// order v, w, dV, dW) when the estimator has one: the Kalman filter's own prediction, accelerations and process
    /// noise included, which is where the next measurements are to be looked for. The default carries the state by
    /// its twist, with no covariance.
    ///
    /// ```
    /// use roitrack_estimators::{Estimator, Tracker, TrackerConfig};
    /// use roitrack_core::{CameraModel, Target};
    ///
    /// let tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
    /// // No track yet: nothing to predict.
    /// assert!(tracker.predicted(0.1).is_none());
    /// ```
    fn predicted(&self, t_s: f64) -> Option<(MotionState, Option<Matrix12>)> {
        self.state()
            .map(|(t_ref_s, state)| (state.predicted(t_s - t_ref_s), None))
    }

    /// The options the estimator runs with.
    fn config(&self) -> &TrackerConfig;

    /// The target it tracks.
    fn target(&self) -> &Target;

    /// Counts of what it has done.
    fn report(&self) -> EstimatorReport;

    /// Tells the estimator the target's acceleration (camera frame, [`roitrack_core::Acceleration`]) from `t_s` on, until
    /// the next one given: a known control input, such as the acceleration a controller commands of the robot that
    /// carries the target. The Kalman filter predicts with it, on top of its own motion model (`x' = F x + B u`), so
    /// that a commanded acceleration does not show as a lag of its velocity; its process noise then stands for the
    /// difference between the input and the truth. Inputs come in time order (one at the same time replaces the
    /// previous), may be given ahead of the measurements (a command acts when it acts, not when it is given), and
    /// hold across tracks; an input whose time has passed applies from the filter's time on (what was predicted is
    /// not predicted again). Only the Kalman filter takes one: the other estimators refuse it
    /// ([`KnownAccelerationError::Unsupported`]); a refused input leaves the estimator as it was.
    ///
    /// ```
    /// use nalgebra::Vector3;
    /// use roitrack_estimators::{Estimator, KnownAccelerationError, Tracker, TrackerConfig};
    /// use roitrack_core::{Acceleration, CameraModel, Target};
    ///
    /// let mut tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
    /// // A controller commands 20 m/s² along the optical axis from t = 0.010 s, then stops accelerating at 0.012 s.
    /// let push = Acceleration { linear_mps2: Vector3::new(0.0, 0.0, 20.0), angular_radps2: Vector3::zeros() };
    /// tracker.set_known_acceleration(0.010, push).unwrap();
    /// tracker.set_known_acceleration(0.012, Acceleration { linear_mps2: Vector3::zeros(), ..push }).unwrap();
    /// // Out of order: refused.
    /// assert!(matches!(
    ///     tracker.set_known_acceleration(0.011, push),
    ///     Err(KnownAccelerationError::OutOfOrder { .. })
    /// ));
    /// ```
    fn set_known_acceleration(
        &mut self,
        _t_s: f64,
        _acceleration: roitrack_core::Acceleration,
    ) -> Result<(), KnownAccelerationError> {
        Err(KnownAccelerationError::Unsupported {
            estimator: self.config().estimator.name(),
        })
    }

    /// Forgets every known acceleration given ([`Self::set_known_acceleration`]): the estimator predicts with its
    /// own motion model alone again.
    fn clear_known_acceleration(&mut self) {}
}

/// Implements [`Estimator`] for a newtype around an estimator (a [`track::Track`], or a boxed [`Estimator`]).
macro_rules! delegate_estimator {
    ($name:ident) => {
        impl Estimator for $name {
            fn push(&mut self, m: &Measurement) -> Result<Option<Estimate>, TrackError> {
                self.0.push(m)
            }
            fn push_batch(
                &mut self,
                measurements: &[Measurement],
                emit: $crate::Emit,
            ) -> Result<Option<Estimate>, TrackError> {
                self.0.push_batch(measurements, emit)
            }
            fn first_refused(
                &self,
                measurements: &[Measurement],
            ) -> Option<(usize, $crate::TrackError)> {
                self.0.first_refused(measurements)
            }
            fn reset(&mut self) {
                self.0.reset()
            }
            fn start_from(
                &mut self,
                t_s: f64,
                state: MotionState,
                covariance: Option<$crate::Matrix12>,
            ) {
                self.0.start_from(t_s, state, covariance)
            }
            fn state(&self) -> Option<(f64, MotionState)> {
                self.0.state()
            }
            fn predicted(&self, t_s: f64) -> Option<(MotionState, Option<$crate::Matrix12>)> {
                self.0.predicted(t_s)
            }
            fn config(&self) -> &TrackerConfig {
                self.0.config()
            }
            fn target(&self) -> &Target {
                self.0.target()
            }
            fn report(&self) -> EstimatorReport {
                self.0.report()
            }
            fn set_known_acceleration(
                &mut self,
                t_s: f64,
                acceleration: roitrack_core::Acceleration,
            ) -> Result<(), $crate::KnownAccelerationError> {
                self.0.set_known_acceleration(t_s, acceleration)
            }
            fn clear_known_acceleration(&mut self) {
                self.0.clear_known_acceleration()
            }
        }
    };
}
pub(crate) use delegate_estimator;

/// The estimator chosen by [`TrackerConfig::estimator`], for code that picks it at run time.
///
/// ```
/// use roitrack_estimators::{EstimatorConfig, Estimator, Tracker, TrackerConfig};
/// use roitrack_core::{CameraModel, Target};
///
/// let config = TrackerConfig { estimator: EstimatorConfig::Batch, ..TrackerConfig::default() };
/// let tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), config).unwrap();
/// assert_eq!(tracker.config().estimator.name(), "batch");
/// ```
#[derive(Debug)]
pub struct Tracker(Box<dyn Estimator>);

impl Tracker {
    /// Builds the configured estimator, refusing invalid options.
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
    ) -> Result<Self, ConfigError> {
        let estimator: Box<dyn Estimator> = match config.estimator {
            EstimatorConfig::Kalman(tuning) => {
                Box::new(KalmanEstimator::new(camera, target, config, tuning)?)
            }
            EstimatorConfig::Vvs(settings) => {
                Box::new(VvsEstimator::new(camera, target, config, settings)?)
            }
            EstimatorConfig::Batch => Box::new(BatchEstimator::new(camera, target, config)?),
            EstimatorConfig::Static => Box::new(StaticEstimator::new(camera, target, config)?),
        };
        Ok(Self(estimator))
    }
}

delegate_estimator!(Tracker);

/// Why [`track`] stopped: a measurement could not be read (`S`), was refused, or an estimate could not be handed on
/// (`K`).
#[derive(Debug, Error)]
pub enum StreamError<S, K = S> {
    /// The source of measurements failed (a file that cannot be read, say).
    #[error(transparent)]
    Source(S),
    /// The estimator refused measurement number `index` (0-based) of the stream.
    #[error("measurement {index}: {source}")]
    Refused {
        /// The measurement's index in the stream (0-based).
        index: usize,
        /// Why the estimator refused it.
        #[source]
        source: TrackError,
    },
    /// The sink of estimates failed (a file that cannot be written, say).
    #[error(transparent)]
    Sink(K),
}

/// Runs `estimator` over a stream of measurements (times not decreasing), handing every estimate to `sink` as it
/// comes: constant memory whatever the stream's length. Returns the estimator's report.
///
/// Consecutive measurements that share a time (the blobs of a global-shutter frame) are one readout, pushed whole
/// ([`Estimator::push_batch`]): its estimate comes after the last of them, so no two estimates share a time and none
/// rests on half a frame, and the Kalman filter fits a readout of three or more together, as the frame tracker's
/// does. A readout of several measurements gives one estimate ([`Emit::EachBatch`]: one per frame, as the frame
/// tracker gives them, whatever [`TrackerConfig::every`] says); measurements that come one at a time (ROIs, a rolling
/// shutter's rows) one every `every` ([`Emit::Every`]). A readout longer than 4,096 measurements is pushed in
/// parts ([`Emit::Hold`] until its last), so memory stays bounded. When the estimator refuses a measurement of a readout
/// (which leaves it as it was), the ones before it are taken (as one readout, [`Estimator::first_refused`]) and the
/// error names the measurement refused by its place in the stream.
///
/// ```
/// use roitrack_estimators::{Tracker, TrackerConfig, track};
/// use roitrack_core::{CameraModel, Measurement, Target};
///
/// let mut tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
/// let measurements = [Measurement { t_s: 0.0, id: 99, u_px: 1.0, v_px: 1.0 }];
/// let mut estimates = Vec::new();
/// let result = track(
///     &mut tracker,
///     measurements.iter().map(|m| Ok::<_, std::convert::Infallible>(*m)),
///     |e| Ok::<_, std::convert::Infallible>(estimates.push(*e)),
/// );
/// // Point 99 is not in the target: refused, with its place in the stream.
/// let error = result.unwrap_err().to_string();
/// assert!(error.starts_with("measurement 0: ") && error.contains("id 99"), "{error}");
/// ```
pub fn track<S, K>(
    estimator: &mut dyn Estimator,
    measurements: impl IntoIterator<Item = Result<Measurement, S>>,
    mut sink: impl FnMut(&Estimate) -> Result<(), K>,
) -> Result<EstimatorReport, StreamError<S, K>> {
    // Measurements that share a time are gathered; the readout they form is pushed (and an estimate given if one is
    // due) when a later time comes, or the stream ends. `first_index`: the stream index of its first measurement.
    let mut readout: Vec<Measurement> = Vec::with_capacity(64);
    let mut first_index = 0;
    // Whether the open readout holds several measurements (a frame), some of them maybe pushed already.
    let mut frame = false;
    // A frame's estimate comes with the frame, whatever `every` says (an estimate every 10 measurements would give
    // one every two or three frames of four dots); one measurement at a time, every `every`.
    let closing = |frame: bool| if frame { Emit::EachBatch } else { Emit::Every };
    for (index, m) in measurements.into_iter().enumerate() {
        let m = m.map_err(StreamError::Source)?;
        let same_time = readout.first().is_some_and(|r| r.t_s == m.t_s);
        if same_time {
            frame = true;
        }
        if !readout.is_empty() && (!same_time || readout.len() == MAX_READOUT) {
            let emit = if same_time {
                Emit::Hold
            } else {
                closing(frame)
            };
            push_readout(estimator, &readout, first_index, emit, &mut sink)?;
            readout.clear();
            frame &= same_time;
        }
        if readout.is_empty() {
            first_index = index;
        }
        readout.push(m);
    }
    if !readout.is_empty() {
        push_readout(estimator, &readout, first_index, closing(frame), &mut sink)?;
    }
    Ok(estimator.report())
}

/// The longest readout (measurements that share a time) that [`track`] pushes at once; a longer one goes in parts.
const MAX_READOUT: usize = 4096;

/// Pushes one readout of [`track`]'s stream (`first_index`: the stream index of its first measurement) and hands on
/// its estimate.
fn push_readout<S, K>(
    estimator: &mut dyn Estimator,
    readout: &[Measurement],
    first_index: usize,
    emit: Emit,
    sink: &mut impl FnMut(&Estimate) -> Result<(), K>,
) -> Result<(), StreamError<S, K>> {
    let refused_at = |index: usize| move |source| StreamError::Refused { index, source };
    let last_index = first_index + readout.len().saturating_sub(1);
    let result = match estimator.push_batch(readout, emit) {
        // A measurement was refused before any was taken: the ones before it are taken (as one readout) and the
        // error names it.
        Err(error) if !matches!(error, TrackError::ImplausibleFirstPose { .. }) => {
            let offset = estimator
                .first_refused(readout)
                .map_or(0, |(offset, _)| offset);
            if offset > 0 {
                estimator
                    .push_batch(&readout[..offset], Emit::Hold)
                    .map_err(refused_at(first_index + offset - 1))?;
            }
            return Err(refused_at(first_index + offset)(error));
        }
        // Taken; or taken and the estimate it closes refused (a first pose out of range): the readout's last.
        result => result,
    };
    match result.map_err(refused_at(last_index))? {
        Some(estimate) => sink(&estimate).map_err(StreamError::Sink),
        None => Ok(()),
    }
}

/// Runs the estimator that `config` chooses over measurements held in memory; returns every estimate and the report.
///
/// ```
/// use roitrack_estimators::{TrackerConfig, track_all};
/// use roitrack_core::{CameraModel, Target};
///
/// let (estimates, report) =
///     track_all(&CameraModel::canonical(), &Target::grid4x4(), TrackerConfig::default(), &[]).unwrap();
/// assert!(estimates.is_empty() && report.measurements == 0);
/// ```
pub fn track_all(
    camera: &CameraModel,
    target: &Target,
    config: TrackerConfig,
    measurements: &[Measurement],
) -> Result<(Vec<Estimate>, EstimatorReport), TrackAllError> {
    let mut tracker = Tracker::new(camera.clone(), target.clone(), config)?;
    let mut estimates = Vec::with_capacity(measurements.len() / config.every.max(1) + 1);
    let report = track(
        &mut tracker,
        measurements
            .iter()
            .map(|m| Ok::<_, std::convert::Infallible>(*m)),
        |e| {
            estimates.push(*e);
            Ok::<_, std::convert::Infallible>(())
        },
    )
    .map_err(|e| match e {
        StreamError::Refused { index, source } => TrackAllError::Refused { index, source },
        StreamError::Source(never) | StreamError::Sink(never) => match never {},
    })?;
    Ok((estimates, report))
}

/// Why [`track_all`] failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrackAllError {
    /// The tracker's configuration was refused.
    #[error("invalid tracker options: {0}")]
    Config(#[from] ConfigError),
    /// The estimator refused a measurement.
    #[error("measurement {index}: {source}")]
    Refused {
        /// The measurement's index in the slice (0-based).
        index: usize,
        /// Why the estimator refused it.
        #[source]
        source: TrackError,
    },
}

/// 1-sigma standard deviations of an error-state covariance, in the order (v, w, dV, dW).
///
/// ```
/// use roitrack_estimators::{Matrix12, standard_deviations};
/// let sigmas = standard_deviations(&(Matrix12::identity() * 4.0));
/// assert_eq!(sigmas, [2.0; 12]);
/// ```
pub fn standard_deviations(covariance: &Matrix12) -> [f64; 12] {
    std::array::from_fn(|i| covariance[(i, i)].max(0.0).sqrt())
}
