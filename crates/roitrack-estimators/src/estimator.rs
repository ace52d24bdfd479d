//! The [`Estimator`] trait that every estimator implements, when its batches give an estimate ([`Emit`]), why it
//! refuses a measurement ([`TrackError`]), and the macro that implements the trait for a newtype by delegation.

use roitrack_core::{Measurement, MotionState, Target};
use thiserror::Error;

use crate::{Estimate, EstimatorReport, KnownAccelerationError, Matrix12, TrackerConfig};
#[cfg(doc)]
use crate::{KalmanEstimator, track};

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

/// A streaming pose-and-velocity estimator (see the [module documentation](crate)).
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
