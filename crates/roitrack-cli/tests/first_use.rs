//! A first use, scripted: a new user's own camera calibration (every file format and distortion model roitrack
//! reads), their own target and measurements, and the mistakes such a user makes (units, paths), each caught with a
//! message that says what to do.

mod common;

use std::path::{Path, PathBuf};

use common::{fails, ok, track_args};
use roitrack::formats::{
    CameraFileOptions, read_camera_file, write_measurements_csv, write_target_csv,
};
use roitrack::nalgebra::{Vector2, Vector3};
use roitrack::{CameraModel, Measurement, MotionState, Target};

/// The camera files of roitrack-formats' tests: written by OpenCV 4 and 5 themselves, and as ROS and Kalibr write them.
fn camera_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../roitrack-formats/tests/data/cameras")
        .join(name)
}

/// OpenCV's raw pixels for the camera with these parameters (roitrack-core's tests/data/opencv_projections.csv,
/// computed by cv2.projectPoints and cv2.fisheye.projectPoints).
fn opencv_projections(camera: &CameraModel) -> Vec<(Vector3<f64>, Vector2<f64>)> {
    let text = include_str!("../../roitrack-core/tests/data/opencv_projections.csv");
    let k = &camera.intrinsics;
    let mut ours = camera.distortion.coefficients();
    let mut out = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let n = |i: usize| f[i].parse::<f64>().unwrap();
        let theirs: Vec<f64> = f[6]
            .split_whitespace()
            .map(|c| c.parse().unwrap())
            .collect();
        if theirs.len() == 4 && ours.len() == 5 && ours[4] == 0.0 {
            ours.truncate(4);
        }
        if f[0] == camera.distortion.model_name()
            && (n(1), n(2), n(3), n(4), n(5)) == (k.fx_px, k.fy_px, k.skew_px, k.cx_px, k.cy_px)
            && theirs == ours
        {
            out.push((Vector3::new(n(7), n(8), n(9)), Vector2::new(n(10), n(11))));
        }
    }
    out
}

/// Noise-free measurements of the bundled 4 x 4 grid at rest 0.6 m in front of `camera`, 4 kHz, 40 cycles.
fn measurements_of_grid_at_rest(camera: &CameraModel, truth: &MotionState) -> Vec<Measurement> {
    let target = Target::grid4x4();
    let mut out = Vec::new();
    for k in 0..40 * target.points().len() {
        let p = &target.points()[k % target.points().len()];
        let t_s = k as f64 * 2.5e-4;
        let px = camera
            .raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, t_s))
            .unwrap();
        assert!(
            camera.contains_raw_pixel(&px),
            "{}: {px:?} off the image",
            camera.name
        );
        out.push(Measurement {
            t_s,
            id: p.id,
            u_px: px.x,
            v_px: px.y,
        });
    }
    out
}

/// The last position of a TUM file (m).
fn last_position_m(tum: &Path) -> Vector3<f64> {
    let text = std::fs::read_to_string(tum).unwrap();
    let last = text.lines().rfind(|l| !l.starts_with('#')).unwrap();
    let f: Vec<f64> = last
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    Vector3::new(f[1], f[2], f[3])
}

