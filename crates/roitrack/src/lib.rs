//! # roitrack
//!
//! roitrack tracks the 3-D pose **and** velocity (12 degrees of freedom) of a rigid target carrying small blobs, from
//! a camera whose every blob measurement has its own timestamp: a camera that reads one small region of interest (ROI)
//! at a time, or a rolling-shutter camera whose rows are read one after another. This crate is the whole library behind
//! one name; the `roitrack` command-line tool is a thin shell over it (and so will be the Python package).
//!
//! ## The data flow
//!
//! ```text
//!  camera model ─┐                      ┌─ ROI camera (RoiCamera) ── RoiImage ── centroid ─┐
//!  (CameraModel, │   full frame (Frame) │                             (timed by TimeModel) │  Measurement
//!   TimeModel)   ├── find_target ───────┤   or a recording, or your own measurements ──────┼─ (t, id, u, v)
//!  target ───────┘   (first pose)       └─ ROI scheduler (where to read next) ◄──┐         │
//!  (Target)                                                                       │         ▼
//!                                                                     Estimate ◄── Estimator (Kalman, VVS, batch,
//!                                                                  (pose, twist,    static), one least-squares
//!                                                                   status, cov.)   solver
//! ```
//!
//! 1. **Camera and target in.** A [`CameraModel`] (pinhole with skew, plumb_bob distortion, and its [`TimeModel`]:
//!    when each blob is exposed) and a [`Target`] (model points in metres, optional blob diameters). Read them from
//!    files with [`formats`], or build them in code.
//! 2. **Measurements or images.** A [`Measurement`] is one blob centroid: the time of its exposure, the target point
//!    it belongs to, and its raw pixel. They come from a file, from your own detector, from ROI images
//!    ([`image::RoiImage`], centroided by [`image::measure_roi`]), or from a live [`image::RoiCamera`] through the
//!    real-time loop ([`pipeline::run_loop`]), which places each ROI where the tracker predicts the blob.
//! 3. **An estimator.** Every estimator is an [`Estimator`]: push a measurement, get an [`Estimate`] every `every`
//!    measurements. [`Tracker`] picks one from a [`TrackerConfig`]: the Kalman filter (default), the paper's virtual
//!    visual servoing loop, or the batch and static baselines.
//! 4. **Estimates out.** Each [`Estimate`] carries the pose (camera_T_object) and the twist (velocity of the object
//!    origin and angular velocity, both in the camera frame) at its time, a status (only `converging` and `tracking`
//!    are vouched for), the residual, a conditioning figure and, where the estimator has one, a covariance. Write them
//!    with [`formats::EstimateWriter`], score them against ground truth with [`eval`], plot them with `plot`.
//!
//! ```
//! use roitrack::{Estimator, Measurement, TrackStatus, Tracker, TrackerConfig};
//! use roitrack::sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
//!
//! // Simulated measurements of the paper's experiment: 4 kHz ROIs, 0.1 px of noise, with ground truth.
//! let run = simulate(&Scenario::new(ScenarioKind::Orthoglide, 1), &SimulationOptions::default()).unwrap();
//! let mut tracker = Tracker::new(run.camera.clone(), run.target.clone(), TrackerConfig::default()).unwrap();
//! let mut estimates = Vec::new();
//! for m in &run.measurements {
//!     let m: &Measurement = m;
//!     if let Some(estimate) = tracker.push(m).unwrap() {
//!         estimates.push(estimate);
//!     }
//! }
//! // 400 Hz estimates of pose and velocity, scored against the truth.
//! let metrics = roitrack::eval::evaluate_estimates(
//!     &run.truth_poses,
//!     &run.truth_twists,
//!     &estimates,
//!     &roitrack::eval::EvalOptions::default(),
//! )
//! .unwrap();
//! assert!(metrics.position_rmse_mm < 0.5 && metrics.velocity_rmse_mm_s.unwrap() < 100.0);
//! assert!(estimates.iter().filter(|e| e.status == TrackStatus::Tracking).count() > 1900);
//! ```
//!
//! ## Conventions
//!
//! - Camera frame: x right, y down, z forward. Poses are camera_T_object: `cam_r_obj` rotates object coordinates into
//!   the camera frame and `cam_t_obj_m` is the object's origin in the camera frame (metres).
//! - The twist is that of the object in the camera frame: `velocity_mps` is the velocity of the object's origin and
//!   `angular_velocity_radps` its angular velocity, both expressed in the camera frame. A model point `p` observed
//!   `d` seconds after an estimate's time is at `Exp(W d) R p + t + V d` (constant twist over the window).
//! - Pixels: pixel (i, j) (column, row) has its centre at (u, v) = (i, j). Raw pixels are what the sensor measures
//!   (distorted); ideal pixels have the distortion removed. Measurements are raw pixels.
//! - Times are seconds on any clock, the same for every measurement; a measurement's time is its exposure's middle.
//! - Units are in names: `_m`, `_s`, `_px`, `_mps`, `_radps`.
//!
//! ## Where things live
//!
//! | module | crate | what |
//! | --- | --- | --- |
//! | [`core`] | `roitrack-core` | camera models, SO(3), the target, the time model, the spatio-temporal projection and its Jacobians, the solver (no I/O, no threads) |
//! | [`estimators`] | `roitrack-estimators` | the estimators (Kalman, VVS, batch, static), the tracker options, the rig of several cameras (no I/O, no threads) |
//! | [`image`] | `roitrack-image` | ROIs and frames, the camera trait, the replay camera, centroids, blob detection |
//! | [`detect`] | `roitrack-detect` | finding the target in a full frame (`find_target`) or a photograph (`detect_target`) with no prior: which blob is which model point |
//! | [`pipeline`] | `roitrack-pipeline` | the ROI scheduler, the two-thread real-time loop, offline ROI tracking, the frame tracker |
//! | [`sim`] | `roitrack-sim` | the renderer and sensor model, the simulated ROI camera and its reflections, the centroid's accuracy on rendered ROIs, scenario motions with ground truth, the measurement simulator, rendered ROI recordings, synthetic photographs |
//! | [`eval`] | `roitrack-eval` | every accuracy metric, the velocity lag included |
//! | [`formats`] | `roitrack-formats` | the files: camera YAML, target CSV, measurements CSV, TUM poses, twists, diagnostics, covariance, ROI recordings, images, detection overlays |
//! | `plot` | `roitrack-plot` | charts and the figures of a run (feature `plot`, on by default) |
//! | `demo` | `roitrack-demo` | the demo: a simulated scenario end to end from rendered ROIs, scored against its truth (feature `demo`, on by default) |
//! | `experiments` | `roitrack-experiments` | the studies: estimator comparison, fault table, lag trade-off, adaptive-estimation sweep, frame cameras (feature `lab`) |
//! | `bench` | `roitrack-bench` | the hot-path, loop, soak and PnP benchmarks (feature `lab`) |
//! | `ros` | `roitrack-ros` | ROS 2 bags in MCAP storage: estimates, camera info, status, images out; image frames in (feature `ros`, on by default) |
//!
//! The programs in `examples/` show the main uses end to end: `track_recording` (files in, estimates out),
//! `simulate_and_evaluate` (your own camera and target, ground truth, metrics), `own_camera` (the real-time loop on a
//! camera of your own), `find_target` (the target in a full frame, no prior) and `detect_photo` (a circle grid in a
//! photograph: yours, or a synthetic one checked against its truth).
#![deny(missing_docs)]

