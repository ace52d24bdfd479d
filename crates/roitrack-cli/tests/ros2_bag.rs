//! `roitrack track --mcap`: the ROS 2 bags read back by two independent readers, Python's `rosbags` (its MCAP storage
//! reader and ROS 2 Humble type store) and `mcap` with `mcap-ros2-support`, through `crates/roitrack-ros/tests/
//! check_bag.py`: every pose equal to the TUM file's, twists to the twists CSV's, covariances symmetric, positive
//! semi-definite and those of the covariance CSV in ROS's order and each message's frame, stamps and frame ids right;
//! the bag of a run that fails midway readable up to its last estimate; the measured centroids of
//! `/roitrack/measurements` (roitrack's own message) those of the measurements CSV, replayed by `track --mcap-in BAG
//! --measurement-topic` to the same estimates (also from a bag `rosbags` wrote); the annotations of frames and of ROI
//! images (`--mcap-rois`); the camera info's distortion model the camera's own; a rig's bag of fused estimates.
//!
//! The readers live in the virtual environment that scripts/setup-test-deps makes (`target/ros-venv`, or
//! `ROITRACK_ROS_VENV`). Without it the tests say they were skipped, unless `ROITRACK_REQUIRE_ROS_PY` is set (as
//! `.ci/run` does), when its absence is a failure.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::{fails, ok};
#[path = "common/process.rs"]
mod process;
use process::{simulate, succeeded};
#[path = "common/outputs.rs"]
mod outputs;
#[path = "common/venv.rs"]
mod venv;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// The Python of the readers' virtual environment, or `None` (the test is then skipped) if it is not installed.
fn python() -> Option<PathBuf> {
    venv::python(&venv::Venv {
        dir_var: "ROITRACK_ROS_VENV",
        default_dir: "ros-venv",
        imports: "rosbags, mcap, mcap_ros2, numpy",
        what: "rosbags and mcap-ros2-support",
        require_var: "ROITRACK_REQUIRE_ROS_PY",
    })
}

/// A script of roitrack-ros' tests (run by the readers' Python).
fn ros_script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../roitrack-ros/tests/{name}"))
}

/// `check_bag.py BAG POSES TWISTS COVARIANCE FRAME CHILD_FRAME EXTRA...` (COVARIANCE `-`: none).
fn run_check_bag(python: &Path, files: [&Path; 4], frame_ids: [&str; 2], extra: &[&str]) -> Output {
    Command::new(python)
        .arg(ros_script("check_bag.py"))
        .args(files)
        .args(frame_ids)
        .args(extra)
        .output()
        .unwrap()
}

/// check_bag.py on `dir`'s run.mcap against its poses.tum, twists.csv and covariance.csv; its report.
fn check_bag(python: &Path, dir: &Path, frame_ids: [&str; 2], extra: &[&str]) -> String {
    let files = ["run.mcap", "poses.tum", "twists.csv", "covariance.csv"].map(|f| dir.join(f));
    succeeded(run_check_bag(
        python,
        files.each_ref().map(PathBuf::as_path),
        frame_ids,
        extra,
    ))
}

/// Asserts that a bag's error names the bag, the topic and `reason`.
fn assert_names_bag_and_topic(error: &str, bag: &Path, topic: &str, reason: &str) {
    assert!(
        error.contains(p(bag)) && error.contains(topic) && error.contains(reason),
        "{error}"
    );
}

fn line_count(path: &Path) -> usize {
    std::fs::read_to_string(path).unwrap().lines().count()
}

/// The bag of a run of `dir`'s simulation that stopped early (`stopped`/run.partial.mcap), checked by check_bag.py against
/// a whole run of the measurements it got (`lines`, the header first) tracked into `dir`: the number of estimates in
/// the bag, and in the whole run.
fn stopped_bag_estimates(
    python: &Path,
    dir: &Path,
    lines: &[&str],
    stopped: &Path,
) -> (usize, usize) {
    let measurements = dir.join("measurements_read.csv");
    std::fs::write(&measurements, lines.join("\n") + "\n").unwrap();
    ok(&strs(&track_args(dir, &measurements, dir)));
    // The stopped run changed no output: its bag up to the last estimate is kept under its own name.
    assert!(!stopped.join("run.mcap").exists());
    std::fs::rename(stopped.join("run.partial.mcap"), dir.join("run.mcap")).unwrap();
    let report = check_bag(python, dir, ["camera", "target"], &["--prefix"]);
    // The number after the bag's name in the report.
    let estimates = report
        .split_whitespace()
        .skip_while(|w| !w.ends_with(".mcap:"))
        .nth(1)
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{report}"));
    (estimates, line_count(&dir.join("poses.tum")))
}

