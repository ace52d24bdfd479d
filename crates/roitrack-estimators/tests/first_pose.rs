//! A first pose too far away or behind the camera is refused with the likely fix: the target's units.

use nalgebra::Vector3;
use roitrack_core::{CameraModel, Measurement, MotionState, Target, TargetPoint};
use roitrack_estimators::{Estimator, TrackError, Tracker, TrackerConfig};

/// Measurement `k` of the 4 x 4 grid at rest 0.6 m in front of the canonical camera: its points in turn, 4 kHz.
fn grid_measurement(k: usize) -> Measurement {
    let camera = CameraModel::canonical();
    let grid = Target::grid4x4();
    let truth = MotionState::at_rest(Default::default(), Vector3::new(0.01, 0.0, 0.6));
    let p = &grid.points()[k % 16];
    let px = camera
        .raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, 0.0))
        .unwrap();
    Measurement {
        t_s: k as f64 * 2.5e-4,
        id: p.id,
        u_px: px.x,
        v_px: px.y,
    }
}

/// The tracker's first result over measurements of the grid 0.6 m away, with the target given as `target`.
fn first_result(target: &Target, config: TrackerConfig) -> Result<Vector3<f64>, TrackError> {
    let mut tracker = Tracker::new(CameraModel::canonical(), target.clone(), config).unwrap();
    for k in 0..64 {
        if let Some(e) = tracker.push(&grid_measurement(k))? {
            return Ok(e.state.cam_t_obj_m);
        }
    }
    panic!("no estimate");
}

/// The errors over `cycles` cycles of the grid seen with `target`: every first pose tried is checked.
fn refusals(target: &Target, cycles: usize) -> usize {
    let mut tracker = Tracker::new(
        CameraModel::canonical(),
        target.clone(),
        TrackerConfig::default(),
    )
    .unwrap();
    let mut refused = 0;
    for k in 0..16 * cycles {
        match tracker.push(&grid_measurement(k)) {
            Err(TrackError::ImplausibleFirstPose { .. }) => refused += 1,
            Err(e) => panic!("{e}"),
            Ok(_) => {}
        }
    }
    // Neither the tracks nor the estimates refused count.
    assert_eq!(tracker.report().initialisations, 0);
    assert_eq!(tracker.report().estimates.total(), 0);
    refused
}

fn scaled(scale: f64) -> Target {
    let points = Target::grid4x4()
        .points()
        .iter()
        .map(|p| TargetPoint {
            point_in_obj_m: p.point_in_obj_m * scale,
            ..*p
        })
        .collect();
    Target::new(points).unwrap()
}

#[test]
fn a_target_in_millimetres_is_refused_with_the_hint() {
    let t = first_result(&scaled(1.0), TrackerConfig::default()).unwrap();
    assert!((t - Vector3::new(0.01, 0.0, 0.6)).norm() < 1e-6);
    let e = first_result(&scaled(1000.0), TrackerConfig::default()).unwrap_err();
    assert!(
        matches!(e, TrackError::ImplausibleFirstPose { distance_m, .. } if distance_m > 500.0),
        "{e}"
    );
    let text = e.to_string();
    assert!(
        text.contains("more than 100 m away") && text.contains("--target-units mm"),
        "{text}"
    );
    // The way past, for a scene that really is that far.
    let far = TrackerConfig {
        max_first_distance_m: f64::INFINITY,
        ..TrackerConfig::default()
    };
    assert!(first_result(&scaled(1000.0), far).unwrap().z > 500.0);
    // A caller that goes on after the error gets it again at each new try: the refused track is not counted.
    assert!(refusals(&scaled(1000.0), 12) >= 3);
    let bad = TrackerConfig {
        max_first_distance_m: f64::NAN,
        ..TrackerConfig::default()
    };
    assert!(bad.validate().is_err());
}
