//! `roitrack track --images` end to end: simulated frame sequences (global and rolling shutter) written as PNG files
//! with a timestamps file, tracked from a folder, a pattern and a glob, scored against the truth; and the inputs that
//! must be refused, each named, with the estimates before an error kept.

use std::path::Path;

use roitrack::core::time::Readout;
use roitrack::formats::{read_tum, write_camera_yaml, write_frame_png, write_target_csv};
use roitrack::image::{Frame, Polarity};
use roitrack::sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};

mod common;
use common::{fails, ok, roitrack};

#[path = "common/covariance_file.rs"]
mod covariance_file;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Writes `count` frames of the sweep as `frames/frame_%05d.png`, `timestamps.csv`, `camera.yaml`, `target.csv`;
/// returns the sequence.
fn write_sequence(dir: &Path, readout: Readout, count: usize) -> FrameSequence {
    let scenario = Scenario::new(ScenarioKind::Sweep, 4);
    let options = FrameOptions {
        readout,
        polarity: Polarity::Bright,
        frame_count: Some(count),
        ..FrameOptions::default()
    };
    let mut frames = FrameSequence::new(&scenario, &options).unwrap();
    std::fs::create_dir_all(dir.join("frames")).unwrap();
    let mut times = String::from("t,file\n");
    let mut frame = Frame::default();
    for k in 0..count {
        frames.render(k, &mut frame);
        let name = format!("frame_{k:05}.png");
        write_frame_png(dir.join("frames").join(&name), &frame).unwrap();
        times.push_str(&format!("{},{name}\n", frame.t_s));
    }
    std::fs::write(dir.join("timestamps.csv"), times).unwrap();
    write_camera_yaml(dir.join("camera.yaml"), frames.camera()).unwrap();
    write_target_csv(dir.join("target.csv"), &scenario.target).unwrap();
    frames
}

