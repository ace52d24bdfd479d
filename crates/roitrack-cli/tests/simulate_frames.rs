//! `roitrack simulate --frames`: every file of a simulated frame sequence written, the frames those of the library's
//! sequence, tracked and scored by `track --images` and `eval` as the README it writes says; bad options refused by
//! name before anything is written (`roitrack lab frame-study`: tests/lab/frame_study.rs).

use std::path::Path;

use roitrack::core::time::Readout;
use roitrack::formats::{FrameSource, FrameTiming, read_camera_yaml, read_frame, read_target_csv};
use roitrack::image::{Frame, Polarity};
use roitrack::sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};

mod common;
use common::{fails, ok, roitrack};
#[path = "common/process.rs"]
mod process;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn png_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".png"))
        .collect();
    names.sort();
    names
}

#[test]
fn frames_are_written_with_their_times_truth_and_how_to_track_them() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sim");
    ok(&[
        "simulate",
        "--frames",
        "--scenario",
        "sweep",
        "--seed",
        "2",
        "--shutter",
        "rolling",
        "--line-delay-s",
        "30e-6",
        "--polarity",
        "dark",
        "--frame-count",
        "8",
        "--out",
        p(&out),
    ]);
    for file in [
        "camera.yaml",
        "target.csv",
        "timestamps.csv",
        "gt_poses.tum",
        "gt_twists.csv",
        "README.txt",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    // As many frames as timestamps, named in order, at k / 30 s.
    let names = png_names(&out.join("frames"));
    let expected: Vec<String> = (0..8).map(|k| format!("frame_{k:05}.png")).collect();
    assert_eq!(names, expected);
    let times = std::fs::read_to_string(out.join("timestamps.csv")).unwrap();
    let mut lines = times.lines();
    assert_eq!(lines.next(), Some("t,file"));
    let rows: Vec<(f64, String)> = lines
        .map(|l| {
            let (t, file) = l.split_once(',').unwrap();
            (t.parse().unwrap(), file.to_owned())
        })
        .collect();
    assert_eq!(rows.len(), names.len());
    for (k, (t, file)) in rows.iter().enumerate() {
        assert!((t - k as f64 / 30.0).abs() < 1e-12, "{t}");
        assert_eq!(file, &names[k]);
    }

    // The frames are the library's, pixel for pixel (rendered on several threads, each frame its own noise).
    let scenario = Scenario::new(ScenarioKind::Sweep, 2);
    let options = FrameOptions {
        readout: Readout::RollingShutter {
            line_delay_s: 30e-6,
        },
        polarity: Polarity::Dark,
        seed: 2,
        frame_count: Some(8),
        ..FrameOptions::default()
    };
    let mut sequence = FrameSequence::new(&scenario, &options).unwrap();
    let mut frame = Frame::default();
    for k in [0, 5, 7] {
        sequence.render(k, &mut frame);
        let written = read_frame(out.join("frames").join(&names[k])).unwrap();
        assert_eq!(written.pixels, frame.pixels, "frame {k}");
    }
    let camera = read_camera_yaml(out.join("camera.yaml")).unwrap();
    assert_eq!((camera.width_px, camera.height_px), (1024, 1024));
    assert_eq!(
        read_target_csv(out.join("target.csv")).unwrap(),
        scenario.target
    );

    // The truth is dense and spans every blob time, the last frame's last row included.
    let poses = roitrack::formats::read_tum(out.join("gt_poses.tum")).unwrap();
    let twists = roitrack::formats::read_twists_csv(out.join("gt_twists.csv")).unwrap();
    assert_eq!(poses.len(), twists.len());
    assert_eq!(poses[0].t_s, 0.0);
    assert!((poses.last().unwrap().t_s - (7.0 / 30.0 + 1023.0 * 30e-6)).abs() < 1e-9);
    assert!(
        poses
            .windows(2)
            .all(|w| w[1].t_s - w[0].t_s <= 0.5e-3 + 1e-12)
    );

    // The frame source reads the folder with its timestamps.
    let timing = FrameTiming {
        timestamps: Some(out.join("timestamps.csv")),
        ..FrameTiming::default()
    };
    let mut source = FrameSource::open(out.join("frames"), &timing).unwrap();
    let mut count = 0;
    while let Some(info) = source.next_frame(&mut frame) {
        let info = info.unwrap();
        assert_eq!(info.t_s, rows[count].0);
        count += 1;
    }
    assert_eq!(count, 8);

    // The README says how the rows were read: the camera file cannot.
    let readme = std::fs::read_to_string(out.join("README.txt")).unwrap();
    assert!(
        readme.contains("--shutter rolling --line-delay-s 3e-5 --exposure-s 1e-3"),
        "{readme}"
    );
    assert!(readme.contains("--polarity dark"), "{readme}");
}

#[test]
fn simulated_frames_are_tracked_and_scored_as_the_readme_says() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sim");
    let simulated = roitrack(&[
        "simulate",
        "--frames",
        "--scenario",
        "sweep",
        "--shutter",
        "rolling",
        "--line-delay-s",
        "30e-6",
        "--frame-count",
        "30",
        "--out",
        p(&out),
    ]);
    assert!(simulated.status.success());
    // The command printed (and the README holds) the track command; run it as given, from the temporary folder.
    let stderr = String::from_utf8(simulated.stderr).unwrap();
    let track = stderr
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("roitrack track "))
        .expect("the track command is printed");
    let readme = std::fs::read_to_string(out.join("README.txt")).unwrap();
    assert!(readme.contains(track));
    let args: Vec<&str> = track.split_whitespace().skip(1).collect();
    process::succeeded(
        process::roitrack_command()
            .args(&args)
            .current_dir(tmp.path())
            .output()
            .unwrap(),
    );
    let metrics = ok(&[
        "eval",
        "--truth",
        p(&out),
        "--poses",
        p(&tmp.path().join("poses.tum")),
        "--twists",
        p(&tmp.path().join("twists.csv")),
        "--json",
    ]);
    let metrics: serde_json::Value = serde_json::from_str(&metrics).unwrap();
    assert_eq!(metrics["count"], 30);
    // Every frame scored, the first ones (velocity converging) included: well under a millimetre.
    let position_mm = metrics["position_rmse_mm"].as_f64().unwrap();
    assert!(position_mm < 1.0, "{metrics}");
}

