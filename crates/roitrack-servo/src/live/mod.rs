//! The closed loop in real time: the controller on its own thread at the control rate, on the wall clock, fed by
//! roitrack's live two-thread loop ([`roitrack_pipeline::realtime::run_loop_with_hooks`]) through the estimate handle
//! ([`crate::handle`]), while a camera renders the simulated robot where it is now ([`run_live_servo`]).
//!
//! Three threads (four with Aravis' fake camera, five with its stream thread):
//! - the **control thread** ticks on the wall clock at [`ServoConfig::control_rate_hz`] (or
//!   [`LiveOptions::control_rate_hz`], faster than the ROIs): it reads the newest
//!   estimate ([`crate::handle::EstimateReader::read`]: no lock, no allocation), computes the command (the same
//!   [`Controller`](crate::control::Controller) as [`crate::run_servo`]), and integrates the simulated robot to the
//!   next tick (RK4, the forces acting after the actuation delay), publishing each integration step into a
//!   [`RobotScene`]. A tick woken more than a period late is a deadline miss: the drive holds its last command over
//!   the ticks missed (counted);
//! - the **acquisition thread** (the caller's) runs the live loop's camera side, paced at one ROI per control tick:
//!   each ROI is rendered from the robot's state at its exposure, read from the [`RobotScene`] (lock-free, the
//!   robot's recent steps interpolated);
//! - the **estimation thread** (the loop's) runs the tracker and publishes each estimate it vouches for. With
//!   [`ServoConfig::known_acceleration`] (the default, as in simulated time) the control thread tells it the
//!   acceleration each command asks of the controller's model, from the instant the command acts, through the live
//!   loop's lock-free queue of known accelerations ([`roitrack_pipeline::realtime::known_acceleration_channel`]).
//!
//! Clocks: the robot's clock starts with the [`RobotScene`]; the loop's clock (the ROIs' and estimates' times) starts
//! with the loop. A [`LoopClockCamera`] wrapped around the camera learns the offset between them at each grab (the
//! smallest `robot now - slot time` seen), so that a ROI of loop time `t` shows the robot at robot time `t + offset`
//! and an estimate of loop time `t_ref` is placed on the robot's clock. The path starts when the controller reads the
//! first estimate made on time ([`LiveOptions::start_max_age_s`]): the live loop's full-frame start takes a while, and
//! the paced loop then catches up on the slots it cost; until then the robot's brakes hold it at rest at home.
//!
//! Latency, per estimate: from the mid-exposure of its newest ROI (its `t_ref_s`, on the robot's clock) to the instant
//! the first command made from it acts on the robot (the control thread's wall-clock instant when it issued the
//! command, plus the simulated drive's [`ServoConfig::actuation_delay_s`]); also to the command alone.
//!
//! [`ServoConfig::control_rate_hz`]: crate::ServoConfig::control_rate_hz
//! [`ServoConfig::known_acceleration`]: crate::ServoConfig::known_acceleration
//! [`ServoConfig::actuation_delay_s`]: crate::ServoConfig::actuation_delay_s

// The robot as the camera sees it is in `scene.rs`, the camera side in `camera.rs`, the run's options and entry points
// in `run.rs`, the control thread in `control.rs` and what the run reports in `report.rs`.
mod camera;
mod control;
mod report;
mod run;
mod scene;

pub use camera::{LoopClockCamera, roi_camera_model, servo_target};
pub use report::LiveServoReport;
pub use run::{
    LiveOptions, run_live_servo, run_live_servo_simulated, run_live_servo_simulated_with_sink,
    run_live_servo_with_sink,
};
pub use scene::RobotScene;
