//! The closed loop in simulated time: the robot moves, the simulated camera sees the target where the robot has it,
//! the tracker estimates, the controller acts ([`run_servo`]). Deterministic for a seed.
//!
//! The clock ticks at the control rate (4 kHz, one ROI per tick). At each tick `t`:
//! 1. the estimates whose processing ended by `t` become available to the controller;
//! 2. the controller computes the forces that act at `t + actuation delay` (the `true-state` floor: the true state now,
//!    acting now);
//! 3. the robot is integrated to the next tick (RK4, 4 steps per tick) under the forces acting, each clipped to the
//!    actuator's limit;
//! 4. the camera exposes: the ROI camera one ROI centred where roitrack's scheduler predicts the blob
//!    ([`roitrack_pipeline::RoiScheduler`]), rendered from the robot's motion over its exposure
//!    ([`roitrack_sim::RoiRenderer`]), centroided ([`roitrack_image::measure_roi`]) and pushed to the tracker
//!    ([`roitrack_estimators::Tracker`]); a frame camera a whole global-shutter frame when one is due, tracked by
//!    [`roitrack_pipeline::FrameTracker`]. An estimate is available `exposure / 2 + readout + processing + extra
//!    latency` after the time it refers to.
//!
//! A run whose error from the path passes [`ServoConfig::divergence_error_m`], whose platform leaves the workspace,
//! whose actuators stay at their force limit (a limit cycle, [`ServoConfig::saturation_window_s`]) or whose
//! controller gives a force that is not finite is stopped and reported unstable.

use std::collections::VecDeque;

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::time::{Readout, TimeModel};
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_estimators::{Estimate, Estimator, TrackError, Tracker, TrackerConfig};
use roitrack_image::{CentroidOptions, Frame, RoiImage, measure_roi};
use roitrack_pipeline::{
    FrameError, FrameTracker, FrameTrackerConfig, Predictor, RoiScheduler, SchedulerConfig,
};
use roitrack_sim::{RenderScratch, RoiRenderer, SensorError, SensorModel};
use thiserror::Error;

use crate::control::{
    ComputedTorque, ControlInput, Controller, Gains, KinematicGains, KinematicServo, Observation,
    VelocitySource,
};
use crate::reference::{ReferencePath, ReferencePoint};
use crate::robot::{Geometry, RobotParams, RobotState, step_rk4};

/// Which controller a run uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    /// Computed torque, the tracker's position and velocity predicted to the actuation instant.
    Ctc,
    /// Computed torque, position only (velocity by differences of the estimated positions).
    CtcPose,
    /// Kinematic visual servo into the drives' joint-velocity loop.
    Kvs,
    /// Computed torque on the true state, with no delay: the floor.
    TrueState,
}

impl ControllerKind {
    /// Every controller, in the table's order.
    pub const ALL: [Self; 4] = [Self::Ctc, Self::CtcPose, Self::Kvs, Self::TrueState];

    /// `ctc`, `ctc-pose`, `kvs`, `true-state`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Ctc => "ctc",
            Self::CtcPose => "ctc-pose",
            Self::Kvs => "kvs",
            Self::TrueState => "true-state",
        }
    }

    /// The controller of that [`Self::name`], if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// What the controller sees the robot through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraKind {
    /// The ROI camera: one ROI every 250 µs, an estimate every 10 (roitrack).
    Roi,
    /// A 120 Hz global-shutter frame camera through the frame tracker.
    Frames120,
    /// A 30 Hz global-shutter frame camera through the frame tracker.
    Frames30,
    /// No camera: the true state (the `true-state` controller's).
    Truth,
}

impl CameraKind {
    /// `roi`, `frames-120`, `frames-30`, `truth`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Roi => "roi",
            Self::Frames120 => "frames-120",
            Self::Frames30 => "frames-30",
            Self::Truth => "truth",
        }
    }

    /// The camera of that [`Self::name`], if any.
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Roi, Self::Frames120, Self::Frames30, Self::Truth]
            .into_iter()
            .find(|k| k.name() == name)
    }

    /// The camera's timing: exposure, readout and processing (docs/servo.md, "Latency").
    pub fn timing(&self) -> CameraTiming {
        match self {
            // 100 µs exposure (the paper's), a small ROI read in 50 µs, 100 µs to centroid and update the filter.
            Self::Roi | Self::Truth => CameraTiming {
                rate_hz: 4000.0,
                exposure_s: 100e-6,
                readout_s: 50e-6,
                processing_s: 100e-6,
            },
            // 1 ms exposure, a 1 Mpx frame read in half a frame period (at most 4 ms), 3 ms to find and fit the blobs.
            Self::Frames120 => CameraTiming {
                rate_hz: 120.0,
                exposure_s: 1e-3,
                readout_s: 4e-3,
                processing_s: 3e-3,
            },
            Self::Frames30 => CameraTiming {
                rate_hz: 30.0,
                exposure_s: 1e-3,
                readout_s: 4e-3,
                processing_s: 3e-3,
            },
        }
    }
}

/// When a camera's images are taken and when their estimates are ready.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraTiming {
    /// ROIs or frames per second.
    pub rate_hz: f64,
    /// Exposure of each ROI or frame.
    pub exposure_s: f64,
    /// From the end of the exposure to the image in memory.
    pub readout_s: f64,
    /// From the image in memory to the estimate.
    pub processing_s: f64,
}

