//! Several cameras with no shared clock, from the command line: `simulate --rig-cameras` / `--rig` writes a folder per
//! camera, `track --rig` fuses them and writes the learnt clocks with `--rig-out`; a one-camera rig is the
//! single-camera path, byte for byte; bad rig files and bad `--measurements NAME=FILE` are refused naming the file
//! and the camera.

use std::path::Path;

mod common;
use common::{fails, ok};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn a_simulated_rig_is_tracked_and_its_clocks_written_back() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    common::simulate_random_rig(&sim, "2", "2", &[]);
    for file in [
        "cam0/measurements.csv",
        "cam1/measurements.csv",
        "cam1/camera.yaml",
        "gt_poses.tum",
        "gt_twists.csv",
        "rig.yaml",
        "rig_truth.yaml",
        "target.csv",
    ] {
        assert!(sim.join(file).is_file(), "{file}");
    }
    let (poses, twists, learnt) = (
        tmp.path().join("poses.tum"),
        tmp.path().join("twists.csv"),
        tmp.path().join("learnt.yaml"),
    );
    let args =
        common::track_simulated_rig_args(&sim, 2, &poses, &twists, &["--rig-out", p(&learnt)]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    // The learnt rig reads back (its calibrations made absolute: it is in another folder) with cam1's clock known,
    // within 0.1 ms of the truth.
    let options = Default::default();
    let learnt = roitrack::formats::read_rig_yaml(&learnt, &options).unwrap();
    let truth = roitrack::formats::read_rig_yaml(sim.join("rig_truth.yaml"), &options).unwrap();
    let (a, b) = (&learnt.rig.cameras()[1], &truth.rig.cameras()[1]);
    assert!(a.offset_known && a.drift_known);
    assert!(
        (a.clock.offset_s - b.clock.offset_s).abs() < 1e-4,
        "{a:?} {b:?}"
    );
    let text = std::fs::read_to_string(tmp.path().join("learnt.yaml")).unwrap();
    assert!(text.contains("clock_offset_sigma_s") && text.contains("clock_drift_sigma_ppm"));
    let report = ok(&["eval", "--truth", p(&sim), "--poses", p(&poses)]);
    assert!(report.contains("position RMSE"), "{report}");
}

#[test]
fn a_one_camera_rig_is_the_single_camera_path() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    ok(&[
        "simulate",
        "--scenario",
        "orthoglide",
        "--duration-s",
        "1",
        "--out",
        p(&sim),
    ]);
    let rig = sim.join("rig.yaml");
    std::fs::write(
        &rig,
        "cameras:\n  - name: only\n    calibration: camera.yaml\n    camera_T_rig: [0, 0, 0, 0, 0, 0, 1]\n",
    )
    .unwrap();
    let out = |name: &str| tmp.path().join(name);
    let common = |poses: &Path, twists: &Path, covariance: &Path| {
        vec![
            "--target".to_string(),
            p(&sim.join("target.csv")).to_string(),
            "--poses".to_string(),
            p(poses).to_string(),
            "--twists".to_string(),
            p(twists).to_string(),
            "--covariance".to_string(),
            p(covariance).to_string(),
        ]
    };
    let mut single = vec![
        "track".to_string(),
        "--camera".to_string(),
        p(&sim.join("camera.yaml")).to_string(),
        "--measurements".to_string(),
        p(&sim.join("measurements.csv")).to_string(),
    ];
    single.extend(common(&out("a.tum"), &out("a.csv"), &out("a_cov.csv")));
    let mut rigged = vec![
        "track".to_string(),
        "--rig".to_string(),
        p(&rig).to_string(),
        "--measurements".to_string(),
        format!("only={}", p(&sim.join("measurements.csv"))),
    ];
    rigged.extend(common(&out("b.tum"), &out("b.csv"), &out("b_cov.csv")));
    ok(&single.iter().map(String::as_str).collect::<Vec<_>>());
    ok(&rigged.iter().map(String::as_str).collect::<Vec<_>>());
    for (a, b) in [
        ("a.tum", "b.tum"),
        ("a.csv", "b.csv"),
        ("a_cov.csv", "b_cov.csv"),
    ] {
        let (a, b) = (
            std::fs::read(out(a)).unwrap(),
            std::fs::read(out(b)).unwrap(),
        );
        assert!(!a.is_empty() && a == b);
    }
}

#[test]
fn bad_rigs_and_streams_are_refused_naming_the_file_and_the_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    common::simulate_random_rig(&sim, "2", "0.2", &[]);
    let good = std::fs::read_to_string(sim.join("rig.yaml")).unwrap();
    let track = |rig_text: &str, streams: &[&str]| {
        let rig = sim.join("bad_rig.yaml");
        std::fs::write(&rig, rig_text).unwrap();
        let mut args = vec![
            "track".to_string(),
            "--rig".to_string(),
            p(&rig).to_string(),
            "--target".to_string(),
            p(&sim.join("target.csv")).to_string(),
            "--poses".to_string(),
            p(&tmp.path().join("p.tum")).to_string(),
            "--twists".to_string(),
            p(&tmp.path().join("t.csv")).to_string(),
        ];
        for s in streams {
            args.push("--measurements".to_string());
            args.push(s.to_string());
        }
        fails(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let cam0 = format!("cam0={}", p(&sim.join("cam0/measurements.csv")));
    let cases = [
        (
            good.replace("name: cam1", "name: cam0"),
            vec![cam0.clone()],
            "camera 'cam0': listed twice",
        ),
        (
            good.replace("cam1/camera.yaml", "cam1/missing.yaml"),
            vec![cam0.clone()],
            "camera 'cam1': calibration",
        ),
        (
            good.replace(", 0.8", ", 0.3"),
            vec![cam0.clone()],
            "not a unit quaternion",
        ),
        (
            good.clone(),
            vec![
                cam0.clone(),
                format!("cam7={}", p(&sim.join("cam1/measurements.csv"))),
            ],
            "has no camera 'cam7'",
        ),
        (
            good.clone(),
            vec![format!("cam1={}", p(&sim.join("cam1/measurements.csv")))],
            "the first camera",
        ),
        (
            good.clone(),
            vec![p(&sim.join("cam0/measurements.csv")).to_string()],
            "NAME=FILE",
        ),
    ];
    for (text, streams, expected) in cases {
        let streams: Vec<&str> = streams.iter().map(String::as_str).collect();
        let e = track(&text, &streams);
        assert!(e.contains(expected), "{expected}: {e}");
        if !expected.contains("NAME=FILE")
            && !expected.contains("cam7")
            && !expected.contains("first camera")
        {
            assert!(e.contains("bad_rig.yaml"), "{e}");
        }
    }
}
