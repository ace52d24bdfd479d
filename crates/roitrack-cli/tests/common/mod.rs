//! Helpers shared by the integration tests: run the `roitrack` binary and check how it ended.

use std::path::Path;
use std::process::{Command, Output};

pub fn roitrack(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_roitrack"))
        .args(args)
        .output()
        .expect("the roitrack binary runs")
}

/// Runs `roitrack args`, asserts success and returns its standard output.
pub fn ok(args: &[&str]) -> String {
    let out = roitrack(args);
    assert!(
        out.status.success(),
        "roitrack {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Runs `roitrack args`, asserts failure and returns its standard error.
pub fn fails(args: &[&str]) -> String {
    let out = roitrack(args);
    assert!(
        !out.status.success(),
        "roitrack {args:?} should have failed"
    );
    String::from_utf8(out.stderr).unwrap()
}

/// `roitrack simulate --scenario random --rig-cameras CAMERAS --duration-s DURATION_S EXTRA... --out SIM`: a simulated
/// rig, a folder per camera and the rig file.
#[allow(dead_code)] // Only the rig tests simulate a rig.
pub fn simulate_random_rig(sim: &Path, cameras: &str, duration_s: &str, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--scenario",
        "random",
        "--rig-cameras",
        cameras,
        "--duration-s",
        duration_s,
    ];
    args.extend_from_slice(extra);
    args.extend(["--out", sim.to_str().unwrap()]);
    ok(&args);
}

/// `track --rig SIM/rig.yaml --target SIM/target.csv --measurements camK=SIM/camK/measurements.csv (each of the
/// first `cameras`) --poses POSES --twists TWISTS EXTRA...`: the arguments of a run that tracks the measurement files
/// of a simulated rig (`simulate --rig-cameras`) together.
#[allow(dead_code)] // Not every test tracks a rig.
pub fn track_simulated_rig_args(
    sim: &Path,
    cameras: usize,
    poses: &Path,
    twists: &Path,
    extra: &[&str],
) -> Vec<String> {
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let mut args: Vec<String> = ["track", "--rig"].map(String::from).to_vec();
    args.extend([
        path(&sim.join("rig.yaml")),
        "--target".into(),
        path(&sim.join("target.csv")),
    ]);
    for k in 0..cameras {
        let file = sim.join(format!("cam{k}")).join("measurements.csv");
        args.extend(["--measurements".into(), format!("cam{k}={}", path(&file))]);
    }
    args.extend([
        "--poses".into(),
        path(poses),
        "--twists".into(),
        path(twists),
    ]);
    args.extend(extra.iter().map(|a| a.to_string()));
    args
}

/// `track --camera CAMERA --target TARGET --measurements MEASUREMENTS --poses POSES --twists TWISTS EXTRA...`: the
/// arguments of a run that tracks a measurements file.
#[allow(dead_code)] // Not every test tracks a measurements file.
pub fn track_args<'a>(
    camera: &'a str,
    target: &'a str,
    measurements: &'a str,
    poses: &'a str,
    twists: &'a str,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "track",
        "--camera",
        camera,
        "--target",
        target,
        "--measurements",
        measurements,
        "--poses",
        poses,
        "--twists",
        twists,
    ];
    args.extend_from_slice(extra);
    args
}