impl CameraTiming {
    /// From the time an estimate refers to (its newest image's mid-exposure) to the estimate ready.
    pub fn latency_s(&self) -> f64 {
        self.exposure_s / 2.0 + self.readout_s + self.processing_s
    }
}

/// One closed-loop run.
#[derive(Debug, Clone)]
pub struct ServoConfig {
    /// The law that drives the robot.
    pub controller: ControllerKind,
    /// What it sees the robot through.
    pub camera: CameraKind,
    /// The path to follow.
    pub path: ReferencePath,
    /// The simulated robot.
    pub robot: RobotParams,
    /// The controller's model: the robot's masses times this (0.8: a payload 25 % of the model's masses unknown to
    /// it, the model 20 % off) and its friction times `model_friction_factor`.
    pub model_mass_factor: f64,
    /// The controller's model: the robot's friction times this.
    pub model_friction_factor: f64,
    /// The gains; `None`: from the loop's latency ([`Gains::for_latency`], [`KinematicGains::for_latency`]), with
    /// [`Self::depth_factor`] along the optical axis for a camera.
    pub gains: Option<Gains>,
    /// [`Gains::depth_factor`] of the gains made from the latency, for the camera-fed controllers (the floor's is 1).
    pub depth_factor: f64,
    /// The natural frequency (or λ) times this: for the study of the largest stable gain.
    pub gain_scale: f64,
    /// From the command to the force (s): the drive's delay. The `true-state` floor has none.
    pub actuation_delay_s: f64,
    /// Latency added between the camera and the controller (s); for the `true-state` floor, the true state this much
    /// old.
    pub extra_latency_s: f64,
    /// Whether the gains made from the latency (`gains: None`) count [`Self::extra_latency_s`]: the loop knows the
    /// age of its feedback (each estimate carries the time it refers to) and tunes for it. `false`: tuned for the
    /// camera's own latency only, to see what an unforeseen delay does.
    pub gains_follow_latency: bool,
    /// The camera's timing; `None`: [`CameraKind::timing`].
    pub timing: Option<CameraTiming>,
    /// The tracker's configuration (ROI camera; the frame tracker's is made from it).
    pub tracker: TrackerConfig,
    /// Gaussian noise added to each ROI centroid (px, standard deviation per image axis), on top of the rendered
    /// image's own (read and shot noise, which leaves the centroids several times below the 0.1 px of the built-in
    /// scenes: docs/servo.md): 0 by default; 0.1 to servo with the built-in scenes' noise.
    pub extra_centroid_noise_px: f64,
    /// Whether the controller tells the tracker the acceleration it commands (ROI camera; `ctc`, `ctc-pose` and
    /// `kvs`): at each tick, the platform's acceleration that its own model gives for the forces it commands
    /// ([`Controller::believed_acceleration`]), in the camera frame, from the instant those forces act (the tick
    /// plus the actuation delay), which the Kalman filter adds to its prediction
    /// (`roitrack_estimators::Estimator::set_known_acceleration`). On by default; off, the filter predicts
    /// with its constant-velocity model alone and its velocity lags the commanded accelerations (docs/servo.md). The
    /// real-time loop ([`crate::live::run_live_servo`]) does the same through the live loop's queue of known
    /// accelerations to its estimation thread.
    pub known_acceleration: bool,
    /// Seed of the camera's noise.
    pub seed: u64,
    /// Distance from the path (m) beyond which the run is stopped as unstable: 50 mm, beyond the largest error of any
    /// run that ends, even at 30 Hz (docs/results.md, "Design measurements behind the code"), and still inside the
    /// image (the path keeps the blobs about 90 mm from its border at 0.6 m).
    pub divergence_error_m: f64,
    /// A run whose actuators are at their force limit more than half of any window this long (s) is stopped as
    /// unstable: 0.1 s. An unstable loop does not always run away: the force limit can hold it in a limit cycle a
    /// few millimetres wide (saturated most of the time), which the distance alone would not catch; a stable loop
    /// on the path saturates only in transients (none in the nominal runs).
    pub saturation_window_s: f64,
    /// Control (and ROI) ticks per second.
    pub control_rate_hz: f64,
    /// RK4 steps per control tick.
    pub substeps: usize,
}

impl ServoConfig {
    /// The run of `controller` through `camera` on the orthoglide path at `speed_scale` times 1 m/s peak, with the
    /// defaults: the Orthoglide-like robot, the model's masses and friction 20 % low, 250 µs actuation delay, gains
    /// from the latency, seed 1.
    ///
    /// ```
    /// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
    /// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
    /// assert_eq!(config.path.name(), "orthoglide");
    /// ```
    pub fn new(controller: ControllerKind, camera: CameraKind, speed_scale: f64) -> Self {
        let camera = if controller == ControllerKind::TrueState {
            CameraKind::Truth
        } else {
            camera
        };
        Self {
            controller,
            camera,
            path: ReferencePath::orthoglide(speed_scale),
            robot: RobotParams::orthoglide(),
            model_mass_factor: 0.8,
            model_friction_factor: 0.8,
            gains: None,
            depth_factor: 0.5,
            gain_scale: 1.0,
            actuation_delay_s: 250e-6,
            extra_latency_s: 0.0,
            gains_follow_latency: true,
            timing: None,
            tracker: servo_tracker_config(),
            extra_centroid_noise_px: 0.0,
            known_acceleration: true,
            seed: 1,
            divergence_error_m: 0.05,
            saturation_window_s: 0.1,
            control_rate_hz: 4000.0,
            substeps: 4,
        }
    }

