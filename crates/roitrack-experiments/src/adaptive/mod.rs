//! The measurement harness of the adaptive-estimation study: the default Kalman filter, which is not told the noise
//! of the centroids nor the motion, against hand-tuned filters searched over a grid on the same data
//! (`roitrack compare --sweep`, the table of `docs/results.md`).
//!
//! Each [`Case`] is a scenario seen by a camera carrying a target, sampled at a ROI rate with a centroid noise
//! ([`cases`]). Every case is simulated once per seed and tracked
//!
//! - by the **default** filter: `TrackerConfig::default()` (0.1 px assumed, the default acceleration densities,
//!   `adapt_noise` and `adapt_motion` on): the user does not know the noise;
//! - by **hand-tuned** filters (`adapt_noise` and `adapt_motion` off: the filter takes its settings as the truth) over
//!   the [`Grid`] of centroid noise (a factor of the true noise) and linear and angular acceleration densities. The
//!   **told-the-truth** filter is the grid's default point: the true noise and the default densities.
//!
//! The grid is searched in two stages ([`Grid`]): a coarse grid (the true noise, every other density of each axis,
//! and the told-the-truth point), then a pattern search on the full grid from the best point so far (each round runs
//! the unvisited neighbours, one step along each axis, and moves to the best, until none improves). The best
//! hand-tuned run's position RMSE is the case's **nominal** error.
//!
//! The targets ([`Goal`]), per case:
//!
//! - [`Goal::Rmse`]: the default filter's position RMSE at most [`RMSE_RATIO_LIMIT`] times the best hand-tuned one;
//! - [`Goal::Clean`]: no `disputed` or `lost` estimate (the data are clean);
//! - [`Goal::Calibrated`]: the covariance is calibrated ([`Consistency::is_calibrated`]: mean NEES of position and
//!   velocity within 0.5-2 times their dimension, at least 95 % of the estimates inside the 99 % chi-square bound);
//! - [`Goal::Lag`]: the velocity lag at most [`MAX_LAG_SAMPLES`] sample, on the moving built-in scenes (orthoglide);
//! - [`Goal::Bounded`]: no estimate marked tracking or converging more than [`BOUND_FACTOR`] times the nominal error
//!   away from the truth.
//!
//! The accuracy cases ([`Purpose::Accuracy`]) are checked against every target (the lag on the built-in scenes only); the
//! calibration set ([`Case::in_calibration_set`]: every built-in scenario, static, orthoglide, spin, random, at 0.03, 0.1,
//! 0.3 and 1 px) against [`Goal::Calibrated`]; its orthoglide rows are accuracy cases too. A calibration-only case
//! ([`Purpose::Calibration`]) runs the default and the told-the-truth filters, no grid.
//!
//! ```
//! use roitrack_experiments::adaptive::{SweepOptions, sweep};
//!
//! // One tiny case: a smoke run (the sweep proper runs every case of `cases()` on the whole grid).
//! let mut options = SweepOptions::quick();
//! options.cases.truncate(1);
//! options.max_duration_s = Some(0.4);
//! let result = sweep(&options, None).unwrap();
//! let case = &result.cases[0];
//! assert_eq!(case.case.name, "4 kHz, 0.1 px");
//! let best = case.best.as_ref().unwrap();
//! // The best hand-tuned run is at most the told-the-truth one: the grid's default point is searched.
//! assert!(best.summary.position_rmse_mm <= case.told_truth.summary.position_rmse_mm);
//! assert!(result.markdown().contains("| case |"));
//! assert!(!result.checks().is_empty());
//! ```
//!
//! [`Consistency::is_calibrated`]: roitrack_eval::Consistency::is_calibrated

// What a case looks at is in `scene.rs`, the cases in `case.rs`, the hand-tuned filters' grid in `grid.rs`, the
// targets in `goal.rs`, a case's figures in `results.rs`, the run in `sweep.rs` and its tables in `report.rs`.
mod case;
mod goal;
mod grid;
mod report;
mod results;
mod scene;
mod sweep;

pub use case::{Case, Purpose, cases};
pub use goal::{BOUND_FACTOR, Check, Goal, MAX_LAG_SAMPLES, RMSE_RATIO_LIMIT};
pub use grid::{Grid, HandTuning};
pub use results::{CaseResult, HandTuned, RunSummary, Visited};
pub use scene::{CameraChoice, Scene, TargetChoice, grid2x3, non_planar_11, wide_angle_1280x1024};
pub use sweep::{Sweep, SweepError, SweepOptions, sweep};