fn track_args<'a>(dir: &'a Path, source: &'a str, out: &'a Path) -> Vec<String> {
    [
        "track",
        "--camera",
        p(&dir.join("camera.yaml")),
        "--target",
        p(&dir.join("target.csv")),
        "--images",
        source,
        "--poses",
        p(&out.join("poses.tum")),
        "--twists",
        p(&out.join("twists.csv")),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn run_ok(args: &[String]) -> String {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(&refs);
    String::from_utf8(roitrack(&refs).stderr).unwrap()
}

fn run_fails(args: &[String]) -> String {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    fails(&refs)
}

/// RMS position error (m) of the poses written, against the sequence's truth at each estimate's time.
fn position_rmse_m(frames: &FrameSequence, poses: &Path) -> (usize, f64) {
    let poses = read_tum(poses).unwrap();
    let sum: f64 = poses
        .iter()
        .map(|s| {
            (s.cam_from_obj.translation.vector - frames.state_at(s.t_s).cam_t_obj_m).norm_squared()
        })
        .sum();
    (poses.len(), (sum / poses.len() as f64).sqrt())
}

#[test]
fn frames_from_a_folder_a_pattern_and_a_glob_give_an_estimate_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let frames = write_sequence(dir.path(), Readout::GlobalShutter, 12);
    let timestamps = dir.path().join("timestamps.csv");
    for source in [
        dir.path().join("frames"),
        dir.path().join("frames/frame_%05d.png"),
        dir.path().join("frames/frame_*.png"),
    ] {
        let out = tempfile::tempdir().unwrap();
        let mut args = track_args(dir.path(), p(&source), out.path());
        args.extend(["--timestamps".into(), p(&timestamps).into()]);
        let stderr = run_ok(&args);
        let (count, rmse) = position_rmse_m(&frames, &out.path().join("poses.tum"));
        assert_eq!(count, 12, "{stderr}");
        assert!(rmse < 0.5e-3, "{} mm: {stderr}", rmse * 1e3);
    }
    // --fps instead of a timestamps file (the sequence is at 30 Hz from t = 0), with the diagnostics and the
    // covariance: one covariance row per pose, its diagonal the diagnostics' sigmas squared.
    let out = tempfile::tempdir().unwrap();
    let mut args = track_args(dir.path(), p(&dir.path().join("frames")), out.path());
    let (diagnostics, covariance) = (
        out.path().join("diagnostics.csv"),
        out.path().join("covariance.csv"),
    );
    args.extend(["--fps".into(), "30".into()]);
    args.extend(["--diagnostics".into(), p(&diagnostics).into()]);
    args.extend(["--covariance".into(), p(&covariance).into()]);
    run_ok(&args);
    let poses = out.path().join("poses.tum");
    assert_eq!(position_rmse_m(&frames, &poses).0, 12);
    let rows =
        covariance_file::check_against_poses_and_diagnostics(&poses, &diagnostics, &covariance);
    assert!(rows.iter().all(|(_, c)| c.iter().all(|x| x.is_finite())));
}

#[test]
fn rolling_shutter_frames_need_the_rolling_model() {
    let dir = tempfile::tempdir().unwrap();
    let frames = write_sequence(
        dir.path(),
        Readout::RollingShutter {
            line_delay_s: 30e-6,
        },
        20,
    );
    let timestamps = dir.path().join("timestamps.csv");
    let source = dir.path().join("frames");
    let mut rmse = Vec::new();
    for shutter in [
        vec!["--shutter", "rolling", "--line-delay-s", "30e-6"],
        vec!["--shutter", "global"],
    ] {
        let out = tempfile::tempdir().unwrap();
        let mut args = track_args(dir.path(), p(&source), out.path());
        args.extend(["--timestamps".into(), p(&timestamps).into()]);
        args.extend(shutter.iter().map(|s| s.to_string()));
        run_ok(&args);
        rmse.push(position_rmse_m(&frames, &out.path().join("poses.tum")).1);
    }
    assert!(3.0 * rmse[0] < rmse[1], "rolling {:?}", rmse);
    // A rolling shutter without its line delay, or a line delay with a global shutter: refused, saying why.
    let out = tempfile::tempdir().unwrap();
    let mut args = track_args(dir.path(), p(&source), out.path());
    args.extend([
        "--fps".into(),
        "30".into(),
        "--shutter".into(),
        "rolling".into(),
    ]);
    assert!(run_fails(&args).contains("--line-delay-s"));
}

#[test]
fn bad_frame_inputs_are_refused_naming_the_frame_and_the_estimates_before_are_kept() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), Readout::GlobalShutter, 8);
    let source = dir.path().join("frames");
    let out = tempfile::tempdir().unwrap();
    // No frame times: refused, naming both options.
    let message = run_fails(&track_args(dir.path(), p(&source), out.path()));
    assert!(
        message.contains("--timestamps") && message.contains("--fps"),
        "{message}"
    );
    // A timestamps file with a row too few.
    let short = dir.path().join("short.csv");
    let full = std::fs::read_to_string(dir.path().join("timestamps.csv")).unwrap();
    let lines: Vec<&str> = full.lines().collect();
    std::fs::write(&short, lines[..lines.len() - 1].join("\n")).unwrap();
    let mut args = track_args(dir.path(), p(&source), out.path());
    args.extend(["--timestamps".into(), p(&short).into()]);
    let message = run_fails(&args);
    assert!(
        message.contains("short.csv") && message.contains("frame_00007.png"),
        "{message}"
    );
    // Times that go backwards.
    let backwards = dir.path().join("backwards.csv");
    std::fs::write(
        &backwards,
        full.replace(&lines[3][..lines[3].find(',').unwrap()], "0.01"),
    )
    .unwrap();
    let mut args = track_args(dir.path(), p(&source), out.path());
    args.extend(["--timestamps".into(), p(&backwards).into()]);
    let message = run_fails(&args);
    assert!(message.contains("backwards.csv:4"), "{message}");
    // A frame that cannot be read, in the middle: an error naming it, and the estimates of the frames before it
    // written.
    std::fs::write(source.join("frame_00005.png"), b"not a png").unwrap();
    let mut args = track_args(dir.path(), p(&source), out.path());
    args.extend(["--fps".into(), "30".into()]);
    let message = run_fails(&args);
    assert!(message.contains("frame_00005.png"), "{message}");
    // (Under the partial name: a failed run leaves the outputs' own names as they were.)
    assert!(!out.path().join("poses.tum").exists());
    let kept = read_tum(out.path().join("poses.partial.tum")).unwrap();
    assert_eq!(kept.len(), 5, "{message}");
    // A frame of another size.
    let small = Frame::new(64, 48, 8);
    write_frame_png(source.join("frame_00005.png"), &small).unwrap();
    let message = run_fails(&args);
    assert!(
        message.contains("frame_00005.png") && message.contains("64 x 48"),
        "{message}"
    );
}

#[test]
fn a_video_is_tracked_with_its_own_timestamps() {
    let has_ffmpeg = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_ffmpeg {
        assert!(
            std::env::var_os("ROITRACK_REQUIRE_FFMPEG").is_none(),
            "ffmpeg is required (ROITRACK_REQUIRE_FFMPEG is set) but not installed"
        );
        eprintln!("ffmpeg is not installed: the video test is skipped");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = write_sequence(dir.path(), Readout::GlobalShutter, 12);
    // Lossless, 30 frames a second: the video's timestamps are k / 30 s, as the sequence's.
    let video = dir.path().join("run.mkv");
    let status = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-framerate", "30", "-i"])
        .arg(dir.path().join("frames/frame_%05d.png"))
        .args(["-c:v", "ffv1", "-pix_fmt", "gray"])
        .arg(&video)
        .status()
        .unwrap();
    assert!(status.success());
    let out = tempfile::tempdir().unwrap();
    run_ok(&track_args(dir.path(), p(&video), out.path()));
    let (count, rmse) = position_rmse_m(&frames, &out.path().join("poses.tum"));
    assert_eq!(count, 12);
    assert!(rmse < 0.5e-3, "{} mm", rmse * 1e3);
}
