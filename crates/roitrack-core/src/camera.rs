//! The camera: pinhole intrinsics with skew and plumb_bob lens distortion (OpenCV's convention).
//!
//! Pixels come in two kinds. *Raw* pixels are what the sensor measures (distorted). *Ideal* pixels are the pinhole
//! projection `u = fx x/z + s y/z + cx`, `v = fy y/z + cy` of the same ray, with the distortion removed. The estimator
//! works in ideal pixels: measured centroids are undistorted once, on arrival.
//!
//! A camera also says when its pixels were exposed ([`TimeModel`]: one ROI at a time, a global or a rolling shutter,
//! and the exposure duration).

use nalgebra::{Matrix2, Vector2, Vector3};
use thiserror::Error;

use crate::time::{TimeModel, TimeModelError};

/// Why a camera model is unusable, or why a pixel could not be undistorted.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CameraError {
    #[error("{field} must be a finite number, got {value}")]
    NotFinite { field: &'static str, value: f64 },
    #[error("{field} must be positive, got {value}")]
    NotPositive { field: &'static str, value: f64 },
    #[error("image size must be positive, got {width_px} x {height_px}")]
    EmptyImage { width_px: u32, height_px: u32 },
    #[error(
        "undistortion did not converge at raw pixel ({u_px}, {v_px}): the pixel lies outside the region where the \
         distortion model is invertible"
    )]
    UndistortionDiverged { u_px: f64, v_px: f64 },
    #[error("{0}")]
    TimeModel(#[from] TimeModelError),
}

/// Pinhole intrinsics (pixels): the camera matrix `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeIntrinsics {
    pub fx_px: f64,
    pub fy_px: f64,
    pub skew_px: f64,
    pub cx_px: f64,
    pub cy_px: f64,
}

impl PinholeIntrinsics {
    /// Checks that the intrinsics are finite with positive focal lengths (so the camera matrix is invertible).
    pub fn validate(&self) -> Result<(), CameraError> {
        for (field, value) in [
            ("fx", self.fx_px),
            ("fy", self.fy_px),
            ("skew", self.skew_px),
            ("cx", self.cx_px),
            ("cy", self.cy_px),
        ] {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { field, value });
            }
        }
        for (field, value) in [("fx", self.fx_px), ("fy", self.fy_px)] {
            if value <= 0.0 {
                return Err(CameraError::NotPositive { field, value });
            }
        }
        Ok(())
    }

    /// Ideal pixel of a normalised image point (x/z, y/z).
    #[inline]
    pub fn pixel_from_normalized(&self, n: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(
            self.fx_px * n.x + self.skew_px * n.y + self.cx_px,
            self.fy_px * n.y + self.cy_px,
        )
    }

    /// Normalised image point of an ideal pixel (the inverse of [`Self::pixel_from_normalized`]).
    #[inline]
    pub fn normalized_from_pixel(&self, p: &Vector2<f64>) -> Vector2<f64> {
        let y = (p.y - self.cy_px) / self.fy_px;
        Vector2::new((p.x - self.cx_px - self.skew_px * y) / self.fx_px, y)
    }

    /// Ideal pixel of a point in the camera frame, or `None` if it is not in front of the camera.
    #[inline]
    pub fn pixel_from_cam(&self, point_in_cam: &Vector3<f64>) -> Option<Vector2<f64>> {
        if point_in_cam.z <= 0.0 || !point_in_cam.z.is_finite() {
            return None;
        }
        let inv_z = 1.0 / point_in_cam.z;
        Some(self.pixel_from_normalized(&Vector2::new(
            point_in_cam.x * inv_z,
            point_in_cam.y * inv_z,
        )))
    }

    /// d(u, v)/d(point in camera frame), the paper's eq. 24, at a point with z > 0.
    #[inline]
    pub fn pixel_jacobian_wrt_cam(&self, p: &Vector3<f64>) -> nalgebra::Matrix2x3<f64> {
        let inv_z = 1.0 / p.z;
        let xz = p.x * inv_z;
        let yz = p.y * inv_z;
        // [[fx, s], [0, fy]] * [[1/z, 0, -x/z²], [0, 1/z, -y/z²]]
        nalgebra::Matrix2x3::new(
            self.fx_px * inv_z,
            self.skew_px * inv_z,
            -(self.fx_px * xz + self.skew_px * yz) * inv_z,
            0.0,
            self.fy_px * inv_z,
            -self.fy_px * yz * inv_z,
        )
    }
}

