//! The object-space error of a pose with the translation eliminated: a quadratic form in the rotation's nine
//! entries (Terzakis and Lourakis, SQPnP, ECCV 2020), built once in O(n) and then evaluated and minimised over SO(3)
//! at a cost that does not depend on the number of points.
//!
//! With `Q_i = I - y_i y_iᵀ` (unit bearing `y_i`) the projector onto the plane normal to the ray of point `i`, the
//! object-space error is `E(R, t) = Σ |Q_i (R x_i + t)|²`, the squared distances of the posed points from their
//! rays. Writing `R x_i = A_i r` with `r` the column-major entries of `R`, the best translation is linear in `r`,
//! `t = P r` with `P = -(Σ Q_i)⁻¹ Σ Q_i A_i`, and then `E = rᵀ Ω r` with
//!
//! ```text
//! Ω = Σ A_iᵀ Q_i A_i - Bᵀ (Σ Q_i)⁻¹ B,   B = Σ Q_i A_i,   (Σ A_iᵀ Q_i A_i) block (k, l) = Σ x_ik x_il Q_i
//! ```
//!
//! Its minima over SO(3) are the candidate poses; Gauss-Newton on a right perturbation `R exp([δ]×)` reaches the one
//! nearest a start in a few steps of 9 x 9 algebra.

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector3};

type Matrix9 = SMatrix<f64, 9, 9>;
type Matrix9x3 = SMatrix<f64, 9, 3>;
type Vector9 = SVector<f64, 9>;

/// `E(R) = rᵀ Ω r` and the best translation `t = P r`, for points centred on their centroid.
pub(super) struct ObjectSpaceCost {
    omega: Matrix9,
    /// `P` of the module's docs: the best translation (of the centred points) from the rotation's entries.
    translation_of: SMatrix<f64, 3, 9>,
}

impl ObjectSpaceCost {
    /// From centred model points and the bearings they are seen along (any length). `None` if the bearings are all
    /// parallel (no translation can be solved for).
    pub(super) fn new(centred_points: &[Vector3<f64>], bearings: &[Vector3<f64>]) -> Option<Self> {
        // Sums of x_ik x_il Q_i (6 point products k <= l) and x_ik Q_i, each a symmetric 3 x 3 matrix kept as its 6
        // upper entries (xx, xy, xz, yy, yz, zz).
        let mut products = [[0.0f64; 6]; 6];
        let mut firsts = [[0.0f64; 6]; 3];
        let mut q_sum = [0.0f64; 6];
        for (x, y) in centred_points.iter().zip(bearings) {
            let y = y.try_normalize(0.0)?;
            let q = [
                1.0 - y.x * y.x,
                -y.x * y.y,
                -y.x * y.z,
                1.0 - y.y * y.y,
                -y.y * y.z,
                1.0 - y.z * y.z,
            ];
            let pairs = [
                x.x * x.x,
                x.x * x.y,
                x.x * x.z,
                x.y * x.y,
                x.y * x.z,
                x.z * x.z,
            ];
            for e in 0..6 {
                q_sum[e] += q[e];
                for a in 0..3 {
                    firsts[a][e] += x[a] * q[e];
                }
                for (k, w) in pairs.iter().enumerate() {
                    products[k][e] += w * q[e];
                }
            }
        }
        let symmetric =
            |u: &[f64; 6]| Matrix3::new(u[0], u[1], u[2], u[1], u[3], u[4], u[2], u[4], u[5]);
        let (products, firsts, q_sum) = (
            products.map(|u| symmetric(&u)),
            firsts.map(|u| symmetric(&u)),
            symmetric(&q_sum),
        );
        let q_inverse = q_sum.try_inverse()?;
        let mut omega = Matrix9::zeros();
        let mut translation_of = SMatrix::<f64, 3, 9>::zeros();
        let mut k = 0;
        for a in 0..3 {
            translation_of
                .fixed_view_mut::<3, 3>(0, 3 * a)
                .copy_from(&(-q_inverse * firsts[a]));
            for b in a..3 {
                let block = products[k] - firsts[a] * q_inverse * firsts[b];
                omega.fixed_view_mut::<3, 3>(3 * a, 3 * b).copy_from(&block);
                if a != b {
                    omega
                        .fixed_view_mut::<3, 3>(3 * b, 3 * a)
                        .copy_from(&block.transpose());
                }
                k += 1;
            }
        }
        omega.iter().all(|x| x.is_finite()).then_some(Self {
            omega,
            translation_of,
        })
    }

    /// `E(R)` (m², in the centred points' units).
    pub(super) fn cost(&self, r: &Rotation3<f64>) -> f64 {
        let v = entries(r);
        v.dot(&(self.omega * v))
    }

    /// The best translation of the centred points for `r`.
    pub(super) fn translation(&self, r: &Rotation3<f64>) -> Vector3<f64> {
        self.translation_of * entries(r)
    }

