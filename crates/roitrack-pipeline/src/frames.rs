//! Tracking from whole frames (image sequences, videos, frame cameras with a global or a rolling shutter): every
//! blob centroid becomes a measurement at its own time, and each frame gives one estimate.
//!
//! Per frame ([`FrameTracker::process`]):
//!
//! 1. With a running track, each target point's blob is predicted from the last estimate (pose, twist and, with the
//!    constant-acceleration filter, accelerations) at the time its row is read (for a rolling shutter, row `v` is read `v * line_delay_s` after row 0: the predicted row
//!    gives the time, the time the row), and measured in a small window there, the ROI path of the paper: the window
//!    is sized by the [`RoiScheduler`] (blob size, motion blur, the prediction's uncertainty), its background is a
//!    plane fitted to its border and taken away (for dark blobs the window is divided by it: printed circles under
//!    uneven light keep their contrast, not their difference). The blob's centre is a weighted mean of the window's
//!    moments ([`measure_blob`]) and of its outline's centre (`CentreBlend`), less the perspective displacement of a
//!    disk's centre.
//! 2. When fewer than [`FrameTrackerConfig::min_window_points`] blobs were found in their windows (the target
//!    accelerated out of them, or was hidden), the target is searched for and identified in the whole frame with no
//!    prior ([`detect_target`]: either polarity, clutter, partial views) and its blobs continue the track; only if
//!    that fails does each predicted point take the blob nearest to it, within half the distance between predicted
//!    points. Without a track, a new one starts from the identified target's static pose, with the twist that
//!    carried the last trusted pose to it.
//! 3. The frame's measurements, in time order, are one batch for the estimator ([`Estimator::push_batch`] with
//!    [`Emit::EachBatch`]): one estimate per frame, at the mean time of its measurements (the estimator's state at the
//!    newest one, carried back by its twist: with a rolling shutter the pose is pinned best in the middle of the
//!    target's readout).
//!    The estimator fits the frame's blobs together (an iterated update, for the Kalman filter).
//! 4. An estimate that is disputed or lost, that puts the frame's blobs more than 5 px from where they were measured,
//!    or whose filter widened its covariance within the frame, is replaced: the frame is found whole and a new track
//!    starts from it.
//!
//! A track the estimator declares lost is dropped, and the next frame is searched whole.
//!
//! [`track_frame_stream`] runs a [`FrameTracker`] over a source of frames with the decoding on its own thread.

use std::sync::mpsc;

use nalgebra::{Vector2, Vector3};
use roitrack_core::estimator::Matrix12;
use roitrack_core::estimator::{
    Adaptation, ConfigError, Emit, Estimate, Estimator, EstimatorConfig, EstimatorReport,
    MotionModel, MotionModelKind, NoiseSample, Observation, TrackError, TrackStatus, Tracker,
    TrackerConfig, refine_static_pose,
};
use roitrack_core::target::{Symmetry, TargetAmbiguity};
use roitrack_core::{
    Acceleration, CameraModel, Measurement, MotionState, SpatioTemporalModel, Target,
};
use roitrack_image::centroid::{
    AUTO_MIN_CONTRAST_DN, AUTO_MIN_CONTRAST_SIGMAS, AUTO_THRESHOLD_FRACTION,
};
use roitrack_image::photo::{OutlineScratch, outline_centre};
use roitrack_image::{
    BlobRejection, Centroid, CentroidOptions, Frame, PhotoBlobOptions, PhotoScratch, Polarity,
    RejectionCounts, Roi, Threshold, detect_photo_blobs, measure_blob, measure_blob_near,
};
use thiserror::Error;

use crate::identify::disk_centre_displacement_px;
use crate::photo::{PhotoOptions, PolarityChoice, detect_target};
use crate::realtime::full_frame_covariance;
use crate::rs_smoothing::RollingSmoother;
use crate::scheduler::{Predictor, RoiRequest, RoiScheduler, SchedulerConfig};

/// Settings of a [`FrameTracker`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTrackerConfig {
    /// The estimator. Its `every` is not used: one estimate per frame.
    pub tracker: TrackerConfig,
    /// The full-frame search (polarity, blob filters, distance range).
    pub detection: PhotoOptions,
    /// Window sizing (sizes between `min_size_px` and `max_size_px`, at most 64).
    pub windows: SchedulerConfig,
    pub centroid: CentroidOptions,
    /// Fewest blobs found in their windows for a frame to be tracked from its windows; with fewer, the frame is
    /// searched whole. `None`: half the target's points, and at least 4.
    pub min_window_points: Option<usize>,
    /// The user chose the Kalman filter's jerk densities (`track --jerk-psd`, `--angular-jerk-psd`): they are kept
    /// with a rolling shutter too, even where they equal the global-shutter defaults (which a rolling shutter
    /// otherwise replaces, see `FrameTracker::new`). `false`: the readout's defaults.
    pub jerk_psd_given: bool,
    /// With a rolling shutter, [`track_frame_stream`] (offline sources) holds each estimate until the two frames
    /// after it are tracked and refits its pose with the twist of the poses around it
    /// ([`crate::rs_smoothing::RollingSmoother`]): on `simulate --scenario sweep --speed-scale 2`, 0.043 mm off
    /// with it, 0.179 mm without (0.0153 mm for global-shutter frames). Ignored with a global shutter (a pose read at one
    /// instant does not depend on the twist) and by [`FrameTracker::process`] itself (live runs). Default: on.
    pub rs_smoothing: bool,
}

impl Default for FrameTrackerConfig {
    fn default() -> Self {
        Self {
            tracker: FrameTrackerConfig::frame_estimator(TrackerConfig::default(), None, None),
            detection: PhotoOptions::default(),
            // Three standard deviations: at frame rates the prediction's spread is many pixels (a target
            // accelerating at 17 m/s² strays 9 mm from a constant-velocity prediction in 1/30 s), and a window must stay
            // within the 64 px the centroid handles.
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
    ///   a twist that is right over the readout: on `roitrack frame-study`, constant acceleration took the
    ///   rolling-shutter position error from 0.175 to 0.041 mm and the velocity error of global-shutter frames from
    ///   19.2 to 3.3 mm/s.
    /// - The filter learns the centroid noise from global-shutter frames, each from the residual of its own blobs
    ///   with the pose alone fitted, and holds it for rolling-shutter frames ([`NoiseSample::Frames`] says why).
    /// - It keeps the process noise it is given (that adaptation follows the innovations from one measurement to
    ///   the next: within a global-shutter frame they share one instant, and the filter leaves it alone there
    ///   whatever `adapt` says; on rolling-shutter frames at 30 Hz it chases the jitter between frames, and
    ///   `roitrack frame-study` had 79 of 540 of them fall back to whole-frame searches, 0.208 mm off against
    ///   0.175 mm, with constant velocity).
    /// - Its twist covariance is never calibrated against the poses around each estimate (8 estimates either side
    ///   are half a second at 30 Hz).
    ///
    /// ```
    /// use roitrack_core::estimator::{
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

/// The oldest last trusted pose a new track takes its twist from (s): three frames at 30 Hz.
const RESTART_TWIST_MAX_GAP_S: f64 = 0.1;
/// The standard deviations of that twist (m/s, rad/s).
const RESTART_TWIST_SIGMAS: [f64; 2] = [0.3, 1.0];
/// A frame whose blobs lie farther than this (RMS, px) from where its estimate puts them is found whole and starts
/// a new track: far beyond any centroid's noise, and beyond what a rolling-shutter frame's readout leaves the filter
/// (whose rolling model the static pose of a new track lacks).
const RESTART_RESIDUAL_PX: f64 = 5.0;

/// How a frame was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameMethod {
    /// In windows around the predicted blobs.
    Windows,
    /// By a full-frame search, continuing the track.
    FullFrame,
    /// By a full-frame search that started a new track.
    Restart,
    /// The target was not found: no estimate.
    NotFound,
}

impl FrameMethod {
    /// `windows`, `full-frame`, `restart` or `not-found`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Windows => "windows",
            Self::FullFrame => "full-frame",
            Self::Restart => "restart",
            Self::NotFound => "not-found",
        }
    }
}

/// What one frame gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOutcome {
    /// The frame's estimate, if the target was measured and the estimator gave one.
    pub estimate: Option<Estimate>,
    pub method: FrameMethod,
    /// Blobs measured in the frame.
    pub measured: usize,
}

/// What a [`FrameTracker`] has done.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTrackReport {
    pub frames: usize,
    /// Frames measured in windows, by a full-frame search that continued the track, or that started a new one.
    pub by_windows: usize,
    pub by_full_frame: usize,
    pub restarts: usize,
    /// Frames in which the target was not found.
    pub not_found: usize,
    /// Frames that gave an estimate.
    pub estimates: usize,
    /// Blobs not found in their windows, by reason.
    pub window_rejections: RejectionCounts,
    /// Blobs left out of their windows because they were nearer another point's prediction than their own: a
    /// neighbour of a dense target, when the point's own blob was not seen or the prediction missed it.
    pub neighbour_blobs: usize,
    /// The weight of the blobs' outlines in the centres of the last frame measured in windows (their moments' is 1
    /// minus it; see `CentreBlend` in the source); 0 before any.
    pub outline_weight: f64,
    /// The polarity in use (decided by the first full-frame search with [`PolarityChoice::Auto`]).
    pub polarity: Option<Polarity>,
    pub estimator: EstimatorReport,
}

