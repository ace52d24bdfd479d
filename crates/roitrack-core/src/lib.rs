//! # roitrack-core
//!
//! The pure mathematics of roitrack, with no I/O and no threads:
//!
//! - [`so3`]: the SO(3) exponential, an accurate logarithm and the left Jacobian (what nalgebra lacks);
//! - [`camera`]: pinhole projection with skew, and the lens models of [`camera::lens`] (one file each) with their
//!   inverses;
//! - [`target`]: the rigid target (model points, optional blob diameters) and the bundled `grid4x4`;
//! - [`state`]: the 12-dof [`state::MotionState`] (pose and constant twist at a reference time);
//! - [`samples`]: timestamped measurements, poses and twists as exchanged with files;
//! - [`roi_order`]: the order in which ROIs visit the points (bit-reversed, row-major, random);
//! - [`stats`]: quantiles, medians and RMS, defined once for every report;
//! - [`time`]: the time model, when each blob was taken (sequential ROIs, global or rolling shutter) and for how long;
//! - [`projection`]: the spatio-temporal projection model and its exact and paper (eqs. 17-24) Jacobians;
//! - [`solver`]: the one nonlinear least-squares solver (Levenberg-Marquardt, and the paper's servo law);
//!
//! The estimators built on this model (Kalman, the paper's VVS loop, the baselines, the rig of several cameras) are
//! the crate `roitrack-estimators`.
//!
//! Conventions (docs/model.md): camera frame x right, y down, z forward. The state holds `cam_r_obj` (c_R_o),
//! `cam_t_obj_m` (c_t_o), the velocity of the object origin `velocity_mps` and the angular velocity
//! `angular_velocity_radps`, both in the camera frame. A model point `p` observed `d` seconds after the reference time is
//! at `Exp(W d) R p + t + V d`. A 12-vector correction `(v, w, dV, dW)` acts as `R <- Exp(w) R`, `t <- t + v`,
//! `V <- V + dV`, `W <- W + dW`.
#![deny(missing_docs)]

pub mod camera;
pub mod projection;
pub mod roi_order;
pub mod samples;
pub mod so3;
pub mod solver;
pub mod state;
pub mod stats;
pub mod target;
#[cfg(any(test, feature = "test-support"))]
pub mod test_support;
pub mod time;

pub use camera::{
    CameraError, CameraModel, Distortion, Equidistant, PinholeIntrinsics, PlumbBob,
    RationalPolynomial,
};
pub use projection::{JacobianKind, SpatioTemporalModel};
pub use roi_order::RoiOrder;
pub use samples::{Measurement, PoseSample, TwistSample};
pub use state::{Acceleration, MotionState};
pub use target::{Target, TargetError, TargetPlane, TargetPoint};
pub use time::{Readout, TimeModel};

/// A 12-vector (v, w, dV, dW): a correction of the state, see [`MotionState::corrected`].
pub type Vector12 = nalgebra::SVector<f64, 12>;
/// A 2 x 12 block of the interaction matrix: d(u, v) / d(correction).
pub type Matrix2x12 = nalgebra::SMatrix<f64, 2, 12>;
