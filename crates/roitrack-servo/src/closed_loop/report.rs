//! What a closed-loop run reports: its samples, errors and estimates.

use nalgebra::Vector3;
use roitrack_estimators::Estimate;

use crate::control::Gains;
use crate::reference::{ReferencePath, ReferencePoint};

use super::{CameraKind, ControllerKind};

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