/// Why a frame could not be processed at all (a frame in which the target is not found is not an error).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FrameError {
    #[error("the frame is {width} x {height} px, the camera's {camera_width} x {camera_height} px")]
    Size {
        width: u32,
        height: u32,
        camera_width: u32,
        camera_height: u32,
    },
    #[error("the frame's time is not finite ({0})")]
    Time(f64),
    #[error(
        "the frame's time {t_s} s does not come after the previous frame's measurements ({previous_s} s): frame times \
         must increase, and a rolling shutter's readout must end before the next frame starts"
    )]
    TimeOrder { t_s: f64, previous_s: f64 },
    #[error("the estimator refused a measurement: {0}")]
    Refused(#[from] TrackError),
}

/// Tracks a target through frames: one estimate per frame (see the [module documentation](self)).
///
/// ```
/// use nalgebra::Vector3;
/// use rand::SeedableRng;
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_image::{Frame, RenderScratch, RoiRenderer, SensorModel};
/// use roitrack_pipeline::frames::{FrameMethod, FrameTracker, FrameTrackerConfig};
///
/// // A target gliding sideways at 0.2 m/s, 30 frames a second through a global shutter.
/// let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
/// let mut start = MotionState::at_rest(Default::default(), Vector3::new(-0.02, 0.0, 0.6));
/// start.velocity_mps = Vector3::new(0.2, 0.0, 0.0);
/// let renderer = RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
/// let mut tracker = FrameTracker::new(camera, target, FrameTrackerConfig::default()).unwrap();
/// let (mut frame, mut scratch) = (Frame::default(), RenderScratch::new());
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
/// let mut last = None;
/// for k in 0..8 {
///     let t_s = k as f64 / 30.0;
///     renderer.render_frame(&|t| start.predicted(t), t_s, &mut rng, &mut scratch, &mut frame);
///     let outcome = tracker.process(&frame).unwrap();
///     // The first frame is searched and identified whole; the second's blobs are found whole (the velocity is not
///     // known yet) and given to the points predicted nearest; from the third on, each is measured in its window.
///     let expected = match k {
///         0 => FrameMethod::Restart,
///         1 => FrameMethod::FullFrame,
///         _ => FrameMethod::Windows,
///     };
///     assert_eq!(outcome.method, expected);
///     last = outcome.estimate;
/// }
/// let last = last.unwrap();
/// assert!((last.state.cam_t_obj_m - start.predicted(last.t_ref_s).cam_t_obj_m).norm() < 1e-3);
/// assert!((last.state.velocity_mps - start.velocity_mps).norm() < 0.05);
/// ```
#[derive(Debug)]
pub struct FrameTracker {
    camera: CameraModel,
    target: Target,
    config: FrameTrackerConfig,
    tracker: Tracker,
    scheduler: RoiScheduler,
    /// The full-frame blob search's settings and buffers.
    blob_options: PhotoBlobOptions,
    photo_scratch: PhotoScratch,
    /// The last estimate, from which the next frame's windows are placed, and its accelerations if the estimator
    /// has them.
    predictor: Option<Predictor>,
    predictor_acceleration: Option<Acceleration>,
    outline: OutlineScratch,
    /// The frame's window centres of both kinds, their weights, and the static fits' observations.
    window_centres: Vec<WindowCentres>,
    centre_blend: CentreBlend,
    fit_observations: Vec<Observation>,
    polarity: Option<Polarity>,
    /// The frame's measurements, in time order.
    measurements: Vec<Measurement>,
    /// Each point's window in the frame being measured (reused).
    requests: Vec<Option<RoiRequest>>,
    window: Vec<u16>,
    last_time_s: Option<f64>,
    /// The time of the last estimate given.
    last_estimate_s: Option<f64>,
    /// The newest pose to trust, and its time: a frame found whole (the static pose of its identified blobs) or an
    /// estimate vouched for. A new track takes its twist from it ([`Self::restart_state`]).
    last_pose: Option<(f64, MotionState)>,
    /// The target's symmetries that identification cannot tell apart, each with the point it takes every point to
    /// (by index): the labellings of a whole-frame detection that fit as well as the one it gives.
    twins: Vec<(Symmetry, Vec<usize>)>,
    report: FrameTrackReport,
}

