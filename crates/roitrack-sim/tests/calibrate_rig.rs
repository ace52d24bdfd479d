//! Calibration of a rig from the target: on random seeded rigs of 2 to 4 cameras around the built-in scene, every
//! camera's pose in the rig and its clock left out but the first camera's, the calibrator finds them from the cameras'
//! measurements alone; the errors are compared with the targets and with the standard deviations it states.

use roitrack_core::so3;
use roitrack_estimators::rig::{
    CameraMount, ClockModel, Rig, RigCalibrationConfig, RigCalibrationError, RigCalibrator,
    RigCamera, RigMeasurement,
};
use roitrack_sim::multi_camera::{CameraRigScene, simulate_rig};
use roitrack_sim::{Scenario, ScenarioKind};

/// The rig as a user gives it before calibration: calibrations only, the first camera's frame and clock the rig's.
fn unknown_poses_and_clocks(truth: &Rig) -> Rig {
    told(truth, false, false)
}

/// The rig as told: every camera's but the first's mount and clock known or not as asked.
fn told(truth: &Rig, mounts_known: bool, clocks_known: bool) -> Rig {
    Rig::new(
        truth
            .cameras()
            .iter()
            .enumerate()
            .map(|(c, camera)| RigCamera {
                mount: if mounts_known {
                    camera.mount
                } else {
                    CameraMount::IDENTITY
                },
                mount_known: mounts_known,
                clock: if c == 0 || clocks_known {
                    camera.clock
                } else {
                    ClockModel::default()
                },
                offset_known: c == 0 || clocks_known,
                drift_known: c == 0 || clocks_known,
                ..camera.clone()
            })
            .collect(),
    )
    .unwrap()
}

struct Errors {
    translation_m: f64,
    rotation_rad: f64,
    offset_s: f64,
    drift_ppm: f64,
    /// The largest error over its stated standard deviation, over every component.
    worst_sigmas: f64,
}

fn calibrate(seed: u64, cameras: usize, duration_s: f64) -> Vec<Errors> {
    calibrate_told(seed, cameras, duration_s, false, false)
}

fn calibrate_told(
    seed: u64,
    cameras: usize,
    duration_s: f64,
    mounts_known: bool,
    clocks_known: bool,
) -> Vec<Errors> {
    let scenario = Scenario::new(ScenarioKind::Random, seed).with_duration_s(duration_s);
    let scene = CameraRigScene::random(scenario, cameras, seed);
    let run = simulate_rig(&scene, 4000.0, 0.1, seed).unwrap();
    let mut calibrator = RigCalibrator::new(
        told(&scene.rig, mounts_known, clocks_known),
        roitrack_core::Target::grid4x4(),
        RigCalibrationConfig::default(),
    )
    .unwrap();
    for (camera, list) in run.measurements.iter().enumerate() {
        for m in list {
            calibrator
                .push(&RigMeasurement {
                    camera,
                    measurement: *m,
                })
                .unwrap();
        }
    }
    let calibration = calibrator.finish().unwrap();
    let mut errors = Vec::new();
    for (c, (found, truth)) in calibration
        .cameras
        .iter()
        .zip(scene.rig.cameras())
        .enumerate()
        .skip(1)
    {
        let translation = found.mount.camera_t_rig_m - truth.mount.camera_t_rig_m;
        let rotation = so3::log(&(found.mount.camera_r_rig * truth.mount.camera_r_rig.inverse()));
        let offset_s = found.clock.offset_s - truth.clock.offset_s;
        let drift_ppm = found.clock.drift_ppm - truth.clock.drift_ppm;
        // What was known is kept exactly (sigma 0); what was found, against its sigma.
        let mut worst: f64 = 0.0;
        let mut against = |error: f64, sigma: f64| {
            if sigma == 0.0 {
                assert_eq!(error, 0.0, "seed {seed} camera {c}: a known value changed");
            } else {
                worst = worst.max(error.abs() / sigma);
            }
        };
        for k in 0..3 {
            against(translation[k], found.mount_sigma_m[k]);
            against(rotation[k], found.mount_sigma_rad[k]);
        }
        against(offset_s, found.offset_sigma_s);
        against(drift_ppm, found.drift_sigma_ppm);
        println!(
            "seed {seed}, camera {c} of {cameras} (placed against {:?}, {} samples, rms {:.3} mm): translation {:.3} mm \
             (sigma {:.3?} mm), rotation {:.4} deg (sigma {:.4?} deg), offset {:.1} us (sigma {:.1} us), drift {:.1} \
             ppm (sigma {:.1} ppm); worst {:.1} sigmas",
            found.placed_against,
            found.samples,
            found.rms_residual_m * 1e3,
            translation.norm() * 1e3,
            (found.mount_sigma_m * 1e3).as_slice(),
            rotation.norm().to_degrees(),
            found.mount_sigma_rad.map(f64::to_degrees).as_slice(),
            offset_s * 1e6,
            found.offset_sigma_s * 1e6,
            drift_ppm,
            found.drift_sigma_ppm,
            worst
        );
        errors.push(Errors {
            translation_m: translation.norm(),
            rotation_rad: rotation.norm(),
            offset_s,
            drift_ppm,
            worst_sigmas: worst,
        });
    }
    errors
}