#[test]
fn step_1_every_camera_file_and_model_is_read_projects_like_opencv_and_tracks() {
    let dir = tempfile::tempdir().unwrap();
    let target_path = dir.path().join("target.csv");
    write_target_csv(&target_path, &Target::grid4x4()).unwrap();
    let truth = MotionState::at_rest(Default::default(), Vector3::new(0.004, -0.003, 0.6));
    // (file, extra options, model)
    let cases: [(&str, &[&str], &str); 9] = [
        ("ros1_rostopic_echo.yaml", &[], "plumb_bob"),
        ("ros2_topic_echo.yaml", &[], "rational_polynomial"),
        ("ros_camera_info_equidistant.yaml", &[], "equidistant"),
        ("kalibr_camchain.yaml", &[], "plumb_bob"),
        (
            "kalibr_camchain.yaml",
            &["--camera-name", "cam1"],
            "equidistant",
        ),
        ("opencv4_calibration.yaml", &[], "plumb_bob"),
        ("opencv5_calibration.xml", &[], "plumb_bob"),
        ("opencv5_rational.yaml", &[], "rational_polynomial"),
        (
            "opencv4_fisheye.xml",
            &["--image-size", "1280x960"],
            "equidistant",
        ),
    ];
    for (k, (file, extra, model)) in cases.into_iter().enumerate() {
        let path = camera_file(file);
        // The library reads it as the CLI will...
        let options = CameraFileOptions {
            image_size: extra
                .windows(2)
                .find(|w| w[0] == "--image-size")
                .map(|_| (1280, 960)),
            camera_name: extra
                .windows(2)
                .find(|w| w[0] == "--camera-name")
                .map(|w| w[1].to_string()),
        };
        let camera = read_camera_file(&path, &options).unwrap();
        assert_eq!(camera.distortion.model_name(), model, "{file}");
        // ... and projects like OpenCV.
        let rows = opencv_projections(&camera);
        assert!(rows.len() >= 60, "{file}: {} OpenCV rows", rows.len());
        for (p, opencv_px) in rows {
            let px = camera.raw_pixel_from_cam(&p).unwrap();
            assert!(
                (px - opencv_px).norm() < 1e-9,
                "{file}: {px:?} vs OpenCV {opencv_px:?}"
            );
        }
        // The user's measurements through that lens, tracked by the CLI from the calibration file itself.
        let measurements = dir.path().join(format!("m{k}.csv"));
        write_measurements_csv(
            &measurements,
            &measurements_of_grid_at_rest(&camera, &truth),
        )
        .unwrap();
        let poses = dir.path().join(format!("p{k}.tum"));
        let twists = dir.path().join(format!("w{k}.csv"));
        ok(&track_args(
            path.to_str().unwrap(),
            target_path.to_str().unwrap(),
            measurements.to_str().unwrap(),
            poses.to_str().unwrap(),
            twists.to_str().unwrap(),
            extra,
        ));
        let error_m = (last_position_m(&poses) - truth.cam_t_obj_m).norm();
        assert!(error_m < 1e-5, "{file}: position error {error_m} m");
    }
    // What a file leaves out, and what does not fit, is said with the option that helps.
    let track = |camera: &Path, extra: &[&str]| {
        fails(&track_args(
            camera.to_str().unwrap(),
            target_path.to_str().unwrap(),
            "nowhere.csv",
            "p.tum",
            "w.csv",
            extra,
        ))
    };
    let e = track(&camera_file("opencv5_fisheye.yaml"), &[]);
    assert!(e.contains("opencv5_fisheye.yaml: field 'image_width': missing: give the image size with --image-size WxH"), "{e}");
    let e = track(
        &camera_file("kalibr_camchain.yaml"),
        &["--camera-name", "cam7"],
    );
    assert!(
        e.contains(
            "kalibr_camchain.yaml: field 'cam7': no such camera in the camchain (it has cam0, cam1)"
        ),
        "{e}"
    );
    let e = track(
        &camera_file("opencv4_calibration.yaml"),
        &["--image-size", "640by480"],
    );
    assert!(e.contains("expected WIDTHxHEIGHT"), "{e}");
    // The detect command takes the same options.
    let e = fails(&[
        "detect",
        "--camera",
        camera_file("opencv4_fisheye.yaml").to_str().unwrap(),
        "--target",
        target_path.to_str().unwrap(),
        "photo.png",
    ]);
    assert!(e.contains("--image-size"), "{e}");
}

/// Runs `track` on the canonical camera with these files and extra options.
fn track(dir: &Path, target: &Path, measurements: &Path, extra: &[&str]) -> Result<String, String> {
    let camera = dir.join("camera.yaml");
    if !camera.exists() {
        roitrack::formats::write_camera_yaml(&camera, &CameraModel::canonical()).unwrap();
    }
    let poses = dir.join("poses.tum");
    let twists = dir.join("twists.csv");
    let out = common::roitrack(&track_args(
        camera.to_str().unwrap(),
        target.to_str().unwrap(),
        measurements.to_str().unwrap(),
        poses.to_str().unwrap(),
        twists.to_str().unwrap(),
        extra,
    ));
    if out.status.success() {
        Ok(std::fs::read_to_string(&poses).unwrap())
    } else {
        Err(String::from_utf8(out.stderr).unwrap())
    }
}

