//! A rig's cameras with inputs of any kind: `track --rig` with `--rois NAME=FILE` and `--images NAME=SOURCE` as well
//! as `--measurements NAME=FILE`, and each camera's frames from a bag (`--images NAME=BAG --topic NAME=TOPIC`). A
//! one-camera rig of a ROI recording is `track --rois`, byte for byte; two cameras' frames fuse; bad `NAME=...` inputs
//! are refused naming the camera.

use std::path::{Path, PathBuf};

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

/// `simulate --rois --scenario random --duration-s DURATION_S --out SIM`, and beside it the rig file of `cameras`
/// ([`write_rig`]), which it returns.
fn random_rois_and_rig(sim: &Path, duration_s: &str, cameras: &[(&str, &str)]) -> PathBuf {
    ok(&[
        "simulate",
        "--rois",
        "--scenario",
        "random",
        "--duration-s",
        duration_s,
        "--out",
        p(sim),
    ]);
    let rig = sim.join("rig.yaml");
    write_rig(&rig, cameras);
    rig
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

/// `rmse_m` plus 4 standard deviations of an RMS error over `count` estimates: an RMS error over n independent errors
/// has a relative standard deviation of 1/sqrt(2 n), and a filter's errors are correlated over about its settling
/// time, taken as 5 frames (n = count / 5).
fn rmse_bound_m(rmse_m: f64, count: usize) -> f64 {
    let independent = count as f64 / 5.0;
    rmse_m * (1.0 + 4.0 / (2.0 * independent).sqrt())
}

#[test]
fn a_one_camera_rig_of_a_roi_recording_is_track_rois_byte_for_byte() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    let rig = random_rois_and_rig(&sim, "1", &[("cam0", "camera.yaml")]);
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
    // Ideal fusion of two equal cameras is 1/sqrt(2) of one; allow the better single camera's error plus the
    // sampling spread of an RMS error.
    let best = single_m.iter().copied().fold(f64::INFINITY, f64::min);
    let bound = rmse_bound_m(best, count);
    assert!(
        fused_m <= bound,
        "fused position RMSE {fused_m:e} m > {bound:e} m (the cameras alone: {single_m:?})"
    );
}

#[test]
fn bad_rig_inputs_are_refused_naming_the_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    let rig = random_rois_and_rig(
        &sim,
        "0.2",
        &[("cam0", "camera.yaml"), ("cam1", "camera.yaml")],
    );
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

/// The position RMSE (m) that `roitrack eval --truth DIR` reports for `poses` (its `position RMSE` row, in mm).
fn eval_position_rmse_m(truth_dir: &Path, poses: &Path, twists: &Path) -> f64 {
    let report = ok(&[
        "eval",
        "--truth",
        p(truth_dir),
        "--poses",
        p(poses),
        "--twists",
        p(twists),
    ]);
    let row = report
        .lines()
        .find(|l| l.starts_with("position RMSE "))
        .unwrap_or_else(|| panic!("no position RMSE in\n{report}"));
    let fields: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(fields[3], "mm", "{row}");
    fields[2].parse::<f64>().unwrap() * 1e-3
}

