//! A rig's cameras with inputs of any kind: `track --rig` with `--rois NAME=FILE` and `--images NAME=SOURCE` as well
//! as `--measurements NAME=FILE`. A one-camera rig of a ROI recording is `track --rois`, byte for byte; two cameras'
//! frames fuse; bad `NAME=...` inputs are refused naming the camera.

use std::path::Path;

mod common;
use common::{fails, ok};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// The rig file of `cameras` (name, calibration relative to the rig file), all at the rig's origin; every camera but
/// the first on the rig's clock, given.
fn write_rig(path: &Path, cameras: &[(&str, &str)]) {
    let mut text = String::from("cameras:\n");
    for (k, (name, calibration)) in cameras.iter().enumerate() {
        text += &format!(
            "  - name: {name}\n    calibration: {calibration}\n    camera_T_rig: [0, 0, 0, 0, 0, 0, 1]\n"
        );
        if k > 0 {
            text += "    clock_offset_s: 0\n    clock_drift_ppm: 0\n";
        }
    }
    std::fs::write(path, text).unwrap();
}

/// TUM rows: (t, position).
fn read_tum(path: &Path) -> Vec<(f64, [f64; 3])> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], [v[1], v[2], v[3]])
        })
        .collect()
}

/// The RMS position error (m) of `estimates` against the truth at the same times (the truth is written at every
/// frame's time and densely between).
fn position_rmse_m(estimates: &Path, truth: &Path) -> (f64, usize) {
    let truth = read_tum(truth);
    let estimates = read_tum(estimates);
    let mut sum = 0.0;
    for (t, x) in &estimates {
        let k = truth
            .partition_point(|(tt, _)| *tt < t - 1e-9)
            .min(truth.len() - 1);
        let g = truth[k].1;
        sum += (0..3).map(|i| (x[i] - g[i]).powi(2)).sum::<f64>();
    }
    (
        (sum / estimates.len().max(1) as f64).sqrt(),
        estimates.len(),
    )
}

#[test]
fn a_one_camera_rig_of_a_roi_recording_is_track_rois_byte_for_byte() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    ok(&[
        "simulate",
        "--rois",
        "--scenario",
        "random",
        "--duration-s",
        "1",
        "--out",
        p(&sim),
    ]);
    let rig = sim.join("rig.yaml");
    write_rig(&rig, &[("cam0", "camera.yaml")]);
    let target = sim.join("target.csv");
    let rois = sim.join("rois.bin");
    let single = [tmp.path().join("a.tum"), tmp.path().join("a.csv")];
    let rigged = [tmp.path().join("b.tum"), tmp.path().join("b.csv")];
    ok(&[
        "track",
        "--camera",
        p(&sim.join("camera.yaml")),
        "--target",
        p(&target),
        "--rois",
        p(&rois),
        "--poses",
        p(&single[0]),
        "--twists",
        p(&single[1]),
    ]);
    let cam0 = format!("cam0={}", p(&rois));
    ok(&[
        "track",
        "--rig",
        p(&rig),
        "--target",
        p(&target),
        "--rois",
        &cam0,
        "--poses",
        p(&rigged[0]),
        "--twists",
        p(&rigged[1]),
    ]);
    for (a, b) in single.iter().zip(&rigged) {
        let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
        assert!(!a.is_empty());
        assert!(
            a == b,
            "the one-camera rig's output differs from track --rois"
        );
    }
}

