//! The PnP benchmark (`roitrack pnp-bench`): times our static pose solver ([`solve_static_pose`]) on a stored PnP
//! problem, the same file the OpenCV peer comparison (`bench/opencv_compare.sh`) reads, and reports its accuracy
//! against the true poses; or solves a suite of one-instance problems (`bench/pnp_families.py`) and reports, problem by
//! problem, every pose it returns and its time.
//!
//! The problem file is JSON (format `roitrack-pnp-problem/1`, written by `bench/opencv_compare.py`):
//!
//! ```json
//! {
//!   "format": "roitrack-pnp-problem/1",
//!   "intrinsics": {"fx_px": 1500, "fy_px": 1500, "skew_px": 0, "cx_px": 512, "cy_px": 512},
//!   "model_points": [{"id": 0, "xyz_m": [-0.03, -0.03, 0.0]}, ...],
//!   "instances": [
//!     {"cam_r_obj": [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]], "cam_t_obj_m": [x, y, z],
//!      "pixels": [[u0, v0], [u1, v1], ...]},
//!     ...
//!   ]
//! }
//! ```
//!
//! `pixels[i]` is the noisy ideal (undistorted) pixel of `model_points[i]`; `cam_r_obj`, `cam_t_obj_m` is the true pose
//! (object to camera, row-major rotation). An optional `"noise_px"` gives the pixels' noise (px per coordinate; the
//! tracker's default noise when absent), which the solver judges ambiguity against. Other keys are ignored.
//!
//! The suite file (format `roitrack-pnp-suite/1`, written by `bench/pnp_families.py`) holds many problems, each of
//! exactly one instance and with its `noise_px`, each tagged with the family it was drawn from:
//!
//! ```json
//! {"format": "roitrack-pnp-suite/1",
//!  "problems": [{"family": "4-5 planar", "problem": {"format": "roitrack-pnp-problem/1", "noise_px": 0.2, ...}}, ...]}
//! ```
//!
//! Every refusal names the field, as a path from the file's top (`instances[0].pixels[3]`,
//! `problems[7].problem.intrinsics.fx_px`), and [`PnpSuite::read`] also names the file.
//!
//! [`solve_static_pose`]: roitrack_estimators::solve_static_pose

// The problem file is read in `problem.rs` and benchmarked in `run.rs`, the suite file read in `suite.rs` and solved
// in `suite_run.rs`; `json.rs` holds the readers of JSON values both files share.
mod json;
mod problem;
mod run;
mod suite;
mod suite_run;

#[cfg(test)]
mod fixtures;

use thiserror::Error;

pub use problem::{PnpInstance, PnpProblem};
pub use run::{PnpReport, Solved, run};
pub use suite::{PnpSuite, SuiteProblem};
pub use suite_run::{SuiteReport, SuiteSolve, run_suite};

/// The format tag a problem file must carry.
pub const FORMAT: &str = "roitrack-pnp-problem/1";

/// The format tag a suite file must carry.
pub const SUITE_FORMAT: &str = "roitrack-pnp-suite/1";

/// Why a problem was refused: the message names the instance and field where it applies.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{message}")]
pub struct PnpError {
    /// What is wrong, naming the instance and field where it applies.
    pub message: String,
}

impl PnpError {
    pub(super) fn new(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
        }
    }
}