/// `track` of `dir`'s camera and target over `measurements`, every output (the bag too) into `out`.
fn track_args(dir: &Path, measurements: &Path, out: &Path) -> Vec<String> {
    outputs::track_into(
        &dir.join("camera.yaml"),
        &dir.join("target.csv"),
        measurements,
        out,
    )
}

fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

#[test]
fn a_bag_from_measurements_reads_back_equal_to_the_tum_and_csv_files() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    simulate(dir, &["--scenario", "random", "--seed", "2"]);
    let mut args = track_args(dir, &dir.join("measurements.csv"), dir);
    args.extend(["--frame-id", "cam0", "--child-frame-id", "tool"].map(String::from));
    ok(&strs(&args));
    let csv = dir.join("measurements.csv");
    let report = check_bag(&python, dir, ["cam0", "tool"], &["--measurements", p(&csv)]);
    assert!(
        report.contains("read back by mcap and rosbags") && report.contains("equal to the CSV's"),
        "{report}"
    );
    // A checker that cannot fail would prove nothing: a bag held against another run's files is refused.
    let other = dir.join("other");
    simulate(&other, &["--scenario", "random", "--seed", "3"]);
    ok(&strs(&track_args(
        &other,
        &other.join("measurements.csv"),
        &other,
    )));
    std::fs::copy(dir.join("run.mcap"), other.join("run.mcap")).unwrap();
    let files = ["run.mcap", "poses.tum", "twists.csv", "covariance.csv"].map(|f| other.join(f));
    let refused = run_check_bag(
        &python,
        files.each_ref().map(PathBuf::as_path),
        ["cam0", "tool"],
        &[],
    );
    assert!(!refused.status.success());
}

#[test]
fn a_bag_from_frames_holds_the_images_and_their_annotations() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sim = dir.join("sim");
    simulate(
        &sim,
        &["--frames", "--scenario", "sweep", "--frame-count", "8"],
    );
    ok(&[
        "track",
        "--camera",
        p(&sim.join("camera.yaml")),
        "--target",
        p(&sim.join("target.csv")),
        "--images",
        p(&sim.join("frames")),
        "--timestamps",
        p(&sim.join("timestamps.csv")),
        "--polarity",
        "bright",
        "--poses",
        p(&dir.join("poses.tum")),
        "--twists",
        p(&dir.join("twists.csv")),
        "--covariance",
        p(&dir.join("covariance.csv")),
        "--mcap",
        p(&dir.join("run.mcap")),
    ]);
    assert_eq!(line_count(&dir.join("poses.tum")), 8);
    check_bag(&python, dir, ["camera", "target"], &["--images", "8"]);
}

#[test]
fn the_bag_of_a_run_that_fails_midway_is_readable_up_to_its_last_estimate() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    simulate(dir, &["--scenario", "orthoglide"]);
    // A bad field two thirds of the way through: the run fails there.
    let text = std::fs::read_to_string(dir.join("measurements.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let cut = 2 * lines.len() / 3;
    let mut broken = lines[..cut].join("\n");
    broken.push_str("\n1e9,abc,1,2\n");
    std::fs::write(dir.join("broken.csv"), broken).unwrap();
    let failed = dir.join("failed");
    std::fs::create_dir(&failed).unwrap();
    let error = fails(&strs(&track_args(dir, &dir.join("broken.csv"), &failed)));
    assert!(error.contains("broken.csv"), "{error}");
    assert!(!failed.join("poses.tum").exists());
    // The same measurements up to the bad line, tracked to the end: the failed run's bag holds their first estimates.
    let (estimates, tracked) = stopped_bag_estimates(&python, dir, &lines[..cut], &failed);
    // 4 kHz measurements, an estimate every 10: all but the last few before the bad line.
    assert!(
        estimates + 2 >= tracked && estimates <= tracked,
        "{estimates} of {tracked}"
    );
}

#[test]
fn bag_options_are_refused_with_a_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    simulate(dir, &["--scenario", "static"]);
    let mut args = track_args(dir, &dir.join("measurements.csv"), dir);
    args.extend(["--frame-id", ""].map(String::from));
    let error = fails(&strs(&args));
    assert!(
        error.contains("run.mcap") && error.contains("frame_id"),
        "{error}"
    );
    let mut args = track_args(dir, &dir.join("measurements.csv"), dir);
    let missing = dir.join("no/such/folder/run.mcap");
    *args.last_mut().unwrap() = p(&missing).to_string();
    let error = fails(&strs(&args));
    assert!(error.contains("no/such/folder/run.mcap"), "{error}");
    // Options that would otherwise be ignored.
    let mut args = track_args(dir, &dir.join("measurements.csv"), dir);
    args.extend(["--image-topic", "/cam/image_raw"].map(String::from));
    assert!(fails(&strs(&args)).contains("--image-topic is for the frames of a bag"));
    let mut args = track_args(dir, &dir.join("measurements.csv"), dir);
    args.truncate(args.len() - 2);
    args.extend(["--child-frame-id", "tool"].map(String::from));
    assert!(fails(&strs(&args)).contains("--mcap"));
}

