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

use crate::control::{
    ComputedTorque, Controller, Gains, KinematicGains, KinematicServo, VelocitySource,
};

mod camera;
mod config;
mod report;
mod saturation;
mod simulated;

pub use config::{
    CameraKind, CameraTiming, ControllerKind, ServoConfig, ServoError, servo_tracker_config,
};
pub use report::{ServoReport, ServoSample};
pub(crate) use saturation::SaturationWindow;
use simulated::SimulatedLoop;

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