impl FrameTracker {
    /// A tracker for frames of `camera` (its time model says how the rows are read) showing `target`.
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: FrameTrackerConfig,
    ) -> Result<Self, ConfigError> {
        camera.time.validate().map_err(|e| ConfigError::Invalid {
            field: match e {
                roitrack_core::time::TimeModelError::Exposure(_) => "exposure_s",
                roitrack_core::time::TimeModelError::LineDelay(_) => "line_delay_s",
            },
            expected: "finite and non-negative",
            value: match e {
                roitrack_core::time::TimeModelError::Exposure(v)
                | roitrack_core::time::TimeModelError::LineDelay(v) => v,
            },
        })?;
        let windows = config.windows;
        if !(windows.min_size_px >= 3
            && windows.max_size_px >= windows.min_size_px
            && windows.max_size_px <= roitrack_image::MAX_ROI_WIDTH)
        {
            return Err(ConfigError::Invalid {
                field: "windows.max_size_px",
                expected: "at least min_size_px (3 or more) and at most 64",
                value: f64::from(windows.max_size_px),
            });
        }
        let tracker = Tracker::new(
            camera.clone(),
            target.clone(),
            Self::for_readout(config.tracker, &camera, config.jerk_psd_given),
        )?;
        let scheduler = RoiScheduler::new(
            camera.clone(),
            target.clone(),
            config.windows,
            config.tracker.noise_px,
        );
        let polarity = match config.detection.polarity {
            PolarityChoice::Auto => None,
            PolarityChoice::Bright => Some(Polarity::Bright),
            PolarityChoice::Dark => Some(Polarity::Dark),
        };
        let max_side = windows.max_size_px as usize;
        let blob_options = config.detection.blob_options(&camera, &target);
        let points = target.len();
        Ok(Self {
            twins: symmetric_twins(&target),
            measurements: Vec::with_capacity(target.len()),
            requests: Vec::with_capacity(target.len()),
            window: Vec::with_capacity(max_side * max_side),
            camera,
            target,
            config,
            tracker,
            scheduler,
            blob_options,
            photo_scratch: PhotoScratch::default(),
            predictor: None,
            predictor_acceleration: None,
            outline: OutlineScratch::default(),
            window_centres: Vec::with_capacity(points),
            centre_blend: CentreBlend::default(),
            fit_observations: Vec::with_capacity(points),
            polarity,
            last_time_s: None,
            last_estimate_s: None,
            last_pose: None,
            report: FrameTrackReport {
                polarity,
                ..FrameTrackReport::default()
            },
        })
    }

    /// `config` for the camera's readout: with a rolling shutter, the frame default's jerk densities
    /// ([`MotionModel::constant_acceleration`]) become the rolling-shutter ones
    /// ([`MotionModel::constant_acceleration_for_rolling_shutter`]); densities a user chose (`jerk_psd_given`) stay,
    /// also when they equal the frame default's. On
    /// `simulate --frames --fps 30 --shutter rolling` (16 points, seed 1) the global-shutter densities left orthoglide's
    /// steps of acceleration (16.7 m/s², switched at once) 4.3 mm off in depth and the random scenario 0.38 mm
    /// (0.30 and 1.8 mm with constant velocity); the rolling-shutter ones leave 0.135 and 0.238 mm, and
    /// `roitrack frame-study`'s rolling-shutter figures move from 0.037-0.050 to 0.038-0.043 mm.
    fn for_readout(
        mut config: TrackerConfig,
        camera: &CameraModel,
        jerk_psd_given: bool,
    ) -> TrackerConfig {
        if let EstimatorConfig::Kalman(tuning) = &mut config.estimator
            && camera.time.is_rolling()
            && !jerk_psd_given
            && tuning.motion_model == MotionModel::constant_acceleration()
        {
            tuning.motion_model = MotionModel::constant_acceleration_for_rolling_shutter();
        }
        config
    }

    /// The camera model (its time model included).
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// Whether [`track_frame_stream`] smooths this tracker's estimates: a rolling shutter and
    /// [`FrameTrackerConfig::rs_smoothing`].
    ///
    /// ```
    /// use roitrack_core::{CameraModel, Target};
    /// use roitrack_pipeline::frames::{FrameTracker, FrameTrackerConfig};
    ///
    /// let tracker = FrameTracker::new(CameraModel::canonical(), Target::grid4x4(), FrameTrackerConfig::default()).unwrap();
    /// assert!(!tracker.smooths_rolling_shutter()); // a global shutter
    /// ```
    pub fn smooths_rolling_shutter(&self) -> bool {
        self.config.rs_smoothing && self.camera.time.is_rolling()
    }

    /// What the tracker has done so far.
    pub fn report(&self) -> FrameTrackReport {
        let estimator = self.tracker.report();
        // The estimator's own counts include the estimates of frames taken again by a new track.
        FrameTrackReport {
            estimator,
            ..self.report
        }
    }

    /// The measurements of the last frame processed, in time order (raw pixels).
    pub fn measurements(&self) -> &[Measurement] {
        &self.measurements
    }

    /// Measures one frame (its `t_s` is the mid-exposure time of its row 0) and gives its estimate.
    pub fn process(&mut self, frame: &Frame) -> Result<FrameOutcome, FrameError> {
        if (frame.width, frame.height) != (self.camera.width_px, self.camera.height_px) {
            return Err(FrameError::Size {
                width: frame.width,
                height: frame.height,
                camera_width: self.camera.width_px,
                camera_height: self.camera.height_px,
            });
        }
        if !frame.t_s.is_finite() {
            return Err(FrameError::Time(frame.t_s));
        }
        if let Some(previous_s) = self.last_time_s
            && frame.t_s <= previous_s
        {
            return Err(FrameError::TimeOrder {
                t_s: frame.t_s,
                previous_s,
            });
        }
        self.report.frames += 1;
        if let (Some(predictor), Some(acceleration)) = (self.predictor, self.predictor_acceleration)
        {
            self.predictor = Some(carried_with_acceleration(
                predictor,
                &acceleration,
                frame.t_s,
            ));
        }
        let mut method = FrameMethod::NotFound;
        if let Some(predictor) = self.predictor
            && self.measure_windows(frame, &predictor) >= self.min_window_points()
        {
            method = FrameMethod::Windows;
        }
        // The target's static pose in this frame, when it was identified whole.
        let mut found = None;
        if method == FrameMethod::NotFound {
            (method, found) = self.search_whole_frame(frame);
        }
        let resets_before = self.tracker.report().covariance_resets;
        let mut estimate = self.estimate_frame(method)?;
        // The running track could not vouch for the frame (its filter rejected the blobs, or lost them, or rejected
        // so many in a row that it widened its covariance within the frame): a frame the target moved through faster
        // than the track predicts. The target identified whole starts a new track instead, rather than one more
        // estimate far from what the frame shows (a covariance widened after half of a frame's blobs had been
        // rejected left the random scenario's 16 points 0.45 mm off in depth, where the pose found whole was 0.03 mm
        // off).
        let reset_within = self.tracker.report().covariance_resets > resets_before;
        if matches!(method, FrameMethod::Windows | FrameMethod::FullFrame)
            && estimate.as_ref().is_some_and(|e| {
                reset_within
                    || matches!(e.status, TrackStatus::Disputed | TrackStatus::Lost)
                    || self.frame_residual_rms_px(e) > RESTART_RESIDUAL_PX
            })
        {
            if method == FrameMethod::Windows {
                // The windows' blobs stay the frame's if the target cannot be identified whole.
                let windowed = std::mem::take(&mut self.measurements);
                found = self.find_whole(frame);
                if found.is_none() {
                    self.measurements = windowed;
                }
            }
            // (A frame matched to the predictions is one where the identification has already failed.)
            if let Some(pose) = found {
                self.scheduler.reset();
                self.restart(frame.t_s, pose);
                method = FrameMethod::Restart;
                estimate = self.estimate_frame(method)?;
            }
        }
        if let Some(e) = &estimate {
            self.report.estimates += 1;
            self.last_estimate_s = Some(e.t_ref_s);
            if method == FrameMethod::Restart || e.status.is_vouched_for() {
                self.last_pose = Some((e.t_ref_s, e.state));
            }
        }
        match method {
            FrameMethod::Windows => self.report.by_windows += 1,
            FrameMethod::FullFrame => self.report.by_full_frame += 1,
            FrameMethod::Restart => self.report.restarts += 1,
            FrameMethod::NotFound => self.report.not_found += 1,
        }
        // The measurements are in time order: the last is the frame's latest time, if later than its row 0.
        let latest_s = self.measurements.last().map_or(frame.t_s, |m| m.t_s);
        self.last_time_s = Some(latest_s.max(frame.t_s));
        if let Some(e) = estimate {
            // A lost track is dropped by the estimator: the next frame is searched whole.
            self.predictor = (e.status != TrackStatus::Lost).then_some(Predictor {
                t_ref_s: e.t_ref_s,
                state: e.state,
                covariance: e.covariance,
            });
            self.predictor_acceleration = e.acceleration;
        }
        Ok(FrameOutcome {
            estimate,
            method,
            // A frame whose target was not found leaves no measurement.
            measured: self.measurements.len(),
        })
    }

    /// The estimate carried back by its own twist from its newest measurement's time to the mean time of the
    /// frame's measurements, where they pin the pose best: a rolling shutter reads the target's blobs over the rows
    /// it spans (150 rows at 30 µs: 4.5 ms), and the state at the last of them is the pose at their middle
    /// extrapolated by the velocity, with the velocity's error times half that span added. With a global shutter the
    /// two times are one. The state goes back with its accelerations when it has them
    /// ([`Estimate::state_at`]); the covariance goes back under the constant twist
    /// ([`roitrack_core::MotionState::transition_jacobian`]: the estimate reports no covariance of the accelerations,
    /// whose part over a few milliseconds is left out). An estimate is never moved to or before the previous one's
    /// time.
    fn at_measurements_mean_time(&self, mut estimate: Estimate) -> Estimate {
        let count = self.measurements.len();
        if count == 0 {
            return estimate;
        }
        let mean_s = self.measurements.iter().map(|m| m.t_s).sum::<f64>() / count as f64;
        let dt_s = mean_s - estimate.t_ref_s;
        if dt_s >= 0.0 || self.last_estimate_s.is_some_and(|last| mean_s <= last) {
            return estimate;
        }
        if let Some(covariance) = &mut estimate.covariance {
            let f = estimate.state.transition_jacobian(dt_s);
            *covariance = f * *covariance * f.transpose();
        }
        // With accelerations, the twist goes back too: under a constant twist, the velocity at the mean time would
        // be the last blob's, which an acceleration of 1.5 m/s² leaves 4.5 mm/s off across 3 ms of rows.
        estimate.state = estimate.state_at(dt_s);
        estimate.t_ref_s = mean_s;
        estimate
    }

    fn min_window_points(&self) -> usize {
        self.config
            .min_window_points
            .unwrap_or(self.target.len().div_ceil(2).max(4))
            .clamp(1, self.target.len())
    }

    /// The window of point `i` at the time its predicted row is read in the frame whose row 0 is read at `t_frame_s`.
    fn request_at_row_time(
        &self,
        predictor: &Predictor,
        i: usize,
        t_frame_s: f64,
    ) -> Option<RoiRequest> {
        let time = self.camera.time;
        let mut request = self.scheduler.request(predictor, i, t_frame_s);
        if time.is_rolling() {
            // The row gives the time and the time the row: two rounds are plenty for any real line delay.
            for _ in 0..2 {
                let r = request?;
                request = self.scheduler.request(
                    predictor,
                    i,
                    time.blob_time_s(t_frame_s, r.predicted_px.y),
                );
            }
        }
        request
    }

    /// Measures every predicted blob in its window; returns how many were found (in `self.measurements`).
    fn measure_windows(&mut self, frame: &Frame, predictor: &Predictor) -> usize {
        self.measurements.clear();
        self.window_centres.clear();
        let polarity = self.polarity.unwrap_or(Polarity::Bright);
        let time = self.camera.time;
        self.requests.clear();
        for i in 0..self.target.len() {
            let request = self.request_at_row_time(predictor, i, frame.t_s);
            // A prediction too uncertain for the largest window (the velocity right after a new track, before a
            // second frame has measured it) could put a neighbouring blob in the window: search the frame instead.
            let largest = f64::from(self.config.windows.max_size_px);
            if request.is_some_and(|r| {
                r.sigma_px
                    .is_some_and(|sigma| 2.0 * self.config.windows.sigma_margin * sigma > largest)
            }) {
                return 0;
            }
            self.requests.push(request);
        }
        let mut cut = 0;
        for i in 0..self.requests.len() {
            let Some(request) = self.requests[i] else {
                continue;
            };
            let roi = request.roi;
            let flat = flatten_window(frame, &roi, polarity, &mut self.window);
            // The blob nearest the prediction, not the brightest: a window sized for an uncertain prediction holds
            // whole neighbours of a dense target, of the same contrast, and the rims of others at its edge (on a
            // 24 x 28 hexagonal grid, the brightest blob was a neighbour's in up to 60 of 230 windows a frame, and
            // the frames went to whole-frame searches; 45 of 60 frames in windows, 58 now).
            let near_px = Some([request.predicted_px.x, request.predicted_px.y]);
            let measured =
                measure_flat_window(&self.window, &roi, &flat, &self.config.centroid, near_px);
            match measured {
                // The blob nearest the prediction is some other point's (the point's own was occluded, or the
                // prediction missed it by half the distance to a neighbour): never measured twice, never swapped.
                Ok(c) if nearest_request(&self.requests, c.u_px, c.v_px) != Some(i) => {
                    self.scheduler.report(i, false);
                    self.report.neighbour_blobs += 1;
                    cut += 1;
                }
                Ok(c) => {
                    self.scheduler.report(i, true);
                    let t_s = time.blob_time_s(frame.t_s, c.v_px);
                    let moments = Vector2::new(c.u_px, c.v_px);
                    let outline = window_outline_centre(&self.window, &roi, &c, &mut self.outline);
                    let shift = self.disk_centre_shift_px(predictor, i, t_s);
                    self.window_centres.push(WindowCentres {
                        point_index: i,
                        t_s,
                        moments_px: moments - shift,
                        outline_px: outline - shift,
                    });
                }
                Err(r) => {
                    self.scheduler.report(i, false);
                    self.report.window_rejections.count(&r);
                    if r == BlobRejection::TouchesBorder {
                        cut += 1;
                    }
                }
            }
        }
        // Blobs cut by their window's edge, or nearer another point's prediction: a few are (a blob at the frame's
        // edge, one merged with a neighbour by blur), and those points are left out of the frame; a prediction that
        // missed the target makes most of them so, and then the blobs the other windows hold may be neighbours too:
        // the frame is measured whole instead. (Abandoning the windows at the first cut blob sent 51 of 60 frames of
        // an 8 x 10 grid to whole-frame searches.)
        let windows = self.requests.iter().filter(|r| r.is_some()).count();
        if 4 * cut >= windows {
            self.window_centres.clear();
            return 0;
        }
        self.take_window_centres(predictor);
        self.measurements.len()
    }

    /// The frame's window centres into `self.measurements`: the mean of their outlines' and their moments' centres,
    /// weighted by [`CentreBlend`] (after comparing them on this frame, if it is one it compares).
    fn take_window_centres(&mut self, predictor: &Predictor) {
        if self.centre_blend.compares_now()
            && let Some(rms2) = self.static_fit_rms2_px2(predictor)
        {
            self.centre_blend.add(rms2);
        }
        let weight = self.centre_blend.outline_weight();
        self.report.outline_weight = weight;
        for w in &self.window_centres {
            let centre = w.moments_px + weight * (w.outline_px - w.moments_px);
            self.measurements.push(Measurement {
                t_s: w.t_s,
                id: self.target.points()[w.point_index].id,
                u_px: centre.x,
                v_px: centre.y,
            });
        }
    }

    /// The mean squared residuals (px²) of the static poses fitted to the frame's window centres by their moments and
    /// by their outlines, each centre first moved along the predicted motion to the centres' mean time (a rolling
    /// shutter reads them at different times); `None` when the outlines changed no centre or the centres do not
    /// determine a pose.
    fn static_fit_rms2_px2(&mut self, predictor: &Predictor) -> Option<[f64; 2]> {
        let required = if self.target.is_planar() { 4 } else { 6 };
        if self.window_centres.len() < required
            || self
                .window_centres
                .iter()
                .all(|w| w.outline_px == w.moments_px)
        {
            return None;
        }
        let count = self.window_centres.len() as f64;
        let mean_s = self.window_centres.iter().map(|w| w.t_s).sum::<f64>() / count;
        let at_mean = predictor.state.predicted(mean_s - predictor.t_ref_s);
        let model = SpatioTemporalModel::new(self.camera.intrinsics);
        let mut rms2 = [0.0; 2];
        for (k, rms2) in rms2.iter_mut().enumerate() {
            self.fit_observations.clear();
            for w in &self.window_centres {
                let p = &self.target.points()[w.point_index].point_in_obj_m;
                let at_blob = predictor.state.predicted(w.t_s - predictor.t_ref_s);
                let moved = model.project(&at_mean, p, 0.0)? - model.project(&at_blob, p, 0.0)?;
                let raw = if k == 0 { w.moments_px } else { w.outline_px };
                let ideal = self.camera.undistort_pixel(&raw).ok()?;
                self.fit_observations.push(Observation {
                    t_s: mean_s,
                    point_index: w.point_index,
                    ideal_px: ideal + moved,
                });
            }
            let fit = refine_static_pose(
                &model,
                &self.target,
                &self.fit_observations,
                &at_mean,
                CENTRE_FIT_ITERATIONS,
            );
            *rms2 = fit.residual_rms_px * fit.residual_rms_px;
        }
        rms2.iter().all(|r| r.is_finite()).then_some(rms2)
    }

    /// How far the centre of point `i`'s image, read at `t_s`, lies from the image of its disk's centre (px, to be
    /// taken away from the measured centre): a disk seen at an angle is imaged as an ellipse whose centre is not the
    /// image of the disk's centre (perspective draws its near half larger), by hundredths of a pixel that move with
    /// the pose. Taken away as the full-frame identification does, with the pose `predictor` predicts (the
    /// displacement changes far less than it is with the pose that moves it); zero for a point without a diameter
    /// or a target that is not planar. Without it, the windows' centres of four 12-14 mm dots 0.5 m away lay 0.05 px
    /// from the images of their centres, 0.035 px of it a bias, against 0.015 px for the full-frame detection's; on
    /// `roitrack frame-study` the global-shutter position RMSE fell from 0.0152 to 0.0137 mm with it.
    fn disk_centre_shift_px(&self, predictor: &Predictor, i: usize, t_s: f64) -> Vector2<f64> {
        let point = &self.target.points()[i];
        let (Some(plane), Some(diameter_m)) = (self.target.plane(), point.diameter_m) else {
            return Vector2::zeros();
        };
        let normal: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
        let state = predictor.state.predicted(t_s - predictor.t_ref_s);
        disk_centre_displacement_px(
            &self.camera,
            &state,
            &point.point_in_obj_m,
            &normal,
            diameter_m,
        )
        .unwrap_or_else(Vector2::zeros)
    }

    /// Searches the whole frame; fills `self.measurements` and says whether the track goes on, restarts, or the
    /// target was not found, with the target's static pose when it was identified. The target identified whole comes
    /// first: blobs matched to the running track's predictions are only as right as those predictions, and a grid
    /// that moved by one spacing more than predicted matches its neighbours (orthoglide's 16 points at 30 Hz: an
    /// estimate 20 mm off that agreed with its blobs). Identified blobs continue a running track (whose estimate
    /// [`Self::process`] then checks against the frame); matching is for frames where the target cannot be
    /// identified whole (part of it hidden or out of the image).
    fn search_whole_frame(&mut self, frame: &Frame) -> (FrameMethod, Option<MotionState>) {
        self.measurements.clear();
        let running = self.predictor.is_some() && self.tracker.state().is_some();
        if let Some(found) = self.find_whole(frame) {
            self.scheduler.reset();
            if running {
                return (FrameMethod::FullFrame, Some(found));
            }
            self.restart(frame.t_s, found);
            return (FrameMethod::Restart, Some(found));
        }
        if let (true, Some(predictor), Some(polarity)) = (running, self.predictor, self.polarity)
            && self.associate_blobs(frame, &predictor, polarity) >= self.min_window_points()
        {
            self.scheduler.reset();
            return (FrameMethod::FullFrame, None);
        }
        self.measurements.clear();
        (FrameMethod::NotFound, None)
    }

    /// The RMS distance (px) between the frame's blobs and where `estimate` puts their points at their own times:
    /// what tells an estimate that agrees with its frame from one the filter could not pull there (a covariance reset
    /// left it re-converging 20 mm off, on orthoglide's 16 points at 30 Hz); infinite if a point does not project.
    fn frame_residual_rms_px(&self, estimate: &Estimate) -> f64 {
        let mut sum_px2 = 0.0;
        for m in &self.measurements {
            let state = estimate.state_at(m.t_s - estimate.t_ref_s);
            let projected = self
                .target
                .index_of(m.id)
                .map(|i| state.point_in_cam_at(&self.target.points()[i].point_in_obj_m, 0.0))
                .and_then(|p| self.camera.raw_pixel_from_cam(&p));
            let Some(px) = projected else {
                return f64::INFINITY;
            };
            sum_px2 += (px - Vector2::new(m.u_px, m.v_px)).norm_squared();
        }
        (sum_px2 / self.measurements.len().max(1) as f64).sqrt()
    }

    /// The frame's measurements (sorted by time) into the estimator; its estimate, at the mean time of its blobs.
    fn estimate_frame(&mut self, method: FrameMethod) -> Result<Option<Estimate>, FrameError> {
        if method == FrameMethod::NotFound {
            return Ok(None);
        }
        self.measurements.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        Ok(self
            .tracker
            .push_batch(&self.measurements, Emit::EachBatch)?
            .map(|e| self.at_measurements_mean_time(e)))
    }

    /// Finds and identifies the target in the whole frame: its blobs into `self.measurements` (each at its row's
    /// time), and its static pose; `None` if it is not there.
    fn find_whole(&mut self, frame: &Frame) -> Option<MotionState> {
        let mut options = self.config.detection;
        if let Some(polarity) = self.polarity {
            options.polarity = match polarity {
                Polarity::Bright => PolarityChoice::Bright,
                Polarity::Dark => PolarityChoice::Dark,
            };
        }
        let detection = detect_target(&self.camera, &self.target, frame, &options).ok()?;
        if self.polarity.is_none() {
            self.polarity = Some(detection.polarity);
            self.report.polarity = Some(detection.polarity);
        }
        let time = self.camera.time;
        let (state, twin) = self.nearest_twin(frame.t_s, detection.state);
        let target = &self.target;
        let relabel = |id: u32| match (twin, target.index_of(id)) {
            (Some(k), Some(i)) => target.points()[self.twins[k].1[i]].id,
            _ => id,
        };
        self.measurements
            .extend(detection.points.iter().map(|p| Measurement {
                t_s: time.blob_time_s(frame.t_s, p.centre_px.y),
                id: relabel(p.id),
                u_px: p.centre_px.x,
                v_px: p.centre_px.y,
            }));
        Some(state)
    }

    /// Of the poses a symmetric target's detection `found` at `t_s` could be (its labelling and its twins'), the one
    /// nearest the last trusted pose carried on by its twist to `t_s`, and which twin it is (`None`: the detection's
    /// own). Identification labels a symmetric grid one fixed way; a track that has turned the grid past half its
    /// symmetry follows another labelling, and a new track on the detection's would turn the pose by the symmetry's
    /// angle and write the twist of that turn (a half turn of an 8 x 10 grid: 7 m/s and 78 rad/s).
    fn nearest_twin(&self, t_s: f64, found: MotionState) -> (MotionState, Option<usize>) {
        let Some((t_last_s, last)) = self.last_pose else {
            return (found, None);
        };
        let dt_s = t_s - t_last_s;
        if self.twins.is_empty() || !(0.0..=RESTART_TWIST_MAX_GAP_S).contains(&dt_s) {
            return (found, None);
        }
        let predicted = last.predicted(dt_s);
        let distance = |s: &MotionState| predicted.pose_distance(s);
        let mut best = (found, None, distance(&found));
        for (k, (symmetry, _)) in self.twins.iter().enumerate() {
            let twin = twin_state(&found, symmetry);
            let d = distance(&twin);
            if d < best.2 {
                best = (twin, Some(k), d);
            }
        }
        (best.0, best.1)
    }

    /// A new track from the static pose `found` of the frame whose row 0 is read at `t_s`; the frame's measurements
    /// (`self.measurements`, those the pose was found from) follow at their own times. The pose is that of their mean
    /// time (a rolling shutter reads them over the rows the target spans); the track starts at `t_s`, carried back by
    /// its twist.
    fn restart(&mut self, t_s: f64, found: MotionState) {
        let count = self.measurements.len();
        let found_s = if count == 0 {
            t_s
        } else {
            self.measurements.iter().map(|m| m.t_s).sum::<f64>() / count as f64
        };
        let (state, covariance) = self.restart_state(found_s, found);
        self.tracker.reset();
        self.tracker
            .start_from(t_s, state.predicted(t_s - found_s), Some(covariance));
    }

    /// The state and covariance a new track starts from at `t_s`, given the static pose `found` there: with the
    /// twist that carried the last trusted pose ([`Self::last_pose`]) to it, if that is at most
    /// [`RESTART_TWIST_MAX_GAP_S`] old, else at rest with a broad twist prior. A frame shows the pose, not the motion:
    /// at rest, a target that moves 50 mm between frames (1.5 m/s at 30 Hz) is far from the next frame's windows and
    /// from the blobs they would be matched with, and every frame would start a new track at rest again (the random
    /// scenario's 16 points at 30 Hz: 65 new tracks in 121 frames, 21 mm RMSE against 0.03 mm for the poses found
    /// frame by frame).
    fn restart_state(&self, t_s: f64, found: MotionState) -> (MotionState, Matrix12) {
        // (For a rolling shutter, `t_s` is the mean time of the blobs the pose was found from.)
        let mut covariance = full_frame_covariance();
        let Some((t_last_s, last)) = self.last_pose else {
            return (found, covariance);
        };
        let dt_s = t_s - t_last_s;
        if !(dt_s > 0.0 && dt_s <= RESTART_TWIST_MAX_GAP_S) {
            return (found, covariance);
        }
        // The pose's change over the gap, in the error state's terms (translation, rotation vector on the left).
        let moved = MotionState::difference(&last, &found) / dt_s;
        let state = MotionState {
            velocity_mps: moved.fixed_rows::<3>(0).into_owned(),
            angular_velocity_radps: moved.fixed_rows::<3>(3).into_owned(),
            ..found
        };
        if !state.is_finite() {
            return (found, covariance);
        }
        // The mean twist between the two frames is the twist at their middle: at the newer one it is off by the
        // acceleration times half the gap (10 m/s² and 30 rad/s² over 17 ms: 0.17 m/s and 0.5 rad/s).
        for (i, sigma) in RESTART_TWIST_SIGMAS.iter().enumerate() {
            for axis in 0..3 {
                let k = 6 + 3 * i + axis;
                covariance[(k, k)] = sigma * sigma;
            }
        }
        (state, covariance)
    }

    /// The frame's blobs attributed to the running track's points: each point takes the blob nearest its prediction
    /// when that blob has no other point nearer, within half the distance between predicted points (so that no blob
    /// can be given to two points however far the target strayed from the prediction). For frames whose blobs left
    /// their windows (a sudden acceleration); returns how many points were measured (in `self.measurements`).
    fn associate_blobs(
        &mut self,
        frame: &Frame,
        predictor: &Predictor,
        polarity: Polarity,
    ) -> usize {
        let blobs = detect_photo_blobs(
            &frame.pixels,
            frame.width,
            frame.height,
            frame.bit_depth,
            polarity,
            &self.blob_options,
            &mut self.photo_scratch,
        );
        let predicted: Vec<(usize, Vector2<f64>)> = (0..self.target.len())
            .filter_map(|i| {
                self.request_at_row_time(predictor, i, frame.t_s)
                    .map(|r| (i, r.predicted_px))
            })
            .collect();
        let mut spacing_px = f64::INFINITY;
        for (a, (_, pa)) in predicted.iter().enumerate() {
            for (_, pb) in &predicted[a + 1..] {
                spacing_px = spacing_px.min((pa - pb).norm());
            }
        }
        let gate_px = 0.5 * spacing_px;
        let nearest = |p: &Vector2<f64>, candidates: &mut dyn Iterator<Item = Vector2<f64>>| {
            candidates
                .enumerate()
                .map(|(k, c)| (k, (c - p).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
        };
        let time = self.camera.time;
        for &(i, p) in &predicted {
            let Some((b, distance)) =
                nearest(&p, &mut blobs.iter().map(|b| Vector2::new(b.u_px, b.v_px)))
            else {
                continue;
            };
            let blob = Vector2::new(blobs[b].u_px, blobs[b].v_px);
            let mutual = nearest(&blob, &mut predicted.iter().map(|(_, q)| *q))
                .is_some_and(|(k, _)| predicted[k].0 == i);
            if distance < gate_px && mutual {
                let t_s = time.blob_time_s(frame.t_s, blob.y);
                let centre = blob - self.disk_centre_shift_px(predictor, i, t_s);
                self.measurements.push(Measurement {
                    t_s,
                    id: self.target.points()[i].id,
                    u_px: centre.x,
                    v_px: centre.y,
                });
            }
        }
        self.measurements.len()
    }
}

/// The centres of one blob measured in its window (raw px, corrected for perspective), by the window's moments and
/// by the blob's outline (the moments when the outline could not be found).
#[derive(Debug, Clone, Copy, PartialEq)]
struct WindowCentres {
    point_index: usize,
    t_s: f64,
    moments_px: Vector2<f64>,
    outline_px: Vector2<f64>,
}

/// Gauss-Newton steps of the static poses that compare the two kinds of centres (from the predicted pose).
const CENTRE_FIT_ITERATIONS: usize = 4;
/// Frames compared before the weights follow the comparison (equal weights until then), and the memory of the
/// comparison (frames).
const CENTRE_BLEND_MIN_FRAMES: usize = 5;
const CENTRE_BLEND_MEMORY_FRAMES: f64 = 20.0;
/// After the first [`CENTRE_BLEND_MEMORY_FRAMES`] frames, the two kinds are compared on one frame in this many (the
/// two static fits cost a tenth of a frame's work).
const CENTRE_BLEND_EVERY_FRAMES: usize = 5;

/// How the centre of a blob measured in its window is made of two: the window's threshold-weighted moments and the
/// centre of the blob's outline ([`outline_centre`], the full-frame detector's). Neither is better everywhere. On
/// sharp blobs under sensor noise and JPEG compression the outline's points average the noise over the whole edge,
/// while the moments move with the pixels near their threshold (four dots in clutter: 0.029 against 0.042 px from the
/// true centres); on the soft blobs of `roitrack simulate --frames`, the moments are the better (four dots 1.5 m
/// away: a position jitter of 0.34 mm with the moments, 0.48 mm with the outlines). Their errors are far from equal,
/// so their weighted mean beats both: each is weighted by the inverse of its mean squared residual in static poses
/// fitted to each frame's centres of that kind, in an exponential average with a memory of
/// [`CENTRE_BLEND_MEMORY_FRAMES`] compared frames. Both kinds are fitted on the same blobs at the same poses, so what
/// differs is mostly the centres' own noise (the two come from the same pixels, and their errors are not independent:
/// the weights are those of independent errors, which is what the measurements above bear out, not an optimum).
/// With the mean: 0.029 px on the clutter's frames (as the detector), and on the simulated sequences a jitter of 0.28
/// instead of 0.31 mm (four dots 1.5 m away), 0.041 instead of 0.048 mm (0.5 m away).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct CentreBlend {
    /// The averaged mean squared residuals (px²): by the moments, by the outlines.
    mean_rms2_px2: [f64; 2],
    /// Frames compared, and frames whose windows gave their centres.
    compared: usize,
    offered: usize,
}

