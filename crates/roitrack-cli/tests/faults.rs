//! The fault flags of `roitrack simulate` and the `roitrack faults` table.

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
    // Without --skip-off-image a blob leaving the image is an error.
    let err = fails(&[
        "simulate",
        "--scenario",
        "static",
        "--out",
        out,
        "--jump",
        "0.5:0.2,0,0",
    ]);
    assert!(err.contains("leaves the image"), "{err}");
    ok(&[
        "simulate",
        "--scenario",
        "static",
        "--out",
        out,
        "--jump",
        "0.5:0.2,0,0",
        "--skip-off-image",
    ]);
}

#[test]
fn faults_json_reports_every_row() {
    let stdout = ok(&["faults", "--json", "--quick"]);
    let rows: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let faults: Vec<&str> = rows.iter().map(|r| r["fault"].as_str().unwrap()).collect();
    assert_eq!(
        faults,
        [
            "clean",
            "burst 40 ROIs lost",
            "jump 20 mm in x",
            "4 blobs leave image 0.4 s"
        ]
    );
    for r in &rows {
        assert_eq!(r["scenario"], "orthoglide");
        assert!(r["position_rmse_mm"].as_f64().unwrap() > 0.0);
        assert!(r["velocity_rmse_mm_s"].as_f64().unwrap() > 0.0);
        assert!(r["unflagged_wrong"].is_u64() && r["lost"].is_u64());
    }
    assert!(rows[0]["recovery_ms"].is_null() && rows[0]["fault_end_s"].is_null());
    assert!(rows[1]["recovery_ms"].as_f64().unwrap() >= 0.0);
    // The burst barely disturbs the clean run; the jump costs accuracy.
    let rmse = |r: &serde_json::Value| r["position_rmse_mm"].as_f64().unwrap();
    assert!(rmse(&rows[1]) < 2.0 * rmse(&rows[0]));
    assert!(rmse(&rows[2]) > rmse(&rows[0]));
    // The estimate that first sees the jump cannot tell it from an outlier: it is flagged (disputed), and no
    // estimate is wrong without a flag.
    assert!(rows[2]["flagged"].as_u64().unwrap() >= 1);
    // Blobs leaving the image and coming back: tracked throughout, recovered within 50 ms of the end.
    assert!(rmse(&rows[3]) < 1.5 * rmse(&rows[0]));
    assert!(rows[3]["recovery_ms"].as_f64().unwrap() <= 50.0);
    for r in &rows {
        assert_eq!(r["unflagged_wrong"], 0, "{}", r["fault"]);
    }
}