    /// The local minimum of `E` nearest `start` (Gauss-Newton on SO(3), halving a step that raises the cost), and its
    /// cost.
    pub(super) fn minimise(
        &self,
        start: &Rotation3<f64>,
        max_iterations: usize,
    ) -> (Rotation3<f64>, f64) {
        let mut r = *start;
        let mut cost = self.cost(&r);
        for _ in 0..max_iterations {
            let before = cost;
            let j = perturbation_jacobian(&r);
            let omega_j: Matrix9x3 = self.omega * j;
            let h = j.transpose() * omega_j;
            let g = omega_j.transpose() * entries(&r);
            let Some(h_inverse) = h.try_inverse() else {
                break;
            };
            let mut step = -(h_inverse * g);
            let mut improved = false;
            for _ in 0..4 {
                let next =
                    roitrack_core::so3::orthonormalized(&(r * roitrack_core::so3::exp(&step)));
                let next_cost = self.cost(&next);
                if next_cost <= cost {
                    improved = next_cost < cost;
                    r = next;
                    cost = next_cost;
                    break;
                }
                step *= 0.5;
            }
            // Converged for ranking minima (the reprojection refinement that follows polishes the one it takes): the
            // cost fell by less than a millionth, or the step is below any noise.
            if !improved || step.norm() < 1e-9 || before - cost <= 1e-6 * before {
                break;
            }
        }
        (r, cost)
    }
}

/// The column-major entries of `r`.
fn entries(r: &Rotation3<f64>) -> Vector9 {
    Vector9::from_column_slice(r.matrix().as_slice())
}

/// `d entries(R exp([δ]×)) / dδ` at `δ = 0`: column `k` of `R [δ]×` is `R (δ × e_k) = -R [e_k]× δ`.
fn perturbation_jacobian(r: &Rotation3<f64>) -> Matrix9x3 {
    let mut j = Matrix9x3::zeros();
    for k in 0..3 {
        let block = -(r.matrix() * roitrack_core::so3::hat(&Vector3::ith(k, 1.0)));
        j.fixed_view_mut::<3, 3>(3 * k, 0).copy_from(&block);
    }
    j
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> (Vec<Vector3<f64>>, Rotation3<f64>, Vector3<f64>) {
        let points: Vec<Vector3<f64>> = (0..7)
            .map(|i| {
                let f = i as f64;
                Vector3::new(
                    (1.3 * f).sin() * 0.05,
                    (0.7 * f).cos() * 0.04,
                    0.01 * (f - 3.0),
                )
            })
            .collect();
        let centre = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
        let centred = points.iter().map(|p| p - centre).collect();
        (
            centred,
            Rotation3::from_euler_angles(0.4, -0.3, 1.1),
            Vector3::new(0.02, -0.03, 0.7),
        )
    }

    /// `rᵀ Ω r` is the object-space error at the best translation, and that translation is `P r`.
    #[test]
    fn the_quadratic_form_is_the_object_space_error() {
        let (points, r, t) = scene();
        let bearings: Vec<Vector3<f64>> = points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                r * p + t + Vector3::new(1e-3 * (i as f64).sin(), 2e-3 * (i as f64).cos(), 0.0)
            })
            .collect();
        let cost = ObjectSpaceCost::new(&points, &bearings).unwrap();
        let other = Rotation3::from_euler_angles(0.45, -0.2, 1.0);
        let t_best = cost.translation(&other);
        let error = |t: &Vector3<f64>| -> f64 {
            points
                .iter()
                .zip(&bearings)
                .map(|(p, y)| {
                    let y = y.normalize();
                    let q = Matrix3::identity() - y * y.transpose();
                    (q * (other * p + t)).norm_squared()
                })
                .sum()
        };
        let (e, c) = (error(&t_best), cost.cost(&other));
        assert!((e - c).abs() < 1e-9 * e, "{e} {c}");
        // Any other translation does worse (the best is a minimum).
        for d in [Vector3::x(), Vector3::y(), Vector3::z()] {
            assert!(error(&(t_best + 1e-4 * d)) > error(&t_best));
        }
    }

    /// From a start 20 degrees off, the minimum of noise-free data is the true pose.
    #[test]
    fn minimise_reaches_the_true_rotation() {
        let (points, r, t) = scene();
        let bearings: Vec<Vector3<f64>> = points.iter().map(|p| r * p + t).collect();
        let cost = ObjectSpaceCost::new(&points, &bearings).unwrap();
        let start = r * Rotation3::new(Vector3::new(0.2, -0.2, 0.2));
        let (found, e) = cost.minimise(&start, 30);
        assert!(
            roitrack_core::so3::angle_between(&found, &r) < 1e-9,
            "{}",
            roitrack_core::so3::angle_between(&found, &r)
        );
        assert!(e < 1e-20);
        assert!((cost.translation(&found) - t).norm() < 1e-9);
    }

    /// The Jacobian of the rotation's entries against central differences.
    #[test]
    fn perturbation_jacobian_matches_central_differences() {
        roitrack_testkit::check_jacobian(
            "rotation entries under a right perturbation",
            Rotation3::identity(),
            |rng, spread| {
                use rand::Rng;
                let axis = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
                roitrack_core::so3::exp(&(axis * std::f64::consts::PI * spread))
            },
            &Vector3::repeat(1.0),
            |r, d| entries(&(r * roitrack_core::so3::exp(d))),
            perturbation_jacobian,
        );
    }
}