    /// The camera's timing in use.
    pub fn camera_timing(&self) -> CameraTiming {
        self.timing.unwrap_or_else(|| self.camera.timing())
    }

    /// The model of the camera the loop sees the robot through (the built-in calibration, its readout and
    /// [`Self::camera_timing`]'s exposure); `None` for the true state, which no camera sees.
    ///
    /// ```
    /// use roitrack_core::time::Readout;
    /// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
    /// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Frames30, 1.0);
    /// assert_eq!(config.camera_model().unwrap().time.readout, Readout::GlobalShutter);
    /// assert!(ServoConfig::new(ControllerKind::TrueState, CameraKind::Truth, 1.0).camera_model().is_none());
    /// ```
    pub fn camera_model(&self) -> Option<CameraModel> {
        let readout = match self.camera {
            CameraKind::Truth => return None,
            CameraKind::Roi => Readout::SequentialRois,
            CameraKind::Frames120 | CameraKind::Frames30 => Readout::GlobalShutter,
        };
        let mut camera = CameraModel::canonical();
        camera.time = TimeModel {
            readout,
            exposure_s: self.camera_timing().exposure_s,
        };
        Some(camera)
    }

    /// How old, on average, the feedback is when the command it made acts (s), as the gains are tuned for it: the
    /// camera's latency, the actuation delay and half the interval between estimates (an estimate every 10 ROIs, or
    /// one per frame), plus the extra latency when [`Self::gains_follow_latency`]; for the `true-state` floor only
    /// that extra latency.
    ///
    /// ```
    /// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
    /// let mut config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
    /// assert!((config.feedback_age_s() - 1.7e-3).abs() < 1e-9);
    /// config.extra_latency_s = 1e-3;
    /// assert!((config.feedback_age_s() - 2.7e-3).abs() < 1e-9);
    /// config.gains_follow_latency = false;
    /// assert!((config.feedback_age_s() - 1.7e-3).abs() < 1e-9);
    /// ```
    pub fn feedback_age_s(&self) -> f64 {
        let extra_s = if self.gains_follow_latency {
            self.extra_latency_s
        } else {
            0.0
        };
        if self.camera == CameraKind::Truth {
            return extra_s;
        }
        let timing = self.camera_timing();
        let estimate_interval_s = match self.camera {
            CameraKind::Roi => self.tracker.every as f64 / timing.rate_hz,
            _ => 1.0 / timing.rate_hz,
        };
        timing.latency_s() + self.actuation_delay_s + estimate_interval_s / 2.0 + extra_s
    }

    /// The natural frequency (rad/s; λ for the kinematic servo) that the gain rule gives for
    /// [`Self::feedback_age_s`] ([`Gains::for_latency`], [`KinematicGains::for_latency`]), before
    /// [`Self::gain_scale`] and the depth factor.
    pub fn rule_gain_radps(&self) -> f64 {
        let age = self.feedback_age_s();
        match self.controller {
            ControllerKind::Kvs => KinematicGains::for_latency(age).lambda_per_s,
            _ => Gains::for_latency(age).natural_frequency_radps,
        }
    }

    pub(crate) fn check(&self) -> Result<(), ServoError> {
        let positive = |field: &'static str, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(ServoError::Invalid { field, value })
            }
        };
        let non_negative = |field: &'static str, value: f64| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(ServoError::Invalid { field, value })
            }
        };
        positive("model_mass_factor", self.model_mass_factor)?;
        non_negative("model_friction_factor", self.model_friction_factor)?;
        positive("gain_scale", self.gain_scale)?;
        positive("depth_factor", self.depth_factor)?;
        non_negative("actuation_delay_s", self.actuation_delay_s)?;
        non_negative("extra_latency_s", self.extra_latency_s)?;
        non_negative("extra_centroid_noise_px", self.extra_centroid_noise_px)?;
        positive("divergence_error_m", self.divergence_error_m)?;
        positive("saturation_window_s", self.saturation_window_s)?;
        positive("control_rate_hz", self.control_rate_hz)?;
        positive("substeps", self.substeps as f64)?;
        if let Some(gains) = self.gains {
            positive(
                "gains.natural_frequency_radps",
                gains.natural_frequency_radps,
            )?;
            positive("gains.damping", gains.damping)?;
        }
        let timing = self.camera_timing();
        positive("timing.rate_hz", timing.rate_hz)?;
        non_negative("timing.exposure_s", timing.exposure_s)?;
        non_negative("timing.readout_s", timing.readout_s)?;
        non_negative("timing.processing_s", timing.processing_s)?;
        if self.camera == CameraKind::Roi && (timing.rate_hz - self.control_rate_hz).abs() > 1e-9 {
            return Err(ServoError::Invalid {
                field: "timing.rate_hz (the ROI camera reads one ROI per control tick)",
                value: timing.rate_hz,
            });
        }
        if (self.controller == ControllerKind::TrueState) != (self.camera == CameraKind::Truth) {
            return Err(ServoError::Invalid {
                field: "camera (the true-state controller and only it sees the truth)",
                value: f64::NAN,
            });
        }
        Ok(())
    }
}