/// Simulated frames (`roitrack simulate --frames`), each also as raw 8-bit pixels beside its PNG for the bag writer.
fn simulate_frames(dir: &Path, count: usize) -> PathBuf {
    let sim = dir.join("sim");
    simulate(
        &sim,
        &[
            "--frames",
            "--scenario",
            "sweep",
            "--frame-count",
            &count.to_string(),
        ],
    );
    let frames = sim.join("frames");
    // Frame times on whole nanoseconds, written as a bag's stamp reads back (sec + 1e-9 nanosec), so that the files
    // and the bag give the tracker the very same times.
    let text = std::fs::read_to_string(sim.join("timestamps.csv")).unwrap();
    let mut times = String::from("t,file\n");
    for line in text.lines().skip(1) {
        let (t, file) = line.split_once(',').unwrap();
        let ns = (t.parse::<f64>().unwrap() * 1e9).round() as u64;
        let t = (ns / 1_000_000_000) as f64 + 1e-9 * (ns % 1_000_000_000) as f64;
        times.push_str(&format!("{t},{file}\n"));
    }
    std::fs::write(sim.join("timestamps.csv"), &times).unwrap();
    std::fs::write(frames.join("timestamps.csv"), &times).unwrap();
    for entry in std::fs::read_dir(&frames).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|x| x == "png") {
            let frame = roitrack::formats::read_frame(&path).unwrap();
            assert_eq!(frame.bit_depth, 8);
            let raw: Vec<u8> = frame.pixels.iter().map(|&v| v as u8).collect();
            std::fs::write(path.with_extension("raw"), raw).unwrap();
        }
    }
    sim
}

/// Writes the frames as a rosbag2 folder with Python's rosbags (`write_image_bag.py`).
fn write_bag(python: &Path, sim: &Path, bag: &Path, encoding: &str, info_size: Option<(u32, u32)>) {
    let camera = roitrack::formats::read_camera_yaml(sim.join("camera.yaml")).unwrap();
    let i = camera.intrinsics;
    let d = camera.distortion.coefficients();
    let mut args: Vec<String> = vec![
        p(bag).into(),
        p(&sim.join("frames")).into(),
        encoding.into(),
        camera.width_px.to_string(),
        camera.height_px.to_string(),
    ];
    args.extend([i.fx_px, i.fy_px, i.cx_px, i.cy_px, i.skew_px].map(|x| x.to_string()));
    args.extend(d.iter().map(|x| x.to_string()));
    if let Some((w, h)) = info_size {
        args.extend([w.to_string(), h.to_string()]);
    }
    succeeded(
        Command::new(python)
            .arg(ros_script("write_image_bag.py"))
            .args(&args)
            .output()
            .unwrap(),
    );
}

fn read_poses(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect()
}

