//! `roitrack servo --live` refusing what it cannot run, with a message that says what to give instead (the runs
//! themselves: roitrack-servo's tests/live.rs on the simulated camera, tests/live.rs here through Aravis).

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

#[cfg(not(feature = "genicam"))]
#[test]
fn live_fake_without_the_genicam_feature_says_how_to_build_it() {
    let (ok, stderr) = servo(&["--live", "--fake"]);
    assert!(!ok);
    assert!(stderr.contains("--features genicam"), "{stderr}");
}