/// The tracker's configuration in the loop: roitrack's default Kalman filter with its process noise fixed at its
/// starting density (1 (m/s²)²/Hz) instead of adapted to the motion. Adapted, it averages the still start down to a
/// density so low that the robot's first accelerations under feedback (force steps at each new estimate) fall
/// outside its gate: the estimates are disputed and the loop diverges (docs/servo.md, "The tracker in the loop").
///
/// ```
/// use roitrack_estimators::EstimatorConfig;
/// let EstimatorConfig::Kalman(tuning) = roitrack_servo::closed_loop::servo_tracker_config().estimator else {
///     unreachable!()
/// };
/// assert!(!tuning.adapt_motion);
/// ```
pub fn servo_tracker_config() -> TrackerConfig {
    let mut config = TrackerConfig::default();
    if let roitrack_estimators::EstimatorConfig::Kalman(tuning) = &mut config.estimator {
        tuning.adapt_motion = false;
    }
    config
}

/// Why a run could not be made (an unstable run is not an error: see [`ServoReport::stable`]).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ServoError {
    /// An option is out of its range.
    #[error("servo option {field} is out of range: {value}")]
    Invalid {
        /// The option's field name.
        field: &'static str,
        /// The value given.
        value: f64,
    },
    /// The simulated camera's sensor model is invalid.
    #[error("the simulated camera: {0}")]
    Sensor(#[from] SensorError),
    /// The tracker refused its configuration.
    #[error("the tracker refused its configuration: {0}")]
    Tracker(String),
    /// The frame tracker failed on a frame.
    #[error("the frame tracker failed on a frame: {0}")]
    Frame(#[from] FrameError),
    /// The tracker refused a measurement.
    #[error("the tracker refused a measurement: {0}")]
    Measurement(#[from] TrackError),
}

/// One control tick of a run (robot frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoSample {
    /// The tick's time (s).
    pub t_s: f64,
    /// The path there.
    pub reference: ReferencePoint,
    /// The platform's true position (m).
    pub achieved_m: Vector3<f64>,
    /// The platform's true velocity (m/s).
    pub achieved_velocity_mps: Vector3<f64>,
    /// The forces acting at `t_s` (N), after clipping.
    pub force_n: Vector3<f64>,
}

impl ServoSample {
    /// The distance from the platform to the path (m).
    pub fn error_m(&self) -> f64 {
        (self.achieved_m - self.reference.position_m).norm()
    }
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct ServoReport {
    /// The law that ran.
    pub controller: ControllerKind,
    /// What it saw the robot through.
    pub camera: CameraKind,
    /// The path it followed.
    pub path: ReferencePath,
    /// RMS distance between the platform and the path over the run (mm).
    pub rms_error_mm: f64,
    /// Largest distance between the platform and the path over the run (mm).
    pub max_error_mm: f64,
    /// Whether the run went to its end.
    pub stable: bool,
    /// Why it was stopped, if it was.
    pub stop_reason: Option<String>,
    /// The gains used (for `kvs`: λ as the natural frequency).
    pub gains: Gains,
    /// Median age of the feedback when the commands it made acted (s): from the mid-exposure of the newest image
    /// in the estimate to the actuation.
    pub median_feedback_age_s: f64,
    /// Fraction of control ticks at which some actuator was at its force limit.
    pub saturated_fraction: f64,
    /// Every control tick.
    pub samples: Vec<ServoSample>,
    /// Every estimate of the tracker (camera frame), in order.
    pub estimates: Vec<Estimate>,
}

/// The robot's motion so far, at every integration step, to render the camera's exposures from.
struct History {
    dt_s: f64,
    states: Vec<RobotState>,
}

impl History {
    /// The state at `t_s`, interpolated (cubic Hermite: position and velocity are both known at each step).
    fn at(&self, t_s: f64) -> RobotState {
        let last = self.states.len() - 1;
        let x = (t_s / self.dt_s).clamp(0.0, last as f64);
        let k = (x.floor() as usize).min(last.saturating_sub(1));
        if last == 0 {
            return self.states[0];
        }
        let (a, b) = (&self.states[k], &self.states[k + 1]);
        let u = x - k as f64;
        let h = self.dt_s;
        let (u2, u3) = (u * u, u * u * u);
        let position = a.position_m * (2.0 * u3 - 3.0 * u2 + 1.0)
            + a.velocity_mps * (h * (u3 - 2.0 * u2 + u))
            + b.position_m * (-2.0 * u3 + 3.0 * u2)
            + b.velocity_mps * (h * (u3 - u2));
        let velocity = (a.position_m * (6.0 * u2 - 6.0 * u) + b.position_m * (-6.0 * u2 + 6.0 * u))
            / h
            + a.velocity_mps * (3.0 * u2 - 4.0 * u + 1.0)
            + b.velocity_mps * (3.0 * u2 - 2.0 * u);
        RobotState {
            position_m: position,
            velocity_mps: velocity,
        }
    }
}

/// The camera side of a run.
enum CameraSide {
    Truth,
    Roi(Box<RoiSide>),
    Frames(Box<FrameSide>),
}

struct RoiSide {
    renderer: RoiRenderer,
    scheduler: RoiScheduler,
    tracker: Tracker,
    predictor: Predictor,
    centroid: CentroidOptions,
    time: TimeModel,
    image: RoiImage,
    scratch: RenderScratch,
    rng: ChaCha8Rng,
    extra_noise: Option<rand_distr::Normal<f64>>,
}

struct FrameSide {
    renderer: RoiRenderer,
    tracker: FrameTracker,
    frame: Frame,
    scratch: RenderScratch,
    rng: ChaCha8Rng,
    rate_hz: f64,
    exposure_s: f64,
    next_frame: usize,
}

impl CameraSide {
    fn new(config: &ServoConfig) -> Result<Self, ServoError> {
        let target = Target::grid4x4();
        let timing = config.camera_timing();
        let (rotation, home) = config.path.home_in_camera();
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        let Some(camera) = config.camera_model() else {
            return Ok(Self::Truth);
        };
        match config.camera {
            CameraKind::Truth => Ok(Self::Truth),
            CameraKind::Roi => {
                let renderer =
                    RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default())?;
                let scheduler = RoiScheduler::new(
                    camera.clone(),
                    target.clone(),
                    SchedulerConfig::default(),
                    config.tracker.noise_px,
                );
                let tracker = Tracker::new(camera.clone(), target, config.tracker)
                    .map_err(|e| ServoError::Tracker(e.to_string()))?;
                Ok(Self::Roi(Box::new(RoiSide {
                    renderer,
                    scheduler,
                    tracker,
                    // The robot starts at rest at home, where the first ROIs are placed.
                    predictor: Predictor {
                        t_ref_s: 0.0,
                        state: MotionState::at_rest(rotation, home),
                        covariance: None,
                    },
                    centroid: CentroidOptions::default(),
                    time: camera.time,
                    image: RoiImage::default(),
                    scratch: RenderScratch::new(),
                    rng,
                    extra_noise: (config.extra_centroid_noise_px > 0.0)
                        .then(|| rand_distr::Normal::new(0.0, config.extra_centroid_noise_px))
                        .transpose()
                        .map_err(|_| ServoError::Invalid {
                            field: "extra_centroid_noise_px",
                            value: config.extra_centroid_noise_px,
                        })?,
                })))
            }
            CameraKind::Frames120 | CameraKind::Frames30 => {
                let renderer =
                    RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default())?;
                let frame_config = FrameTrackerConfig {
                    tracker: FrameTrackerConfig::frame_estimator(config.tracker, None, None),
                    ..FrameTrackerConfig::default()
                };
                let tracker = FrameTracker::new(camera, target, frame_config)
                    .map_err(|e| ServoError::Tracker(e.to_string()))?;
                Ok(Self::Frames(Box::new(FrameSide {
                    renderer,
                    tracker,
                    frame: Frame::default(),
                    scratch: RenderScratch::new(),
                    rng,
                    rate_hz: timing.rate_hz,
                    exposure_s: timing.exposure_s,
                    next_frame: 0,
                })))
            }
        }
    }

    /// Tells the tracker the target's acceleration (camera frame) from `t_s` on, as the controller believes it
    /// (ROI camera only: the frame tracker predicts with its own motion model).
    fn tell_acceleration(
        &mut self,
        t_s: f64,
        linear_mps2: &Vector3<f64>,
    ) -> Result<(), ServoError> {
        if let Self::Roi(side) = self {
            let known = roitrack_core::Acceleration {
                linear_mps2: *linear_mps2,
                angular_radps2: Vector3::zeros(),
            };
            side.tracker
                .set_known_acceleration(t_s, known)
                .map_err(|e| ServoError::Tracker(e.to_string()))?;
        }
        Ok(())
    }

    /// Exposes what is due by `t_now_s` (the robot's motion is known up to it): the ROI of the tick `t_tick_s`, or the
    /// frames whose exposure has ended. Returns the estimates made.
    fn expose(
        &mut self,
        t_tick_s: f64,
        t_now_s: f64,
        state_at: &impl Fn(f64) -> MotionState,
        out: &mut Vec<Estimate>,
    ) -> Result<(), ServoError> {
        match self {
            Self::Truth => Ok(()),
            Self::Roi(side) => {
                let Some(request) = side.scheduler.next(&side.predictor, t_tick_s) else {
                    return Ok(());
                };
                let point_id = side.tracker.target().points()[request.point_index].id;
                let bit_depth = side.renderer.sensor().bit_depth as u8;
                side.image.set(t_tick_s, point_id, request.roi, bit_depth);
                side.renderer.render_readout(
                    state_at,
                    &request.roi,
                    t_tick_s,
                    &mut side.rng,
                    &mut side.scratch,
                    &mut side.image.pixels,
                );
                let mut measured = measure_roi(&side.image, &side.centroid, &side.time);
                side.scheduler.report(request.point_index, measured.is_ok());
                if let (Ok(m), Some(noise)) = (&mut measured, &side.extra_noise) {
                    use rand_distr::Distribution as _;
                    m.u_px += noise.sample(&mut side.rng);
                    m.v_px += noise.sample(&mut side.rng);
                }
                if let Ok(measurement) = measured
                    && let Some(estimate) = side.tracker.push(&measurement)?
                {
                    if estimate.status.is_vouched_for() {
                        side.predictor = Predictor {
                            t_ref_s: estimate.t_ref_s,
                            state: estimate.state,
                            covariance: estimate.covariance,
                        };
                    }
                    out.push(estimate);
                }
                Ok(())
            }
            Self::Frames(side) => loop {
                let t_frame = side.next_frame as f64 / side.rate_hz;
                if t_frame + side.exposure_s / 2.0 > t_now_s {
                    return Ok(());
                }
                side.next_frame += 1;
                side.renderer.render_frame(
                    state_at,
                    t_frame,
                    &mut side.rng,
                    &mut side.scratch,
                    &mut side.frame,
                );
                let outcome = side.tracker.process(&side.frame)?;
                if let Some(estimate) = outcome.estimate {
                    out.push(estimate);
                }
            },
        }
    }
}