impl CentreBlend {
    /// Whether this frame, whose windows gave their centres, compares the two kinds (counts the frame).
    fn compares_now(&mut self) -> bool {
        self.offered += 1;
        self.offered as f64 <= CENTRE_BLEND_MEMORY_FRAMES
            || self.offered.is_multiple_of(CENTRE_BLEND_EVERY_FRAMES)
    }

    /// Folds in one frame's mean squared residuals (px²): by the moments, by the outlines.
    fn add(&mut self, rms2_px2: [f64; 2]) {
        self.compared += 1;
        let weight = 1.0 / (self.compared as f64).min(CENTRE_BLEND_MEMORY_FRAMES);
        for (mean, sample) in self.mean_rms2_px2.iter_mut().zip(rms2_px2) {
            *mean += weight * (sample - *mean);
        }
    }

    /// The outline's weight in a blob's centre (the moments' is 1 minus it).
    fn outline_weight(&self) -> f64 {
        let [moments, outline] = self.mean_rms2_px2;
        if self.compared < CENTRE_BLEND_MIN_FRAMES || moments + outline <= 0.0 {
            return 0.5;
        }
        moments / (moments + outline)
    }
}

/// Farthest (px) the outline's centre may lie from the window's moments for a blob: beyond, the outline found is not
/// the blob's alone (a neighbour's rim, clutter touching it), and the moments stand.
const MAX_OUTLINE_SHIFT_PX: f64 = 0.5;

