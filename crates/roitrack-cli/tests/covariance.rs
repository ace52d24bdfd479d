//! `roitrack track --covariance`: the full 12 x 12 covariance per estimate, one row per pose, consistent with the
//! diagnostics file's 1-sigma columns; NaN for the static baseline.

use std::path::Path;

mod common;
use common::{fails, ok};

#[path = "common/covariance_file.rs"]
mod covariance_file;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Simulates orthoglide and keeps the first `rows` measurements (0.3 s at 4 kHz for 1,200).
fn small_measurements(dir: &Path, rows: usize) {
    ok(&["simulate", "--scenario", "orthoglide", "--out", p(dir)]);
    let path = dir.join("measurements.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let kept: Vec<&str> = text.lines().take(1 + rows).collect();
    std::fs::write(&path, kept.join("\n") + "\n").unwrap();
}

/// Runs `track` with poses, twists, diagnostics and covariance into `dir/{name}.*`; returns those paths.
fn track(
    dir: &Path,
    name: &str,
    options: &[&str],
) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let (poses, twists) = (
        dir.join(format!("{name}.tum")),
        dir.join(format!("{name}_twists.csv")),
    );
    let (diagnostics, covariance) = (
        dir.join(format!("{name}_diagnostics.csv")),
        dir.join(format!("{name}_covariance.csv")),
    );
    let (camera, target, measurements) = (
        dir.join("camera.yaml"),
        dir.join("target.csv"),
        dir.join("measurements.csv"),
    );
    let mut args = common::track_args(
        p(&camera),
        p(&target),
        p(&measurements),
        p(&poses),
        p(&twists),
        &[
            "--diagnostics",
            p(&diagnostics),
            "--covariance",
            p(&covariance),
        ],
    );
    args.extend_from_slice(options);
    ok(&args);
    (poses, diagnostics, covariance)
}

#[test]
fn track_writes_one_covariance_row_per_pose_matching_the_diagnostics_sigmas() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    small_measurements(dir, 1200);

    // The default estimator (Kalman): 1,200 measurements, an estimate every 10 after the initialisation.
    let (poses, diagnostics, covariance) = track(dir, "kalman", &[]);
    let rows =
        covariance_file::check_against_poses_and_diagnostics(&poses, &diagnostics, &covariance);
    assert!(rows.len() > 80, "{} rows", rows.len());
    for (t, entries) in &rows {
        let c = roitrack::formats::covariance_from_upper_triangle(entries);
        assert!(c.iter().all(|x| x.is_finite()), "{t}");
        // Position within a few mm, rotation within a few degrees: plausible 1-sigma figures (m, rad).
        assert!((0..3).all(|i| c[(i, i)].sqrt() < 5e-3), "{t}: {c}");
        assert!((3..6).all(|i| c[(i, i)].sqrt() < 0.1), "{t}: {c}");
        // A covariance: positive semi-definite (to rounding).
        let eigenvalues = c.symmetric_eigenvalues();
        assert!(
            eigenvalues.min() > -1e-12 * eigenvalues.max(),
            "{t}: {eigenvalues}"
        );
    }

    // The static baseline has no covariance: every entry NaN, and NaN sigmas in the diagnostics, except in its first
    // estimate, which comes from the initialisation's 12-dof fit.
    let (poses, diagnostics, covariance) = track(dir, "static", &["--estimator", "static"]);
    let rows =
        covariance_file::check_against_poses_and_diagnostics(&poses, &diagnostics, &covariance);
    assert!(rows[0].1.iter().all(|x| x.is_finite()));
    assert!(
        rows[1..]
            .iter()
            .all(|(_, entries)| entries.iter().all(|x| x.is_nan()))
    );
    let text = std::fs::read_to_string(&covariance).unwrap();
    let second = text.lines().nth(2).unwrap();
    assert!(second.ends_with(&",NaN".repeat(78)), "{second}");
}

#[test]
fn covariance_into_a_missing_folder_is_refused_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    small_measurements(dir, 400);
    let poses = dir.join("p.tum");
    let err = fails(&common::track_args(
        p(&dir.join("camera.yaml")),
        p(&dir.join("target.csv")),
        p(&dir.join("measurements.csv")),
        p(&poses),
        p(&dir.join("t.csv")),
        &["--covariance", p(&dir.join("missing").join("c.csv"))],
    ));
    assert!(err.contains("c.csv") && err.contains("missing"), "{err}");
    assert!(!poses.exists());
}
