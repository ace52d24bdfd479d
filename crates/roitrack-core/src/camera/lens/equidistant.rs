//! equidistant, the fisheye model of OpenCV's `cv::fisheye`.

use nalgebra::{Matrix2, Vector2};

use super::{LensExample, LensModel};

/// equidistant (fisheye) lens distortion, OpenCV's `cv::fisheye` model and ROS's `equidistant`: the angle
/// `θ = atan(r)` between the ray and the optical axis becomes `θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`, and the
/// normalised point `(x, y)` becomes `(θd / r) (x, y)`.
///
/// Rays at 90° or more from the axis have no normalised point, so this model covers fields of view under 180°; the
/// estimator's ideal pixels grow without bound towards 90°.
///
/// ```
/// use nalgebra::Vector2;
/// use roitrack_core::camera::{Equidistant, LensModel};
///
/// let d = Equidistant::from_coefficients([-0.01, 0.003, -0.001, 2e-4]);
/// let n = Vector2::new(0.8, -0.5);
/// assert!((d.undistort(&d.distort(&n)).unwrap() - n).norm() < 1e-13);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Equidistant {
    /// Coefficient of `θ³` in `θd`.
    pub k1: f64,
    /// Coefficient of `θ⁵` in `θd`.
    pub k2: f64,
    /// Coefficient of `θ⁷` in `θd`.
    pub k3: f64,
    /// Coefficient of `θ⁹` in `θd`.
    pub k4: f64,
}

impl Equidistant {
    /// `[k1, k2, k3, k4]`, the order of `cv::fisheye` and ROS.
    pub fn from_coefficients(c: [f64; 4]) -> Self {
        Self {
            k1: c[0],
            k2: c[1],
            k3: c[2],
            k4: c[3],
        }
    }

    /// `[k1, k2, k3, k4]`, the order of [`Self::from_coefficients`].
    pub fn coefficients(&self) -> [f64; 4] {
        [self.k1, self.k2, self.k3, self.k4]
    }

    /// `θd(θ)` and its derivative.
    #[inline]
    fn theta_d(&self, theta: f64) -> (f64, f64) {
        let t2 = theta * theta;
        let poly = 1.0 + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4)));
        let d_poly = 1.0
            + t2 * (3.0 * self.k1
                + t2 * (5.0 * self.k2 + t2 * (7.0 * self.k3 + t2 * 9.0 * self.k4)));
        (theta * poly, d_poly)
    }
}

impl LensModel for Equidistant {
    const NAME: &'static str = "equidistant";
    const COEFFICIENT_NAMES: &'static [&'static str] = &["k1", "k2", "k3", "k4"];
    const COUNTS: &'static str = "4";
    const ENDS_AT_90_DEGREES: bool = true;

    fn from_list(c: &[f64]) -> Result<Self, String> {
        match *c {
            [k1, k2, k3, k4] => Ok(Self::from_coefficients([k1, k2, k3, k4])),
            _ => Err(format!(
                "equidistant takes 4 numbers [k1, k2, k3, k4], got {}",
                c.len()
            )),
        }
    }

    type Coefficients = [f64; 4];

    fn coefficient_array(&self) -> [f64; 4] {
        self.coefficients()
    }

    /// Never: with zero coefficients it is still the f-θ lens, `θd = θ`, which no pinhole is.
    fn is_identity(&self) -> bool {
        false
    }

    #[inline]
    fn distort_with_jacobian(&self, n: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let r2 = n.norm_squared();
        let r = r2.sqrt();
        // Below 1e-8 the scale is 1 to within r², as in OpenCV.
        if r <= 1e-8 {
            return (*n, Matrix2::identity());
        }
        let theta = r.atan();
        let (theta_d, d_theta_d) = self.theta_d(theta);
        let scale = theta_d / r;
        // d(scale)/dr, divided by r: the Jacobian is scale I + (d scale / dr / r) n nᵀ.
        let d_scale_over_r = (d_theta_d / (1.0 + r2) - scale) / r2;
        let outer = n * n.transpose();
        (
            n * scale,
            Matrix2::identity() * scale + outer * d_scale_over_r,
        )
    }

    /// Newton's method on the angle `θ` (to 1e-15 rad), then `tan θ`. `None` if it does not converge, or if the angle would be 90° or more (outside the model's
    /// range, or beyond the turning point of `θd(θ)`).
    fn undistort(&self, distorted: &Vector2<f64>) -> Option<Vector2<f64>> {
        let theta_d = distorted.norm();
        if !theta_d.is_finite() {
            return None;
        }
        if theta_d <= 1e-8 {
            return Some(*distorted);
        }
        let half_pi = std::f64::consts::FRAC_PI_2;
        let mut theta = theta_d.min(1.5);
        let mut converged = false;
        for _ in 0..50 {
            let (f, df) = self.theta_d(theta);
            if df <= 0.0 || !df.is_finite() {
                return None;
            }
            let step = (f - theta_d) / df;
            theta -= step;
            if !theta.is_finite() || theta < 0.0 || theta >= half_pi {
                return None;
            }
            if step.abs() < 1e-15 {
                converged = true;
                break;
            }
        }
        let residual = (self.theta_d(theta).0 - theta_d).abs();
        if !converged && residual > 1e-12 {
            return None;
        }
        // The map must be increasing up to θ, or another angle could give the same θd.
        if self.theta_d(theta).1 <= 0.0 {
            return None;
        }
        Some(distorted * (theta.tan() / theta_d))
    }

    fn examples() -> Vec<LensExample> {
        vec![
            // A fisheye seeing 90° off the axis within its image (a 180° field of view), out to 80° off the axis.
            LensExample::new(
                Self::from_coefficients([-0.0052, 0.041, -0.038, 0.0066]),
                80f64.to_radians().tan(),
            ),
            LensExample::new(
                Self::from_coefficients([-0.013, 0.021, -0.011, 0.0023]),
                3.0,
            ),
            LensExample::new(Self::from_coefficients([-0.01, 0.003, -0.001, 2e-4]), 2.0),
        ]
    }
}