#[test]
fn a_second_shorter_simulation_leaves_no_old_frame_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sim");
    let simulate = |count: &str| {
        ok(&[
            "simulate",
            "--frames",
            "--scenario",
            "sweep",
            "--frame-count",
            count,
            "--out",
            p(&out),
        ])
    };
    simulate("6");
    std::fs::write(out.join("frames").join("notes.txt"), "mine").unwrap();
    simulate("3");
    assert_eq!(
        png_names(&out.join("frames")),
        ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    );
    // Only the simulator's own frames are removed.
    assert!(out.join("frames").join("notes.txt").is_file());
    let times = std::fs::read_to_string(out.join("timestamps.csv")).unwrap();
    assert_eq!(times.lines().count(), 1 + 3);
}

#[test]
fn bad_frame_options_are_refused_by_name_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sim");
    let refused = |extra: &[&str], expected: &str| {
        let mut args = vec!["simulate", "--scenario", "sweep", "--out", p(&out)];
        args.extend_from_slice(extra);
        let stderr = fails(&args);
        assert!(stderr.contains(expected), "{extra:?}: {stderr}");
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    };
    refused(
        &["--frames", "--line-delay-s", "30e-6"],
        "--line-delay-s is for --shutter rolling",
    );
    refused(
        &["--frames", "--shutter", "rolling"],
        "--shutter rolling needs --line-delay-s",
    );
    // 1,024 rows 30 µs apart take 30.7 ms: more than a frame at 60 fps.
    refused(
        &[
            "--frames",
            "--fps",
            "60",
            "--shutter",
            "rolling",
            "--line-delay-s",
            "30e-6",
        ],
        "lower the frame rate, the line delay or the exposure",
    );
    refused(
        &["--frames", "--fps", "0"],
        "invalid value '0' for '--fps <F>'",
    );
    refused(&["--frames", "--exposure-s", "0.05"], "exposure");
    refused(
        &["--frames", "--shutter", "rolling", "--line-delay-s=-1e-6"],
        "for '--line-delay-s <D>'",
    );
    refused(
        &["--frames", "--frame-count", "0"],
        "for '--frame-count <N>'",
    );
    refused(&["--frames", "--fps", "1e300"], "for '--fps <F>'");
    // Frame options without --frames, and measurement options with it.
    refused(&["--fps", "30"], "--frames");
    refused(&["--shutter", "rolling"], "--frames");
    refused(&["--frames", "--rois"], "--rois");
    refused(&["--frames", "--noise-px", "0.2"], "--noise-px");
    refused(&["--frames", "--polarity", "grey"], "grey");
}

#[test]
fn a_simulation_of_the_other_kind_leaves_no_file_of_the_previous_one() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sim");
    let names = |dir: &Path| {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    let measurements = [
        "simulate",
        "--scenario",
        "sweep",
        "--duration-s",
        "0.5",
        "--rois",
        "--out",
        p(&out),
    ];
    let frames = [
        "simulate",
        "--frames",
        "--scenario",
        "sweep",
        "--frame-count",
        "3",
        "--out",
        p(&out),
    ];
    ok(&measurements);
    let run_files = [
        "camera.yaml",
        "gt_poses.tum",
        "gt_twists.csv",
        "measurements.csv",
        "rois.bin",
        "target.csv",
    ];
    assert_eq!(names(&out), run_files);
    // Frames where measurements were: the measurements and the recording go, and a file of the user's stays.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    ok(&frames);
    assert_eq!(
        names(&out),
        [
            "README.txt",
            "camera.yaml",
            "frames",
            "gt_poses.tum",
            "gt_twists.csv",
            "notes.txt",
            "target.csv",
            "timestamps.csv"
        ]
    );
    // Measurements where frames were: the frames (their folder with them), the times and the README go.
    ok(&measurements);
    let mut expected = run_files.to_vec();
    expected.insert(4, "notes.txt");
    assert_eq!(names(&out), expected);
    // A README and a folder of frames that are not ours stay; our frames in that folder go.
    ok(&frames);
    std::fs::write(out.join("frames").join("mine.txt"), "mine").unwrap();
    ok(&measurements);
    assert_eq!(names(&out.join("frames")), ["mine.txt"]);
    std::fs::write(out.join("README.txt"), "my own notes").unwrap();
    ok(&measurements);
    assert_eq!(
        std::fs::read_to_string(out.join("README.txt")).unwrap(),
        "my own notes"
    );
    // A demo into a simulation's folder: its ROI recording would not match the demo's measurements; what is not
    // ours stays.
    assert!(out.join("rois.bin").is_file());
    ok(&["demo", "--scenario", "static", "--out", p(&out)]);
    let after = names(&out);
    assert!(!after.contains(&"rois.bin".to_string()), "{after:?}");
    assert_eq!(names(&out.join("frames")), ["mine.txt"]);
    assert_eq!(
        std::fs::read_to_string(out.join("README.txt")).unwrap(),
        "my own notes"
    );
    assert!(after.contains(&"kalman_poses.tum".to_string()), "{after:?}");
}
