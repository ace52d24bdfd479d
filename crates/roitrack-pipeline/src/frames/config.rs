//! The frame tracker's settings, and the estimator's tuning made for frames.

use roitrack_estimators::{
    Adaptation, EstimatorConfig, MotionModel, MotionModelKind, NoiseSample, TrackerConfig,
};
use roitrack_image::CentroidOptions;

use crate::scheduler::SchedulerConfig;
use roitrack_detect::photo::PhotoOptions;

#[cfg(doc)]
use super::{FrameTracker, track_frame_stream};

/// Settings of a [`FrameTracker`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTrackerConfig {
    /// The estimator. Its `every` is not used: one estimate per frame.
    pub tracker: TrackerConfig,
    /// The full-frame search (polarity, blob filters, distance range).
    pub detection: PhotoOptions,
    /// Window sizing (sizes between `min_size_px` and `max_size_px`, at most 64).
    pub windows: SchedulerConfig,
    /// How each blob is measured in its window once the window is flattened: the threshold (an automatic one is
    /// taken from the background the flattening found), the weighting, the area limits and the symmetry check. The
    /// whole-frame search measures with `detection` instead.
    pub centroid: CentroidOptions,
    /// Fewest blobs found in their windows for a frame to be tracked from its windows; with fewer, the frame is
    /// searched whole. `None`: half the target's points, and at least 4.
    pub min_window_points: Option<usize>,
    /// The user chose the Kalman filter's jerk densities (`track --jerk-psd`, `--angular-jerk-psd`): they are kept
    /// with a rolling shutter too, even where they equal the global-shutter defaults (which a rolling shutter
    /// otherwise replaces, see `FrameTracker::new`). `false`: the readout's defaults.
    pub jerk_psd_given: bool,
    /// With a rolling shutter, [`track_frame_stream`] (offline sources) holds each estimate until the four frames
    /// after it are tracked and refits its pose with the twist of the poses around it
    /// ([`crate::rs_smoothing::RollingSmoother`]; docs/frames.md, "Rolling shutter: offline smoothing", has what
    /// it gains). Ignored with a global shutter (a pose read at one instant does not depend on the twist) and by
    /// [`FrameTracker::process`] itself (live runs). Default: on.
    pub rs_smoothing: bool,
}

impl Default for FrameTrackerConfig {
    fn default() -> Self {
        Self {
            tracker: FrameTrackerConfig::frame_estimator(TrackerConfig::default(), None, None),
            detection: PhotoOptions::default(),
            // Three standard deviations: at frame rates the prediction's spread is many pixels (a target
            // accelerating at 17 m/s² strays 9 mm from a constant-velocity prediction in 1/30 s), and a window must
            // stay within the 64 px the centroid handles.
            windows: SchedulerConfig {
                sigma_margin: 3.0,
                ..SchedulerConfig::default()
            },
            centroid: CentroidOptions::default(),
            min_window_points: None,
            jerk_psd_given: false,
            rs_smoothing: true,
        }
    }
}

impl FrameTrackerConfig {
    /// `config` made for frames, unless the user's choices say otherwise (`track --adapt` as `adapt`,
    /// `track --motion-model` as `motion`):
    /// - The Kalman filter's process model is constant acceleration (unless `motion` is constant velocity; the
    ///   densities of a `config` that already has it are kept). Between frames tens of milliseconds apart the twist
    ///   changes, and a rolling-shutter frame's blobs, read one row band after the other, pin its depth only through
    ///   a twist that is right over the readout (docs/estimation.md, "Frame cameras", has the study that chose it).
    /// - The filter learns the centroid noise from global-shutter frames, each from the residual of its own blobs
    ///   with the pose alone fitted, and holds it for rolling-shutter frames ([`NoiseSample::Frames`] says why).
    /// - It keeps the process noise it is given (that adaptation follows the innovations from one measurement to
    ///   the next: within a global-shutter frame they share one instant, and the filter leaves it alone there
    ///   whatever `adapt` says; on rolling-shutter frames at 30 Hz it chases the jitter between frames and sends
    ///   frames to whole-frame searches).
    /// - Its twist covariance is never calibrated against the poses around each estimate (8 estimates either side
    ///   are half a second at 30 Hz).
    ///
    /// ```
    /// use roitrack_estimators::{
    ///     Adaptation, EstimatorConfig, MotionModel, MotionModelKind, NoiseSample, TrackerConfig,
    /// };
    /// use roitrack_pipeline::frames::FrameTrackerConfig;
    ///
    /// let config = FrameTrackerConfig::frame_estimator(TrackerConfig::default(), None, None);
    /// let EstimatorConfig::Kalman(tuning) = config.estimator else { unreachable!() };
    /// assert!(tuning.adapt_noise && !tuning.adapt_motion && !tuning.calibrate_twist_covariance);
    /// assert_eq!(tuning.noise_sample, NoiseSample::Frames);
    /// assert_eq!(tuning.motion_model, MotionModel::constant_acceleration());
    ///
    /// // A hand-tuned constant-velocity filter: nothing learnt.
    /// let config = FrameTrackerConfig::frame_estimator(
    ///     TrackerConfig::default(),
    ///     Some(Adaptation::None),
    ///     Some(MotionModelKind::ConstantVelocity),
    /// );
    /// let EstimatorConfig::Kalman(tuning) = config.estimator else { unreachable!() };
    /// assert!(!tuning.adapt_noise && !tuning.adapt_motion && !tuning.calibrate_twist_covariance);
    /// assert_eq!(tuning.motion_model, MotionModel::ConstantVelocity);
    /// ```
    pub fn frame_estimator(
        mut config: TrackerConfig,
        adapt: Option<Adaptation>,
        motion: Option<MotionModelKind>,
    ) -> TrackerConfig {
        if let EstimatorConfig::Kalman(tuning) = &mut config.estimator {
            let adapt = adapt.unwrap_or(Adaptation::Noise);
            tuning.adapt_noise = matches!(adapt, Adaptation::Both | Adaptation::Noise);
            tuning.adapt_motion = matches!(adapt, Adaptation::Both | Adaptation::Motion);
            tuning.calibrate_twist_covariance = false;
            tuning.noise_sample = NoiseSample::Frames;
            tuning.motion_model = match (motion, tuning.motion_model) {
                (Some(MotionModelKind::ConstantVelocity), _) => MotionModel::ConstantVelocity,
                (_, given @ MotionModel::ConstantAcceleration { .. }) => given,
                (_, MotionModel::ConstantVelocity) => MotionModel::constant_acceleration(),
            };
        }
        config
    }
}