#[test]
fn a_bag_written_by_rosbags_tracks_like_the_same_frames_from_files() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sim = simulate_frames(dir, 10);
    let common = |poses: &str| -> Vec<String> {
        [
            "track",
            "--target",
            p(&sim.join("target.csv")),
            "--polarity",
            "bright",
            "--poses",
            p(&dir.join(poses)),
            "--twists",
            p(&dir.join(format!("{poses}.twists.csv"))),
        ]
        .map(String::from)
        .to_vec()
    };
    let mut files = common("files.tum");
    files.extend(
        [
            "--camera",
            p(&sim.join("camera.yaml")),
            "--images",
            p(&sim.join("frames")),
            "--timestamps",
            p(&sim.join("timestamps.csv")),
        ]
        .map(String::from),
    );
    ok(&strs(&files));
    let expected = read_poses(&dir.join("files.tum"));
    assert_eq!(expected.len(), 10);
    for (encoding, topic, with_camera) in [
        ("mono8", "/cam/image_raw", false),
        ("rgb8", "/cam/image_raw", true),
        ("bgr8", "/cam/image_raw", false),
        ("png", "/cam/image_raw/compressed", false),
    ] {
        let bag = dir.join(format!("bag_{encoding}"));
        write_bag(&python, &sim, &bag, encoding, None);
        let poses = format!("{encoding}.tum");
        let mut args = common(&poses);
        args.extend(["--mcap-in", p(&bag), "--image-topic", topic].map(String::from));
        if with_camera {
            args.extend(["--camera", p(&sim.join("camera.yaml"))].map(String::from));
        } else if encoding == "png" {
            args.extend(["--camera-info-topic", "/cam/camera_info"].map(String::from));
        }
        ok(&strs(&args));
        let got = read_poses(&dir.join(&poses));
        assert_eq!(got.len(), expected.len(), "{encoding}");
        for (g, e) in got.iter().zip(&expected) {
            // The same frames at the same times: the same estimates, to the last bit.
            assert_eq!(g, e, "{encoding}");
        }
    }
}

#[test]
fn bad_bags_are_refused_naming_the_bag_and_the_topic() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sim = simulate_frames(dir, 3);
    let (target, poses, twists) = (
        sim.join("target.csv"),
        dir.join("poses.tum"),
        dir.join("twists.csv"),
    );
    let track = |bag: &Path, topic: &str, extra: &[&str]| {
        let mut args = vec![
            "track",
            "--target",
            p(&target),
            "--poses",
            p(&poses),
            "--twists",
            p(&twists),
            "--mcap-in",
            p(bag),
            "--image-topic",
            topic,
        ];
        args.extend(extra);
        fails(&args)
    };
    let bag = dir.join("bag");
    write_bag(&python, &sim, &bag, "mono8", None);
    let error = track(&bag, "/cam/nothing", &[]);
    assert_names_bag_and_topic(&error, &bag, "/cam/nothing", "no such topic");
    assert!(
        error.contains("/cam/image_raw (sensor_msgs/msg/Image)"),
        "{error}"
    );
    let error = track(&bag, "/cam/camera_info", &[]);
    assert!(error.contains("not sensor_msgs/msg/Image"), "{error}");
    // A camera info that disagrees with the images.
    let wrong = dir.join("wrong_info");
    write_bag(&python, &sim, &wrong, "mono8", Some((640, 480)));
    let error = track(&wrong, "/cam/image_raw", &[]);
    assert_names_bag_and_topic(&error, &wrong, "/cam/image_raw", "640 x 480");
    // A truncated bag.
    let mcap = std::fs::read_dir(&bag)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let bytes = std::fs::read(&mcap).unwrap();
    std::fs::write(&mcap, &bytes[..bytes.len() / 2]).unwrap();
    let error = track(
        &bag,
        "/cam/image_raw",
        &["--camera", p(&sim.join("camera.yaml"))],
    );
    assert_names_bag_and_topic(&error, &bag, "/cam/image_raw", "truncated");
    // Without a camera and not a bag: --camera is required.
    let error = fails(&[
        "track",
        "--target",
        p(&sim.join("target.csv")),
        "--images",
        p(&sim.join("frames")),
        "--timestamps",
        p(&sim.join("timestamps.csv")),
        "--poses",
        p(&dir.join("poses.tum")),
        "--twists",
        p(&dir.join("twists.csv")),
    ]);
    assert!(error.contains("--camera is required"), "{error}");
}