/// The gains (for `kvs`: λ as the natural frequency) and the controller of `config`, made from its feedback age as
/// [`run_servo`] makes them.
pub(crate) fn build_controller(config: &ServoConfig) -> (Gains, Box<dyn Controller + Send>) {
    let robot = config.robot;
    let model = robot
        .with_mass_factor(config.model_mass_factor)
        .with_friction_factor(config.model_friction_factor);
    let age = config.feedback_age_s();
    match config.controller {
        ControllerKind::Kvs => {
            let mut kinematic = KinematicGains::for_latency(age);
            if let Some(g) = config.gains {
                kinematic.lambda_per_s = g.natural_frequency_radps;
            }
            kinematic.lambda_per_s *= config.gain_scale;
            (
                Gains::critically_damped(kinematic.lambda_per_s),
                Box::new(KinematicServo::new(model, kinematic)),
            )
        }
        kind => {
            let depth_factor = if kind == ControllerKind::TrueState {
                1.0
            } else {
                config.depth_factor
            };
            let gains = config
                .gains
                .unwrap_or_else(|| Gains::for_latency(age).with_depth_factor(depth_factor))
                .scaled(config.gain_scale);
            let velocity = if kind == ControllerKind::CtcPose {
                VelocitySource::PoseDifferences
            } else {
                VelocitySource::Estimate
            };
            (
                gains,
                Box::new(ComputedTorque::new(kind.name(), model, gains, velocity)),
            )
        }
    }
}