/// `simulate --frames --rig` of two cameras, one at the rig's origin on its clock, one 0.3 m aside turned 31 degrees
/// towards the scene with a clock 12.3 ms late and 40 ppm fast: a folder of frames per camera on its own clock and
/// the truth on the rig's; each camera alone follows the truth once carried through the rig file's mount and clock,
/// and `track --rig` of both frames is, by `roitrack eval`, no worse than the worse camera alone by more than the
/// sampling spread of an RMS error.
#[test]
fn simulate_frames_rig_writes_each_cameras_frames_on_its_clock_and_they_fuse() {
    let tmp = tempfile::tempdir().unwrap();
    // A calibration: the scenario's camera.
    let cal = tmp.path().join("cal");
    ok(&[
        "simulate",
        "--scenario",
        "static",
        "--duration-s",
        "0.01",
        "--out",
        p(&cal),
    ]);
    // camera_R_rig is a turn of `yaw` about y; the right camera looks at (0, 0, 0.6) m from (0.3, 0, 0.1) m.
    let yaw = 2.0 * 0.266_933_6_f64.atan2(0.963_714_9);
    let (mount_t, offset_s, drift_ppm) = ([-0.308_697_5, 0.0, 0.068_599_4], 0.0123, 40.0);
    let rig = tmp.path().join("rig.yaml");
    std::fs::write(
        &rig,
        format!(
            "cameras:\n  - name: left\n    calibration: cal/camera.yaml\n    camera_T_rig: [0, 0, 0, 0, 0, 0, 1]\n  \
             - name: right\n    calibration: cal/camera.yaml\n    camera_T_rig: [{}, {}, {}, 0, 0.2669336, 0, \
             0.9637149]\n    clock_offset_s: {offset_s}\n    clock_drift_ppm: {drift_ppm}\n",
            mount_t[0], mount_t[1], mount_t[2]
        ),
    )
    .unwrap();
    let frames = 150;
    let sim = tmp.path().join("sim");
    ok(&[
        "simulate",
        "--frames",
        "--rig",
        p(&rig),
        "--scenario",
        "orthoglide",
        "--speed-scale",
        "0.5",
        "--frame-count",
        &frames.to_string(),
        "--out",
        p(&sim),
    ]);
    for file in [
        "target.csv",
        "gt_poses.tum",
        "gt_twists.csv",
        "rig.yaml",
        "rig_truth.yaml",
    ] {
        assert!(sim.join(file).is_file(), "{file}");
    }
    for name in ["left", "right"] {
        let dir = sim.join(name);
        for file in ["camera.yaml", "target.csv", "timestamps.csv", "README.txt"] {
            assert!(dir.join(file).is_file(), "{name}/{file}");
        }
        let pngs = std::fs::read_dir(dir.join("frames")).unwrap().count();
        assert_eq!(pngs, frames, "{name}/frames");
        // Frame k at k / 30 s of the camera's own clock.
        let times = std::fs::read_to_string(dir.join("timestamps.csv")).unwrap();
        let last = times.lines().last().unwrap();
        let expected = format!("{},frame_{:05}.png", 149.0 / 30.0, frames - 1);
        assert_eq!(last, expected);
    }
    let target = sim.join("target.csv");
    let truth = sim.join("gt_poses.tum");

    // Each camera alone. The left camera's frame and clock are the rig's.
    let track_alone = |name: &str| {
        let (poses, twists) = (
            tmp.path().join(format!("{name}.tum")),
            tmp.path().join(format!("{name}.csv")),
        );
        ok(&[
            "track",
            "--camera",
            p(&sim.join(name).join("camera.yaml")),
            "--target",
            p(&target),
            "--images",
            p(&sim.join(name).join("frames")),
            "--fps",
            "30",
            "--poses",
            p(&poses),
            "--twists",
            p(&twists),
        ]);
        (poses, twists)
    };
    let (left_poses, left_twists) = track_alone("left");
    let left_m = eval_position_rmse_m(&sim, &left_poses, &left_twists);
    // The right camera's track carried into the rig's frame (x_rig = R^T (x_camera - t)) at the rig's time of each
    // estimate, and, to show that its frames are on its own clock, at its camera time taken as the rig's.
    let (right_poses, _) = track_alone("right");
    let truth_rows = read_tum(&truth);
    let (cos, sin) = (yaw.cos(), yaw.sin());
    let carried_rmse_m = |with_clock: bool| {
        let estimates = read_tum(&right_poses);
        let mut sum = 0.0;
        for (t, x) in &estimates {
            let d = [x[0] - mount_t[0], x[1] - mount_t[1], x[2] - mount_t[2]];
            let rig_x = [cos * d[0] - sin * d[2], d[1], sin * d[0] + cos * d[2]];
            let t_rig = if with_clock {
                offset_s + t / (1.0 + drift_ppm * 1e-6)
            } else {
                *t
            };
            // The truth is dense (0.5 ms): linear interpolation.
            let k = truth_rows
                .partition_point(|(tt, _)| *tt < t_rig)
                .clamp(1, truth_rows.len() - 1);
            let ((t0, a), (t1, b)) = (truth_rows[k - 1], truth_rows[k]);
            let f = ((t_rig - t0) / (t1 - t0)).clamp(0.0, 1.0);
            sum += (0..3)
                .map(|i| (rig_x[i] - (a[i] + f * (b[i] - a[i]))).powi(2))
                .sum::<f64>();
        }
        (sum / estimates.len() as f64).sqrt()
    };
    let (right_m, right_unclocked_m) = (carried_rmse_m(true), carried_rmse_m(false));
    // 12.3 ms at up to 0.5 m/s is millimetres; the frames' own error is tens of micrometres.
    assert!(
        right_unclocked_m > 10.0 * right_m,
        "right camera carried to the rig: {right_m:e} m with its clock, {right_unclocked_m:e} m without"
    );

    let (fused, fused_twists) = (tmp.path().join("fused.tum"), tmp.path().join("fused.csv"));
    let (left, right) = (
        format!("left={}", p(&sim.join("left/frames"))),
        format!("right={}", p(&sim.join("right/frames"))),
    );
    ok(&[
        "track",
        "--rig",
        p(&sim.join("rig.yaml")),
        "--target",
        p(&target),
        "--images",
        &left,
        "--images",
        &right,
        "--fps",
        "30",
        "--poses",
        p(&fused),
        "--twists",
        p(&fused_twists),
    ]);
    let count = read_tum(&fused).len();
    assert!(
        count > frames * 9 / 10,
        "{count} fused estimates of {frames} frames per camera"
    );
    let fused_m = eval_position_rmse_m(&sim, &fused, &fused_twists);
    let worse = left_m.max(right_m);
    let bound = rmse_bound_m(worse, count);
    eprintln!(
        "position RMSE: left alone {left_m:e} m, right alone {right_m:e} m (clock ignored: {right_unclocked_m:e} m), \
         fused {fused_m:e} m ({count} estimates), bound {bound:e} m"
    );
    assert!(
        fused_m <= bound,
        "fused position RMSE {fused_m:e} m > {bound:e} m (left alone {left_m:e} m, right alone {right_m:e} m)"
    );
}