/// plumb_bob lens distortion (OpenCV): radial k1, k2, k3 and tangential p1, p2, acting on normalised coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlumbBob {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl PlumbBob {
    /// `[k1, k2, p1, p2, k3]`, the order of ROS camera_info and OpenCV.
    pub fn from_coefficients(c: [f64; 5]) -> Self {
        Self {
            k1: c[0],
            k2: c[1],
            p1: c[2],
            p2: c[3],
            k3: c[4],
        }
    }

    pub fn coefficients(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    pub fn is_identity(&self) -> bool {
        self.coefficients().iter().all(|&c| c == 0.0)
    }

    pub fn validate(&self) -> Result<(), CameraError> {
        let names = ["k1", "k2", "p1", "p2", "k3"];
        for (field, value) in names.into_iter().zip(self.coefficients()) {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { field, value });
            }
        }
        Ok(())
    }

    /// Distorted normalised point of an undistorted one, and the 2x2 Jacobian of that map.
    #[inline]
    pub fn distort_with_jacobian(&self, n: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let d_radial_d_r2 = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let xy = x * y;
        let distorted = Vector2::new(
            x * radial + 2.0 * self.p1 * xy + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * xy,
        );
        let cross = 2.0 * xy * d_radial_d_r2 + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let jacobian = Matrix2::new(
            radial + 2.0 * x * x * d_radial_d_r2 + 2.0 * self.p1 * y + 6.0 * self.p2 * x,
            cross,
            cross,
            radial + 2.0 * y * y * d_radial_d_r2 + 6.0 * self.p1 * y + 2.0 * self.p2 * x,
        );
        (distorted, jacobian)
    }

    #[inline]
    pub fn distort(&self, n: &Vector2<f64>) -> Vector2<f64> {
        self.distort_with_jacobian(n).0
    }

    /// The undistorted normalised point whose distortion is `distorted`, by Newton's method (quadratic convergence,
    /// typically 3-5 iterations), to 1e-14 in normalised units (about 1e-11 px). `None` if it does not converge.
    pub fn undistort(&self, distorted: &Vector2<f64>) -> Option<Vector2<f64>> {
        if self.is_identity() {
            return Some(*distorted);
        }
        let mut n = *distorted;
        for _ in 0..50 {
            let (d, j) = self.distort_with_jacobian(&n);
            let residual = d - distorted;
            if residual.norm() < 1e-14 {
                return Some(n);
            }
            let step = j.try_inverse()? * residual;
            n -= step;
            if !n.x.is_finite() || !n.y.is_finite() {
                return None;
            }
        }
        let residual = (self.distort(&n) - distorted).norm();
        (residual < 1e-11).then_some(n)
    }
}

/// A calibrated camera: image size, pinhole intrinsics, plumb_bob distortion, and when its pixels are exposed.
///
/// ```
/// use nalgebra::{Vector2, Vector3};
/// use roitrack_core::CameraModel;
/// use roitrack_core::time::{Readout, TimeModel};
///
/// let camera = CameraModel::canonical();
/// let px = camera.raw_pixel_from_cam(&Vector3::new(0.01, -0.02, 0.6)).unwrap();
/// assert!((px - Vector2::new(537.0, 462.0)).norm() < 1e-9);
/// // A rolling-shutter version of the same camera, 20 µs a row, 1 ms exposure.
/// let rolling = camera
///     .with_time_model(TimeModel { readout: Readout::RollingShutter { line_delay_s: 20e-6 }, exposure_s: 1e-3 })
///     .unwrap();
/// assert!(rolling.time.is_rolling());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    pub name: String,
    pub width_px: u32,
    pub height_px: u32,
    pub intrinsics: PinholeIntrinsics,
    pub distortion: PlumbBob,
    /// When each blob is exposed (default: sequential ROIs, 100 µs).
    pub time: TimeModel,
}