/// Two cameras at the same place and clock, each with its own frames of the same motion (independent sensor noise):
/// the fused track is no worse than the better camera's own by more than the sampling spread of an RMS error.
#[test]
fn two_cameras_of_frames_fuse_no_worse_than_the_better_one() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = 150;
    for (name, seed) in [("cam0", "1"), ("cam1", "2")] {
        ok(&[
            "simulate",
            "--frames",
            "--scenario",
            "orthoglide",
            "--speed-scale",
            "0.5",
            "--seed",
            seed,
            "--frame-count",
            &frames.to_string(),
            "--out",
            p(&tmp.path().join(name)),
        ]);
    }
    let rig = tmp.path().join("rig.yaml");
    write_rig(
        &rig,
        &[("cam0", "cam0/camera.yaml"), ("cam1", "cam1/camera.yaml")],
    );
    let target = tmp.path().join("cam0/target.csv");
    let truth = tmp.path().join("cam0/gt_poses.tum");
    let mut single_m = Vec::new();
    for name in ["cam0", "cam1"] {
        let poses = tmp.path().join(format!("{name}.tum"));
        ok(&[
            "track",
            "--camera",
            p(&tmp.path().join(name).join("camera.yaml")),
            "--target",
            p(&target),
            "--images",
            p(&tmp.path().join(name).join("frames")),
            "--fps",
            "30",
            "--poses",
            p(&poses),
            "--twists",
            p(&tmp.path().join(format!("{name}.csv"))),
        ]);
        single_m.push(position_rmse_m(&poses, &truth).0);
    }
    let fused = tmp.path().join("fused.tum");
    let (cam0, cam1) = (
        format!("cam0={}", p(&tmp.path().join("cam0/frames"))),
        format!("cam1={}", p(&tmp.path().join("cam1/frames"))),
    );
    ok(&[
        "track",
        "--rig",
        p(&rig),
        "--target",
        p(&target),
        "--images",
        &cam0,
        "--images",
        &cam1,
        "--fps",
        "30",
        "--poses",
        p(&fused),
        "--twists",
        p(&tmp.path().join("fused.csv")),
    ]);
    let (fused_m, count) = position_rmse_m(&fused, &truth);
    assert!(
        count > frames * 9 / 10,
        "{count} fused estimates of {frames} frames"
    );
    // An RMS error over n independent errors has a relative standard deviation of 1/sqrt(2 n); a filter's errors
    // are correlated over about its settling time, taken as 5 frames. Ideal fusion of two equal cameras is 1/sqrt(2)
    // of one; allow the better single camera's error plus 4 of those standard deviations.
    let independent = count as f64 / 5.0;
    let best = single_m.iter().copied().fold(f64::INFINITY, f64::min);
    let bound = best * (1.0 + 4.0 / (2.0 * independent).sqrt());
    assert!(
        fused_m <= bound,
        "fused position RMSE {fused_m:e} m > {bound:e} m (the cameras alone: {single_m:?})"
    );
}

#[test]
fn bad_rig_inputs_are_refused_naming_the_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    ok(&[
        "simulate",
        "--rois",
        "--scenario",
        "random",
        "--duration-s",
        "0.2",
        "--out",
        p(&sim),
    ]);
    let rig = sim.join("rig.yaml");
    write_rig(&rig, &[("cam0", "camera.yaml"), ("cam1", "camera.yaml")]);
    let target = sim.join("target.csv");
    let rois = p(&sim.join("rois.bin")).to_string();
    let measurements = p(&sim.join("measurements.csv")).to_string();
    let (poses, twists) = (tmp.path().join("x.tum"), tmp.path().join("x.csv"));
    let run = |inputs: &[&str]| {
        let mut args = vec!["track", "--rig", p(&rig), "--target", p(&target)];
        args.extend_from_slice(inputs);
        args.extend_from_slice(&["--poses", p(&poses), "--twists", p(&twists)]);
        fails(&args)
    };
    let unknown = run(&[
        "--rois",
        &format!("cam0={rois}"),
        "--images",
        "left=frames/",
    ]);
    assert!(
        unknown.contains("no camera 'left'") && unknown.contains("cam0, cam1"),
        "{unknown}"
    );
    let twice = run(&[
        "--measurements",
        &format!("cam1={measurements}"),
        "--rois",
        &format!("cam0={rois}"),
        "--rois",
        &format!("cam1={rois}"),
    ]);
    assert!(
        twice.contains("camera 'cam1' is given twice") && twice.contains("--measurements cam1="),
        "{twice}"
    );
    let unnamed = run(&["--rois", &rois]);
    assert!(
        unnamed.contains("--rois") && unnamed.contains("NAME=FILE"),
        "{unnamed}"
    );
    let first_missing = run(&["--rois", &format!("cam1={rois}")]);
    assert!(first_missing.contains("'cam0'"), "{first_missing}");
    let unreadable = run(&["--images", "cam0=no/such/frames", "--fps", "30"]);
    assert!(
        unreadable.contains("camera 'cam0'") && unreadable.contains("no/such/frames"),
        "{unreadable}"
    );
    assert!(!poses.exists() && !twists.exists());
}