#[test]
fn step_2_unit_and_range_mistakes_are_caught_with_their_hint() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let camera = CameraModel::canonical();
    let truth = MotionState::at_rest(Default::default(), Vector3::new(0.004, -0.003, 0.6));
    let measurements = measurements_of_grid_at_rest(&camera, &truth);
    let good_m = d.join("m.csv");
    write_measurements_csv(&good_m, &measurements).unwrap();
    let good_t = d.join("target.csv");
    write_target_csv(&good_t, &Target::grid4x4()).unwrap();
    let position = |tum: &str| {
        let f: Vec<f64> = tum
            .lines()
            .next_back()
            .unwrap()
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        Vector3::new(f[1], f[2], f[3])
    };
    assert!(
        (position(&track(d, &good_t, &good_m, &[]).unwrap()) - truth.cam_t_obj_m).norm() < 1e-5
    );

    // A target written in millimetres: refused with the hint, read with --target-units mm.
    let mut mm = String::from("id,x,y,z,diameter\n");
    for p in Target::grid4x4().points() {
        let q = p.point_in_obj_m * 1000.0;
        mm.push_str(&format!(
            "{},{},{},{},{}\n",
            p.id,
            q.x,
            q.y,
            q.z,
            p.diameter_m.unwrap() * 1000.0
        ));
    }
    let mm_t = d.join("target_mm.csv");
    std::fs::write(&mm_t, mm).unwrap();
    let e = track(d, &mm_t, &good_m, &[]).unwrap_err();
    assert!(
        e.contains("target_mm.csv: field 'x, y, z': its points span")
            && e.contains("--target-units mm"),
        "{e}"
    );
    let tum = track(d, &mm_t, &good_m, &["--target-units", "mm"]).unwrap();
    assert!((position(&tum) - truth.cam_t_obj_m).norm() < 1e-5);
    // Insisting that it is in metres gives a first pose 600 m away: refused too, with the same hint.
    let e = track(d, &mm_t, &good_m, &["--target-units", "m"]).unwrap_err();
    assert!(
        e.contains("more than 100 m away") && e.contains("--target-units mm or cm"),
        "{e}"
    );

    // Times in milliseconds: refused with the hint, read with --time-units ms.
    let ms: Vec<Measurement> = measurements
        .iter()
        .map(|m| Measurement {
            t_s: m.t_s * 1e3,
            ..*m
        })
        .collect();
    let ms_m = d.join("m_ms.csv");
    write_measurements_csv(&ms_m, &ms).unwrap();
    let e = track(d, &good_t, &ms_m, &[]).unwrap_err();
    assert!(
        e.contains("m_ms.csv:3: field 't': ") && e.contains("--time-units ms"),
        "{e}"
    );
    let tum = track(d, &good_t, &ms_m, &["--time-units", "ms"]).unwrap();
    assert!(
        tum.lines().next_back().unwrap().starts_with("0.15"),
        "{}",
        tum.lines().next_back().unwrap()
    );
    // And nanoseconds since 1970.
    let ns: Vec<Measurement> = measurements
        .iter()
        .map(|m| Measurement {
            t_s: 1.764e18 + m.t_s * 1e9,
            ..*m
        })
        .collect();
    let ns_m = d.join("m_ns.csv");
    write_measurements_csv(&ns_m, &ns).unwrap();
    let e = track(d, &good_t, &ns_m, &[]).unwrap_err();
    assert!(
        e.contains("m_ns.csv:2: field 't': ") && e.contains("--time-units ns"),
        "{e}"
    );

    // A centroid 4,000 px off a 1,024 px image: the file, the line and the field.
    let mut off = measurements.clone();
    off[37].u_px += 4000.0;
    let off_m = d.join("m_off.csv");
    write_measurements_csv(&off_m, &off).unwrap();
    let e = track(d, &good_t, &off_m, &[]).unwrap_err();
    assert!(
        e.contains("m_off.csv:39: field 'u': centroid u = ")
            && e.contains("outside the image, which is 1024 px wide"),
        "{e}"
    );
}

/// `track` with these (name, path) options over the grid's files in `dir`; stdin from `stdin` if given.
fn track_paths(dir: &Path, paths: &[(&str, &str)], stdin: Option<&[u8]>) -> std::process::Output {
    use std::io::Write as _;
    let camera = dir.join("camera.yaml");
    if !camera.exists() {
        roitrack::formats::write_camera_yaml(&camera, &CameraModel::canonical()).unwrap();
        write_target_csv(dir.join("target.csv"), &Target::grid4x4()).unwrap();
        let truth = MotionState::at_rest(Default::default(), Vector3::new(0.004, -0.003, 0.6));
        let m = measurements_of_grid_at_rest(&CameraModel::canonical(), &truth);
        write_measurements_csv(dir.join("m.csv"), &m).unwrap();
    }
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_roitrack"));
    command
        .current_dir(dir)
        .args(["track", "--camera", "camera.yaml", "--target", "target.csv"]);
    for (name, path) in paths {
        command.args([name, path]);
    }
    command.stdin(std::process::Stdio::piped());
    command.stdout(std::process::Stdio::piped());
    command.stderr(std::process::Stdio::piped());
    let mut child = command.spawn().unwrap();
    let mut input = child.stdin.take().unwrap();
    if let Some(bytes) = stdin {
        input.write_all(bytes).unwrap();
    }
    drop(input);
    child.wait_with_output().unwrap()
}