/// Runs one closed loop (see the [module docs](self)).
///
/// ```
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig, run_servo};
/// // The floor: computed torque on the true state, the orthoglide path at 1 m/s.
/// let report = run_servo(&ServoConfig::new(ControllerKind::TrueState, CameraKind::Truth, 1.0)).unwrap();
/// assert!(report.stable);
/// assert!(report.rms_error_mm < 0.5, "{}", report.rms_error_mm);
/// ```
pub fn run_servo(config: &ServoConfig) -> Result<ServoReport, ServoError> {
    config.check()?;
    let (gains, controller) = build_controller(config);
    let mut run = SimulatedLoop::new(config, controller)?;
    let mut stop_reason = None;
    for n in 0..run.ticks {
        if let Some(reason) = run.tick(n)? {
            stop_reason = Some(reason);
            break;
        }
    }
    let errors: Vec<f64> = run.samples.iter().map(ServoSample::error_m).collect();
    let rms_error_mm =
        (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt() * 1e3;
    let max_error_mm = errors.iter().copied().fold(0.0, f64::max) * 1e3;
    Ok(ServoReport {
        controller: config.controller,
        camera: config.camera,
        path: config.path.clone(),
        rms_error_mm,
        max_error_mm,
        stable: stop_reason.is_none(),
        stop_reason,
        gains,
        median_feedback_age_s: if run.ages.is_empty() {
            f64::NAN
        } else {
            roitrack_core::stats::median(&run.ages)
        },
        saturated_fraction: run.saturated_ticks as f64 / run.ticks.max(1) as f64,
        samples: run.samples,
        estimates: run.estimates,
    })
}

/// One closed loop in simulated time: the controller, the robot it drives, the camera and tracker watching it, and
/// what is kept for the report. Ticks run one after the other from [`SimulatedLoop::tick`].
struct SimulatedLoop<'a> {
    config: &'a ServoConfig,
    controller: Box<dyn Controller + Send>,
    /// The controller sees the true state (the floor): no actuation delay, no camera.
    truth_fed: bool,
    actuation_delay_s: f64,
    /// When an estimate reaches the controller after the instant it refers to: the camera's latency and the extra.
    availability_s: f64,
    tick_s: f64,
    step_s: f64,
    ticks: usize,
    camera: CameraSide,
    state: RobotState,
    /// Every integration step's state, for the camera and the delayed truth.
    history: History,
    /// The forces acting.
    force: Vector3<f64>,
    /// The commands waiting for their actuation instant.
    commands: VecDeque<(f64, Vector3<f64>)>,
    /// The estimates not yet available to the controller, with the instant they are.
    pending: VecDeque<(f64, Observation)>,
    /// The newest estimate available to the controller.
    observation: Option<Observation>,
    estimates: Vec<Estimate>,
    new_estimates: Vec<Estimate>,
    samples: Vec<ServoSample>,
    ages: Vec<f64>,
    saturated_ticks: usize,
    saturation: SaturationWindow,
}

