//! `roitrack track` on a run that `roitrack simulate` wrote, for the tests that look at what comes after it.

use std::path::Path;

/// Tracks the simulated run in `dir` (its camera.yaml, target.csv and measurements.csv) into `dir`: est.tum,
/// est.csv, diag.csv and cov.csv.
pub fn track_simulated(dir: &Path) {
    let file = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let args = [
        "track",
        "--camera",
        &file("camera.yaml"),
        "--target",
        &file("target.csv"),
        "--measurements",
        &file("measurements.csv"),
        "--poses",
        &file("est.tum"),
        "--twists",
        &file("est.csv"),
        "--diagnostics",
        &file("diag.csv"),
        "--covariance",
        &file("cov.csv"),
    ];
    super::ok(&args);
}
