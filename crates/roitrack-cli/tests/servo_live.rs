//! `roitrack servo --live` refusing what it cannot run, with a message that says what to give instead (the runs
//! themselves: roitrack-servo's tests/live.rs on the simulated camera, tests/live.rs here through Aravis, and
//! tests/ros2_dds.rs with `--ros2`), and telling the live tracker the commanded acceleration unless
//! `--no-known-acceleration`.

use std::process::Command;

fn servo(args: &[&str]) -> (bool, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_roitrack"))
        .arg("servo")
        .args(args)
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn live_without_a_camera_is_refused_naming_both() {
    let (ok, stderr) = servo(&["--live"]);
    assert!(!ok);
    assert!(
        stderr.contains("--fake") && stderr.contains("--sim-camera"),
        "{stderr}"
    );
}

#[test]
fn a_rate_beyond_4_khz_is_refused_not_run() {
    let (ok, stderr) = servo(&["--live", "--sim-camera", "--rate-hz", "10000"]);
    assert!(!ok);
    assert!(stderr.contains("rate-hz"), "{stderr}");
}

#[test]
fn fake_without_live_and_true_state_live_are_refused() {
    let (ok, stderr) = servo(&["--fake"]);
    assert!(!ok, "{stderr}");
    let (ok, stderr) = servo(&["--live", "--sim-camera", "--controller", "true-state"]);
    assert!(!ok);
    assert!(stderr.contains("true-state"), "{stderr}");
}

/// `--paced` paces a simulated-time run's publishing; the real-time loop publishes on the wall clock already.
#[test]
fn live_paced_is_refused_saying_why() {
    let (ok, stderr) = servo(&["--live", "--sim-camera", "--paced"]);
    assert!(!ok);
    assert!(
        stderr.contains("--paced") && stderr.contains("wall clock"),
        "{stderr}"
    );
}

#[cfg(not(feature = "genicam"))]
#[test]
fn live_fake_without_the_genicam_feature_says_how_to_build_it() {
    let (ok, stderr) = servo(&["--live", "--fake"]);
    assert!(!ok);
    assert!(stderr.contains("--features genicam"), "{stderr}");
}

/// The last line of a `--json` run of `servo --live --sim-camera` at 500 Hz with `extra` arguments.
fn live_json(extra: &[&str]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_roitrack"))
        .args([
            "servo",
            "--live",
            "--sim-camera",
            "--rate-hz",
            "500",
            "--json",
        ])
        .args(extra)
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.lines().last().unwrap_or_default()).unwrap()
}

/// By default the control thread sends each command's acceleration and the live tracker takes every one (none
/// refused; none lost to a full queue on a machine that keeps up, said if one was); `--no-known-acceleration` sends
/// none. Whether the run stays stable is not judged here (roitrack-servo's tests/live_known_acceleration.rs).
#[test]
fn live_tells_the_tracker_the_commanded_acceleration_unless_told_not_to() {
    let told = live_json(&[]);
    assert_eq!(told["known_acceleration"], true, "{told}");
    let sent = told["known_accelerations_sent"].as_u64().unwrap();
    let taken = told["known_accelerations_told"].as_u64().unwrap();
    let superseded = told["known_accelerations_superseded"].as_u64().unwrap();
    assert!(sent > 0, "{told}");
    assert_eq!(taken + superseded, sent, "{told}");
    assert_eq!(told["known_accelerations_refused"], 0, "{told}");
    let not_told = live_json(&["--no-known-acceleration"]);
    assert_eq!(not_told["known_acceleration"], false, "{not_told}");
    assert_eq!(not_told["known_accelerations_sent"], 0, "{not_told}");
    assert_eq!(not_told["known_accelerations_told"], 0, "{not_told}");
}
