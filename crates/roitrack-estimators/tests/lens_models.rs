//! The default estimator through every lens model: noise-free measurements of a target at rest give its position.

use nalgebra::Vector3;
use roitrack_core::camera::{Distortion, Equidistant, PlumbBob, RationalPolynomial};
use roitrack_core::{CameraModel, Measurement, MotionState, PinholeIntrinsics, Target};
use roitrack_estimators::{Tracker, TrackerConfig};

/// Noise-free measurements of a target at rest, seen through `camera`, tracked by the default estimator.
fn tracked_position_error_m(camera: &CameraModel) -> f64 {
    let target = Target::grid4x4();
    let truth = MotionState::at_rest(Default::default(), Vector3::new(0.03, -0.02, 0.6));
    let mut tracker =
        Tracker::new(camera.clone(), target.clone(), TrackerConfig::default()).unwrap();
    let mut last = None;
    let mut k = 0;
    for cycle in 0..40 {
        for p in target.points() {
            let t_s = k as f64 * 2.5e-4;
            k += 1;
            let px = camera
                .raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, t_s))
                .unwrap();
            let m = Measurement {
                t_s,
                id: p.id,
                u_px: px.x,
                v_px: px.y,
            };
            if let Some(e) = roitrack_estimators::Estimator::push(&mut tracker, &m).unwrap() {
                last = Some(e);
            }
        }
        let _ = cycle;
    }
    let e = last.expect("estimates");
    (e.state.cam_t_obj_m - truth.cam_t_obj_m).norm()
}

#[test]
fn the_estimator_tracks_through_every_model() {
    let k = PinholeIntrinsics {
        fx_px: 1210.0,
        fy_px: 1205.0,
        skew_px: 0.3,
        cx_px: 640.0,
        cy_px: 512.0,
    };
    for distortion in [
        Distortion::None,
        PlumbBob::from_coefficients([-0.12, 0.05, 5e-4, -3e-4, 0.0]).into(),
        RationalPolynomial::from_coefficients([
            0.42, -0.11, 7e-4, -4e-4, 0.013, 0.71, -0.05, 0.021,
        ])
        .into(),
        Equidistant::from_coefficients([-0.013, 0.021, -0.011, 0.0023]).into(),
    ] {
        let camera = CameraModel::new("c", 1280, 1024, k, distortion).unwrap();
        let error_m = tracked_position_error_m(&camera);
        assert!(
            error_m < 1e-6,
            "{}: position error {error_m} m",
            distortion.model_name()
        );
    }
}
