//! # roitrack-estimators
//!
//! The 12-dof pose and velocity estimators and their baselines, behind one trait, on the model of `roitrack-core`;
//! pure math, no I/O and no threads.
//!
//! Every estimator is an [`Estimator`]: it takes raw centroids one at a time ([`Estimator::push`]), undistorts them,
//! initialises itself from the first two cycles with no prior (a static pose, then a 12-dof fit of the two cycles so
//! that a target already moving starts with its velocity), then every `every` measurements emits an [`Estimate`] at
//! the time of the newest measurement, with a status, a residual, a conditioning figure and, where it has one, a
//! covariance. Each lives in its own module:
//!
//! - [`KalmanEstimator`] (default, [`kalman`]): an error-state Kalman filter with a constant-velocity model; every
//!   centroid updates the state once, at its own time.
//! - [`VvsEstimator`] ([`vvs`]): the paper's virtual visual servoing loop: predict with the current twist, then
//!   `iterations` steps `δ = -λ L⁺ e` on the window, with the exact or the paper's interaction matrix.
//! - [`BatchEstimator`] ([`batch`]): baseline, Levenberg-Marquardt of the 12 parameters to convergence on the window.
//! - [`StaticEstimator`] ([`static_baseline`]): baseline, static PnP as if the newest centroids were simultaneous,
//!   velocity by finite differences.
//!
//! [`Tracker`] is the one to use when the estimator is chosen at run time ([`TrackerConfig::estimator`]); [`track`]
//! runs one over a stream of measurements. The window fits share one [`WindowProblem`] and the
//! [`solver`](roitrack_core::solver); the static pose ([`solve_static_pose`]) also serves the full-frame initialisation.
//!
//! Every estimator refuses to update on a degenerate window (reciprocal condition number of the column-scaled
//! Jacobian below [`TrackerConfig::min_inverse_condition`]), flags the estimate, and widens its window.
//!
//! ```
//! use roitrack_estimators::{Estimator, TrackStatus, Tracker, TrackerConfig};
//! use roitrack_core::roi_order::bit_reversed_indices;
//! use roitrack_core::{CameraModel, Measurement, MotionState, Target};
//! use nalgebra::Vector3;
//!
//! let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
//! // A target 0.6 m away moving at 0.1 m/s along x, seen one point every 250 µs in the bit-reversed order.
//! let mut truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
//! truth.velocity_mps = Vector3::new(0.1, 0.0, 0.0);
//! let order = bit_reversed_indices(16);
//! let mut tracker = Tracker::new(camera.clone(), target.clone(), TrackerConfig::default()).unwrap();
//! let mut last = None;
//! for k in 0..400 {
//!     let t_s = k as f64 * 250e-6;
//!     let point = &target.points()[order[k % 16]];
//!     let px = camera.raw_pixel_from_cam(&truth.point_in_cam_at(&point.point_in_obj_m, t_s)).unwrap();
//!     let m = Measurement { t_s, id: point.id, u_px: px.x, v_px: px.y };
//!     if let Some(estimate) = tracker.push(&m).unwrap() {
//!         last = Some(estimate);
//!     }
//! }
//! let last = last.unwrap();
//! assert_eq!(last.status, TrackStatus::Tracking);
//! assert!((last.state.velocity_mps - truth.velocity_mps).norm() < 1e-6);
//! ```
#![deny(missing_docs)]

pub mod batch;
mod calibration;
mod config;
mod estimate;
mod estimator;
pub mod kalman;
mod model_error;
mod options;
mod point_noise;
mod problem;
mod report;
pub mod rig;
pub mod rolling_refit;
pub mod static_baseline;
mod static_pose;
mod stream;
mod track;
mod tracker;
pub mod vvs;
mod window;

pub use batch::BatchEstimator;
pub use config::{
    ConfigError, EstimatorConfig, MAX_ITERATIONS, MAX_NOISE_PX, MAX_WINDOW, PSD_RANGE,
    TrackerConfig,
};
pub use estimate::{Estimate, TrackStatus, standard_deviations};
pub(crate) use estimator::delegate_estimator;
pub use estimator::{Emit, Estimator, TrackError};
pub use kalman::{
    KNOWN_ACCELERATION_CAPACITY, KalmanEstimator, KalmanTuning, KnownAccelerationError, Matrix12,
    MotionModel, NoiseSample,
};
pub use model_error::{MODEL_UNCERTAINTY, ModelEffect, ModelResidual, ModelUncertainty};
pub use options::{
    Adaptation, EstimatorKind, MotionModelKind, OptionConflict, TrackerOptions, UnknownName,
};
pub use problem::{Observation, RobustLoss, WindowProblem};
pub use report::{EstimatorReport, StartFailure, StatusCounts};
pub use rolling_refit::{
    MAX_STENCIL_POSES, PoseRefit, StencilMotion, TimedPose, pose_residuals, refit_pose,
    stencil_motion, stencil_motion_at_start,
};
pub use static_baseline::StaticEstimator;
pub use static_pose::{
    AMBIGUITY_CHI2, InitError, MAX_STATIC_POSES, MODEL_SPREAD_SIGMAS, PixelNoise, PoseFit,
    StaticPoses, best_static_pose, is_rival, refine_static_pose, relabelling_is_rival,
    solve_static_pose, static_model_residual,
};
pub use stream::{StreamError, TrackAllError, track, track_all};
pub use tracker::Tracker;
pub use vvs::{VvsEstimator, VvsSettings};
pub use window::WindowMode;
