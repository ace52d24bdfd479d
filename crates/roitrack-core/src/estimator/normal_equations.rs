//! Gauss-Newton normal equations, accumulated row pair by row pair (no per-step allocation), with a conditioning
//! figure and a damped, column-scaled solve.

use nalgebra::{SMatrix, SVector, Vector2};

/// `JᵀWJ` and `JᵀWe` of a least-squares problem with `N` parameters, built one 2-row block at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEquations<const N: usize> {
    pub jtj: SMatrix<f64, N, N>,
    pub jte: SVector<f64, N>,
    /// Σ w |e|² (px²).
    pub weighted_cost: f64,
    /// Σ |e|² (px²), unweighted.
    pub cost: f64,
    /// Number of 2-row blocks (measurements) added.
    pub count: usize,
}

impl<const N: usize> Default for NormalEquations<N> {
    fn default() -> Self {
        Self {
            jtj: SMatrix::zeros(),
            jte: SVector::zeros(),
            weighted_cost: 0.0,
            cost: 0.0,
            count: 0,
        }
    }
}

impl<const N: usize> NormalEquations<N> {
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Adds one measurement: its 2 x N Jacobian, residual `e` = predicted - measured (px), and weight.
    #[inline]
    pub fn add(&mut self, jacobian: &SMatrix<f64, 2, N>, residual: &Vector2<f64>, weight: f64) {
        let jt = jacobian.transpose();
        self.jtj += jt * jacobian * weight;
        self.jte += jt * residual * weight;
        let r2 = residual.norm_squared();
        self.weighted_cost += weight * r2;
        self.cost += r2;
        self.count += 1;
    }

    /// Root mean square of the residual (px, per coordinate), unweighted.
    pub fn residual_rms_px(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            (self.cost / (2 * self.count) as f64).sqrt()
        }
    }

    /// The column scale `1/sqrt(diag JᵀJ)` that makes the problem unit-free (zero columns keep scale 1).
    fn column_scale(&self) -> SVector<f64, N> {
        SVector::from_fn(|i, _| {
            let d = self.jtj[(i, i)];
            if d > 0.0 { 1.0 / d.sqrt() } else { 1.0 }
        })
    }

    /// `JᵀJ` with its columns and rows scaled by [`Self::column_scale`]: unit diagonal.
    fn scaled_jtj(&self) -> SMatrix<f64, N, N> {
        let s = self.column_scale();
        SMatrix::<f64, N, N>::from_fn(|i, j| self.jtj[(i, j)] * s[i] * s[j])
    }

    /// The Gauss-Newton step `-(JᵀJ + μ D)⁻¹ Jᵀe` with Levenberg-Marquardt damping `μ = damping` on the unit-diagonal
    /// scaled problem (0 = Gauss-Newton). `None` if the system cannot be factorised (singular or not finite).
    pub fn solve(&self, damping: f64) -> Option<SVector<f64, N>> {
        let s = self.column_scale();
        let mut scaled = self.scaled_jtj();
        for i in 0..N {
            scaled[(i, i)] += damping;
        }
        let rhs = self.jte.component_mul(&s);
        let scaled_step = scaled.cholesky()?.solve(&rhs);
        let step = -scaled_step.component_mul(&s);
        step.iter().all(|x| x.is_finite()).then_some(step)
    }
}

/// nalgebra's symmetric eigensolver needs a concrete dimension: implemented for the sizes roitrack uses.
macro_rules! impl_inverse_condition {
    ($($n:literal),*) => {$(
        impl NormalEquations<$n> {
            /// Reciprocal condition number of the column-scaled Jacobian: sqrt(λmin / λmax) of the scaled `JᵀJ`.
            /// 1 is perfect, 0 is singular. Independent of the parameters' units.
            pub fn inverse_condition(&self) -> f64 {
                let eigenvalues = self.scaled_jtj().symmetric_eigenvalues();
                let (min, max) = eigenvalues
                    .iter()
                    .fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| (lo.min(e), hi.max(e)));
                if max <= 0.0 || !min.is_finite() {
                    0.0
                } else {
                    (min.max(0.0) / max).sqrt()
                }
            }
        }
    )*};
}
impl_inverse_condition!(2, 3, 6, 12);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_linear_problem_exactly() {
        // e(x) = A x - b, with x* known: one Gauss-Newton step from 0 lands on x*.
        let x_true = SVector::<f64, 3>::new(1.0, -2.0, 0.5);
        let mut ne = NormalEquations::<3>::default();
        for k in 0..5 {
            let a =
                SMatrix::<f64, 2, 3>::from_fn(|i, j| ((k * 7 + i * 3 + j * 5) % 11) as f64 - 5.0);
            let b = a * x_true;
            ne.add(&a, &(-b), 1.0);
        }
        let step = ne.solve(0.0).unwrap();
        assert!((step - x_true).norm() < 1e-12);
        assert!(ne.inverse_condition() > 0.01);
    }

    #[test]
    fn singular_problems_report_zero_conditioning() {
        let mut ne = NormalEquations::<3>::default();
        // The third parameter never appears: a zero column.
        let a = SMatrix::<f64, 2, 3>::new(1.0, 2.0, 0.0, 3.0, -1.0, 0.0);
        ne.add(&a, &Vector2::new(1.0, 1.0), 1.0);
        assert!(ne.inverse_condition() < 1e-12);
        // Two equal columns.
        let mut ne = NormalEquations::<2>::default();
        ne.add(
            &SMatrix::<f64, 2, 2>::new(1.0, 1.0, 2.0, 2.0),
            &Vector2::new(1.0, 0.0),
            1.0,
        );
        assert!(ne.inverse_condition() < 1e-7);
    }
}