/// Poses within 0.5 mm and 0.05 degrees of the truth on random rigs of 2 to 4 cameras (8 s of the random scene), clocks
/// within 50 us, and every error within what the stated standard deviations allow.
#[test]
fn calibrate_rig_recovers_poses_and_clocks_on_random_rigs() {
    let mut all = Vec::new();
    for (seed, cameras) in [(1, 2), (2, 3), (3, 4), (4, 2), (5, 3), (6, 4)] {
        all.extend(calibrate(seed, cameras, 8.0));
    }
    for e in &all {
        assert!(
            e.translation_m < 0.5e-3,
            "translation {} mm",
            e.translation_m * 1e3
        );
        assert!(
            e.rotation_rad < 0.05f64.to_radians(),
            "rotation {} deg",
            e.rotation_rad.to_degrees()
        );
        assert!(e.offset_s.abs() < 50e-6, "offset {} us", e.offset_s * 1e6);
        assert!(e.drift_ppm.abs() < 50.0, "drift {} ppm", e.drift_ppm);
    }
    // 8 components per camera, 15 cameras: at 4.5 sigmas a right Gaussian error is beyond on 1 in 100,000 components.
    let worst = all.iter().map(|e| e.worst_sigmas).fold(0.0, f64::max);
    assert!(worst < 4.5, "an error {worst:.1} of its stated sigmas");
}

/// A camera that never sees the target is named.
#[test]
fn a_camera_without_a_track_is_named() {
    let scenario = Scenario::new(ScenarioKind::Random, 1).with_duration_s(1.0);
    let scene = CameraRigScene::random(scenario, 2, 1);
    let run = simulate_rig(&scene, 4000.0, 0.1, 1).unwrap();
    let mut calibrator = RigCalibrator::new(
        unknown_poses_and_clocks(&scene.rig),
        roitrack_core::Target::grid4x4(),
        RigCalibrationConfig::default(),
    )
    .unwrap();
    for m in &run.measurements[0] {
        calibrator
            .push(&RigMeasurement {
                camera: 0,
                measurement: *m,
            })
            .unwrap();
    }
    let e = calibrator.finish().unwrap_err();
    assert!(
        matches!(&e, RigCalibrationError::NoTrack { camera, .. } if camera == "cam1"),
        "{e}"
    );
}

/// Only the clocks unknown (the mounts given), and only the mounts unknown (the clocks given): each is found alone,
/// the rest kept as given.
#[test]
fn calibrate_rig_finds_what_is_left_out_only() {
    let mut all = calibrate_told(7, 3, 6.0, true, false);
    all.extend(calibrate_told(8, 3, 6.0, false, true));
    for e in &all {
        assert!(e.translation_m < 0.5e-3 && e.rotation_rad < 0.05f64.to_radians());
        assert!(e.offset_s.abs() < 50e-6 && e.drift_ppm.abs() < 50.0);
    }
    let worst = all.iter().map(|e| e.worst_sigmas).fold(0.0, f64::max);
    assert!(worst < 4.5, "an error {worst:.1} of its stated sigmas");
}

/// A camera whose clock is further off than the search is refused, naming it, rather than placed at the edge.
#[test]
fn a_clock_beyond_the_search_is_named() {
    let scenario = Scenario::new(ScenarioKind::Random, 9).with_duration_s(3.0);
    let mut scene = CameraRigScene::random(scenario, 2, 9);
    let mut cameras = scene.rig.cameras().to_vec();
    cameras[1].clock.offset_s = 0.3;
    scene.rig = Rig::new(cameras).unwrap();
    let run = simulate_rig(&scene, 4000.0, 0.1, 9).unwrap();
    let mut calibrator = RigCalibrator::new(
        unknown_poses_and_clocks(&scene.rig),
        roitrack_core::Target::grid4x4(),
        RigCalibrationConfig::default(),
    )
    .unwrap();
    for (camera, list) in run.measurements.iter().enumerate() {
        for m in list {
            calibrator
                .push(&RigMeasurement {
                    camera,
                    measurement: *m,
                })
                .unwrap();
        }
    }
    let e = calibrator.finish().unwrap_err();
    assert!(
        matches!(&e, RigCalibrationError::ClockBeyondSearch { camera, .. } if camera == "cam1")
            || matches!(&e, RigCalibrationError::NoOverlap { camera, .. } if camera == "cam1"),
        "{e}"
    );
}
