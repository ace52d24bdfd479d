//! Every camera model against OpenCV's own projections (tests/data/opencv_projections.csv, made by
//! opencv_projections.py beside it), its undistortion against its projection, and its Jacobian against central
//! differences. The estimators on each model are tested in roitrack-estimators.

use nalgebra::{Vector2, Vector3};
use roitrack_core::camera::{Distortion, Equidistant};
use roitrack_core::{CameraModel, PinholeIntrinsics};

struct Row {
    camera: CameraModel,
    point_in_cam_m: Vector3<f64>,
    opencv_px: Vector2<f64>,
}

fn opencv_rows() -> Vec<Row> {
    let text = include_str!("data/opencv_projections.csv");
    let mut rows = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 12, "{line}");
        let n = |i: usize| f[i].parse::<f64>().unwrap();
        let coefficients: Vec<f64> = f[6]
            .split_whitespace()
            .map(|c| c.parse().unwrap())
            .collect();
        let intrinsics = PinholeIntrinsics {
            fx_px: n(1),
            fy_px: n(2),
            skew_px: n(3),
            cx_px: n(4),
            cy_px: n(5),
        };
        let camera = CameraModel::new(
            f[0],
            1280,
            960,
            intrinsics,
            Distortion::from_model(f[0], &coefficients).unwrap(),
        )
        .unwrap();
        rows.push(Row {
            camera,
            point_in_cam_m: Vector3::new(n(7), n(8), n(9)),
            opencv_px: Vector2::new(n(10), n(11)),
        });
    }
    rows
}

#[test]
fn every_model_projects_like_opencv_to_1e_9_px() {
    let rows = opencv_rows();
    let mut worst = std::collections::BTreeMap::<&str, f64>::new();
    for row in &rows {
        let px = row.camera.raw_pixel_from_cam(&row.point_in_cam_m).unwrap();
        let error = (px - row.opencv_px).norm();
        let w = worst.entry(row.camera.distortion.model_name()).or_default();
        *w = w.max(error);
        assert!(
            error < 1e-9,
            "{}: {:?} -> {px:?}, OpenCV {:?} ({error:e} px)",
            row.camera.name,
            row.point_in_cam_m,
            row.opencv_px
        );
    }
    // Every model is in the data, and with the coefficient counts the readers take.
    for model in ["none", "plumb_bob", "rational_polynomial", "equidistant"] {
        assert!(worst.contains_key(model), "{model} missing from the data");
    }
    assert!(rows.len() > 300);
}

#[test]
fn undistortion_inverts_the_projection() {
    for row in opencv_rows() {
        let camera = &row.camera;
        let p = row.point_in_cam_m;
        let ideal = camera.intrinsics.pixel_from_cam(&p).unwrap();
        let raw = row.opencv_px;
        let back = camera.undistort_pixel(&raw).unwrap();
        // Relative to the ideal pixel's distance from the centre: a fisheye's ideal pixels at 80° are 2,000 px out.
        let scale =
            1.0 + (ideal - Vector2::new(camera.intrinsics.cx_px, camera.intrinsics.cy_px)).norm();
        assert!(
            (back - ideal).norm() < 1e-11 * scale.max(1e3),
            "{}: {p:?}: undistorted {back:?}, ideal {ideal:?}",
            camera.name
        );
        // And the raw pixel of the undistorted one is the raw pixel again.
        assert!((camera.distort_pixel(&back) - raw).norm() < 1e-9);
    }
}

#[test]
fn raw_pixel_jacobians_match_central_differences() {
    for row in opencv_rows() {
        let camera = &row.camera;
        let p = row.point_in_cam_m;
        let (px, j) = camera.raw_pixel_with_jacobian_wrt_cam(&p).unwrap();
        assert_eq!(px, camera.raw_pixel_from_cam(&p).unwrap());
        roitrack_testkit::jacobian::check_at(
            &camera.name,
            &p,
            &Vector3::repeat(p.norm()),
            |p, delta| camera.raw_pixel_from_cam(&(p + delta)).unwrap(),
            &j,
        );
        // The 2x2 distortion Jacobian on its own, too.
        let n = Vector2::new(p.x / p.z, p.y / p.z);
        roitrack_testkit::jacobian::check_at(
            &camera.name,
            &n,
            &Vector2::repeat(1.0),
            |n, delta| camera.distortion.distort(&(n + delta)),
            &camera.distortion.distort_with_jacobian(&n).1,
        );
    }
}

#[test]
fn undistortion_over_a_whole_fisheye_image_and_refusal_beyond_its_range() {
    let camera = CameraModel::new(
        "fisheye",
        1280,
        960,
        PinholeIntrinsics {
            fx_px: 285.3,
            fy_px: 285.1,
            skew_px: 0.0,
            cx_px: 640.0,
            cy_px: 480.0,
        },
        Equidistant::from_coefficients([-0.0052, 0.041, -0.038, 0.0066]),
    )
    .unwrap();
    // This lens sees 90° off the axis within the image (a 180° field of view): the image corners are beyond it.
    let theta_d_85 = camera
        .distortion
        .distort(&Vector2::new(85f64.to_radians().tan(), 0.0))
        .x;
    let mut worst: f64 = 0.0;
    let mut count = 0;
    for i in 0..=40 {
        for j in 0..=30 {
            let raw = Vector2::new(i as f64 * 32.0, j as f64 * 32.0);
            if camera.intrinsics.normalized_from_pixel(&raw).norm() > theta_d_85 {
                continue;
            }
            count += 1;
            let ideal = camera.undistort_pixel(&raw).unwrap();
            worst = worst.max((camera.distort_pixel(&ideal) - raw).norm());
        }
    }
    assert!(
        count > 400 && worst < 1e-9,
        "worst round trip {worst} px over {count} pixels"
    );
    // A raw pixel whose ray would be 90° or more off the axis has no ideal pixel: an error, not a wrong answer.
    assert!(
        camera
            .undistort_pixel(&Vector2::new(640.0 + 285.3 * 1.7, 480.0))
            .is_err()
    );
    assert!(camera.undistort_pixel(&Vector2::new(0.0, 0.0)).is_err());
}
