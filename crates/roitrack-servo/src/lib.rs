//! # roitrack-servo
//!
//! What roitrack's pose and velocity are worth inside a control loop: a simulated fast robot, controllers fed by what
//! the camera gives, and the closed loop between them in simulated time (docs/servo.md).
//!
//! - [`robot`]: an Orthoglide-like 3-dof translational parallel robot, its kinematics and joint-space dynamics
//!   (configuration-dependent inertia, viscous and Coulomb friction, force limits). Pure math.
//! - [`reference`](mod@reference): the paths to follow (the simulator's orthoglide path at any speed, seeded random paths).
//! - [`control`]: the controllers behind one trait: computed torque with the tracker's pose and velocity, the same
//!   with pose only, the kinematic visual servo, and the true-state floor. Pure math.
//! - [`closed_loop`]: the loop in simulated time through the simulated ROI or frame camera and roitrack's trackers
//!   ([`run_servo`]), deterministic for a seed, with divergence detected and reported.
//! - [`output`]: a run's files (reference and achieved poses in TUM, the estimates, the per-tick log) and figures.
//! - [`handle`]: the newest estimate for a user's control thread, read without locks or allocation.
//! - [`live`]: the closed loop in real time: the controller on its own thread on the wall clock, fed by the live
//!   two-thread loop through the handle, the camera rendering the simulated robot where it is ([`live::run_live_servo`]).
//! - [`sweep`]: the largest stable gain against latency, per scheme.
#![deny(missing_docs)]

pub mod closed_loop;
pub mod control;
pub mod handle;
pub mod live;
pub mod reference;
pub mod robot;
pub mod sweep;

pub use closed_loop::{
    CameraKind, CameraTiming, ControllerKind, ServoConfig, ServoError, ServoReport, ServoSample,
    run_servo,
};
pub mod output;
