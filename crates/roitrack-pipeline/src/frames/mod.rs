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

mod centre_blend;
mod config;
mod joint_start;
mod outcome;
mod restart;
mod search;
mod stream;
mod windows;

pub use config::FrameTrackerConfig;
pub use outcome::{FrameError, FrameMethod, FrameOutcome, FrameTrackReport};
/// The window measurement, now in the image crate: re-exported where the frame tracker's callers found it.
pub use roitrack_image::window::{FlatWindow, flatten_window, measure_flat_window};
pub use stream::{FrameStreamError, track_frame_stream, track_frame_stream_leaving_out};

use nalgebra::Vector2;
use roitrack_core::{CameraModel, Measurement, Target};
use roitrack_estimators::{
    ConfigError, Emit, Estimate, Estimator, EstimatorConfig, MotionModel, Observation, TrackStatus,
    Tracker, TrackerConfig,
};
use roitrack_image::{Frame, PhotoScratch, Polarity};

use crate::scheduler::{Predictor, RoiScheduler};
use joint_start::RecentFrames;
use restart::{TrackMemory, symmetric_twins};
use roitrack_detect::photo::PolarityChoice;
use search::WholeFrameSearch;
use windows::{Windows, carried_with_acceleration};

#[cfg(doc)]
use roitrack_detect::photo::detect_target;
#[cfg(doc)]
use roitrack_image::measure_blob;

/// A frame whose blobs lie farther than this (RMS, px) from where its estimate puts them is found whole and starts
/// a new track: far beyond any centroid's noise, and beyond what a rolling-shutter frame's readout leaves the filter
/// (whose rolling model the static pose of a new track lacks).
const RESTART_RESIDUAL_PX: f64 = 5.0;