/// Ctrl-C while tracking: the run stops at its next estimate through the error path, so the bag is completed (its
/// summary written), kept as run.partial.mcap, and reads back with the estimates before the interruption.
#[cfg(unix)]
#[test]
fn ctrl_c_completes_the_bag() {
    use std::io::Write;
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    simulate(dir, &["--scenario", "orthoglide"]);
    let text = std::fs::read_to_string(dir.join("measurements.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let cut = lines.len() / 2;
    let interrupted = dir.join("interrupted");
    std::fs::create_dir(&interrupted).unwrap();
    let mut args = track_args(dir, Path::new("-"), &interrupted);
    args.remove(0);
    let mut child = process::roitrack_command()
        .arg("track")
        .args(&args)
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    // The first half: write_all returns once the pipe holds the last 64 KiB at most; then time to track those.
    stdin
        .write_all((lines[..cut].join("\n") + "\n").as_bytes())
        .unwrap();
    stdin.flush().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    process::interrupt(&child);
    // The rest: the next estimate finds the interruption.
    let _ = stdin.write_all((lines[cut..].join("\n") + "\n").as_bytes());
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("interrupted (Ctrl-C)"), "{stderr}");
    assert!(!interrupted.join("poses.tum").exists());
    let (estimates, tracked) = stopped_bag_estimates(&python, dir, &lines[..cut], &interrupted);
    assert!(
        estimates * 2 >= tracked && estimates <= tracked,
        "{estimates} of {tracked}"
    );
}

fn max_difference(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(x, y)| (x - y).abs()))
        .fold(0.0, f64::max)
}

/// `track --mcap-in BAG --measurement-topic TOPIC` with the target of `dir` (the camera from the bag unless given):
/// the poses of the replay.
fn replay(
    dir: &Path,
    bag: &Path,
    topic: &str,
    camera: Option<&Path>,
    poses: &str,
) -> Vec<Vec<f64>> {
    let target = dir.join("target.csv");
    let mut args = vec![
        "track",
        "--target",
        p(&target),
        "--mcap-in",
        p(bag),
        "--measurement-topic",
        topic,
    ];
    if let Some(camera) = camera {
        args.extend(["--camera", p(camera)]);
    }
    let (tum, twists) = (dir.join(poses), dir.join(format!("{poses}.twists.csv")));
    args.extend(["--poses", p(&tum), "--twists", p(&twists)]);
    ok(&args);
    read_poses(&tum)
}

#[test]
fn recorded_measurements_replay_from_a_bag_to_the_estimates_of_the_csv() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    simulate(dir, &["--scenario", "orthoglide", "--duration-s", "1.5"]);
    ok(&strs(&track_args(dir, &dir.join("measurements.csv"), dir)));
    let expected = read_poses(&dir.join("poses.tum"));
    assert!(expected.len() > 500);
    // roitrack's own bag, the camera from its camera info.
    let got = replay(
        dir,
        &dir.join("run.mcap"),
        "/roitrack/measurements",
        None,
        "own.tum",
    );
    let difference = max_difference(&got, &expected);
    assert!(difference <= 1e-9, "{difference}");
    // A bag written by rosbags from the message's documented definition, 7 centroids a message (not roitrack's
    // batches), with sigmas.
    let script = ros_script("write_measurement_bag.py");
    let write = |bag: &Path, damage: Option<&str>| {
        let mut command = Command::new(&python);
        command
            .arg(&script)
            .args([p(bag), p(&dir.join("measurements.csv")), "/cam/blobs", "7"]);
        command.args(damage);
        succeeded(command.output().unwrap());
    };
    let theirs = dir.join("theirs");
    write(&theirs, None);
    let camera = dir.join("camera.yaml");
    let got = replay(dir, &theirs, "/cam/blobs", Some(&camera), "theirs.tum");
    let difference = max_difference(&got, &expected);
    assert!(difference <= 1e-9, "{difference}");

    // Bad input: each error names the bag, the topic and, for a bad message, its index and field.
    let track = |bag: &Path, topic: &str| {
        fails(&[
            "track",
            "--camera",
            p(&camera),
            "--target",
            p(&dir.join("target.csv")),
            "--mcap-in",
            p(bag),
            "--measurement-topic",
            topic,
            "--poses",
            p(&dir.join("bad.tum")),
            "--twists",
            p(&dir.join("bad.csv")),
        ])
    };
    let run = dir.join("run.mcap");
    let error = track(&run, "/roitrack/blobs");
    assert_names_bag_and_topic(&error, &run, "/roitrack/blobs", "no such topic");
    assert!(
        error.contains("/roitrack/measurements (roitrack_msgs/msg/BlobMeasurements)"),
        "{error}"
    );
    let error = track(&run, "/roitrack/pose");
    assert!(
        error.contains("/roitrack/pose")
            && error.contains("not roitrack_msgs/msg/BlobMeasurements"),
        "{error}"
    );
    for (damage, expected) in [
        (
            "unknown-id",
            "message 2, field point_ids[1]: unknown point id 9999",
        ),
        (
            "short-u",
            "message 2, field u_px: 6 entries for 7 point ids",
        ),
    ] {
        let bag = dir.join(damage);
        write(&bag, Some(damage));
        let error = track(&bag, "/cam/blobs");
        assert_names_bag_and_topic(&error, &bag, "/cam/blobs", expected);
    }
    let bytes = std::fs::read(&run).unwrap();
    let truncated = dir.join("truncated.mcap");
    std::fs::write(&truncated, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let error = track(&truncated, "/roitrack/measurements");
    assert_names_bag_and_topic(&error, &truncated, "/roitrack/measurements", "truncated");
    // Options that do not go with a replay.
    let (target, csv) = (dir.join("target.csv"), dir.join("measurements.csv"));
    let (bad_tum, bad_csv) = (dir.join("bad.tum"), dir.join("bad.csv"));
    let mut args = vec![
        "track",
        "--target",
        p(&target),
        "--measurement-topic",
        "/roitrack/measurements",
        "--measurements",
        p(&csv),
        "--camera",
        p(&camera),
        "--poses",
        p(&bad_tum),
        "--twists",
        p(&bad_csv),
    ];
    let error = fails(&args);
    assert!(
        error.contains("--measurement-topic is for the measurements of a ROS 2 bag"),
        "{error}"
    );
    args.truncate(5);
    args.extend(["--mcap-in", p(&run), "--image-topic", "/roitrack/image"]);
    assert!(fails(&args).contains("cannot be used with"));
}