/// A rig of frames written over a rig of measurements in the same folder, and back: each run leaves its own files
/// only.
#[test]
fn rig_runs_of_frames_and_of_measurements_replace_each_other() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("rig");
    let files = |dir: &Path| {
        let mut list: Vec<String> = walk(dir)
            .iter()
            .map(|p| p.strip_prefix(dir).unwrap().display().to_string())
            .collect();
        list.sort();
        list
    };
    let measurements = [
        "simulate",
        "--scenario",
        "sweep",
        "--duration-s",
        "0.2",
        "--rig-cameras",
        "2",
        "--out",
        p(&out),
    ];
    ok(&measurements);
    let of_measurements = files(&out);
    assert!(of_measurements.contains(&"cam1/measurements.csv".to_string()));
    ok(&[
        "simulate",
        "--frames",
        "--frame-count",
        "2",
        "--scenario",
        "sweep",
        "--duration-s",
        "0.2",
        "--rig-cameras",
        "2",
        "--out",
        p(&out),
    ]);
    let of_frames = files(&out);
    for name in ["cam0", "cam1"] {
        for file in [
            "README.txt",
            "camera.yaml",
            "frames/frame_00000.png",
            "frames/frame_00001.png",
            "target.csv",
            "timestamps.csv",
        ] {
            assert!(
                of_frames.contains(&format!("{name}/{file}")),
                "{of_frames:?}"
            );
        }
        assert!(!of_frames.contains(&format!("{name}/measurements.csv")));
    }
    ok(&measurements);
    assert_eq!(files(&out), of_measurements);
}

/// Every file under `dir`, recursively.
fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push(path);
        }
    }
    files
}

/// Each camera of a rig of frames timed by its own `--timestamps NAME=FILE` (the simulator's, on that camera's
/// clock): the same estimates, byte for byte, as with `--fps`; a timestamps file of an unknown camera, of a camera
/// given twice or of a camera whose input is not frames is refused naming the camera.
/// `simulate --frames` of a random rig of 2 cameras, 12 frames each, in `dir/sim`; returns that folder.
fn simulate_frame_rig(dir: &Path) -> std::path::PathBuf {
    let sim = dir.join("sim");
    ok(&[
        "simulate",
        "--frames",
        "--scenario",
        "sweep",
        "--rig-cameras",
        "2",
        "--frame-count",
        "12",
        "--out",
        p(&sim),
    ]);
    sim
}

#[test]
fn a_rig_of_frames_takes_each_cameras_timestamps() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = simulate_frame_rig(tmp.path());
    let file = |name: &str| p(&sim.join(name)).to_string();
    let (rig, target) = (file("rig.yaml"), file("target.csv"));
    let images = [
        format!("cam0={}", file("cam0/frames")),
        format!("cam1={}", file("cam1/frames")),
    ];
    let times = [
        format!("cam0={}", file("cam0/timestamps.csv")),
        format!("cam1={}", file("cam1/timestamps.csv")),
    ];
    let outputs = |stem: &str| {
        [
            tmp.path().join(format!("{stem}.tum")),
            tmp.path().join(format!("{stem}.csv")),
        ]
    };
    let args = |timing: &[&str], out: &[std::path::PathBuf; 2]| {
        let mut args = vec![
            "track".to_string(),
            "--rig".into(),
            rig.clone(),
            "--target".into(),
            target.clone(),
            "--images".into(),
            images[0].clone(),
            "--images".into(),
            images[1].clone(),
            "--polarity".into(),
            "bright".into(),
        ];
        args.extend(timing.iter().map(|s| s.to_string()));
        args.extend([
            "--poses".into(),
            p(&out[0]).into(),
            "--twists".into(),
            p(&out[1]).into(),
        ]);
        args
    };
    let (by_fps, by_files) = (outputs("fps"), outputs("files"));
    ok(&strs(&args(&["--fps", "30"], &by_fps)));
    ok(&strs(&args(
        &["--timestamps", &times[0], "--timestamps", &times[1]],
        &by_files,
    )));
    for (a, b) in by_fps.iter().zip(&by_files) {
        let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
        assert!(!a.is_empty());
        assert!(
            a == b,
            "the rig's output with --timestamps differs from --fps"
        );
    }
    let refused = |timing: &[&str]| fails(&strs(&args(timing, &outputs("bad"))));
    let unknown = refused(&["--timestamps", &times[0], "--timestamps", "left=t.csv"]);
    assert!(
        unknown.contains("no camera 'left'") && unknown.contains("cam0, cam1"),
        "{unknown}"
    );
    let twice = refused(&["--timestamps", &times[0], "--timestamps", &times[0]]);
    assert!(twice.contains("camera 'cam0' is given twice"), "{twice}");
    let unnamed = refused(&["--timestamps", &file("cam0/timestamps.csv")]);
    assert!(unnamed.contains("NAME=FILE"), "{unnamed}");
    let measurements = format!("cam1={}", file("cam1/measurements.csv"));
    let not_frames = fails(&[
        "track",
        "--rig",
        &rig,
        "--target",
        &target,
        "--images",
        &images[0],
        "--measurements",
        &measurements,
        "--timestamps",
        &times[1],
        "--poses",
        p(&tmp.path().join("bad.tum")),
        "--twists",
        p(&tmp.path().join("bad.csv")),
    ]);
    assert!(
        not_frames.contains("camera 'cam1' has no --images"),
        "{not_frames}"
    );
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

