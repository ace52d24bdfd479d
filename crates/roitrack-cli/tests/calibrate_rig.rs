//! `roitrack calibrate-rig` from the command line: a simulated rig whose file leaves out every pose and clock but the
//! first camera's is calibrated from its measurements, the rig written is read back with the true one's poses and
//! clocks within the stated standard deviations, and `track --rig` then fuses the cameras with it; bad input is refused
//! naming the camera.

use std::path::Path;

mod common;
use common::{fails, ok};
use roitrack::core::so3;
use roitrack::formats::read_rig_yaml;

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn a_rig_without_poses_is_calibrated_then_tracked() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = tmp.path().join("sim");
    common::simulate_random_rig(&sim, "3", "6", &["--seed", "3"]);
    // What a user has before calibration: the calibrations only.
    let rig_text = std::fs::read_to_string(sim.join("rig.yaml")).unwrap();
    let bare_text: String = rig_text
        .lines()
        .filter(|l| !l.contains("camera_T_rig"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(sim.join("bare.yaml"), bare_text).unwrap();
    let measurements: Vec<String> = (0..3)
        .map(|c| {
            format!(
                "cam{c}={}",
                p(&sim.join(format!("cam{c}/measurements.csv")))
            )
        })
        .collect();
    let found = sim.join("found.yaml");
    let (bare, target) = (sim.join("bare.yaml"), sim.join("target.csv"));
    let (poses, twists) = (tmp.path().join("poses.tum"), tmp.path().join("twists.csv"));
    let mut args = vec![
        "calibrate-rig",
        "--rig",
        p(&bare),
        "--target",
        p(&target),
        "--out",
        p(&found),
    ];
    for m in &measurements {
        args.extend(["--measurements", m.as_str()]);
    }
    ok(&args);
    let found_rig = read_rig_yaml(&found, &Default::default()).unwrap().rig;
    let truth = read_rig_yaml(sim.join("rig_truth.yaml"), &Default::default())
        .unwrap()
        .rig;
    let text = std::fs::read_to_string(&found).unwrap();
    for (c, (f, t)) in found_rig
        .cameras()
        .iter()
        .zip(truth.cameras())
        .enumerate()
        .skip(1)
    {
        let translation_m = (f.mount.camera_t_rig_m - t.mount.camera_t_rig_m).norm();
        let rotation_rad = so3::angle_between(&f.mount.camera_r_rig, &t.mount.camera_r_rig);
        assert!(
            translation_m < 0.5e-3,
            "camera {c}: {} mm off",
            translation_m * 1e3
        );
        assert!(
            rotation_rad < 0.05f64.to_radians(),
            "camera {c}: {} deg off",
            rotation_rad.to_degrees()
        );
        assert!(
            (f.clock.offset_s - t.clock.offset_s).abs() < 50e-6,
            "camera {c}"
        );
        assert!(f.mount_known && f.clock_known());
    }
    assert!(text.contains("camera_T_rig_sigma_m:") && text.contains("clock_drift_sigma_ppm:"));
    // `track --rig RIG` over every camera's measurements, run by `run` (`ok` or `fails`).
    let track = |rig: &Path, run: fn(&[&str]) -> String| {
        let mut args = vec![
            "track",
            "--rig",
            p(rig),
            "--target",
            p(&target),
            "--poses",
            p(&poses),
            "--twists",
            p(&twists),
        ];
        for m in &measurements {
            args.extend(["--measurements", m.as_str()]);
        }
        run(&args)
    };
    // The calibrated rig tracks as the true one does.
    track(&found, ok);
    // An uncalibrated rig is refused by track, naming the camera and the command.
    let e = track(&bare, fails);
    assert!(
        e.contains("bare.yaml: camera 'cam1'")
            && e.contains("calibrate-rig")
            && !e.contains("tracker options"),
        "{e}"
    );
    // A camera to be found without its measurements, and an unknown camera, are named.
    let e = fails(&[
        "calibrate-rig",
        "--rig",
        p(&bare),
        "--target",
        p(&target),
        "--measurements",
        &measurements[0],
        "--measurements",
        &measurements[1],
        "--out",
        p(&tmp.path().join("x.yaml")),
    ]);
    assert!(
        e.contains("camera 'cam2'") && e.contains("--measurements cam2=FILE"),
        "{e}"
    );
    let e = fails(&[
        "calibrate-rig",
        "--rig",
        p(&bare),
        "--target",
        p(&target),
        "--measurements",
        "left=nowhere.csv",
        "--out",
        p(&tmp.path().join("x.yaml")),
    ]);
    assert!(
        e.contains("no camera 'left'") && e.contains("cam0, cam1, cam2"),
        "{e}"
    );
    assert!(!tmp.path().join("x.yaml").exists());
}