impl CameraModel {
    /// Builds a camera, refusing non-finite values, non-positive focal lengths and an empty image.
    pub fn new(
        name: impl Into<String>,
        width_px: u32,
        height_px: u32,
        intrinsics: PinholeIntrinsics,
        distortion: PlumbBob,
    ) -> Result<Self, CameraError> {
        if width_px == 0 || height_px == 0 {
            return Err(CameraError::EmptyImage {
                width_px,
                height_px,
            });
        }
        intrinsics.validate()?;
        distortion.validate()?;
        Ok(Self {
            name: name.into(),
            width_px,
            height_px,
            intrinsics,
            distortion,
            time: TimeModel::default(),
        })
    }

    /// The same camera with another time model (refused if invalid).
    pub fn with_time_model(self, time: TimeModel) -> Result<Self, CameraError> {
        time.validate()?;
        Ok(Self { time, ..self })
    }

    /// The canonical camera of SPEC section 6: 1024 x 1024 px, fx = fy = 1500, no skew, centre (512, 512), no distortion.
    pub fn canonical() -> Self {
        Self {
            name: "roitrack_canonical".to_string(),
            width_px: 1024,
            height_px: 1024,
            intrinsics: PinholeIntrinsics {
                fx_px: 1500.0,
                fy_px: 1500.0,
                skew_px: 0.0,
                cx_px: 512.0,
                cy_px: 512.0,
            },
            distortion: PlumbBob::default(),
            time: TimeModel::default(),
        }
    }

    /// A strongly distorting but realistic 1024 x 1024 wide-angle lens (an industrial lens calibrated with OpenCV:
    /// k1 = -0.28, skew 0.8 px), for exercising the distortion paths in tests and benchmarks.
    pub fn wide_angle_example() -> Self {
        Self {
            name: "wide".to_string(),
            width_px: 1024,
            height_px: 1024,
            intrinsics: PinholeIntrinsics {
                fx_px: 1480.0,
                fy_px: 1510.0,
                skew_px: 0.8,
                cx_px: 515.0,
                cy_px: 506.0,
            },
            distortion: PlumbBob::from_coefficients([-0.28, 0.12, 1.2e-3, -8e-4, -0.03]),
            time: TimeModel::default(),
        }
    }

    /// Raw (distorted) pixel of a point in the camera frame, or `None` if it is behind the camera.
    pub fn raw_pixel_from_cam(&self, point_in_cam: &Vector3<f64>) -> Option<Vector2<f64>> {
        if point_in_cam.z <= 0.0 || !point_in_cam.z.is_finite() {
            return None;
        }
        let n = Vector2::new(
            point_in_cam.x / point_in_cam.z,
            point_in_cam.y / point_in_cam.z,
        );
        Some(
            self.intrinsics
                .pixel_from_normalized(&self.distortion.distort(&n)),
        )
    }

    /// Raw (distorted) pixel of an ideal pixel.
    pub fn distort_pixel(&self, ideal: &Vector2<f64>) -> Vector2<f64> {
        let n = self.intrinsics.normalized_from_pixel(ideal);
        self.intrinsics
            .pixel_from_normalized(&self.distortion.distort(&n))
    }

    /// Ideal (undistorted) pixel of a raw measured pixel.
    pub fn undistort_pixel(&self, raw: &Vector2<f64>) -> Result<Vector2<f64>, CameraError> {
        let distorted = self.intrinsics.normalized_from_pixel(raw);
        match self.distortion.undistort(&distorted) {
            Some(n) => Ok(self.intrinsics.pixel_from_normalized(&n)),
            None => Err(CameraError::UndistortionDiverged {
                u_px: raw.x,
                v_px: raw.y,
            }),
        }
    }