pub mod camera_input;

pub use nalgebra;
pub use roitrack_core as core;
#[cfg(feature = "demo")]
pub use roitrack_demo as demo;
pub use roitrack_detect as detect;
pub use roitrack_estimators as estimators;
pub use roitrack_eval as eval;
pub use roitrack_formats as formats;
pub use roitrack_image as image;
pub use roitrack_pipeline as pipeline;
#[cfg(feature = "plot")]
pub use roitrack_plot as plot;
#[cfg(feature = "ros")]
pub use roitrack_ros as ros;
#[cfg(feature = "servo")]
pub use roitrack_servo as servo;
pub use roitrack_sim as sim;
#[cfg(feature = "lab")]
pub use {roitrack_bench as bench, roitrack_experiments as experiments};

pub use roitrack_core::{
    CameraModel, Measurement, MotionState, PoseSample, Readout, Target, TargetPoint, TimeModel,
    TwistSample,
};
pub use roitrack_estimators::{
    ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport, KalmanTuning, StreamError,
    TrackError, TrackStatus, Tracker, TrackerConfig, VvsSettings, WindowMode, track, track_all,
};
pub use roitrack_image::{Frame, RoiCamera, RoiImage};

/// The README's Rust examples, compiled by `cargo test --doc` so that they stay true.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
pub struct ReadmeExamples;