/// The centre of the outline ([`outline_centre`]) of the blob whose moments in the flattened `window` (of `roi`) are
/// `moments`; the moments when it cannot be found (see [`CentreBlend`]).
fn window_outline_centre(
    window: &[u16],
    roi: &Roi,
    moments: &Centroid,
    scratch: &mut OutlineScratch,
) -> Vector2<f64> {
    let at = Vector2::new(moments.u_px, moments.v_px);
    let origin = Vector2::new(f64::from(roi.x0), f64::from(roi.y0));
    outline_centre(
        window,
        roi.width as usize,
        roi.height as usize,
        at - origin,
        f64::from(moments.area_px),
        scratch,
    )
    .map(|local| local + origin)
    .filter(|centre| (centre - at).norm() <= MAX_OUTLINE_SHIFT_PX)
    .unwrap_or(at)
}

/// `predictor` carried to `t_s` with `acceleration`: the scheduler predicts under a constant twist, and between
/// frames (33 ms at 30 Hz) an acceleration of 10 m/s² moves a blob 5.4 mm from that prediction. The covariance is
/// carried under the constant twist ([`MotionState::transition_jacobian`]), as the scheduler would have.
fn carried_with_acceleration(
    predictor: Predictor,
    acceleration: &Acceleration,
    t_s: f64,
) -> Predictor {
    let dt_s = t_s - predictor.t_ref_s;
    let f = predictor.state.transition_jacobian(dt_s);
    Predictor {
        t_ref_s: t_s,
        state: acceleration.predicted(&predictor.state, dt_s),
        covariance: predictor.covariance.map(|p| f * p * f.transpose()),
    }
}

