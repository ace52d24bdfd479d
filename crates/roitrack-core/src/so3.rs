//! SO(3): exponential, logarithm, and the left Jacobian with its inverse.
//!
//! Rotations are nalgebra's [`Rotation3`]. A tangent vector `a` (rad) maps to `Exp(a) = I + sin(θ) K + (1 - cos θ) K²`
//! with `θ = |a|`, `K = [a/θ]×` (the paper's eq. 3 prints `1 - cos²`: a typo). Perturbations are on the left:
//! `Exp(a + δ) ≈ Exp(J_l(a) δ) Exp(a)`.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Below this angle (rad) the closed forms lose digits and their Taylor series are used instead.
const SMALL_ANGLE_RAD: f64 = 1e-4;

/// Below this angle (rad) [`rodrigues_coefficients`] uses Taylor series through θ⁸. Their truncation error is below
/// θ¹⁰/10! < 3e-17 relative here, while the closed forms lose `ε/θ²` to cancellation (1e-14 relative at 0.1 rad,
/// 1e-8 at 1e-4): the series are the more accurate side of the switch, and they spare the `sin_cos` of the hot path
/// (the rotation of a blob between its time and the reference time, |W| d, is a few milliradians).
const SERIES_ANGLE_RAD: f64 = 0.1;

/// The coefficients of `Exp(a) = I + s1 K + c1 K²` and `J_l(a) = I + c1 K + c2 K²`, with `K = [a]×` (not normalised)
/// and `θ² = |a|²`: `s1 = sin θ/θ`, `c1 = (1 - cos θ)/θ²`, `c2 = (θ - sin θ)/θ³`.
#[inline]
pub fn rodrigues_coefficients(theta2: f64) -> (f64, f64, f64) {
    if theta2 < SERIES_ANGLE_RAD * SERIES_ANGLE_RAD {
        // Horner in θ², terms through θ⁸.
        let t = theta2;
        let s1 = 1.0 - t / 6.0 * (1.0 - t / 20.0 * (1.0 - t / 42.0 * (1.0 - t / 72.0)));
        let c1 = 0.5 * (1.0 - t / 12.0 * (1.0 - t / 30.0 * (1.0 - t / 56.0 * (1.0 - t / 90.0))));
        let c2 = (1.0 - t / 20.0 * (1.0 - t / 42.0 * (1.0 - t / 72.0 * (1.0 - t / 110.0)))) / 6.0;
        (s1, c1, c2)
    } else {
        let theta = theta2.sqrt();
        let (s, c) = theta.sin_cos();
        (
            s / theta,
            (1.0 - c) / theta2,
            (theta - s) / (theta2 * theta),
        )
    }
}

/// A rotation vector `a` with its [`rodrigues_coefficients`], applying `Exp(a)` and `J_l(a)` by cross products
/// without forming matrices: the hot path of the projection Jacobian.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationIncrement {
    a: Vector3<f64>,
    s1: f64,
    c1: f64,
    c2: f64,
}

impl RotationIncrement {
    /// The increment of rotation vector `a` (rad, axis times angle), its coefficients computed once.
    #[inline]
    pub fn new(a: &Vector3<f64>) -> Self {
        let (s1, c1, c2) = rodrigues_coefficients(a.norm_squared());
        Self { a: *a, s1, c1, c2 }
    }

    /// `Exp(a) v = v + s1 a × v + c1 a × (a × v)`.
    #[inline]
    pub fn rotate(&self, v: &Vector3<f64>) -> Vector3<f64> {
        let av = self.a.cross(v);
        v + av * self.s1 + self.a.cross(&av) * self.c1
    }

    /// The row vectors `bᵀ Exp(a)` and `bᵀ J_l(a)` (as columns), sharing their cross products: `bᵀ K = (b × a)ᵀ`, so
    /// `bᵀ Exp(a) = b + s1 b × a + c1 (b × a) × a` and `bᵀ J_l(a) = b + c1 b × a + c2 (b × a) × a`.
    #[inline]
    pub fn row_times_exp_and_left_jacobian(
        &self,
        b: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let ba = b.cross(&self.a);
        let baa = ba.cross(&self.a);
        (
            b + ba * self.s1 + baa * self.c1,
            b + ba * self.c1 + baa * self.c2,
        )
    }
}

