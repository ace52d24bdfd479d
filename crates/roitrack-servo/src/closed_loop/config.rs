//! What a closed-loop run is made of: its controller, its camera and their timing, its configuration and errors.

use roitrack_core::CameraModel;
use roitrack_core::time::{Readout, TimeModel};
use roitrack_estimators::{TrackError, TrackerConfig};
use roitrack_pipeline::FrameError;
use roitrack_sim::SensorError;
use thiserror::Error;

use crate::control::{Gains, KinematicGains};
use crate::reference::ReferencePath;
use crate::robot::RobotParams;

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
    ///
    /// [`Controller::believed_acceleration`]: crate::control::Controller::believed_acceleration
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
///
/// [`ServoReport::stable`]: super::ServoReport::stable
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