impl<'a> SimulatedLoop<'a> {
    /// The robot at rest at home, holding against gravity the force the controller's model asks there.
    fn new(
        config: &'a ServoConfig,
        controller: Box<dyn Controller + Send>,
    ) -> Result<Self, ServoError> {
        let path = &config.path;
        let model = config
            .robot
            .with_mass_factor(config.model_mass_factor)
            .with_friction_factor(config.model_friction_factor);
        let truth_fed = config.controller == ControllerKind::TrueState;
        let actuation_delay_s = if truth_fed {
            0.0
        } else {
            config.actuation_delay_s
        };
        let timing = config.camera_timing();
        let availability_s = timing.latency_s() + config.extra_latency_s;
        let tick_s = 1.0 / config.control_rate_hz;
        let step_s = tick_s / config.substeps as f64;
        let ticks = (path.duration_s() / tick_s).round() as usize;
        let camera = CameraSide::new(config)?;
        let state = RobotState::default();
        let mut history = History {
            dt_s: step_s,
            states: Vec::with_capacity(ticks * config.substeps + 1),
        };
        history.states.push(state);
        let hold = Geometry::at(&model, &Vector3::zeros())
            .expect("home is in the workspace")
            .gravity_forces(&model);
        let mut samples = Vec::with_capacity(ticks + 1);
        samples.push(ServoSample {
            t_s: 0.0,
            reference: path.at(0.0),
            achieved_m: state.position_m,
            achieved_velocity_mps: state.velocity_mps,
            force_n: hold,
        });
        // The ticks of the last `saturation_window_s` at which an actuator was at its limit.
        let window_ticks =
            ((config.saturation_window_s * config.control_rate_hz).round() as usize).max(1);
        Ok(SimulatedLoop {
            config,
            controller,
            truth_fed,
            actuation_delay_s,
            availability_s,
            tick_s,
            step_s,
            ticks,
            camera,
            state,
            history,
            force: hold,
            commands: VecDeque::new(),
            pending: VecDeque::new(),
            observation: None,
            estimates: Vec::new(),
            new_estimates: Vec::new(),
            samples,
            ages: Vec::with_capacity(ticks),
            saturated_ticks: 0,
            saturation: SaturationWindow::new(window_ticks),
        })
    }

    /// Tick `n`: the estimates ready by now, the command, the robot to the next tick, the camera. Some: why the
    /// loop stops there (a force or state not finite, instability, divergence).
    fn tick(&mut self, n: usize) -> Result<Option<String>, ServoError> {
        let config = self.config;
        let path = &config.path;
        let tick_s = self.tick_s;
        let t_s = n as f64 * tick_s;
        // 1. The estimates ready by now.
        while self
            .pending
            .front()
            .is_some_and(|(ready_s, _)| *ready_s <= t_s + 1e-12)
        {
            self.observation = self.pending.pop_front().map(|(_, o)| o);
        }
        // 2. The command.
        let t_act_s = t_s + self.actuation_delay_s;
        let command = self.command(t_s, t_act_s);
        if !command.iter().all(|f| f.is_finite()) {
            return Ok(Some(format!(
                "the controller gave a force that is not finite at t = {t_s:.4} s"
            )));
        }
        let limit = config.robot.force_limit_n;
        let command = command.map(|x| x.clamp(-limit, limit));
        self.commands.push_back((t_act_s, command));
        if config.known_acceleration
            && let Some(believed) = self.controller.believed_acceleration(&command)
        {
            // The robot frame has the camera's axes (docs/servo.md, "The robot"): the platform's acceleration is
            // the target's in the camera frame as it is; the platform only translates.
            self.camera.tell_acceleration(t_act_s, &believed)?;
        }
        // 3. The robot to the next tick.
        let saturated = match self.advance_robot(t_s) {
            Ok(saturated) => saturated,
            Err(reason) => return Ok(Some(reason)),
        };
        self.saturated_ticks += usize::from(saturated);
        if let Some(saturated_percent) = self.saturation.push(saturated) {
            return Ok(Some(format!(
                "unstable: an actuator at its force limit {:.0} % of the {:.0} ms before t = {:.4} s (a limit cycle \
                 the force limit bounds)",
                saturated_percent,
                config.saturation_window_s * 1e3,
                t_s + tick_s
            )));
        }
        let t_next = (n + 1) as f64 * tick_s;
        let sample = ServoSample {
            t_s: t_next,
            reference: path.at(t_next),
            achieved_m: self.state.position_m,
            achieved_velocity_mps: self.state.velocity_mps,
            force_n: self.force,
        };
        self.samples.push(sample);
        if sample.error_m() > config.divergence_error_m {
            return Ok(Some(format!(
                "diverged: {:.1} mm from the path at t = {t_next:.4} s (limit {:.1} mm)",
                sample.error_m() * 1e3,
                config.divergence_error_m * 1e3
            )));
        }
        // 4. The camera: the ROI exposed around this tick (its exposure has ended), or the frames due.
        self.expose(t_s, t_next)?;
        Ok(None)
    }