#[test]
fn roi_images_go_to_the_bag_with_their_place_and_centroid() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Reflections: some ROIs' blobs are rejected (not centrally symmetric), and annotated so.
    simulate(
        dir,
        &[
            "--scenario",
            "orthoglide",
            "--duration-s",
            "0.5",
            "--rois",
            "--reflections",
            "0.1",
        ],
    );
    let mut args = track_args(dir, &dir.join("measurements.csv"), dir);
    let at = args.iter().position(|a| a == "--measurements").unwrap();
    args[at] = "--rois".into();
    args[at + 1] = p(&dir.join("rois.bin")).into();
    let mut with_rois = args.clone();
    with_rois.push("--mcap-rois".into());
    ok(&strs(&with_rois));
    let rois = line_count(&dir.join("measurements.csv")) - 1;
    let report = check_bag(
        &python,
        dir,
        ["camera", "target"],
        &["--rois", &rois.to_string()],
    );
    let centroids: usize = report
        .split("ROI images, ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{report}"));
    assert!(
        centroids > rois / 2 && centroids < rois,
        "{centroids} of {rois}: {report}"
    );
    // Without --mcap-rois: the measurements, not the images.
    ok(&strs(&args));
    check_bag(&python, dir, ["camera", "target"], &[]);
    // --mcap-rois where there are no ROIs is refused, not ignored.
    let mut measurements = track_args(dir, &dir.join("measurements.csv"), dir);
    measurements.push("--mcap-rois".into());
    assert!(
        fails(&strs(&measurements)).contains("--mcap-rois is for the ROI images of `track --rois`")
    );
}

#[test]
fn the_camera_info_names_a_fisheye_cameras_own_model() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let camera = dir.join("fisheye.yaml");
    std::fs::write(
        &camera,
        "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 1024\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   \
         cols: 3\n   dt: d\n   data: [ 900., 0., 639.5, 0., 900., 511.5, 0., 0., 1. ]\n\
         distortion_model: equidistant\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 4\n   \
         dt: d\n   data: [ 0.05, -0.01, 0.002, 0. ]\n",
    )
    .unwrap();
    let sim = dir.join("sim");
    simulate(
        &sim,
        &[
            "--scenario",
            "orthoglide",
            "--camera",
            p(&camera),
            "--distance-m",
            "0.9",
            "--duration-s",
            "1",
        ],
    );
    ok(&strs(&track_args(&sim, &sim.join("measurements.csv"), dir)));
    check_bag(
        &python,
        dir,
        ["camera", "target"],
        &["--distortion", "equidistant:4"],
    );
    // The replay takes the camera from the bag, fisheye and all: the same estimates.
    let expected = read_poses(&dir.join("poses.tum"));
    std::fs::copy(sim.join("target.csv"), dir.join("target.csv")).unwrap();
    let got = replay(
        dir,
        &dir.join("run.mcap"),
        "/roitrack/measurements",
        None,
        "replay.tum",
    );
    assert!(max_difference(&got, &expected) <= 1e-9);
}