/// Tracks a target through frames: one estimate per frame (see the [module documentation](self)).
///
/// ```
/// use nalgebra::Vector3;
/// use rand::SeedableRng;
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_image::Frame;
/// use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};
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
    /// The window path: the scheduler, the windows' buffers and the blend of their two kinds of centres.
    windows: Windows,
    /// The whole-frame search: its settings and buffers, the polarity in use and the target's symmetric twins.
    search: WholeFrameSearch,
    /// What the track carries from one frame to the next: the predictor, the last times, the last trusted pose.
    memory: TrackMemory,
    /// With a rolling shutter, the last frames' measurements, from which a new track's start is fitted.
    recent: RecentFrames,
    /// The frame's measurements, in time order.
    measurements: Vec<Measurement>,
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
        let blob_options = config.detection.blob_options(&camera, &target);
        let points = target.len();
        Ok(Self {
            windows: Windows::new(scheduler, points),
            search: WholeFrameSearch {
                blob_options,
                scratch: PhotoScratch::default(),
                polarity,
                twins: symmetric_twins(&target),
            },
            memory: TrackMemory::default(),
            recent: RecentFrames::default(),
            measurements: Vec::with_capacity(points),
            camera,
            target,
            config,
            tracker,
            report: FrameTrackReport {
                polarity,
                ..FrameTrackReport::default()
            },
        })
    }

    /// `config` for the camera's readout: with a rolling shutter, the frame default's jerk densities
    /// ([`MotionModel::constant_acceleration`]) become the rolling-shutter ones
    /// ([`MotionModel::constant_acceleration_for_rolling_shutter`]); densities a user chose (`jerk_psd_given`) stay,
    /// also when they equal the frame default's. A rolling-shutter frame's blobs, read over milliseconds, show the
    /// motion within the frame, so the filter can follow faster changes of acceleration there without taking a frame's
    /// noise for motion; with the global-shutter densities, sudden steps of acceleration left such tracks millimetres
    /// off in depth (measured in docs/estimation.md, "Frame cameras", and docs/results.md, "Design measurements behind
    /// the code").
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
        self.check_frame(frame)?;
        self.report.frames += 1;
        // The windows go where the running filter predicts the frame, with its uncertainty: its accelerations
        // and the process noise of the frame interval included (carried by the last estimate's covariance alone, a
        // fast random motion at 30 Hz was predicted at 4 px where it lay 43 px off, a whole grid spacing, and the
        // windows measured each point's neighbour).
        if let Some(predictor) = self.memory.predictor {
            // (An estimator without a covariance of its own prediction keeps the last estimate, carried as before:
            // its covariance belongs to the estimate's time.)
            self.memory.predictor = Some(match self.tracker.predicted(frame.t_s) {
                Some((state, Some(covariance))) => Predictor {
                    t_ref_s: frame.t_s,
                    state,
                    covariance: Some(covariance),
                },
                _ => match self.memory.acceleration {
                    Some(acceleration) => {
                        carried_with_acceleration(predictor, &acceleration, frame.t_s)
                    }
                    None => predictor,
                },
            });
        }
        let mut method = FrameMethod::NotFound;
        if let Some(predictor) = self.memory.predictor
            && self.measure_windows(frame, &predictor) >= self.min_window_points()
        {
            method = FrameMethod::Windows;
        }
        // The target's static pose in this frame, when it was identified whole.
        let mut found = None;
        if method == FrameMethod::NotFound {
            (method, found) = self.search_whole_frame(frame)?;
        }
        // A rolling-shutter track still resting on fewer frames than a joint start takes starts again from them and
        // this frame fitted together, before the filter is given this frame.
        if matches!(method, FrameMethod::Windows | FrameMethod::FullFrame)
            && self.wants_joint_start()
        {
            let guesses = self.joint_guesses(found);
            self.joint_start(frame.t_s, &guesses)?;
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
                self.windows.scheduler.reset();
                self.restart(frame.t_s, pose)?;
                method = FrameMethod::Restart;
                estimate = self.estimate_frame(method)?;
            }
        }
        // A new track started from one rolling-shutter frame alone: its static pose read the target's motion over
        // the readout as a change of pose, which one frame cannot tell apart (at 1.5 m/s, 9 mm off where the
        // track started at rest), so its first estimate is not vouched for.
        if method == FrameMethod::Restart
            && self.camera.time.is_rolling()
            && self.recent.track_frames == 0
            && let Some(e) = estimate.as_mut()
            && matches!(e.status, TrackStatus::Tracking | TrackStatus::Converging)
        {
            e.status = TrackStatus::Degenerate;
        }
        self.record(frame, method, estimate.as_ref());
        Ok(FrameOutcome {
            estimate,
            method,
            // A frame whose target was not found leaves no measurement.
            measured: self.measurements.len(),
        })
    }

    /// Refuses a frame of another size than the camera's, or whose time is not finite or does not come after the
    /// previous frame's measurements.
    fn check_frame(&self, frame: &Frame) -> Result<(), FrameError> {
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
        if let Some(previous_s) = self.memory.last_time_s
            && frame.t_s <= previous_s
        {
            return Err(FrameError::TimeOrder {
                t_s: frame.t_s,
                previous_s,
            });
        }
        Ok(())
    }

    /// Counts the frame's outcome and keeps what the next frame needs: the trusted pose, the frame's latest time and
    /// the predictor.
    fn record(&mut self, frame: &Frame, method: FrameMethod, estimate: Option<&Estimate>) {
        if let Some(e) = estimate {
            self.report.estimates += 1;
            self.memory.last_estimate_s = Some(e.t_ref_s);
            if method == FrameMethod::Restart || e.status.is_vouched_for() {
                self.memory.last_pose = Some((e.t_ref_s, e.state));
            }
        }
        match method {
            FrameMethod::Windows => self.report.by_windows += 1,
            FrameMethod::FullFrame => self.report.by_full_frame += 1,
            FrameMethod::Restart => self.report.restarts += 1,
            FrameMethod::NotFound => self.report.not_found += 1,
        }
        if self.camera.time.is_rolling() {
            if estimate.is_some() {
                self.recent.track_frames += 1;
            }
            self.recent.remember(frame.t_s, &self.measurements);
        }
        // The measurements are in time order: the last is the frame's latest time, if later than its row 0.
        let latest_s = self.measurements.last().map_or(frame.t_s, |m| m.t_s);
        self.memory.last_time_s = Some(latest_s.max(frame.t_s));
        if let Some(e) = estimate {
            // A lost track is dropped by the estimator: the next frame is searched whole.
            self.memory.predictor = (e.status != TrackStatus::Lost).then_some(Predictor {
                t_ref_s: e.t_ref_s,
                state: e.state,
                covariance: e.covariance,
            });
            self.memory.acceleration = e.acceleration;
            self.memory.noise_px = Some(e.noise_px);
            self.memory.tracking = e.status == TrackStatus::Tracking;
        }
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
        if dt_s >= 0.0
            || self
                .memory
                .last_estimate_s
                .is_some_and(|last| mean_s <= last)
        {
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

    /// The RMS distance (px) between the frame's blobs and where `estimate` puts their points at their own times: what
    /// tells an estimate that agrees with its frame from one the filter could not pull there (a covariance reset left
    /// it re-converging far off: docs/results.md, "Design measurements behind the code"); infinite if a point does not
    /// project.
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
}

/// The observation of measurement `m`: its point's index in `target` and its centroid undistorted by `camera`;
/// `None` for an id `target` does not have or a centroid that does not undistort (the joint start's and the
/// smoother's fits leave such blobs out).
pub(crate) fn observation_of(
    target: &Target,
    camera: &CameraModel,
    m: &Measurement,
) -> Option<Observation> {
    Some(Observation {
        t_s: m.t_s,
        point_index: target.index_of(m.id)?,
        ideal_px: camera.undistort_pixel(&Vector2::new(m.u_px, m.v_px)).ok()?,
    })
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
                estimator: EstimatorConfig::Kalman(roitrack_estimators::KalmanTuning {
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
