//! The default estimator: an error-state extended Kalman filter on the 12-dof state with a constant-velocity (or a
//! constant-acceleration) process model; every centroid updates the state once, at its own time.
//!
//! The error state is the correction `δ = (v, w, dV, dW)` of [`MotionState::corrected`]. Between measurements the
//! state moves with its twist; the twist drifts as a random walk driven by white linear and angular acceleration of
//! spectral densities `q_a` ((m/s²)²/Hz) and `q_α` ((rad/s²)²/Hz). Innovations beyond the gate are rejected as
//! outliers; a run of rejections widens the covariance (a jump of the target, or a bad update), by escalating steps.
//! With [`MotionModel::ConstantAcceleration`] the state also carries the linear and angular accelerations (18 error
//! states), which drift under white jerk; the frame tracker uses it. After their updates one by one, the blobs of
//! one readout (a frame) are also fitted together by an iterated update (`ErrorStateKalman::refine`); a readout of
//! one instant half or more of whose blobs are rejected is taken again from a covariance widened at once to the broad
//! prior (the filter no longer predicts the target), and kept if it explains more of them than the first pass.
//!
//! By default the filter is told neither the noise of the centroids nor how the target moves; it learns both:
//! - **Centroid noise**: at each control step, the window's least-squares residual at its own optimum divided by its
//!   redundancy (`2 m - 12` for m measurements) is an unbiased sample of the noise variance, whatever the process
//!   noise; an exponential memory of about 2,000 degrees of freedom averages them, each window moving the estimate by
//!   at most a factor 4 (an outlier does not drag it). The initialisation starts it from the median residual of its
//!   two-cycle fit, so that a noise ten times the configured one still initialises. Steps whose measurements share
//!   one instant (global-shutter frames) sample their own measurements instead, the pose alone fitted
//!   ([`NoiseSample`]). On streams of measurements one at a time, each point also learns its share of that noise
//!   from the second differences of its own innovations (`point_noise`): a noisier blob is weighted down and gated
//!   by its own noise.
//! - **Process noise**: the linear and the angular density are each scaled by a factor that follows the
//!   *persistence* of the innovations: the innovation projected on the displacement that the recent corrections
//!   (their exponential average over the filter's own time constant, at least two cycles) predict for the measured
//!   point, normalised to a standard normal variable. Innovations of a filter with the right gain are white and
//!   their persistence averages zero; a lagging filter keeps correcting one way (positive), a filter that chases the
//!   noise undoes its corrections (negative).
//!   The logarithm of each factor moves by 0.05 times the persistence per measurement: a still target is averaged
//!   down, a manoeuvre raises the process noise within tens of measurements. Steps whose measurements share one
//!   instant (frames) leave the factors as they are.
//!
//! With [`KalmanTuning::adapt_noise`] and [`KalmanTuning::adapt_motion`] off, the filter takes
//! [`TrackerConfig::noise_px`] and the densities as the truth: a hand-tuned filter.

use nalgebra::{Matrix2, Rotation3, SMatrix, SVector, Vector2, Vector3, Vector6};

use super::calibration::TwistCalibration;
use super::point_noise::PointNoise;
use super::problem::{Observation, ResidualFigures, ResidualTally, TallyMark};
use super::track::{Law, Step, Track, TrackCore};
use super::{
    ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport, TrackError, TrackStatus,
    TrackerConfig,
};
use roitrack_core::{
    Acceleration, CameraModel, JacobianKind, Measurement, MotionState, SpatioTemporalModel, Target,
    Vector12, so3,
};

mod filter;
mod known;
mod law;
mod motion_model;
mod noise;
mod readout;
#[cfg(test)]
mod tests;
mod tuning;

pub(crate) use filter::pose_matching_scale;
use filter::*;
pub(crate) use known::KnownAcceleration;
pub use known::{KNOWN_ACCELERATION_CAPACITY, KnownAccelerationError};
use law::*;
use motion_model::*;
use noise::*;
use readout::*;
pub use tuning::{KalmanTuning, MotionModel, NoiseSample};

/// A 12 x 12 matrix: covariances of the error state (v, w, dV, dW).
pub type Matrix12 = SMatrix<f64, 12, 12>;

/// The default estimator: an error-state Kalman filter, every centroid one update at its own time (see the
/// [module documentation](self)).
///
/// ```
/// use roitrack_estimators::{Estimator, KalmanEstimator, KalmanTuning, TrackerConfig};
/// use roitrack_core::{CameraModel, Measurement, Target};
///
/// let mut kalman = KalmanEstimator::new(
///     CameraModel::canonical(),
///     Target::grid4x4(),
///     TrackerConfig::default(),
///     KalmanTuning::default(),
/// )
/// .unwrap();
/// // Until two cycles over the 16 points have been seen, there is nothing to estimate.
/// let m = Measurement { t_s: 0.0, id: 0, u_px: 480.0, v_px: 480.0 };
/// assert_eq!(kalman.push(&m).unwrap(), None);
/// assert_eq!(kalman.report().measurements, 1);
/// ```
#[derive(Debug, Clone)]
pub struct KalmanEstimator(Track<KalmanLaw>);

impl KalmanEstimator {
    /// A Kalman filter for `camera` and `target` with the common options of `config` and the filter's `tuning`
    /// (which replaces `config.estimator`).
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
        tuning: KalmanTuning,
    ) -> Result<Self, ConfigError> {
        Track::new(
            camera,
            target,
            config,
            EstimatorConfig::Kalman(tuning),
            KalmanLaw::new(tuning),
        )
        .map(Self)
    }
}

super::delegate_estimator!(KalmanEstimator);
