//! Fault injection, inputs side: the inputs a careless or hostile user gives, generated here on the fly (nothing large
//! is committed), each with the outcome it must have. A bad input is refused with an error naming the file and the
//! line or field, or the option; nothing hangs, nothing fills memory, nothing is silently wrong. (Output aliasing,
//! signals and full disks: tests/output_discipline.rs. That the readers stay bounded in memory is measured by a
//! counting allocator in crates/roitrack-formats/tests/bounded_readers.rs.)

// The helpers of the other tests' checks are not all needed here.
#[allow(dead_code)]
mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::roitrack;

/// A simulated run (the orthoglide scenario, 1 s) in a fresh folder.
struct Run {
    dir: tempfile::TempDir,
}

impl Run {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("sim");
        let done = roitrack(&["simulate", "--duration-s", "1", "--out", s(&out)]);
        assert!(done.status.success(), "{}", stderr(&done));
        Self { dir }
    }

    fn sim(&self, name: &str) -> PathBuf {
        self.dir.path().join("sim").join(name)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// `roitrack track` on this run's files, with `replace` (option, value) pairs instead of the run's own.
    fn track(&self, replace: &[(&str, &Path)], extra: &[&str]) -> Output {
        let (poses, twists) = (self.path("poses.tum"), self.path("twists.csv"));
        let mut inputs: Vec<(&str, PathBuf)> = vec![
            ("--camera", self.sim("camera.yaml")),
            ("--target", self.sim("target.csv")),
            ("--measurements", self.sim("measurements.csv")),
        ];
        for (option, path) in replace {
            match inputs.iter_mut().find(|(o, _)| o == option) {
                Some(slot) => slot.1 = path.to_path_buf(),
                None => inputs.push((option, path.to_path_buf())),
            }
        }
        let mut args: Vec<String> = vec!["track".into()];
        for (option, path) in &inputs {
            args.push((*option).into());
            args.push(path.display().to_string());
        }
        args.extend(["--poses", s(&poses), "--twists", s(&twists)].map(String::from));
        args.extend(extra.iter().map(|a| a.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        roitrack(&args)
    }
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts that the run failed (with exit status `code`) and that its error holds every one of `needles`.
fn refused(out: &Output, code: i32, needles: &[&str]) -> String {
    let e = stderr(out);
    assert_eq!(out.status.code(), Some(code), "{e}");
    for needle in needles {
        assert!(e.contains(needle), "{needle:?} not in: {e}");
    }
    e
}

/// The camera file with `from` replaced by `to` (an exact piece of its text).
fn camera_with(run: &Run, name: &str, from: &str, to: &str) -> PathBuf {
    let text = std::fs::read_to_string(run.sim("camera.yaml")).unwrap();
    assert!(text.contains(from), "{from} not in the camera file");
    let path = run.path(name);
    std::fs::write(&path, text.replace(from, to)).unwrap();
    path
}

#[test]
fn devices_binary_files_and_files_without_line_breaks_are_refused_naming_them() {
    let run = Run::new();
    // A megabyte of digits without a line break: more than any line may hold.
    let endless = run.path("endless.csv");
    std::fs::write(&endless, vec![b'7'; 1 << 20]).unwrap();
    let mut bag = b"\x89MCAP0\r\n".to_vec();
    bag.extend(vec![0u8; 4096]);
    let bag_path = run.path("run.mcap");
    std::fs::write(&bag_path, &bag).unwrap();
    let big = run.path("big.yaml");
    std::fs::write(&big, vec![b'#'; 2 << 20]).unwrap();
    let zero = Path::new("/dev/zero");
    let line = |p: &Path| format!("{}:1: line 1 is longer than 65536 bytes", p.display());
    for (option, path, needles) in [
        ("--measurements", endless.as_path(), vec![line(&endless)]),
        ("--target", endless.as_path(), vec![line(&endless)]),
        (
            "--camera",
            bag_path.as_path(),
            vec![format!(
                "{}: this is an MCAP file (a ROS 2 bag)",
                bag_path.display()
            )],
        ),
        (
            "--camera",
            big.as_path(),
            vec![format!("{}: the file is 2 MiB", big.display())],
        ),
    ] {
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        refused(&run.track(&[(option, path)], &[]), 1, &needles);
    }
    if zero.exists() {
        for option in ["--measurements", "--target"] {
            refused(&run.track(&[(option, zero)], &[]), 1, &[&line(zero)]);
        }
        refused(
            &run.track(&[("--camera", zero)], &[]),
            1,
            &["/dev/zero:1: not a text file (a NUL byte at byte 0)"],
        );
        let out = roitrack(&["eval", "--truth", s(&run.sim("")), "--poses", "/dev/zero"]);
        refused(&out, 1, &[&line(zero)]);
    }
}

#[test]
fn deep_yaml_is_refused_fast_and_a_byte_order_mark_is_read() {
    let run = Run::new();
    // 400 KB of nested flow collections, over many lines (each under the line limit): the depth is refused before
    // the YAML parser, which took minutes on such a file.
    let depth = 100_000;
    let nested = run.path("nested.yaml");
    std::fs::write(
        &nested,
        format!("a: {}{}", "[\n".repeat(depth), "]\n".repeat(depth)),
    )
    .unwrap();
    refused(
        &run.track(&[("--camera", &nested)], &[]),
        1,
        &["nested.yaml:32: lists and mappings nested 33 deep"],
    );
    // A UTF-8 byte-order mark, as Windows editors write it, in every text input.
    let with_bom = |name: &str, from: &Path| {
        let path = run.path(name);
        let mut bytes = "\u{feff}".as_bytes().to_vec();
        bytes.extend(std::fs::read(from).unwrap());
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let camera = with_bom("camera.yaml", &run.sim("camera.yaml"));
    let target = with_bom("target.csv", &run.sim("target.csv"));
    let measurements = with_bom("measurements.csv", &run.sim("measurements.csv"));
    let out = run.track(
        &[
            ("--camera", &camera),
            ("--target", &target),
            ("--measurements", &measurements),
        ],
        &[],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let poses = with_bom("poses_bom.tum", &run.path("poses.tum"));
    let out = roitrack(&["eval", "--truth", s(&run.sim("")), "--poses", s(&poses)]);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn implausible_cameras_are_refused_naming_the_field() {
    let run = Run::new();
    let k = "data: [1500.0, 0.0, 512.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]";
    let d = "data: [0.0, 0.0, 0.0, 0.0, 0.0]";
    for (name, from, to, field, says) in [
        (
            "k1_big.yaml",
            d,
            "data: [1000000.0, 0.0, 0.0, 0.0, 0.0]",
            "distortion_coefficients.data[0] (k1)",
            "k1 = 1000000: the plumb_bob lens model scales a point",
        ),
        (
            "k1_folds.yaml",
            d,
            "data: [-1000000.0, 0.0, 0.0, 0.0, 0.0]",
            "distortion_coefficients.data[0] (k1)",
            "folds back",
        ),
        (
            "k2_folds.yaml",
            d,
            "data: [0.0, -2.0, 0.0, 0.0, 0.0]",
            "distortion_coefficients.data[1] (k2)",
            "not invertible over the image",
        ),
        (
            "fx_tiny.yaml",
            k,
            "data: [1e-300, 0.0, 512.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]",
            "camera_matrix.data[0] (fx)",
            "fx = 1e-300 px",
        ),
        (
            "fx_huge.yaml",
            k,
            "data: [1e308, 0.0, 512.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]",
            "camera_matrix.data[0] (fx)",
            "fx = 1e308 px",
        ),
        (
            "skew.yaml",
            k,
            "data: [1500.0, 1e12, 512.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]",
            "camera_matrix.data[1] (skew)",
            "skew = 1e12 px",
        ),
        (
            "cx.yaml",
            k,
            "data: [1500.0, 0.0, 51200.0, 0.0, 1500.0, 512.0, 0.0, 0.0, 1.0]",
            "camera_matrix.data[2] (cx)",
            "principal point",
        ),
        (
            "width.yaml",
            "image_width: 1024",
            "image_width: 100000",
            "image_width",
            "at most 65536 px a side",
        ),
    ] {
        let camera = camera_with(&run, name, from, to);
        let field = format!("{name}: field '{field}': ");
        refused(
            &run.track(&[("--camera", &camera)], &[]),
            1,
            &[&field, says],
        );
    }
}

#[test]
fn duplicate_rows_and_times_in_other_units_are_refused_or_read_in_the_unit_said() {
    let run = Run::new();
    // Every row given twice: refused, naming both lines, not tracked as twice the measurements.
    let text = std::fs::read_to_string(run.sim("measurements.csv")).unwrap();
    let mut lines = text.lines();
    let mut doubled = format!("{}\n", lines.next().unwrap());
    for line in lines {
        doubled += &format!("{line}\n{line}\n");
    }
    let path = run.path("doubled.csv");
    std::fs::write(&path, doubled).unwrap();
    refused(
        &run.track(&[("--measurements", &path)], &[]),
        1,
        &["doubled.csv:3: field 'id': point 0 at t = 0 s is already on line 2"],
    );

    // Frame timestamps in milliseconds: refused with the option that reads them, and read with it.
    let frames = run.path("frames");
    let out = roitrack(&[
        "simulate",
        "--frames",
        "--scenario",
        "sweep",
        "--frame-count",
        "4",
        "--out",
        s(&frames),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let seconds = std::fs::read_to_string(frames.join("timestamps.csv")).unwrap();
    let mut ms = String::from("t,file\n");
    for row in seconds.lines().skip(1) {
        let (t, file) = row.split_once(',').unwrap();
        ms += &format!("{},{file}\n", t.parse::<f64>().unwrap() * 1e3);
    }
    let ms_path = run.path("timestamps_ms.csv");
    std::fs::write(&ms_path, ms).unwrap();
    let (camera, target, images) = (
        frames.join("camera.yaml"),
        frames.join("target.csv"),
        frames.join("frames"),
    );
    let (poses, twists) = (run.path("frame_poses.tum"), run.path("frame_twists.csv"));
    let track_frames = |extra: &[&str]| {
        let mut args = vec![
            "track",
            "--camera",
            s(&camera),
            "--target",
            s(&target),
            "--images",
            s(&images),
            "--timestamps",
            s(&ms_path),
            "--poses",
            s(&poses),
            "--twists",
            s(&twists),
        ];
        args.extend(extra);
        roitrack(&args)
    };
    refused(
        &track_frames(&[]),
        1,
        &[
            "timestamps_ms.csv:3: field 't': successive frames are 33.3",
            "--time-units ms",
        ],
    );
    let out = track_frames(&["--time-units", "ms"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn implausible_options_are_refused_naming_the_option_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let run = Run::new();
    let camera = run.sim("camera.yaml");
    for (args, option) in [
        (vec!["simulate", "--duration-s", "1e6"], "--duration-s"),
        (vec!["simulate", "--rate-hz", "1e9"], "--rate-hz"),
        (vec!["simulate", "--noise-px=-1"], "--noise-px"),
        (
            vec![
                "simulate",
                "--camera",
                s(&camera),
                "--image-size",
                "100000x100000",
            ],
            "--image-size",
        ),
        (vec!["simulate", "--frames", "--fps", "1e300"], "--fps"),
        (
            vec!["simulate", "--frames", "--exposure-s", "1e9"],
            "--exposure-s",
        ),
        (
            vec!["simulate", "--frames", "--frame-count", "1000000000"],
            "--frame-count",
        ),
        (vec!["simulate", "--speed-scale", "1e-9"], "--speed-scale"),
    ] {
        let mut args = args;
        args.extend(["--out", s(&out)]);
        let e = refused(&roitrack(&args), 2, &["invalid value", option]);
        assert!(!out.exists(), "{args:?} wrote its folder: {e}");
    }
    // The demo holds its run in memory: a day of it, or a run slowed a hundredfold, would not fit.
    for (extra, option) in [
        (["--duration-s", "86400"], "--duration-s"),
        (["--speed-scale", "0.01"], "--speed-scale"),
    ] {
        let e = refused(
            &roitrack(&["demo", extra[0], extra[1], "--out", s(&out)]),
            1,
            &[option, "in memory", "at most 120 s"],
        );
        assert!(!out.exists(), "{extra:?} wrote its folder: {e}");
    }
    for (extra, option) in [
        (["--window", "4000000000"], "--window"),
        (["--every", "0"], "--every"),
        (["--noise-px", "1e6"], "--noise-px"),
        (["--accel-psd", "1e300"], "--accel-psd"),
        (["--iterations", "1000000"], "--iterations"),
    ] {
        refused(&run.track(&[], &extra), 2, &["invalid value", option]);
        assert!(!run.path("poses.tum").exists());
    }
    let e = roitrack(&[
        "eval",
        "--truth",
        s(&run.sim("")),
        "--poses",
        s(&camera),
        "--max-file-mib",
        "0",
    ]);
    refused(&e, 2, &["--max-file-mib"]);
}