#[cfg(unix)]
#[test]
fn step_3_unsafe_outputs_are_refused_or_handled_and_inputs_stay_intact() {
    use std::os::unix::fs::{FileTypeExt, symlink};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |paths: &[(&str, &str)]| track_paths(d, paths, None);
    let stderr = |o: &std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        run(&[
            ("--measurements", "m.csv"),
            ("--poses", "p.tum"),
            ("--twists", "w.csv")
        ])
        .status
        .success()
    );
    let inputs: Vec<(&str, Vec<u8>)> = ["camera.yaml", "target.csv", "m.csv"]
        .into_iter()
        .map(|f| (f, std::fs::read(d.join(f)).unwrap()))
        .collect();
    let inputs_intact = || {
        for (f, bytes) in &inputs {
            assert_eq!(&std::fs::read(d.join(f)).unwrap(), bytes, "{f} changed");
        }
    };
    symlink("m.csv", d.join("link_to_m.csv")).unwrap();
    std::fs::hard_link(d.join("target.csv"), d.join("hard_target.csv")).unwrap();
    // An output that is an input: by its name, through a symbolic link, through a hard link.
    for (output, input, option) in [
        ("m.csv", "--measurements", "--poses"),
        ("link_to_m.csv", "--measurements", "--twists"),
        ("hard_target.csv", "--target", "--poses"),
        ("camera.yaml", "--camera", "--twists"),
    ] {
        let mut paths = vec![
            ("--measurements", "m.csv"),
            ("--poses", "p.tum"),
            ("--twists", "w.csv"),
        ];
        paths.retain(|(name, _)| *name != option);
        paths.push((option, output));
        let out = run(&paths);
        assert!(!out.status.success());
        let e = stderr(&out);
        assert!(
            e.contains(&format!(
                "the output {option} is the input given as {input}"
            )),
            "{e}"
        );
        inputs_intact();
    }
    // Two outputs to one file, also by two spellings; '-' twice.
    let out = run(&[
        ("--measurements", "m.csv"),
        ("--poses", "out.txt"),
        ("--twists", "./out.txt"),
    ]);
    assert!(
        stderr(&out).contains("--poses and --twists would both write"),
        "{}",
        stderr(&out)
    );
    assert!(!d.join("out.txt").exists());
    let out = run(&[
        ("--measurements", "m.csv"),
        ("--poses", "-"),
        ("--twists", "-"),
    ]);
    assert!(
        stderr(&out).contains("--poses, --twists all write to the standard output"),
        "{}",
        stderr(&out)
    );
    // '-': poses on the standard output, measurements from the standard input.
    let m = std::fs::read(d.join("m.csv")).unwrap();
    let out = track_paths(
        d,
        &[
            ("--measurements", "-"),
            ("--poses", "-"),
            ("--twists", "w2.csv"),
        ],
        Some(&m),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(stdout, std::fs::read_to_string(d.join("p.tum")).unwrap());
    assert!(!d.join("-").exists());
    // A symbolic link as an output: its target is written, the link stays.
    std::fs::create_dir(d.join("results")).unwrap();
    symlink("results/poses.tum", d.join("latest.tum")).unwrap();
    assert!(
        run(&[
            ("--measurements", "m.csv"),
            ("--poses", "latest.tum"),
            ("--twists", "w.csv")
        ])
        .status
        .success()
    );
    assert!(
        std::fs::symlink_metadata(d.join("latest.tum"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(
        std::fs::read(d.join("results/poses.tum")).unwrap(),
        std::fs::read(d.join("p.tum")).unwrap()
    );
    // A FIFO is written in place, never replaced; /dev/null takes any output.
    assert!(
        std::process::Command::new("mkfifo")
            .arg(d.join("twists.fifo"))
            .status()
            .unwrap()
            .success()
    );
    let reader = {
        let fifo = d.join("twists.fifo");
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    let out = run(&[
        ("--measurements", "m.csv"),
        ("--poses", "/dev/null"),
        ("--twists", "twists.fifo"),
        ("--diagnostics", "/dev/null"),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        reader.join().unwrap(),
        std::fs::read_to_string(d.join("w.csv")).unwrap()
    );
    assert!(
        std::fs::symlink_metadata(d.join("twists.fifo"))
            .unwrap()
            .file_type()
            .is_fifo()
    );
    assert!(
        std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );
    // A regular file is still written atomically: a run that fails leaves the previous file as it was.
    let before = std::fs::read(d.join("p.tum")).unwrap();
    let mut broken = std::fs::read_to_string(d.join("m.csv")).unwrap();
    broken.push_str("oops,1,1,1\n");
    std::fs::write(d.join("broken.csv"), broken).unwrap();
    let out = run(&[
        ("--measurements", "broken.csv"),
        ("--poses", "p.tum"),
        ("--twists", "w.csv"),
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("broken.csv:642: field 't'"),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read(d.join("p.tum")).unwrap(), before);
    inputs_intact();
}