/// The point whose predicted blob centre is nearest to `(u_px, v_px)`.
fn nearest_request(requests: &[Option<RoiRequest>], u_px: f64, v_px: f64) -> Option<usize> {
    requests
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            r.as_ref()
                .map(|r| (i, (r.predicted_px.x - u_px).hypot(r.predicted_px.y - v_px)))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// The level a flattened window's background is lifted to (1/16 of the frame's range): see [`flatten_window`].
fn window_offset(frame: &Frame) -> u16 {
    let max_value = (1u32 << frame.bit_depth.clamp(1, 16)) - 1;
    ((max_value + 1) / 16) as u16
}

/// The background plane `[a, b, c]` (`a + b x + c y`) through the `border` pixels that `keep` marks
/// ([`roitrack_image::background::fit_plane`]).
fn fit_plane(border: &[(f64, f64, f64)], keep: &[bool]) -> Option<[f64; 3]> {
    roitrack_image::background::fit_plane(
        border
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p),
    )
}

/// Copies the window `roi` of `frame` into `out` with its background taken away, so that the blob stands bright on
/// a flat, dark background whatever the light: the background is a least-squares plane through the border pixels
/// that belong to it, not to the blob or its neighbours (see `border_plane`). Bright blobs: `value - plane`; dark
/// blobs: the contrast `1 - value / plane`, scaled to the frame's range (under uneven light a printed circle keeps
/// its contrast, not its difference in grey level). An offset of 1/16 of the range keeps the background's noise above
/// zero. The frame tracker measures every window through it. Windows up to 64 x 64 px, the largest the centroid
/// takes: the border pixels of a larger one beyond the first 256 are not used.
///
/// # Panics
/// If `roi` does not lie inside `frame`.
///
/// ```
/// use roitrack_image::{Frame, Polarity, Roi};
/// use roitrack_pipeline::frames::flatten_window;
///
/// // A light background brighter to the right, with one dark pixel in the middle of a 5 x 5 window.
/// let mut frame = Frame { width: 5, height: 5, bit_depth: 8, t_s: 0.0, pixels: vec![0; 25] };
/// for (k, value) in frame.pixels.iter_mut().enumerate() {
///     *value = 150 + 10 * (k % 5) as u16;
/// }
/// frame.pixels[12] = 40;
/// let mut window = Vec::new();
/// flatten_window(&frame, &Roi::new(0, 0, 5, 5), Polarity::Dark, &mut window);
/// // The background is flat at the offset (16 of 255), the dark pixel bright.
/// assert!(window.iter().enumerate().all(|(k, &v)| if k == 12 { v > 180 } else { v == 16 }));
/// ```
pub fn flatten_window(
    frame: &Frame,
    roi: &Roi,
    polarity: Polarity,
    out: &mut Vec<u16>,
) -> FlatWindow {
    let (w, h) = (roi.width as usize, roi.height as usize);
    out.clear();
    out.resize(w * h, 0);
    let max_value = ((1u32 << frame.bit_depth.clamp(1, 16)) - 1) as f64;
    let offset = f64::from(window_offset(frame));
    let at = |i: usize, j: usize| {
        f64::from(frame.pixels[(roi.y0 as usize + j) * frame.width as usize + roi.x0 as usize + i])
    };
    // The blob's extreme value: where the contrast is measured from (row slices, integer extremes).
    let rows = (0..h).map(|j| {
        let start = (roi.y0 as usize + j) * frame.width as usize + roi.x0 as usize;
        &frame.pixels[start..start + w]
    });
    let blob_extreme = f64::from(match polarity {
        Polarity::Dark => rows
            .map(|row| row.iter().copied().min().unwrap_or(u16::MAX))
            .min()
            .unwrap_or(0),
        Polarity::Bright => rows
            .map(|row| row.iter().copied().max().unwrap_or(0))
            .max()
            .unwrap_or(0),
    });
    let (a, b, c, noise) = border_plane(w, h, polarity, blob_extreme, at);
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let frame_width = frame.width as usize;
    // The hot loop of the windows path: row slices (no per-pixel index checks), the polarity chosen once per window,
    // and rounding as +0.5 then truncation (`f64::round` is a library call; the values are clamped non-negative
    // first, where the two agree).
    // The flattened window's peak, kept as it is filled: the centroid's threshold is measured from it.
    let mut peak = 0u16;
    let mut fill = |flat: fn(f64, f64, f64) -> f64| {
        for (j, out_row) in out.chunks_exact_mut(w).enumerate() {
            let y = j as f64 - cy;
            let start = (roi.y0 as usize + j) * frame_width + roi.x0 as usize;
            let row = &frame.pixels[start..start + w];
            for (i, (o, &v)) in out_row.iter_mut().zip(row).enumerate() {
                let plane = a + b * (i as f64 - cx) + c * y;
                let value = flat(f64::from(v), plane, max_value) + offset;
                *o = (value + 0.5).clamp(0.0, max_value) as u16;
                peak = peak.max(*o);
            }
        }
    };
    let noise_dn = match polarity {
        Polarity::Bright => {
            fill(|v, plane, _| v - plane);
            noise
        }
        Polarity::Dark => {
            fill(|v, plane, max_value| {
                if plane > 0.0 {
                    (1.0 - v / plane) * max_value
                } else {
                    0.0
                }
            });
            if a > 0.0 { noise * max_value / a } else { 0.0 }
        }
    };
    FlatWindow {
        background_dn: offset,
        noise_dn,
        peak_dn: peak,
    }
}

