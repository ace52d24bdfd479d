//! # roitrack-servo
//!
//! What roitrack's pose and velocity are worth inside a control loop: a simulated fast robot, controllers fed by what
//! the camera gives, and the closed loop between them in simulated time (docs/servo.md).
//!
//! - [`robot`]: an Orthoglide-like 3-dof translational parallel robot, its kinematics and joint-space dynamics
//!   (configuration-dependent inertia, viscous and Coulomb friction, force limits). Pure math.

pub mod robot;