#[test]
fn demo_writes_the_centroids_and_rois_its_loop_measured() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("out");
    let bag = dir.join("run.mcap");
    ok(&[
        "demo",
        "--scenario",
        "static",
        "--out",
        p(&out),
        "--mcap",
        p(&bag),
        "--mcap-rois",
    ]);
    let target = roitrack::formats::read_target_csv(out.join("target.csv")).unwrap();
    let ids: Vec<u32> = target.points().iter().map(|p| p.id).collect();
    let measured: Vec<roitrack::Measurement> =
        roitrack::ros::BagMeasurementSource::open(&bag, "/roitrack/measurements")
            .unwrap()
            .with_known_ids(ids)
            .collect::<Result<_, _>>()
            .unwrap();
    // The loop's 4,000 ROI slots, less the full frame's and the ROIs whose blob was rejected.
    assert!(
        measured.len() > 3900 && measured.len() < 4000,
        "{}",
        measured.len()
    );
    let poses = read_poses(&out.join("kalman_poses.tum"));
    assert!(measured.last().unwrap().t_s >= poses.last().unwrap()[0]);
    // The ROI images, read by roitrack's own frame reader (they are sensor_msgs/msg/Image), then by check_bag.
    let mut rois = roitrack::ros::BagFrameSource::open(&bag, "/roitrack/roi/image").unwrap();
    let mut frame = roitrack::Frame::default();
    let mut count = 0;
    while let Some(info) = rois.next_frame(&mut frame) {
        info.unwrap();
        count += 1;
    }
    assert!(count >= measured.len(), "{count} ROI images");
    for file in ["kalman_poses.tum", "kalman_twists.csv"] {
        std::fs::copy(out.join(file), dir.join(file)).unwrap();
    }
    let report = succeeded(run_check_bag(
        &python,
        [
            &bag,
            &dir.join("kalman_poses.tum"),
            &dir.join("kalman_twists.csv"),
            Path::new("-"),
        ],
        ["camera", "target"],
        &["--rois", &count.to_string()],
    ));
    assert!(
        report.contains(&format!(
            "{count} ROI images, {} with their centroid",
            measured.len()
        )),
        "{report}"
    );
    // --mcap-rois is refused where the ROIs are not at hand (live, or track from measurements).
    let mut args = track_args(&out, &out.join("measurements.csv"), dir);
    args.push("--mcap-rois".into());
    assert!(
        fails(&strs(&args))
            .contains("--mcap-rois is for the ROI images of `track --rois` and `demo`")
    );
}