/// The skew-symmetric matrix `[v]×` such that `[v]× x = v × x`.
#[inline]
pub fn hat(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The SO(3) exponential of a rotation vector (rad), exact for every angle.
#[inline]
pub fn exp(a: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::new(*a)
}

/// `r` pulled back onto SO(3) after products of rotations have let round-off accumulate: one Newton-Schulz step
/// `R (3 I - RᵀR) / 2`, which squares the departure from orthonormality (from 1e-15 after a product to below the
/// round-off of the step itself). Why not nalgebra's `renormalize`: it iterates a general polar decomposition and
/// cost 5 % of a control step (perf) for a departure that is always tiny here.
#[inline]
pub fn orthonormalized(r: &Rotation3<f64>) -> Rotation3<f64> {
    let m = r.matrix();
    let gram = m.transpose() * m;
    Rotation3::from_matrix_unchecked(m * (Matrix3::identity() * 3.0 - gram) * 0.5)
}

/// The SO(3) logarithm: the rotation vector (rad, angle in [0, π]) of `r`.
///
/// nalgebra's `scaled_axis` recovers the angle through `acos`, which loses half the digits near zero (about 1e-8 rad);
/// this goes through the unit quaternion and `atan2`, accurate to machine precision at every angle.
pub fn log(r: &Rotation3<f64>) -> Vector3<f64> {
    log_quaternion(&UnitQuaternion::from_rotation_matrix(r))
}

/// The rotation vector (rad) of a unit quaternion, accurate at every angle (see [`log`]).
pub fn log_quaternion(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    // q and -q are the same rotation: pick w >= 0 so the angle is in [0, π].
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let n = v.norm();
    if n < 1e-300 {
        return Vector3::zeros();
    }
    let angle = 2.0 * n.atan2(w);
    v * (angle / n)
}

/// The geodesic angle (rad) between two rotations: `|Log(a⁻¹ b)|`.
pub fn angle_between(a: &Rotation3<f64>, b: &Rotation3<f64>) -> f64 {
    log(&(a.inverse() * b)).norm()
}

/// The left Jacobian `J_l(a) = I + (1 - cos θ)/θ² [a]× + (θ - sin θ)/θ³ [a]×²`.
pub fn left_jacobian(a: &Vector3<f64>) -> Matrix3<f64> {
    let (_, c1, c2) = rodrigues_coefficients(a.norm_squared());
    let k = hat(a);
    Matrix3::identity() + k * c1 + k * k * c2
}

/// The inverse of [`left_jacobian`]: `I - ½ [a]× + (1/θ² - (1 + cos θ)/(2 θ sin θ)) [a]×²`. Singular at θ = 2π.
pub fn left_jacobian_inverse(a: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = a.norm_squared();
    let theta = theta2.sqrt();
    let k = hat(a);
    let c2 = if theta < SMALL_ANGLE_RAD {
        1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    } else {
        let (s, c) = theta.sin_cos();
        1.0 / theta2 - (1.0 + c) / (2.0 * theta * s)
    };
    Matrix3::identity() - k * 0.5 + k * k * c2
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vec3(max: f64) -> impl Strategy<Value = Vector3<f64>> {
        (-max..max, -max..max, -max..max).prop_map(|(x, y, z)| Vector3::new(x, y, z))
    }

    /// Rotation vectors of every scale, so the small-angle branches are always exercised.
    fn tangent() -> impl Strategy<Value = Vector3<f64>> {
        (vec3(1.0), -12.0..0.45f64).prop_map(|(v, log_scale)| v * 10f64.powf(log_scale))
    }

    /// Exp(a + δ) Exp(a)^-1 = Exp(J_l(a) δ + O(δ²)).
    #[test]
    fn left_jacobian_is_the_derivative_of_exp() {
        use rand::Rng;
        roitrack_testkit::check_jacobian(
            "left_jacobian",
            Vector3::zeros(),
            |rng, spread| {
                let axis = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                axis.normalize() * rng.random_range(0.0..3.0) * spread
            },
            &Vector3::repeat(1.0),
            |a, delta| log(&(exp(&(a + delta)) * exp(a).inverse())),
            left_jacobian,
        );
    }

    proptest! {
        #[test]
        fn log_inverts_exp(a in tangent()) {
            // Stay inside the injectivity radius |a| < π.
            prop_assume!(a.norm() < 3.1);
            let back = log(&exp(&a));
            prop_assert!((back - a).norm() <= 1e-14 + 1e-13 * a.norm(), "a = {a:?}, back = {back:?}");
        }

        #[test]
        fn exp_inverts_log(a in vec3(3.0)) {
            let r = exp(&a);
            let again = exp(&log(&r));
            prop_assert!((again.matrix() - r.matrix()).norm() < 1e-13);
        }

        #[test]
        fn exp_matches_rodrigues_with_cos_not_cos_squared(a in vec3(3.0)) {
            let theta = a.norm();
            prop_assume!(theta > 1e-3);
            let k = hat(&(a / theta));
            let rodrigues = Matrix3::identity() + k * theta.sin() + k * k * (1.0 - theta.cos());
            prop_assert!((exp(&a).matrix() - rodrigues).norm() < 1e-14);
        }

        #[test]
        fn left_jacobian_inverse_inverts(a in tangent()) {
            prop_assume!(a.norm() < 3.0);
            let product = left_jacobian(&a) * left_jacobian_inverse(&a);
            prop_assert!((product - Matrix3::identity()).norm() < 1e-12);
        }
    }

    #[test]
    fn series_coefficients_match_the_closed_forms_at_the_switch() {
        // Near 0.1 rad the closed forms are good to about 1e-14 relative: the series must agree with them there, and
        // be continuous across the switch.
        for theta in [0.03, 0.05, 0.08, 0.0999, 0.1, 0.1001, 0.12] {
            let (s, c) = f64::sin_cos(theta);
            let closed = (
                s / theta,
                (1.0 - c) / (theta * theta),
                (theta - s) / theta.powi(3),
            );
            let ours = rodrigues_coefficients(theta * theta);
            for (x, y) in [(ours.0, closed.0), (ours.1, closed.1), (ours.2, closed.2)] {
                assert!((x - y).abs() <= 1e-11 * y, "θ = {theta}: {x} vs {y}");
            }
        }
        let below = rodrigues_coefficients((SERIES_ANGLE_RAD * (1.0 - 1e-12)).powi(2));
        let above = rodrigues_coefficients((SERIES_ANGLE_RAD * (1.0 + 1e-12)).powi(2));
        assert!((below.2 - above.2).abs() < 1e-13);
        assert_eq!(rodrigues_coefficients(0.0), (1.0, 0.5, 1.0 / 6.0));
    }

    #[test]
    fn rotation_increment_matches_the_matrices() {
        let b = Vector3::new(0.7, -1.3, 2.1);
        // Against nalgebra's exponential and the closed-form left Jacobian, on both sides of the series switch.
        for scale in [
            0.0, 1e-9, 1e-7, 1e-5, 0.99e-4, 1.01e-4, 1e-3, 0.05, 0.2, 0.3, 1.5, 2.0, 3.0,
        ] {
            let a = Vector3::new(0.3, -0.5, 0.8) * scale;
            let (e, j) = (*exp(&a).matrix(), left_jacobian(&a));
            let inc = RotationIncrement::new(&a);
            assert!((inc.rotate(&b) - e * b).norm() < 1e-14, "scale {scale}");
            let (be, bj) = inc.row_times_exp_and_left_jacobian(&b);
            assert!((be - e.transpose() * b).norm() < 1e-14);
            assert!((bj - j.transpose() * b).norm() < 1e-14);
        }
    }

    #[test]
    fn orthonormalized_removes_accumulated_round_off() {
        let departure =
            |r: &Rotation3<f64>| (r.matrix().transpose() * r.matrix() - Matrix3::identity()).norm();
        // A rotation spoiled by 1e-9 comes back to machine precision, and moves by no more than the spoiling.
        let r = exp(&Vector3::new(0.4, -1.1, 2.0));
        let spoiled = Rotation3::from_matrix_unchecked(
            r.matrix() + Matrix3::from_fn(|i, j| 1e-9 * ((i * 3 + j) as f64 - 4.0)),
        );
        assert!(departure(&spoiled) > 1e-9);
        let fixed = orthonormalized(&spoiled);
        assert!(departure(&fixed) < 1e-15, "{}", departure(&fixed));
        assert!((fixed.matrix() - r.matrix()).norm() < 1e-8);
        // A million products with a step after each stay orthonormal.
        let step = exp(&Vector3::new(1e-3, -2e-3, 0.5e-3));
        let mut r = Rotation3::identity();
        for _ in 0..1_000_000 {
            r = orthonormalized(&(step * r));
        }
        assert!(departure(&r) < 1e-14, "{}", departure(&r));
    }

    #[test]
    fn small_angle_limits() {
        for scale in [0.0, 1e-12, 1e-8, 1e-5, 0.99e-4, 1.01e-4] {
            let a = Vector3::new(0.3, -0.5, 0.8) * scale;
            // Exp(a) ≈ I + [a]× to first order; J_l(a) ≈ I + ½[a]×.
            let r = exp(&a);
            assert!(
                (r.matrix() - (Matrix3::identity() + hat(&a))).norm() <= a.norm_squared() + 1e-16
            );
            assert!(
                (left_jacobian(&a) - (Matrix3::identity() + hat(&a) * 0.5)).norm()
                    <= a.norm_squared() + 1e-16
            );
            assert!((log(&r) - a).norm() <= 1e-15 * (1.0 + a.norm()));
        }
        // The branch switch is continuous.
        let a = Vector3::new(0.0, 0.0, SMALL_ANGLE_RAD);
        let below = left_jacobian(&(a * (1.0 - 1e-9)));
        let above = left_jacobian(&(a * (1.0 + 1e-9)));
        assert!((below - above).norm() < 1e-12);
        let below = left_jacobian_inverse(&(a * (1.0 - 1e-9)));
        let above = left_jacobian_inverse(&(a * (1.0 + 1e-9)));
        assert!((below - above).norm() < 1e-12);
    }

    #[test]
    fn log_is_accurate_where_acos_is_not() {
        let a = Vector3::new(3e-9, -1e-9, 2e-9);
        let err = (log(&exp(&a)) - a).norm();
        assert!(err < 1e-22, "err = {err}");
    }

    #[test]
    fn log_near_pi() {
        let a = Vector3::new(1.0, 2.0, -0.5).normalize() * (std::f64::consts::PI - 1e-9);
        let back = log(&exp(&a));
        assert!((back - a).norm() < 1e-7);
    }
}
