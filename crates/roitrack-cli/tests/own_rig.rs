//! Simulating one's own rig before building it: a user's calibration (an OpenCV FileStorage file of a fisheye lens) and
//! target (a grid made by `roitrack target grid`), the motion moved farther, slowed down and cut short; then tracked,
//! scored and plotted. And a rig whose target would leave the image, refused with the option that fixes it.

use std::path::Path;

mod common;
use common::{fails, ok};
#[path = "common/rig.rs"]
mod rig;
use rig::{FISHEYE_YAML, fisheye_camera_and_grid};
#[path = "common/run.rs"]
mod run;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn gt_peak_speed(dir: &Path) -> f64 {
    roitrack::formats::read_twists_csv(dir.join("gt_twists.csv"))
        .unwrap()
        .iter()
        .map(|t| t.velocity_mps.norm())
        .fold(0.0, f64::max)
}

/// The camera a run wrote into its folder `dir` (`camera.yaml`), read back.
fn written_camera(dir: &Path) -> roitrack::CameraModel {
    roitrack::formats::read_camera_file(
        dir.join("camera.yaml"),
        &roitrack::formats::CameraFileOptions::default(),
    )
    .unwrap()
}

#[test]
fn own_camera_and_target_simulated_tracked_scored_and_plotted() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera = dir.join("fisheye.yaml");
    std::fs::write(&camera, FISHEYE_YAML).unwrap();
    let target = dir.join("grid.csv");
    ok(&[
        "target",
        "grid",
        "--rows",
        "3",
        "--cols",
        "4",
        "--spacing-m",
        "0.03",
        "--diameter-m",
        "0.012",
        "--out",
        p(&target),
    ]);
    let (plain, mine) = (dir.join("plain"), dir.join("mine"));
    ok(&["simulate", "--scenario", "orthoglide", "--out", p(&plain)]);
    ok(&[
        "simulate",
        "--scenario",
        "orthoglide",
        "--camera",
        p(&camera),
        "--target",
        p(&target),
        "--distance-m",
        "0.9",
        "--speed-scale",
        "0.5",
        "--duration-s",
        "6",
        "--out",
        p(&mine),
    ]);
    // The rig's own camera and target are what the simulation wrote and used.
    let written = written_camera(&mine);
    assert_eq!((written.width_px, written.height_px), (1280, 1024));
    assert_eq!(written.distortion.model_name(), "equidistant");
    assert_eq!(
        roitrack::formats::read_target_csv(mine.join("target.csv"))
            .unwrap()
            .len(),
        12
    );
    let truth = roitrack::formats::read_tum(mine.join("gt_poses.tum")).unwrap();
    let last = truth.last().unwrap();
    assert!((last.t_s - 6.0).abs() < 0.01, "{}", last.t_s);
    let mean_z = truth
        .iter()
        .map(|p| p.cam_from_obj.translation.vector.z)
        .sum::<f64>()
        / truth.len() as f64;
    assert!((mean_z - 0.9).abs() < 0.01, "{mean_z}");
    // Half the speed.
    let ratio = gt_peak_speed(&mine) / gt_peak_speed(&plain);
    assert!((ratio - 0.5).abs() < 0.01, "{ratio}");

    run::track_simulated(&mine);
    let metrics: serde_json::Value = serde_json::from_str(&ok(&[
        "eval",
        "--truth",
        p(&mine),
        "--poses",
        p(&mine.join("est.tum")),
        "--twists",
        p(&mine.join("est.csv")),
        "--json",
    ]))
    .unwrap();
    let rmse = metrics["position_rmse_mm"].as_f64().unwrap();
    // 12 blobs at 0.9 m through a 900 px lens: a millimetre at most.
    assert!(rmse < 1.0, "{metrics}");
    let figures = mine.join("figures");
    ok(&[
        "plot",
        "--poses",
        p(&mine.join("est.tum")),
        "--twists",
        p(&mine.join("est.csv")),
        "--diagnostics",
        p(&mine.join("diag.csv")),
        "--covariance",
        p(&mine.join("cov.csv")),
        "--truth",
        p(&mine),
        "--out",
        p(&figures),
    ]);
    for stem in ["motion", "errors", "status"] {
        assert!(figures.join(format!("{stem}.png")).is_file());
        assert!(figures.join(format!("{stem}.svg")).is_file());
    }
}

#[test]
fn a_rig_that_loses_the_target_is_refused_with_the_fix() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let err = fails(&[
        "simulate",
        "--scenario",
        "orthoglide",
        "--distance-m",
        "0.15",
        "--out",
        p(&dir.join("near")),
    ]);
    assert!(
        err.contains("out of the image") && err.contains("--distance-m"),
        "{err}"
    );
    let err = fails(&[
        "simulate",
        "--speed-scale",
        "0",
        "--out",
        p(&dir.join("still")),
    ]);
    assert!(err.contains("--speed-scale"), "{err}");
    let err = fails(&[
        "simulate",
        "--target",
        p(&dir.join("missing.csv")),
        "--out",
        p(&dir.join("x")),
    ]);
    assert!(err.contains("missing.csv"), "{err}");
}

/// `demo` runs on the rig too: its loop renders the target through the user's camera (`lab compare` and `lab tradeoff`
/// do as well: tests/lab).
#[test]
fn demo_takes_the_rig() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (camera, target) = fisheye_camera_and_grid(dir);
    // The demo's loop starts from a full frame, which needs a target whose labelling a view decides: the built-in
    // grid with its larger key blob (a plain grid's half turn is ambiguous, and the loop refuses to start on a guess).
    let out = dir.join("demo");
    ok(&[
        "demo",
        "--scenario",
        "spin",
        "--camera",
        p(&camera),
        "--distance-m",
        "1.0",
        "--duration-s",
        "1.0",
        "--out",
        p(&out),
    ]);
    let written = written_camera(&out);
    assert_eq!(written.distortion.model_name(), "equidistant");
    assert!(out.join("kalman_poses.tum").is_file());
    // A plain 4 x 5 grid looks the same turned half way round: the loop cannot start, and says why.
    let err = fails(&[
        "demo",
        "--scenario",
        "spin",
        "--target",
        p(&target),
        "--duration-s",
        "0.3",
        "--out",
        p(&dir.join("plain")),
    ]);
    assert!(
        err.contains("never identified") && err.contains("marked point"),
        "{err}"
    );
}

/// A simulation into the folder that holds its own camera file would overwrite it (with the ROS form of it): refused,
/// the file left as it was; so are `target --out` and `--camera-out` on one file.
#[test]
fn outputs_never_overwrite_the_rig_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera = dir.join("camera.yaml");
    std::fs::write(&camera, FISHEYE_YAML).unwrap();
    let err = fails(&[
        "simulate",
        "--camera",
        p(&camera),
        "--distance-m",
        "1.0",
        "--out",
        p(dir),
    ]);
    assert!(
        err.contains("--camera") && err.contains("camera.yaml"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&camera).unwrap(), FISHEYE_YAML);
    assert!(!dir.join("measurements.csv").exists());
    let err = fails(&[
        "demo",
        "--camera",
        p(&camera),
        "--distance-m",
        "1.0",
        "--out",
        p(dir),
    ]);
    assert!(err.contains("--camera"), "{err}");
    assert_eq!(std::fs::read_to_string(&camera).unwrap(), FISHEYE_YAML);
    let both = dir.join("both.csv");
    let err = fails(&["target", "--out", p(&both), "--camera-out", p(&both)]);
    assert!(
        err.contains("--out") && err.contains("--camera-out"),
        "{err}"
    );
}
