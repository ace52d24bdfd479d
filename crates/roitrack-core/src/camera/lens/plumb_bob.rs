//! plumb_bob, OpenCV's default lens model (`cv::projectPoints` with 4 or 5 coefficients).

use nalgebra::{Matrix2, Vector2};

use super::{LensExample, LensModel, undistort_by_newton};

/// plumb_bob lens distortion (OpenCV): radial k1, k2, k3 and tangential p1, p2, acting on normalised coordinates:
/// the radial factor `1 + k1 r² + k2 r⁴ + k3 r⁶` and the tangential terms `p1 p2`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlumbBob {
    /// Radial coefficient of `r²`.
    pub k1: f64,
    /// Radial coefficient of `r⁴`.
    pub k2: f64,
    /// First tangential coefficient: adds `2 p1 x y` to `x` and `p1 (r² + 2 y²)` to `y`.
    pub p1: f64,
    /// Second tangential coefficient: adds `p2 (r² + 2 x²)` to `x` and `2 p2 x y` to `y`.
    pub p2: f64,
    /// Radial coefficient of `r⁶` (0 when a file gives 4 coefficients).
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

    /// `[k1, k2, p1, p2, k3]`, the order of [`Self::from_coefficients`].
    pub fn coefficients(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }
}

impl LensModel for PlumbBob {
    const NAME: &'static str = "plumb_bob";
    const COEFFICIENT_NAMES: &'static [&'static str] = &["k1", "k2", "p1", "p2", "k3"];
    const COUNTS: &'static str = "4 or 5";

    /// 4 (`k3 = 0`) or 5 coefficients.
    fn from_list(c: &[f64]) -> Result<Self, String> {
        match *c {
            [k1, k2, p1, p2] => Ok(Self::from_coefficients([k1, k2, p1, p2, 0.0])),
            [k1, k2, p1, p2, k3] => Ok(Self::from_coefficients([k1, k2, p1, p2, k3])),
            _ => Err(format!(
                "plumb_bob takes 4 or 5 numbers [k1, k2, p1, p2(, k3)], got {} (8 would be rational_polynomial)",
                c.len()
            )),
        }
    }

    type Coefficients = [f64; 5];

    fn coefficient_array(&self) -> [f64; 5] {
        self.coefficients()
    }

    #[inline]
    fn distort_with_jacobian(&self, n: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let r2 = n.x * n.x + n.y * n.y;
        let (radial, d_radial_d_r2) = radial_polynomial(r2, self.k1, self.k2, self.k3);
        radial_tangential(n, r2, radial, d_radial_d_r2, self.p1, self.p2)
    }

    /// Newton's method (quadratic convergence, typically 3-5 iterations), to 1e-14 in normalised units (about
    /// 1e-11 px); the identity returns the point as it is.
    fn undistort(&self, distorted: &Vector2<f64>) -> Option<Vector2<f64>> {
        if self.is_identity() {
            return Some(*distorted);
        }
        undistort_by_newton(distorted, |n| self.distort_with_jacobian(n))
    }

    fn examples() -> Vec<LensExample> {
        vec![
            // The wide-angle example camera's lens (an industrial lens calibrated with OpenCV): barrel, folding back
            // near r = 1.
            LensExample::new(
                Self::from_coefficients([-0.28, 0.12, 1.2e-3, -8e-4, -0.03]),
                0.7,
            ),
            // Four coefficients, as cv::calibrateCamera with CALIB_FIX_K3 gives them.
            LensExample::new(
                Self::from_coefficients([-0.12, 0.05, 5e-4, -3e-4, 0.0]),
                1.0,
            ),
            // Pincushion.
            LensExample::new(
                Self::from_coefficients([0.15, 0.02, -1e-3, 2e-3, 0.01]),
                1.0,
            ),
        ]
    }
}

/// The polynomial `1 + k1 r² + k2 r⁴ + k3 r⁶` of `r2 = r²` (Horner's form) and its derivative `d / d r²`: plumb_bob's
/// radial factor, and each of the numerator and the denominator of rational_polynomial's.
#[inline(always)]
pub(super) fn radial_polynomial(r2: f64, k1: f64, k2: f64, k3: f64) -> (f64, f64) {
    (
        1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)),
        k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3),
    )
}

/// The Brown-Conrady form shared by plumb_bob and rational_polynomial: the normalised point `n` (with `r2 = |n|²`)
/// scaled by the radial factor `radial(r²)` plus the tangential terms `p1`, `p2`, and the 2x2 Jacobian of that map
/// from `radial` and its derivative `d radial / d r²`.
#[inline(always)]
pub(super) fn radial_tangential(
    n: &Vector2<f64>,
    r2: f64,
    radial: f64,
    d_radial_d_r2: f64,
    p1: f64,
    p2: f64,
) -> (Vector2<f64>, Matrix2<f64>) {
    let (x, y) = (n.x, n.y);
    let xy = x * y;
    let distorted = Vector2::new(
        x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy,
    );
    let cross = 2.0 * xy * d_radial_d_r2 + 2.0 * p1 * x + 2.0 * p2 * y;
    let jacobian = Matrix2::new(
        radial + 2.0 * x * x * d_radial_d_r2 + 2.0 * p1 * y + 6.0 * p2 * x,
        cross,
        cross,
        radial + 2.0 * y * y * d_radial_d_r2 + 6.0 * p1 * y + 2.0 * p2 * x,
    );
    (distorted, jacobian)
}