/// What [`flatten_window`] knows of the window it flattened: its background's level and noise in the flattened
/// values, measured on the border pixels that belong to the background.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlatWindow {
    /// The flattened background's level (DN): 1/16 of the frame's range.
    pub background_dn: f64,
    /// Its noise (DN, one standard deviation: 1.2533 times the mean absolute residual of the border's
    /// background pixels about the plane).
    pub noise_dn: f64,
    /// The flattened window's largest value (DN).
    pub peak_dn: u16,
}

/// Measures the blob of `window` as [`flatten_window`] flattened it into `flat`, with `options`, but for an automatic
/// threshold taken from the background it found rather than from the window's border: the threshold is the background
/// plus [`AUTO_THRESHOLD_FRACTION`] of the peak's contrast, and the blob absent when the contrast is under
/// [`AUTO_MIN_CONTRAST_SIGMAS`] times its noise (or [`AUTO_MIN_CONTRAST_DN`]). The border of a window in a dense grid
/// crosses the neighbouring blobs: the centroid's own estimate from it takes their rims for noise and finds nothing
/// standing out (on real photographs of a hexagonal grid of printed circles, most of the windows).
///
/// ```
/// use roitrack_image::{CentroidOptions, Frame, Polarity, Roi};
/// use roitrack_pipeline::frames::{flatten_window, measure_flat_window};
///
/// // A dark 3 x 3 blob on a light, uneven background.
/// let mut frame = Frame { width: 15, height: 15, bit_depth: 8, t_s: 0.0, pixels: vec![0; 225] };
/// for (k, value) in frame.pixels.iter_mut().enumerate() {
///     *value = 150 + (k % 15) as u16;
/// }
/// for j in 6..9 {
///     for i in 7..10 {
///         frame.pixels[j * 15 + i] = 40;
///     }
/// }
/// let roi = Roi::new(0, 0, 15, 15);
/// let mut window = Vec::new();
/// let flat = flatten_window(&frame, &roi, Polarity::Dark, &mut window);
/// let c = measure_flat_window(&window, &roi, &flat, &CentroidOptions::default(), None).unwrap();
/// // Its contrast varies a little with the light across it: within a hundredth of a pixel of its centre.
/// assert!((c.u_px - 8.0).abs() < 0.01 && (c.v_px - 7.0).abs() < 0.01);
/// ```
///
/// # Panics
/// As [`measure_blob`].
pub fn measure_flat_window(
    window: &[u16],
    roi: &Roi,
    flat: &FlatWindow,
    options: &CentroidOptions,
    near_px: Option<[f64; 2]>,
) -> Result<Centroid, BlobRejection> {
    let measure = |options: &CentroidOptions| match near_px {
        Some(near_px) => measure_blob_near(window, roi, options, near_px),
        None => measure_blob(window, roi, options),
    };
    if options.threshold != Threshold::Auto {
        return measure(options);
    }
    let contrast = f64::from(flat.peak_dn) - flat.background_dn;
    if contrast < (AUTO_MIN_CONTRAST_SIGMAS * flat.noise_dn).max(AUTO_MIN_CONTRAST_DN) {
        return Err(BlobRejection::Absent);
    }
    let threshold = (flat.background_dn + AUTO_THRESHOLD_FRACTION * contrast) as u16;
    let options = CentroidOptions {
        threshold: Threshold::Fixed(threshold),
        // 0 where the flattening could not measure it (no plane, or a black background): the border's range then.
        background_noise_dn: (flat.noise_dn > 0.0).then_some(flat.noise_dn),
        ..*options
    };
    measure(&options)
}

/// Most border pixels of a window (64 x 64).
const MAX_BORDER_PX: usize = 4 * 64;

/// The background plane `a + b x + c y` (x, y from the window's centre) through the border pixels of a `w` x `h` window
/// whose pixel (i, j) is `at(i, j)` and whose blob's extreme value (the darkest pixel for dark blobs, the brightest for
/// bright ones) is `blob_extreme`, and the background's noise (one standard deviation). First fitted through the border
/// pixels within a quarter of the contrast of the border's background extreme (its lightest pixel for dark blobs), then
/// up to three more times through those that stand towards the blob less than twice the noise from the last plane (a
/// pixel away from the blob, a highlight on a dark blob's border, stays in), the noise taken each time from the
/// residuals on the background's side of the plane. A dense grid puts parts of the neighbouring circles on a window's
/// border, often most of it, and partly covered pixels at their rims: a plane fitted through them tilts and sinks
/// towards them, which gives the flattened blob a slant that moves its centroid. On the 7 photographs of a 24 x 28
/// hexagonal grid of printed circles (gaps of a fifth of a circle's diameter), the plane through the whole border put
/// the window centroids a median 0.59 px from the circles' outline centres and found 51 of the 2,337 circles in their
/// windows; this one, a median 0.040 px and 652.
fn border_plane(
    w: usize,
    h: usize,
    polarity: Polarity,
    blob_extreme: f64,
    at: impl Fn(usize, usize) -> f64,
) -> (f64, f64, f64, f64) {
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let mut border = [(0.0f64, 0.0f64, 0.0f64); MAX_BORDER_PX];
    let mut n = 0;
    let mut push = |i: usize, j: usize| {
        if n < MAX_BORDER_PX {
            border[n] = (i as f64 - cx, j as f64 - cy, at(i, j));
            n += 1;
        }
    };
    for i in 0..w {
        push(i, 0);
        if h > 1 {
            push(i, h - 1);
        }
    }
    for j in 1..h.saturating_sub(1) {
        push(0, j);
        if w > 1 {
            push(w - 1, j);
        }
    }
    let border = &border[..n];
    // Values measured towards the blob: +v for bright blobs, -v for dark ones.
    let towards_blob = match polarity {
        Polarity::Dark => -1.0,
        Polarity::Bright => 1.0,
    };
    let background_level = border
        .iter()
        .map(|p| towards_blob * p.2)
        .fold(f64::INFINITY, f64::min);
    let midpoint = background_level + 0.25 * (towards_blob * blob_extreme - background_level);
    let mut background = [false; MAX_BORDER_PX];
    for (keep, p) in background.iter_mut().zip(border) {
        *keep = towards_blob * p.2 <= midpoint;
    }
    let Some(first) = fit_plane(border, &background[..n]) else {
        let mean = border.iter().map(|p| p.2).sum::<f64>() / n.max(1) as f64;
        return (mean, 0.0, 0.0, 0.0);
    };
    let plane_at =
        |plane: &[f64; 3], p: &(f64, f64, f64)| plane[0] + plane[1] * p.0 + plane[2] * p.1;
    // Refits without the pixels that stand towards the blob by more than twice the background's noise, the noise
    // taken from the residuals on the background's own side of the plane, where no blob's rim reaches (half a normal
    // distribution, whose mean absolute value is 0.798 standard deviations). Partly covered pixels at a neighbour's
    // rim pass the midpoint split and pull the first plane towards the blobs; each refit leaves more of them out.
    let background_noise = |plane: &[f64; 3]| {
        let (mut sum, mut m) = (0.0, 0.0);
        for p in border {
            let r = p.2 - plane_at(plane, p);
            if towards_blob * r <= 0.0 {
                sum -= towards_blob * r;
                m += 1.0;
            }
        }
        if m > 0.0 { 1.2533 * sum / m } else { 0.0 }
    };
    let mut plane = first;
    let mut noise = background_noise(&plane);
    for _ in 0..3 {
        let limit = (2.0 * noise).max(2.0);
        let mut changed = false;
        for (keep, p) in background.iter_mut().zip(border) {
            let is_background = towards_blob * (p.2 - plane_at(&plane, p)) <= limit;
            changed |= is_background != *keep;
            *keep = is_background;
        }
        if !changed {
            break;
        }
        let Some(refit) = fit_plane(border, &background[..n]) else {
            break;
        };
        plane = refit;
        noise = background_noise(&plane);
    }
    (plane[0], plane[1], plane[2], noise)
}

