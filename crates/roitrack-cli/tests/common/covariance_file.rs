//! Checks of a `track --covariance` file against the poses and diagnostics written by the same run (included by the
//! tests that use it with `#[path]`, not through `common`).

use std::path::Path;

use roitrack::formats::{
    COVARIANCE_ENTRIES, covariance_entry_index, covariance_from_upper_triangle, covariance_header,
};

/// The covariance file's rows as (time as written, the 78 entries).
pub fn read_rows(covariance: &Path) -> Vec<(String, [f64; COVARIANCE_ENTRIES])> {
    let text = std::fs::read_to_string(covariance).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(covariance_header().as_str()));
    lines
        .map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), 1 + COVARIANCE_ENTRIES, "{line}");
            let entries: Vec<f64> = fields[1..].iter().map(|x| x.parse().unwrap()).collect();
            (fields[0].to_string(), entries.try_into().unwrap())
        })
        .collect()
}

/// Checks that the covariance file has one row per pose, at the poses' times, and that the square roots of its
/// diagonal entries (0-2 and 6-8) are the diagnostics file's sigma columns; returns its rows.
pub fn check_against_poses_and_diagnostics(
    poses: &Path,
    diagnostics: &Path,
    covariance: &Path,
) -> Vec<(String, [f64; COVARIANCE_ENTRIES])> {
    let rows = read_rows(covariance);
    let pose_times: Vec<String> = std::fs::read_to_string(poses)
        .unwrap()
        .lines()
        .map(|l| l.split(' ').next().unwrap().to_string())
        .collect();
    assert!(!rows.is_empty());
    assert_eq!(rows.len(), pose_times.len(), "one covariance row per pose");
    let diagnostics = std::fs::read_to_string(diagnostics).unwrap();
    let mut diagnostics = diagnostics.lines();
    let header: Vec<&str> = diagnostics.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|&h| h == name).unwrap();
    let sigma_columns = [
        (column("sigma_x_m"), 0),
        (column("sigma_y_m"), 1),
        (column("sigma_z_m"), 2),
        (column("sigma_vx_mps"), 6),
        (column("sigma_vy_mps"), 7),
        (column("sigma_vz_mps"), 8),
    ];
    let diagnostics: Vec<&str> = diagnostics.collect();
    assert_eq!(diagnostics.len(), rows.len());
    for ((t, entries), (line, pose_t)) in rows.iter().zip(diagnostics.iter().zip(&pose_times)) {
        let fields: Vec<&str> = line.split(',').collect();
        assert_eq!(t, fields[0], "same time as the diagnostics row");
        assert_eq!(
            t.parse::<f64>().unwrap(),
            pose_t.parse::<f64>().unwrap(),
            "same time as the pose"
        );
        for &(col, i) in &sigma_columns {
            let sigma: f64 = fields[col].parse().unwrap();
            let from_covariance = entries[covariance_entry_index(i, i)].sqrt();
            if sigma.is_nan() {
                assert!(from_covariance.is_nan(), "{t}: {}", header[col]);
            } else {
                assert!(
                    (from_covariance - sigma).abs() <= 1e-12 * sigma,
                    "{t}: {} is {sigma}, the covariance gives {from_covariance}",
                    header[col]
                );
            }
        }
        // The entries are a symmetric matrix with a positive diagonal where there is a covariance.
        let c = covariance_from_upper_triangle(entries);
        if !c[(0, 0)].is_nan() {
            assert!((0..12).all(|i| c[(i, i)] > 0.0), "{t}: {c}");
        }
    }
    rows
}
