//! The fault flags of `roitrack simulate` (the `roitrack lab faults` table: tests/lab/faults.rs).

use std::path::Path;

mod common;
use common::{fails, ok};

/// (t, id) of every measurement in a simulation folder.
fn measurements(dir: &Path) -> Vec<(f64, u32)> {
    std::fs::read_to_string(dir.join("measurements.csv"))
        .unwrap()
        .lines()
        .filter_map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            Some((fields.first()?.parse().ok()?, fields.get(1)?.parse().ok()?))
        })
        .collect()
}

/// (t, tx) of every ground-truth pose.
fn truth_x(dir: &Path) -> Vec<(f64, f64)> {
    std::fs::read_to_string(dir.join("gt_poses.tum"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (f[0], f[1])
        })
        .collect()
}

fn simulate(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--scenario",
        "orthoglide",
        "--out",
        dir.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    ok(&args);
}

#[test]
fn simulate_fault_flags_produce_their_faults() {
    let tmp = tempfile::tempdir().unwrap();
    let (clean, faulty) = (tmp.path().join("clean"), tmp.path().join("faulty"));
    simulate(&clean, &[]);
    simulate(
        &faulty,
        &[
            "--occlude",
            "0,5,10,15@1.0:1.2",
            "--gap",
            "2.0:0.05",
            "--burst",
            "1.5:40",
            "--jump",
            "2.5:0.02,0,0",
            "--skip-off-image",
        ],
    );
    let (c, f) = (measurements(&clean), measurements(&faulty));
    assert_eq!(c.len() - f.len(), 200 + 200 + 40);
    assert!(
        !f.iter()
            .any(|(t, id)| (1.0..1.2).contains(t) && [0, 5, 10, 15].contains(id))
    );
    assert!(f.iter().any(|(t, _)| (1.0..1.2).contains(t)));
    assert!(!f.iter().any(|(t, _)| (2.0..2.05).contains(t)));
    assert!(!f.iter().any(|(t, _)| (1.5..1.51).contains(t)));
    for ((t, a), (_, b)) in truth_x(&clean).iter().zip(truth_x(&faulty)) {
        let expected = if *t >= 2.5 { 0.02 } else { 0.0 };
        assert!((b - a - expected).abs() < 1e-6, "t = {t}: {a} -> {b}");
    }
}

#[test]
fn bad_fault_flags_are_refused_naming_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().to_str().unwrap();
    for (flag, value) in [
        ("--occlude", "0,x@1:2"),
        ("--occlude", "0,5@1.2"),
        ("--occlude", "0@2:1"),
        ("--gap", "2.0"),
        ("--gap", "2.0:-1"),
        ("--burst", "1.5:many"),
        ("--jump", "2.5:0.02,0"),
        ("--jump", "later:0,0,0"),
    ] {
        let err = fails(&["simulate", "--out", out, flag, value]);
        assert!(
            err.contains(flag) && err.contains("invalid value"),
            "{flag} {value}: {err}"
        );
    }
    // Without --skip-off-image a blob leaving the image is an error; with it, the run goes on.
    let off_image = [
        "simulate",
        "--scenario",
        "static",
        "--out",
        out,
        "--jump",
        "0.5:0.2,0,0",
    ];
    let err = fails(&off_image);
    assert!(err.contains("leaves the image"), "{err}");
    ok(&[&off_image[..], &["--skip-off-image"]].concat());
}
