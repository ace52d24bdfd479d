//! roitrack's static pose solver side by side with OpenCV's solvePnP on random PnP families:
//! `bench/pnp_families.py --check --per-family 25 --seed 34` draws 25 problems in each of eight families (3 points,
//! 4-5 and 6-40 points planar, off-plane and 3-D, symmetric grids; random cameras, lenses, poses, noise, and a user's
//! model off the truth), solves them with `roitrack lab pnp-bench --suite` (this test's binary) and with OpenCV, and fails,
//! naming the family and the figure, where roitrack's correct rate, median normalised error or wrong answers given
//! without a flag are worse than the best OpenCV method's. Times are printed, never checked.
//!
//! OpenCV lives in the virtual environment that scripts/setup-test-deps makes (`target/opencv-venv`, or
//! `ROITRACK_OPENCV_VENV`). Without it the test says it was skipped, unless `ROITRACK_REQUIRE_OPENCV` is set, when its
//! absence is a failure.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The Python of OpenCV's virtual environment, or `None` (the test is then skipped) if it is not installed.
fn python() -> Option<PathBuf> {
    crate::venv::python(&crate::venv::Venv {
        dir_var: "ROITRACK_OPENCV_VENV",
        default_dir: "opencv-venv",
        imports: "cv2, numpy",
        what: "opencv-python-headless",
        require_var: "ROITRACK_REQUIRE_OPENCV",
    })
}

#[test]
fn roitrack_does_as_well_as_opencv_on_every_family() {
    let Some(python) = python() else { return };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench/pnp_families.py");
    let out = Command::new(&python)
        .arg(&script)
        .args(["--roitrack", env!("CARGO_BIN_EXE_roitrack")])
        .args(["--check", "--per-family", "25", "--seed", "34"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The tables are the test's report: shown with `--nocapture`, and with the failure.
    println!("{stdout}");
    assert!(
        out.status.success(),
        "bench/pnp_families.py --check failed (status {:?}):\n{stdout}\n{stderr}",
        out.status.code()
    );
    // Every family was compared (a script that stopped early must not pass).
    for family in [
        "3 points",
        "4-5 planar",
        "4-5 3-D",
        "6-40 planar",
        "6-40 off-plane 0.1-1%",
        "6-40 off-plane 1-10%",
        "6-40 3-D",
        "symmetric grids",
    ] {
        assert!(
            stdout.contains(&format!("## {family}: 25 problems")),
            "no table for {family}:\n{stdout}"
        );
    }
    assert!(stdout.contains("# check: PASS"), "{stdout}");
}
