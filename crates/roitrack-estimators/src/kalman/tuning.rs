//! How a user tunes the Kalman filter: its densities, gate, what it learns, and its motion model.

/// Tuning of the Kalman filter.
///
/// ```
/// use roitrack_estimators::{EstimatorConfig, KalmanTuning, TrackerConfig};
/// // A hand-tuned filter: less lag, more noise with a larger linear acceleration density, held fixed.
/// let tuning = KalmanTuning { linear_accel_psd: 10.0, adapt_motion: false, ..KalmanTuning::default() };
/// let config = TrackerConfig { estimator: EstimatorConfig::Kalman(tuning), ..TrackerConfig::default() };
/// assert!(config.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanTuning {
    /// White linear acceleration spectral density q_a ((m/s²)²/Hz). Larger: less lag, more noise. With
    /// [`Self::adapt_motion`], only the starting value.
    pub linear_accel_psd: f64,
    /// White angular acceleration spectral density q_α ((rad/s²)²/Hz). With [`Self::adapt_motion`], only the
    /// starting value.
    pub angular_accel_psd: f64,
    /// Innovations beyond this many standard deviations (Mahalanobis, 2 dof) are rejected as outliers. Default 3:
    /// it rejects exp(-9/2) = 1.1 % of good measurements. Against 6, it costs little on clean measurements and keeps
    /// the error far lower when reflections merge with blobs (a reflection biases the centroid by a fraction of a
    /// pixel, well inside 6 σ of the prediction); 3.5 does worse (measured in docs/results.md, "Reflections in the
    /// ROIs: the symmetry check").
    pub gate_sigma: f64,
    /// Huber threshold (standard deviations, Mahalanobis): a larger innovation gets its measurement noise inflated
    /// by `distance / huber_sigma` (the Huber weight), so a moderate outlier pulls less; `f64::INFINITY` turns it off.
    pub huber_sigma: f64,
    /// Estimate the centroid noise online from the innovations (default): `TrackerConfig::noise_px` is then only the
    /// starting value. Off, the filter takes `noise_px` as the truth (a hand-tuned filter).
    pub adapt_noise: bool,
    /// Let the process noise follow the motion (default): the acceleration densities above are then only starting
    /// values, lowered while the innovations show the filter over-reacting (a still target is averaged down) and
    /// raised while they show it lagging. Off, they are fixed (a hand-tuned filter).
    pub adapt_motion: bool,
    /// Scale the reported covariance of the linear and the angular velocity (default) by how far the estimates'
    /// twists actually stray from the mean twist of the poses around them (see docs/estimation.md): the process noise
    /// the filter needs to follow manoeuvres makes it claim a velocity uncertainty two to four times too wide on
    /// smooth motion. Only the reported covariance changes, never the estimate.
    pub calibrate_twist_covariance: bool,
    /// Which residual the noise estimate samples (with [`Self::adapt_noise`]). Default [`NoiseSample::Window`].
    pub noise_sample: NoiseSample,
    /// With [`Self::adapt_noise`], let each point learn its share of the noise on streams of measurements one at a
    /// time (default; docs/estimation.md): a blob noisier than the others is weighted down and gated by its own noise.
    /// Off, every point takes the target's noise.
    pub learn_point_noise: bool,
    /// How the filter expects the target to move between measurements. Default
    /// [`MotionModel::ConstantVelocity`], driven by [`Self::linear_accel_psd`] and [`Self::angular_accel_psd`].
    pub motion_model: MotionModel,
}

/// The Kalman filter's process model.
///
/// ```
/// use roitrack_estimators::{KalmanTuning, MotionModel};
///
/// assert_eq!(KalmanTuning::default().motion_model, MotionModel::ConstantVelocity);
/// let tuning = KalmanTuning { motion_model: MotionModel::constant_acceleration(), ..KalmanTuning::default() };
/// assert!(matches!(tuning.motion_model, MotionModel::ConstantAcceleration { .. }));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionModel {
    /// The twist drifts as a random walk driven by white acceleration of the tuning's densities
    /// ([`KalmanTuning::linear_accel_psd`], [`KalmanTuning::angular_accel_psd`]); the 12-state filter.
    ConstantVelocity,
    /// The state also carries the linear and the angular acceleration (18 states), which drift as a random walk
    /// driven by white jerk of these spectral densities ((m/s³)²/Hz and (rad/s³)²/Hz). It predicts across the gaps
    /// where a constant twist falls behind a changing one: between rolling-shutter frames, whose blobs are read one
    /// row band after the other, a turn that speeds up between two frames leaves a constant-twist filter a twist
    /// that is wrong over the next frame's readout, which the frame's depth absorbs. More work per update than the
    /// 12-state filter (`roitrack bench --json` measures it: `kalman_update_constant_acceleration_us_median`).
    ConstantAcceleration {
        /// Spectral density of the white linear jerk ((m/s³)²/Hz): how fast the linear acceleration may drift.
        linear_jerk_psd: f64,
        /// Spectral density of the white angular jerk ((rad/s³)²/Hz): how fast the angular acceleration may drift.
        angular_jerk_psd: f64,
    },
}

