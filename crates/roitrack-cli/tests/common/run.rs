//! `roitrack track` on a run that `roitrack simulate` wrote, for the tests that look at what comes after it.

use std::path::Path;

/// Tracks the simulated run in `dir` (its camera.yaml, target.csv and measurements.csv) into `dir`: est.tum,
/// est.csv, diag.csv and cov.csv.
pub fn track_simulated(dir: &Path) {
    let file = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (diagnostics, covariance) = (file("diag.csv"), file("cov.csv"));
    super::ok(&crate::common::track_args(
        &file("camera.yaml"),
        &file("target.csv"),
        &file("measurements.csv"),
        &file("est.tum"),
        &file("est.csv"),
        &["--diagnostics", &diagnostics, "--covariance", &covariance],
    ));
}