/// `track --rig` with each camera's recorded centroids on a topic of one bag (written by `rosbags`, the two cameras'
/// messages interleaved in time): the same estimates, byte for byte, as the same centroids from measurement files;
/// a bag without its topic, a topic of a file that is not a bag, a topic of a camera with no input and a topic the
/// bag does not have are refused naming the camera.
#[test]
fn a_rig_reads_each_cameras_topic_of_one_bag() {
    let Some(python) = python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    simulate(
        dir,
        &[
            "--scenario",
            "sweep",
            "--duration-s",
            "0.5",
            "--rig-cameras",
            "2",
        ],
    );
    // A bag's times are not negative, a camera's own clock may be: every camera's times 1 s later (the second
    // camera's clock is learnt, so a shift common to all is no change to the run).
    for name in ["cam0", "cam1"] {
        let text = std::fs::read_to_string(dir.join(name).join("measurements.csv")).unwrap();
        let mut shifted = String::from("t,id,u,v\n");
        for line in text.lines().skip(1) {
            let (t, rest) = line.split_once(',').unwrap();
            shifted += &format!("{:?},{rest}\n", t.parse::<f64>().unwrap() + 1.0);
        }
        std::fs::write(dir.join(format!("{name}.csv")), shifted).unwrap();
    }
    let bag = dir.join("rig_bag");
    let csvs = format!("{},{}", p(&dir.join("cam0.csv")), p(&dir.join("cam1.csv")));
    succeeded(
        Command::new(&python)
            .arg(ros_script("write_measurement_bag.py"))
            .args([p(&bag), &csvs, "/left/blobs,/right/blobs", "7"])
            .output()
            .unwrap(),
    );
    let (rig, target) = (dir.join("rig.yaml"), dir.join("target.csv"));
    let track = |inputs: &[&str], out: &str| -> Vec<String> {
        let outputs = [
            dir.join(format!("{out}.tum")),
            dir.join(format!("{out}.csv")),
        ];
        let mut args = vec!["track", "--rig", p(&rig), "--target", p(&target)];
        args.extend_from_slice(inputs);
        args.extend(["--poses", p(&outputs[0]), "--twists", p(&outputs[1])]);
        ok(&args);
        outputs
            .iter()
            .map(|f| std::fs::read_to_string(f).unwrap())
            .collect()
    };
    let (cam0_csv, cam1_csv) = (
        format!("cam0={}", p(&dir.join("cam0.csv"))),
        format!("cam1={}", p(&dir.join("cam1.csv"))),
    );
    let from_files = track(
        &["--measurements", &cam0_csv, "--measurements", &cam1_csv],
        "files",
    );
    let (cam0_bag, cam1_bag) = (format!("cam0={}", p(&bag)), format!("cam1={}", p(&bag)));
    let from_bag = track(
        &[
            "--measurements",
            &cam0_bag,
            "--topic",
            "cam0=/left/blobs",
            "--measurements",
            &cam1_bag,
            "--topic",
            "cam1=/right/blobs",
        ],
        "bag",
    );
    assert!(from_files[0].lines().count() > 100, "{}", from_files[0]);
    assert_eq!(from_bag, from_files);
    // A camera's bag and a camera's file mixed in one run, too.
    let mixed = track(
        &[
            "--measurements",
            &cam0_csv,
            "--measurements",
            &cam1_bag,
            "--topic",
            "cam1=/right/blobs",
        ],
        "mixed",
    );
    assert_eq!(mixed, from_files);

    // Bad input, each error naming the camera.
    let refused = |inputs: &[&str]| {
        let mut args = vec!["track", "--rig", p(&rig), "--target", p(&target)];
        args.extend_from_slice(inputs);
        let (poses, twists) = (dir.join("bad.tum"), dir.join("bad.csv"));
        args.extend(["--poses", p(&poses), "--twists", p(&twists)]);
        fails(&args)
    };
    let error = refused(&["--measurements", &cam0_bag, "--measurements", &cam1_csv]);
    assert!(
        error.contains("camera 'cam0'") && error.contains("--topic cam0=TOPIC"),
        "{error}"
    );
    let error = refused(&[
        "--measurements",
        &cam0_csv,
        "--topic",
        "cam0=/left/blobs",
        "--measurements",
        &cam1_csv,
    ]);
    assert!(
        error.contains("cam0") && error.contains("is not a ROS 2 bag"),
        "{error}"
    );
    let error = refused(&["--measurements", &cam0_csv, "--topic", "cam1=/right/blobs"]);
    assert!(error.contains("camera 'cam1' has no input"), "{error}");
    let error = refused(&[
        "--measurements",
        &cam0_bag,
        "--topic",
        "cam0=/left/blob",
        "--measurements",
        &cam1_csv,
    ]);
    assert!(
        error.contains("camera 'cam0'") && error.contains("/left/blob"),
        "{error}"
    );
}

/// A rig's fused estimates go to the bag in the rig's frame (`--frame-id` defaulting to `rig`), read back by both
/// readers equal to the files; a rig's bag holds no camera info and no centroids (they belong to each camera).
#[test]
fn a_rigs_bag_holds_its_fused_estimates_in_the_rig_frame() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    common::simulate_random_rig(&sim, "2", "1", &[]);
    let file = |name: &str| dir.path().join(name);
    let (poses, twists, covariance, bag) = (
        file("poses.tum"),
        file("twists.csv"),
        file("covariance.csv"),
        file("run.mcap"),
    );
    let rig_run =
        |extra: &[&str]| common::track_simulated_rig_args(&sim, 2, &poses, &twists, extra);
    let args = rig_run(&["--covariance", p(&covariance), "--mcap", p(&bag)]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(line_count(&poses) > 100);
    let report = check_bag(&python, dir.path(), ["rig", "target"], &["--rig"]);
    assert!(
        report.contains("no camera info, no measurements"),
        "{report}"
    );
    // Read as a single camera's bag, it lacks the camera's topics: the check can fail.
    let single = run_check_bag(
        &python,
        [&bag, &poses, &twists, &covariance],
        ["rig", "target"],
        &[],
    );
    assert!(!single.status.success());
    // --mcap-rois has no ROI images to write in a rig's run.
    let args = rig_run(&["--mcap", p(&bag), "--mcap-rois"]);
    let error = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(error.contains("--mcap-rois"), "{error}");
}
