//! What an estimator gives: an [`Estimate`] of the state with its figures, and the [`TrackStatus`] that says
//! whether it is vouched for.

use roitrack_core::MotionState;

use crate::Matrix12;
#[cfg(doc)]
use crate::{MotionModel, StatusCounts, TrackerConfig};

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