impl MotionModel {
    /// [`Self::ConstantAcceleration`] with its default densities.
    pub fn constant_acceleration() -> Self {
        Self::constant_acceleration_with(None, None)
    }

    /// [`Self::ConstantAcceleration`] with the frame tracker's densities for rolling-shutter frames, ten times the
    /// defaults': a rolling-shutter frame's blobs, read over milliseconds, show the motion within the frame, so the
    /// filter can follow faster changes of acceleration without taking each frame's noise for motion (global-shutter
    /// frames, one instant each, cannot tell the two apart).
    pub fn constant_acceleration_for_rolling_shutter() -> Self {
        Self::ConstantAcceleration {
            linear_jerk_psd: 10.0 * DEFAULT_LINEAR_JERK_PSD,
            angular_jerk_psd: 10.0 * DEFAULT_ANGULAR_JERK_PSD,
        }
    }

    /// [`Self::ConstantAcceleration`] with these densities, the defaults where `None`.
    pub fn constant_acceleration_with(
        linear_jerk_psd: Option<f64>,
        angular_jerk_psd: Option<f64>,
    ) -> Self {
        Self::ConstantAcceleration {
            linear_jerk_psd: linear_jerk_psd.unwrap_or(DEFAULT_LINEAR_JERK_PSD),
            angular_jerk_psd: angular_jerk_psd.unwrap_or(DEFAULT_ANGULAR_JERK_PSD),
        }
    }
}

/// The constant-acceleration model's default white jerk densities ((m/s³)²/Hz and (rad/s³)²/Hz).
pub(super) const DEFAULT_LINEAR_JERK_PSD: f64 = 100.0;

pub(super) const DEFAULT_ANGULAR_JERK_PSD: f64 = 300.0;

/// Which residuals the Kalman filter's noise estimate samples.
///
/// Measurements that come a frame at a time (the blobs of global-shutter frames, several at each time) are sampled
/// frame by frame in either case: each frame's residual with its pose alone fitted and the twist held at the
/// filter's, of redundancy `2 m - 6`. A frame alone cannot tell the twist, and a window spanning several frames, tens
/// of milliseconds apart, takes the motion's change for noise: a 4-point target's window learnt many times the true
/// noise (measured in docs/results.md, "Design measurements behind the code").
///
/// ```
/// use roitrack_estimators::{KalmanTuning, NoiseSample};
///
/// assert_eq!(KalmanTuning::default().noise_sample, NoiseSample::Window);
/// // What the frame tracker uses.
/// let frames = KalmanTuning { noise_sample: NoiseSample::Frames, ..KalmanTuning::default() };
/// assert!(frames.adapt_noise);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseSample {
    /// Every other control step: its window (as [`crate::TrackerConfig::window`] selects it, at least
    /// 24 measurements for targets of fewer than 12 points) under one constant twist, all 12 parameters fitted: right
    /// for ROIs, a few milliseconds apart.
    Window,
    /// Only the steps of one instant: the measurements come a frame at a time, and a rolling-shutter frame (whose
    /// blobs are not simultaneous) leaves the noise as it is. Its own residual misses what matters there: its blobs
    /// also pin the twist, through the image's stretch over the readout, and an error of the twist over the readout
    /// bends the frame in ways the pose absorbs. Learnt from rolling-shutter frames that way, the noise came out near
    /// the centroids' alone, which helped on one simulated camera but hurt on another (measured in docs/results.md,
    /// "Design measurements behind the code").
    Frames,
}

impl Default for KalmanTuning {
    fn default() -> Self {
        Self {
            linear_accel_psd: 1.0,
            angular_accel_psd: 10.0,
            gate_sigma: 3.0,
            huber_sigma: 2.5,
            adapt_noise: true,
            adapt_motion: true,
            calibrate_twist_covariance: true,
            noise_sample: NoiseSample::Window,
            learn_point_noise: true,
            motion_model: MotionModel::ConstantVelocity,
        }
    }
}
