//! The truth of every circle: its centre's image, whether it is wholly in the image, its size and the area centroid
//! of its image.

use nalgebra::{Matrix2, Matrix2x3, Matrix3x2, Vector2, Vector3};
use roitrack_core::CameraModel;

use super::PhotoPoint;
use super::board::Board;
use super::scene::PhotoScene;

/// Rim points projected to decide whether a circle is fully visible and to measure its size.
const RIM_POINTS: usize = 128;

/// Quadrature of a circle's image centroid: Gauss-Legendre nodes across the radius, equally spaced angles around.
const CENTROID_RADII: usize = 12;

const CENTROID_ANGLES: usize = 64;

/// The truth of every circle.
pub(super) fn truth(scene: &PhotoScene, board: &Board) -> Vec<PhotoPoint> {
    let camera = &scene.camera;
    let r = scene.cam_r_obj;
    let (e1, e2) = (r * board.e1_obj, r * board.e2_obj);
    let rule = gauss_legendre_unit(CENTROID_RADII);
    scene
        .target
        .points()
        .iter()
        .map(|p| {
            let centre_cam = r * p.point_in_obj_m + scene.cam_t_obj_m;
            let centre_px = camera.raw_pixel_from_cam(&centre_cam);
            let radius = scene.circle_diameter_m(p) / 2.0;
            let mut inside = centre_px.is_some();
            let mut distance_sum = 0.0;
            let mut in_front = centre_px.is_some();
            for k in 0..RIM_POINTS {
                let angle = std::f64::consts::TAU * k as f64 / RIM_POINTS as f64;
                let rim = centre_cam + radius * (angle.cos() * e1 + angle.sin() * e2);
                match (camera.raw_pixel_from_cam(&rim), centre_px) {
                    (Some(px), Some(c)) => {
                        inside &= camera.contains_raw_pixel(&px);
                        distance_sum += (px - c).norm();
                    }
                    _ => {
                        inside = false;
                        in_front = false;
                    }
                }
            }
            PhotoPoint {
                id: p.id,
                centre_px,
                fully_visible: inside,
                diameter_px: in_front.then(|| 2.0 * distance_sum / RIM_POINTS as f64),
                area_centroid_px: if in_front {
                    disk_image_centroid(camera, &centre_cam, &e1, &e2, radius, &rule)
                } else {
                    None
                },
            }
        })
        .collect()
}

/// Area centroid (raw pixels) of the image of the disk `centre + a e1 + b e2`, `a² + b² <= radius²` (camera frame):
/// the integrals of the pixel and of the area element `|det d(pixel)/d(a, b)|` over the disk, in polar coordinates,
/// by Gauss-Legendre quadrature across the radius (`rule`, on 0..1) and the trapezoidal rule around (both converge
/// exponentially for this analytic integrand). `None` if part of the disk is not in front of the camera.
fn disk_image_centroid(
    camera: &CameraModel,
    centre: &Vector3<f64>,
    e1: &Vector3<f64>,
    e2: &Vector3<f64>,
    radius: f64,
    rule: &[(f64, f64)],
) -> Option<Vector2<f64>> {
    let k = &camera.intrinsics;
    let camera_matrix = Matrix2::new(k.fx_px, k.skew_px, 0.0, k.fy_px);
    let axes = Matrix3x2::from_columns(&[*e1, *e2]);
    let (mut sum, mut total) = (Vector2::zeros(), 0.0);
    for &(x, weight) in rule {
        let rho = radius * x;
        for a in 0..CENTROID_ANGLES {
            let (sin, cos) = (std::f64::consts::TAU * a as f64 / CENTROID_ANGLES as f64).sin_cos();
            let p = centre + rho * (cos * e1 + sin * e2);
            if p.z <= 0.0 {
                return None;
            }
            let inv_z = 1.0 / p.z;
            let n = Vector2::new(p.x * inv_z, p.y * inv_z);
            let (distorted, jd) = camera.distortion.distort_with_jacobian(&n);
            let dn_dp = Matrix2x3::new(inv_z, 0.0, -n.x * inv_z, 0.0, inv_z, -n.y * inv_z);
            let area = (camera_matrix * jd * dn_dp * axes).determinant().abs();
            let w = weight * rho * area;
            sum += w * k.pixel_from_normalized(&distorted);
            total += w;
        }
    }
    (total > 0.0).then(|| sum / total)
}

/// Gauss-Legendre nodes and weights of order `n` on 0..1 (Newton's method on the Legendre polynomial).
fn gauss_legendre_unit(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut derivative = 1.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let k = k as f64;
                    (p0, p1) = (p1, ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k);
                }
                derivative = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let step = p1 / derivative;
                x -= step;
                if step.abs() < 1e-15 {
                    break;
                }
            }
            let weight = 2.0 / ((1.0 - x * x) * derivative * derivative);
            (0.5 * (x + 1.0), 0.5 * weight)
        })
        .collect()
}