    /// Whether a raw pixel lies on the sensor (pixel centres at integer coordinates, edges at -0.5 and size - 0.5).
    pub fn contains_raw_pixel(&self, raw: &Vector2<f64>) -> bool {
        raw.x >= -0.5
            && raw.y >= -0.5
            && raw.x <= self.width_px as f64 - 0.5
            && raw.y <= self.height_px as f64 - 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistortion_round_trip_over_the_whole_image() {
        let camera = CameraModel::wide_angle_example();
        let mut worst_px: f64 = 0.0;
        for i in 0..=64 {
            for j in 0..=64 {
                let raw = Vector2::new(i as f64 * 1023.0 / 64.0, j as f64 * 1023.0 / 64.0);
                let ideal = camera.undistort_pixel(&raw).unwrap();
                worst_px = worst_px.max((camera.distort_pixel(&ideal) - raw).norm());
                // And the other way round, starting from an ideal pixel.
                let raw2 = camera.distort_pixel(&raw);
                worst_px = worst_px.max((camera.undistort_pixel(&raw2).unwrap() - raw).norm());
            }
        }
        assert!(worst_px < 1e-6, "worst round trip error {worst_px} px");
    }

    #[test]
    fn distortion_jacobian_matches_central_differences() {
        let d = CameraModel::wide_angle_example().distortion;
        for n in [
            Vector2::new(0.1, -0.2),
            Vector2::new(-0.3, 0.25),
            Vector2::new(0.0, 0.0),
        ] {
            let (_, j) = d.distort_with_jacobian(&n);
            let h = 1e-7;
            for k in 0..2 {
                let mut e = Vector2::zeros();
                e[k] = h;
                let numeric = (d.distort(&(n + e)) - d.distort(&(n - e))) / (2.0 * h);
                assert!((numeric - j.column(k)).norm() < 1e-8);
            }
        }
    }

    #[test]
    fn skew_sits_in_u_only() {
        let k = CameraModel::wide_angle_example().intrinsics;
        let p = Vector3::new(0.1, 0.2, 1.0);
        let px = k.pixel_from_cam(&p).unwrap();
        assert!((px.x - (1480.0 * 0.1 + 0.8 * 0.2 + 515.0)).abs() < 1e-12);
        assert!((px.y - (1510.0 * 0.2 + 506.0)).abs() < 1e-12);
        assert!((k.normalized_from_pixel(&px) - Vector2::new(0.1, 0.2)).norm() < 1e-15);
    }

    #[test]
    fn pixel_jacobian_matches_central_differences() {
        let k = CameraModel::wide_angle_example().intrinsics;
        let p = Vector3::new(0.05, -0.03, 0.6);
        let j = k.pixel_jacobian_wrt_cam(&p);
        let h = 1e-7;
        for c in 0..3 {
            let mut e = Vector3::zeros();
            e[c] = h;
            let numeric = (k.pixel_from_cam(&(p + e)).unwrap()
                - k.pixel_from_cam(&(p - e)).unwrap())
                / (2.0 * h);
            assert!((numeric - j.column(c)).norm() < 1e-5 * j.norm());
        }
    }

    #[test]
    fn invalid_cameras_are_refused() {
        let mut k = CameraModel::canonical().intrinsics;
        k.fx_px = 0.0;
        assert!(matches!(
            CameraModel::new("x", 10, 10, k, PlumbBob::default()),
            Err(CameraError::NotPositive { field: "fx", .. })
        ));
        k.fx_px = f64::NAN;
        assert!(matches!(
            CameraModel::new("x", 10, 10, k, PlumbBob::default()),
            Err(CameraError::NotFinite { field: "fx", .. })
        ));
        let k = CameraModel::canonical().intrinsics;
        assert!(CameraModel::new("x", 0, 10, k, PlumbBob::default()).is_err());
    }

    #[test]
    fn points_behind_the_camera_do_not_project() {
        let camera = CameraModel::canonical();
        assert!(
            camera
                .raw_pixel_from_cam(&Vector3::new(0.0, 0.0, -1.0))
                .is_none()
        );
        assert!(
            camera
                .intrinsics
                .pixel_from_cam(&Vector3::new(0.0, 0.0, 0.0))
                .is_none()
        );
    }
}
