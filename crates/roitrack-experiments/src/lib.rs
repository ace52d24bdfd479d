//! # roitrack-experiments
//!
//! The experiments behind roitrack's tables and figures, each a library call on typed values (no files, no printing):
//! the command line (and, to come, the Python package) only shows what they return.
//!
//! - [`compare`]: every estimator and baseline on one scenario at the measurement level;
//! - [`faults`]: the default estimator under faults (outliers, drops, occlusions, gaps, jumps, blobs leaving the
//!   image, reflections in the ROIs): accuracy, recovery, flagged and unflagged wrong estimates;
//! - [`tradeoff`]: velocity noise against velocity lag, for the paper's gain and the Kalman filter's process noise;
//! - [`adaptive`]: the sweep harness: the default (adaptive) Kalman filter against hand-tuned filters searched over
//!   a grid on the same data, on every case of the sweep, with the calibration of its covariance (NEES);
//! - [`frames`]: frame cameras (global and rolling shutters, bright and dark blobs) on simulated image sequences,
//!   each tracked with the right time model and the wrong one, and the frame-camera targets checked.
//!
//! Each tracks simulated runs and scores them against their truth with [`roitrack_demo::scoring`]; every metric comes
//! from [`roitrack_eval`], every estimator from [`roitrack_estimators`].
//!
//! ```
//! use roitrack_experiments::compare::{compare, table};
//! use roitrack_sim::ScenarioKind;
//!
//! let rows = compare(ScenarioKind::Static, 1, 0.1).unwrap();
//! assert_eq!(rows.len(), 5);
//! // The default estimator holds a still target to a fraction of a millimetre.
//! assert!(rows[0].metrics.position_rmse_mm < 0.5);
//! assert!(table(&rows).starts_with("estimator"));
//! ```
#![deny(missing_docs)]

pub mod adaptive;
pub mod compare;
pub mod faults;
pub mod frames;
pub mod tradeoff;

/// Why an experiment could not run: the causes of the demo's runs (simulation, rendering, the sensor model,
/// tracking, the real-time loop, evaluation), since every experiment is made of such runs.
pub use roitrack_demo::DemoError as ExperimentError;
