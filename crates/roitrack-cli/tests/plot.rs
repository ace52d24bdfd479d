//! `roitrack plot`: the figures of a run from its files, with and without truth, diagnostics and covariance; side
//! files of another run refused.

use std::path::Path;

mod common;
use common::{fails, ok};
#[path = "common/run.rs"]
mod run;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Simulates `scenario` into `dir` and tracks it, writing est.tum, est.csv, diag.csv and cov.csv.
fn tracked(dir: &Path, scenario: &str) {
    ok(&["simulate", "--scenario", scenario, "--out", p(dir)]);
    run::track_simulated(dir);
}

fn png_size(path: &Path) -> (u32, u32) {
    let image = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (image.width(), image.height())
}

#[test]
fn a_run_with_truth_diagnostics_and_covariance_gives_three_figures() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    tracked(dir, "spin");
    let out = dir.join("figures");
    let listed = ok(&[
        "plot",
        "--poses",
        p(&dir.join("est.tum")),
        "--twists",
        p(&dir.join("est.csv")),
        "--diagnostics",
        p(&dir.join("diag.csv")),
        "--covariance",
        p(&dir.join("cov.csv")),
        "--truth",
        p(dir),
        "--out",
        p(&out),
    ]);
    for stem in ["motion", "errors", "status"] {
        let (png, svg) = (
            out.join(format!("{stem}.png")),
            out.join(format!("{stem}.svg")),
        );
        assert!(
            listed.contains(p(&png)) && listed.contains(p(&svg)),
            "{listed}"
        );
        assert_eq!(png_size(&png), (1400, 1100));
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.starts_with("<svg"), "{stem}.svg");
        // Every axis says its unit.
        assert!(
            text.contains("time (s)"),
            "{stem}.svg has no time axis label"
        );
    }
    let motion = std::fs::read_to_string(out.join("motion.svg")).unwrap();
    for unit in ["mm", "deg", "mm/s", "deg/s", "rotation vector", "truth"] {
        assert!(motion.contains(unit), "motion.svg lacks {unit}");
    }
    let errors = std::fs::read_to_string(out.join("errors.svg")).unwrap();
    assert!(errors.contains("3 sigma") && errors.contains("rotation error"));
    // The bands are drawn: filled polygons, one per axis and panel.
    assert!(errors.matches("<polygon").count() >= 12, "no sigma bands");
    let status = std::fs::read_to_string(out.join("status.svg")).unwrap();
    for word in ["tracking", "converging", "lost", "log scale"] {
        assert!(status.contains(word), "status.svg lacks {word}");
    }
}

#[test]
fn poses_alone_give_the_motion_figure_only() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    tracked(dir, "static");
    let out = dir.join("alone");
    ok(&["plot", "--poses", p(&dir.join("est.tum")), "--out", p(&out)]);
    assert!(out.join("motion.png").is_file() && out.join("motion.svg").is_file());
    assert!(!out.join("errors.png").exists() && !out.join("status.png").exists());
}

#[test]
fn side_files_of_another_run_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    tracked(&a, "static");
    // A shorter run: its diagnostics have other rows.
    ok(&["simulate", "--scenario", "spin", "--out", p(&b)]);
    let measurements = std::fs::read_to_string(b.join("measurements.csv")).unwrap();
    let half: Vec<&str> = measurements.lines().take(2000).collect();
    std::fs::write(b.join("short.csv"), half.join("\n") + "\n").unwrap();
    ok(&common::track_args(
        p(&b.join("camera.yaml")),
        p(&b.join("target.csv")),
        p(&b.join("short.csv")),
        p(&b.join("est.tum")),
        p(&b.join("est.csv")),
        &["--diagnostics", p(&b.join("diag.csv"))],
    ));
    let err = fails(&[
        "plot",
        "--poses",
        p(&a.join("est.tum")),
        "--diagnostics",
        p(&b.join("diag.csv")),
        "--out",
        p(&tmp.path().join("x")),
    ]);
    assert!(
        err.contains("diag.csv") && err.contains("not the same run"),
        "{err}"
    );
    // A covariance file that is not one.
    let err = fails(&[
        "plot",
        "--poses",
        p(&a.join("est.tum")),
        "--covariance",
        p(&a.join("est.csv")),
        "--out",
        p(&tmp.path().join("x")),
    ]);
    assert!(err.contains("est.csv") && err.contains("c0_0"), "{err}");
}
