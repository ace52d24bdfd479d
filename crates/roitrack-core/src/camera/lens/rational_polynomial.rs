//! rational_polynomial, OpenCV's `CALIB_RATIONAL_MODEL`.

use nalgebra::{Matrix2, Vector2};

use super::plumb_bob::{radial_polynomial, radial_tangential};
use super::{LensExample, LensModel, undistort_by_newton};

/// rational_polynomial lens distortion (OpenCV's `CALIB_RATIONAL_MODEL`, ROS's `rational_polynomial`): the radial
/// factor `(1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)` and plumb_bob's tangential terms.
///
/// ```
/// use nalgebra::Vector2;
/// use roitrack_core::camera::{LensModel, RationalPolynomial};
///
/// let d = RationalPolynomial::from_coefficients([0.1, -0.02, 1e-3, -5e-4, 0.0, 0.05, 0.0, 0.0]);
/// let n = Vector2::new(0.2, -0.1);
/// assert!((d.undistort(&d.distort(&n)).unwrap() - n).norm() < 1e-13);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RationalPolynomial {
    /// Numerator coefficient of `r²`.
    pub k1: f64,
    /// Numerator coefficient of `r⁴`.
    pub k2: f64,
    /// First tangential coefficient, as [`super::PlumbBob::p1`].
    pub p1: f64,
    /// Second tangential coefficient, as [`super::PlumbBob::p2`].
    pub p2: f64,
    /// Numerator coefficient of `r⁶`.
    pub k3: f64,
    /// Denominator coefficient of `r²`.
    pub k4: f64,
    /// Denominator coefficient of `r⁴`.
    pub k5: f64,
    /// Denominator coefficient of `r⁶`.
    pub k6: f64,
}

impl RationalPolynomial {
    /// `[k1, k2, p1, p2, k3, k4, k5, k6]`, the order of ROS camera_info and OpenCV.
    pub fn from_coefficients(c: [f64; 8]) -> Self {
        Self {
            k1: c[0],
            k2: c[1],
            p1: c[2],
            p2: c[3],
            k3: c[4],
            k4: c[5],
            k5: c[6],
            k6: c[7],
        }
    }

    /// `[k1, k2, p1, p2, k3, k4, k5, k6]`, the order of [`Self::from_coefficients`].
    pub fn coefficients(&self) -> [f64; 8] {
        [
            self.k1, self.k2, self.p1, self.p2, self.k3, self.k4, self.k5, self.k6,
        ]
    }
}

impl LensModel for RationalPolynomial {
    const NAME: &'static str = "rational_polynomial";
    const COEFFICIENT_NAMES: &'static [&'static str] =
        &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"];
    const COUNTS: &'static str = "8";

    /// 8 coefficients, or OpenCV's 12 or 14 when the thin-prism and tilt terms past the eighth (which roitrack does
    /// not model) are zero.
    fn from_list(c: &[f64]) -> Result<Self, String> {
        let extra_zero = |rest: &[f64]| rest.iter().all(|&c| c == 0.0);
        match c.split_first_chunk::<8>() {
            Some((eight, rest))
                if rest.is_empty() || (matches!(rest.len(), 4 | 6) && extra_zero(rest)) =>
            {
                Ok(Self::from_coefficients(*eight))
            }
            _ => Err(format!(
                "rational_polynomial takes 8 numbers [k1, k2, p1, p2, k3, k4, k5, k6], got {} (OpenCV's 12 or 14 \
                 only with the thin-prism and tilt terms after the 8th zero)",
                c.len()
            )),
        }
    }

    type Coefficients = [f64; 8];

    fn coefficient_array(&self) -> [f64; 8] {
        self.coefficients()
    }

    #[inline]
    fn distort_with_jacobian(&self, n: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let r2 = n.x * n.x + n.y * n.y;
        let (num, d_num) = radial_polynomial(r2, self.k1, self.k2, self.k3);
        let (den, d_den) = radial_polynomial(r2, self.k4, self.k5, self.k6);
        let d_radial_d_r2 = (d_num * den - num * d_den) / (den * den);
        radial_tangential(n, r2, num / den, d_radial_d_r2, self.p1, self.p2)
    }

    /// Newton's method, to 1e-14 in normalised units.
    fn undistort(&self, distorted: &Vector2<f64>) -> Option<Vector2<f64>> {
        undistort_by_newton(distorted, |n| self.distort_with_jacobian(n))
    }

    fn examples() -> Vec<LensExample> {
        vec![
            // A wide-angle lens as OpenCV's rational model calibrates it: the numerator and denominator both large.
            LensExample::new(
                Self::from_coefficients([0.42, -0.11, 7e-4, -4e-4, 0.013, 0.71, -0.05, 0.021]),
                1.0,
            ),
            // A mild one with the denominator alone.
            LensExample::new(
                Self::from_coefficients([0.1, -0.02, 1e-3, -5e-4, 0.0, 0.05, 0.0, 0.0]),
                1.0,
            ),
        ]
    }
}