/// Why [`track_frame_stream`] stopped: the source failed (`S`: an unreadable frame, a timestamps file that does not
/// match), a frame could not be processed, or an estimate could not be handed on (`K`). The estimates handed on before
/// are kept.
#[derive(Debug, Error)]
pub enum FrameStreamError<S, K, I> {
    #[error(transparent)]
    Source(S),
    /// Frame number `index` (0-based), which `next_frame` described as `info`, could not be processed.
    #[error("frame {index}: {source}")]
    Frame {
        index: usize,
        info: I,
        #[source]
        source: FrameError,
    },
    #[error(transparent)]
    Sink(K),
    #[error("the decoding thread panicked")]
    DecoderPanicked,
}

/// Frames decoded ahead of the tracker: enough to ride out a slow frame, few enough to bound memory.
const FRAMES_IN_FLIGHT: usize = 4;

/// Runs `tracker` over the frames `next_frame` decodes, the decoding on a thread of its own beside the tracker (the
/// two-thread loop): `next_frame` fills the frame it is given (a reused buffer, its `t_s` set) and returns what the
/// caller wants to know of it (a file name, say), `None` at the end. `sink` gets every frame's outcome with that
/// information and the centroids measured in the frame ([`FrameTracker::measurements`]: what the tracker saw, the
/// measurements its estimate rests on), in order. Returns the tracker's report; on an error, what was handed to `sink` stays handed.
/// With a rolling shutter ([`FrameTracker::smooths_rolling_shutter`]), each frame reaches `sink` two frames late, its
/// pose refitted with the twist of the poses around it ([`RollingSmoother`]); the frames held when the source ends or
/// fails are handed over before it returns.
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::Frame;
/// use roitrack_pipeline::frames::{FrameTracker, FrameTrackerConfig, track_frame_stream};
///
/// // Three black frames: no target, no estimate, no error.
/// let mut tracker =
///     FrameTracker::new(CameraModel::canonical(), Target::grid4x4(), FrameTrackerConfig::default()).unwrap();
/// let mut k = 0;
/// let next = move |frame: &mut Frame| {
///     k += 1;
///     (k <= 3).then(|| {
///         frame.resize(1024, 1024, 8);
///         frame.pixels.fill(0);
///         frame.t_s = k as f64 / 30.0;
///         Ok::<_, std::convert::Infallible>(k)
///     })
/// };
/// let mut seen = Vec::new();
/// let report = track_frame_stream(&mut tracker, next, |k, outcome, measured| {
///     assert!(measured.is_empty());
///     seen.push((*k, outcome.estimate.is_some()));
///     Ok::<_, std::convert::Infallible>(())
/// })
/// .unwrap();
/// assert_eq!(seen, vec![(1, false), (2, false), (3, false)]);
/// assert_eq!(report.not_found, 3);
/// ```
pub fn track_frame_stream<I, S, K>(
    tracker: &mut FrameTracker,
    mut next_frame: impl FnMut(&mut Frame) -> Option<Result<I, S>> + Send,
    mut sink: impl FnMut(&I, &FrameOutcome, &[Measurement]) -> Result<(), K>,
) -> Result<FrameTrackReport, FrameStreamError<S, K, I>>
where
    I: Send,
    S: Send,
{
    let (full_tx, full_rx) = mpsc::sync_channel::<Result<(Frame, I), S>>(FRAMES_IN_FLIGHT);
    let (empty_tx, empty_rx) = mpsc::channel::<Frame>();
    for _ in 0..FRAMES_IN_FLIGHT + 1 {
        let _ = empty_tx.send(Frame::default());
    }
    std::thread::scope(|scope| {
        let decoder = scope.spawn(move || {
            // Buffers come back from the tracker once used; when it stops taking frames (an error), stop too.
            while let Ok(mut frame) = empty_rx.recv() {
                match next_frame(&mut frame) {
                    None => break,
                    Some(Ok(info)) => {
                        if full_tx.send(Ok((frame, info))).is_err() {
                            break;
                        }
                    }
                    Some(Err(e)) => {
                        let _ = full_tx.send(Err(e));
                        break;
                    }
                }
            }
        });
        let mut result = Ok(());
        // Offline, a rolling shutter's estimates come two frames late, refined (FrameTrackerConfig::rs_smoothing).
        let mut smoother = tracker
            .smooths_rolling_shutter()
            .then(|| RollingSmoother::new(tracker.camera().clone(), tracker.target.clone()));
        for (index, item) in full_rx.iter().enumerate() {
            let (frame, info) = match item {
                Ok(item) => item,
                Err(e) => {
                    result = Err(FrameStreamError::Source(e));
                    break;
                }
            };
            let outcome = match tracker.process(&frame) {
                Ok(outcome) => outcome,
                Err(source) => {
                    result = Err(FrameStreamError::Frame {
                        index,
                        info,
                        source,
                    });
                    break;
                }
            };
            let _ = empty_tx.send(frame);
            let sunk = match &mut smoother {
                Some(smoother) => match smoother.push(info, outcome, tracker.measurements()) {
                    Some((info, outcome, measured)) => sink(&info, &outcome, &measured),
                    None => Ok(()),
                },
                None => sink(&info, &outcome, tracker.measurements()),
            };
            if let Err(e) = sunk {
                result = Err(FrameStreamError::Sink(e));
                break;
            }
        }
        // The frames still held, also when the source or a frame failed: what was estimated before is kept.
        if let Some(smoother) = &mut smoother
            && !matches!(result, Err(FrameStreamError::Sink(_)))
        {
            for (info, outcome, measured) in smoother.finish() {
                if let Err(e) = sink(&info, &outcome, &measured) {
                    result = Err(FrameStreamError::Sink(e));
                    break;
                }
            }
        }
        // Unblocks a decoder waiting for a buffer or for room in the queue.
        drop(empty_tx);
        drop(full_rx);
        if decoder.join().is_err() {
            return Err(FrameStreamError::DecoderPanicked);
        }
        result
    })?;
    Ok(tracker.report())
}

/// The symmetries of `target` that identification cannot tell apart ([`Target::ambiguity`]), each with the index of
/// the point it takes each point to.
fn symmetric_twins(target: &Target) -> Vec<(Symmetry, Vec<usize>)> {
    let Some(TargetAmbiguity::Symmetric { motions }) = target.ambiguity() else {
        return Vec::new();
    };
    let points = target.points();
    motions
        .into_iter()
        .filter_map(|symmetry| {
            let image: Option<Vec<usize>> = points
                .iter()
                .map(|p| {
                    let moved = symmetry.obj_r * p.point_in_obj_m + symmetry.obj_t_m;
                    (0..points.len()).min_by(|&a, &b| {
                        (points[a].point_in_obj_m - moved)
                            .norm()
                            .total_cmp(&(points[b].point_in_obj_m - moved).norm())
                    })
                })
                .collect();
            image.map(|image| (symmetry, image))
        })
        .collect()
}

/// The pose under which the target's points, relabelled by `symmetry` (point `p` named as `S p`), project where
/// they do under `state`: `cam_T_obj S⁻¹`.
fn twin_state(state: &MotionState, symmetry: &Symmetry) -> MotionState {
    let cam_r_obj = state.cam_r_obj * symmetry.obj_r.inverse();
    MotionState {
        cam_r_obj,
        cam_t_obj_m: state.cam_t_obj_m - cam_r_obj * symmetry.obj_t_m,
        ..*state
    }
}

#[cfg(test)]
mod tests {
    use roitrack_core::time::Readout;

    use super::*;

    fn tuning(config: &TrackerConfig) -> MotionModel {
        let EstimatorConfig::Kalman(tuning) = config.estimator else {
            unreachable!()
        };
        tuning.motion_model
    }

    #[test]
    fn a_users_jerk_densities_equal_to_the_global_defaults_stay_with_a_rolling_shutter() {
        let mut rolling = CameraModel::canonical();
        rolling.time.readout = Readout::RollingShutter {
            line_delay_s: 30e-6,
        };
        // `--jerk-psd 100 --angular-jerk-psd 300`: the global-shutter defaults' values, chosen by the user.
        let given = FrameTrackerConfig::frame_estimator(
            TrackerConfig {
                estimator: EstimatorConfig::Kalman(roitrack_core::estimator::KalmanTuning {
                    motion_model: MotionModel::constant_acceleration_with(Some(100.0), Some(300.0)),
                    ..Default::default()
                }),
                ..TrackerConfig::default()
            },
            None,
            None,
        );
        assert_eq!(tuning(&given), MotionModel::constant_acceleration());
        let kept = FrameTracker::for_readout(given, &rolling, true);
        assert_eq!(tuning(&kept), MotionModel::constant_acceleration());
        // Without a choice, the rolling shutter's own defaults.
        let defaulted = FrameTracker::for_readout(given, &rolling, false);
        assert_eq!(
            tuning(&defaulted),
            MotionModel::constant_acceleration_for_rolling_shutter()
        );
        // A global shutter keeps the global defaults either way.
        let global = FrameTracker::for_readout(given, &CameraModel::canonical(), false);
        assert_eq!(tuning(&global), MotionModel::constant_acceleration());
    }
}