    /// The controller's command at tick `t_s` for the instant it acts, `t_act_s`, from what it is fed; records the
    /// feedback's age at that instant.
    fn command(&mut self, t_s: f64, t_act_s: f64) -> Vector3<f64> {
        let config = self.config;
        let geometry =
            Geometry::at(&config.robot, &self.state.position_m).expect("checked at each step");
        let fed = if self.truth_fed {
            // The true state, `extra_latency_s` old.
            let t_seen_s = (t_s - config.extra_latency_s).max(0.0);
            let seen = if config.extra_latency_s > 0.0 {
                self.history.at(t_seen_s)
            } else {
                self.state
            };
            Some(Observation {
                t_s: t_seen_s,
                position_m: seen.position_m,
                velocity_mps: seen.velocity_mps,
                acceleration_mps2: None,
            })
        } else {
            self.observation
        };
        if let Some(o) = &fed {
            self.ages.push(t_act_s - o.t_s);
        }
        let input = ControlInput {
            t_act_s,
            dt_s: self.tick_s,
            reference: config.path.at(t_act_s),
            observation: fed,
            drive_joint_velocity_mps: geometry.joint_velocity(&self.state.velocity_mps),
        };
        self.controller.command(&input)
    }

    /// Integrates the robot over the tick from `t_s` in `substeps` steps, each command taking over from its
    /// actuation instant; whether an actuator was at its force limit at any step. Err: why the loop stops.
    fn advance_robot(&mut self, t_s: f64) -> Result<bool, String> {
        let robot = &self.config.robot;
        let step_s = self.step_s;
        let mut saturated = false;
        for j in 0..self.config.substeps {
            let t_step = t_s + j as f64 * step_s;
            while self
                .commands
                .front()
                .is_some_and(|(at_s, _)| *at_s <= t_step + 1e-12)
            {
                self.force = self.commands.pop_front().map(|(_, f)| f).expect("checked");
            }
            saturated |= self.force.amax() >= robot.force_limit_n;
            match step_rk4(robot, &self.state, &self.force, step_s) {
                Ok(next)
                    if next
                        .position_m
                        .iter()
                        .chain(&next.velocity_mps)
                        .all(|x| x.is_finite()) =>
                {
                    self.state = next
                }
                Ok(_) => {
                    return Err(format!(
                        "the robot's state is not finite at t = {t_step:.4} s"
                    ));
                }
                Err(e) => return Err(format!("at t = {t_step:.4} s {e}")),
            }
            self.history.states.push(self.state);
        }
        Ok(saturated)
    }

    /// The camera over the tick from `t_s` to `t_next`: its new estimates kept, and those the tracker vouches for
    /// queued for the controller from the instant they are available, in the robot frame (relative to home).
    fn expose(&mut self, t_s: f64, t_next: f64) -> Result<(), ServoError> {
        let path = &self.config.path;
        let history = &self.history;
        let state_at = |t: f64| {
            let s = history.at(t);
            path.camera_state(&s.position_m, &s.velocity_mps)
        };
        self.new_estimates.clear();
        self.camera
            .expose(t_s, t_next, &state_at, &mut self.new_estimates)?;
        let (_, home_cam) = path.home_in_camera();
        for estimate in &self.new_estimates {
            if estimate.status.is_vouched_for() && estimate.state.is_finite() {
                self.pending.push_back((
                    estimate.t_ref_s + self.availability_s,
                    Observation {
                        t_s: estimate.t_ref_s,
                        position_m: estimate.state.cam_t_obj_m - home_cam,
                        velocity_mps: estimate.state.velocity_mps,
                        acceleration_mps2: estimate.acceleration.map(|a| a.linear_mps2),
                    },
                ));
            }
        }
        self.estimates.extend_from_slice(&self.new_estimates);
        Ok(())
    }
}

/// The share of recent control ticks with an actuator at its force limit, over a window of ticks: a loop that keeps
/// its actuators saturated most of the time has gone unstable (in simulated time and in real time alike).
pub(crate) struct SaturationWindow {
    recent: VecDeque<bool>,
    saturated: usize,
    window_ticks: usize,
}

impl SaturationWindow {
    pub(crate) fn new(window_ticks: usize) -> Self {
        SaturationWindow {
            recent: VecDeque::with_capacity(window_ticks + 1),
            saturated: 0,
            window_ticks,
        }
    }

    /// Adds a tick; once the window is full and more than half its ticks saturated, their share (%).
    pub(crate) fn push(&mut self, saturated: bool) -> Option<f64> {
        self.recent.push_back(saturated);
        self.saturated += usize::from(saturated);
        if self.recent.len() > self.window_ticks {
            self.saturated -= usize::from(self.recent.pop_front().unwrap_or(false));
        }
        (self.recent.len() == self.window_ticks && 2 * self.saturated > self.window_ticks)
            .then(|| 100.0 * self.saturated as f64 / self.window_ticks as f64)
    }
}