#[test]
fn a_rig_reads_each_cameras_frames_from_a_bag() {
    // Each camera's frames recorded to a bag of its own by `track --mcap` (on /roitrack/image, each frame at its
    // time, to the nanosecond), then tracked as a rig from the bags: the estimates of the same frames from files, to
    // what the nanosecond stamps change (a 0.5 ns time at a few m/s: under 1e-9 m).
    let tmp = tempfile::tempdir().unwrap();
    let sim = simulate_frame_rig(tmp.path());
    let file = |name: &str| p(&sim.join(name)).to_string();
    let (rig, target) = (file("rig.yaml"), file("target.csv"));
    let out = |stem: &str| {
        [
            p(&tmp.path().join(format!("{stem}.tum"))).to_string(),
            p(&tmp.path().join(format!("{stem}.csv"))).to_string(),
        ]
    };
    for name in ["cam0", "cam1"] {
        let [poses, twists] = out(name);
        ok(&[
            "track",
            "--camera",
            &file(&format!("{name}/camera.yaml")),
            "--target",
            &target,
            "--images",
            &file(&format!("{name}/frames")),
            "--timestamps",
            &file(&format!("{name}/timestamps.csv")),
            "--polarity",
            "bright",
            "--mcap",
            p(&tmp.path().join(format!("{name}.mcap"))),
            "--poses",
            &poses,
            "--twists",
            &twists,
        ]);
    }
    let rig_run = |inputs: &[String], stem: &str| {
        let [poses, twists] = out(stem);
        let mut args: Vec<String> = ["track", "--rig", &rig, "--target", &target]
            .iter()
            .map(|s| s.to_string())
            .collect();
        args.extend(inputs.iter().cloned());
        args.extend(
            [
                "--polarity",
                "bright",
                "--poses",
                &poses,
                "--twists",
                &twists,
            ]
            .map(String::from),
        );
        ok(&strs(&args));
        read_tum(Path::new(&poses))
    };
    let from_files = rig_run(
        &[
            "--images".into(),
            format!("cam0={}", file("cam0/frames")),
            "--timestamps".into(),
            format!("cam0={}", file("cam0/timestamps.csv")),
            "--images".into(),
            format!("cam1={}", file("cam1/frames")),
            "--timestamps".into(),
            format!("cam1={}", file("cam1/timestamps.csv")),
        ],
        "files",
    );
    let bag = |name: &str| format!("{name}={}", p(&tmp.path().join(format!("{name}.mcap"))));
    let from_bags = rig_run(
        &[
            "--images".into(),
            bag("cam0"),
            "--topic".into(),
            "cam0=/roitrack/image".into(),
            "--images".into(),
            bag("cam1"),
            "--topic".into(),
            "cam1=/roitrack/image".into(),
        ],
        "bags",
    );
    assert!(from_files.len() >= 12, "{}", from_files.len());
    assert_eq!(from_bags.len(), from_files.len());
    for ((t_bag, bag), (t_file, file)) in from_bags.iter().zip(&from_files) {
        assert!((t_bag - t_file).abs() < 1e-9, "{t_bag} against {t_file}");
        for (a, b) in bag.iter().zip(file) {
            assert!((a - b).abs() < 1e-9, "t {t_file}: {bag:?} against {file:?}");
        }
    }
}
