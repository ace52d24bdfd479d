//! Gauss-Newton normal equations, accumulated row pair by row pair (no per-step allocation), with a conditioning
//! figure and a damped, column-scaled solve.

use nalgebra::{SMatrix, SVector, Vector2};

/// `JᵀWJ` and `JᵀWe` of a least-squares problem with `N` parameters, built one 2-row block at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEquations<const N: usize> {
    /// Upper triangle of `JᵀWJ` (the lower one is not maintained: use [`Self::symmetric_jtj`]).
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
    ///
    /// Only the upper triangle of `JᵀJ` is accumulated (half the work); [`Self::jtj`] is symmetrised on read by
    /// [`Self::symmetric_jtj`], and every method here uses it.
    #[inline]
    pub fn add(&mut self, jacobian: &SMatrix<f64, 2, N>, residual: &Vector2<f64>, weight: f64) {
        // Column-major storage: the 2 x N Jacobian is N pairs, `JᵀJ`'s column j is jtj[j N .. j N + N].
        let pairs = jacobian.as_slice();
        let jtj = self.jtj.as_mut_slice();
        for (j, (column, pair_j)) in jtj
            .chunks_exact_mut(N)
            .zip(pairs.chunks_exact(2))
            .enumerate()
        {
            let (a0, a1) = (pair_j[0] * weight, pair_j[1] * weight);
            for (c, pair_i) in column[..=j].iter_mut().zip(pairs.chunks_exact(2)) {
                *c += a0 * pair_i[0] + a1 * pair_i[1];
            }
            self.jte[j] += a0 * residual.x + a1 * residual.y;
        }
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
    pub fn column_scale(&self) -> SVector<f64, N> {
        SVector::from_fn(|i, _| {
            let d = self.jtj[(i, i)];
            if d > 0.0 { 1.0 / d.sqrt() } else { 1.0 }
        })
    }

    /// The full symmetric `JᵀWJ`.
    pub fn symmetric_jtj(&self) -> SMatrix<f64, N, N> {
        SMatrix::<f64, N, N>::from_fn(|i, j| {
            if i <= j {
                self.jtj[(i, j)]
            } else {
                self.jtj[(j, i)]
            }
        })
    }

    /// `JᵀJ` with its columns and rows scaled by [`Self::column_scale`]: unit diagonal.
    fn scaled_jtj(&self) -> SMatrix<f64, N, N> {
        let s = self.column_scale();
        SMatrix::<f64, N, N>::from_fn(|i, j| {
            let v = if i <= j {
                self.jtj[(i, j)]
            } else {
                self.jtj[(j, i)]
            };
            v * s[i] * s[j]
        })
    }

    /// The step (as [`Self::solve`]) and an estimate of the reciprocal condition number (as
    /// [`Self::inverse_condition`]) from one Cholesky factorisation: λmax by power iteration, λmin by inverse
    /// iteration on the factor, a few iterations each (Rayleigh quotients: λmin is over-estimated by a few percent at
    /// most when the two smallest eigenvalues are close, and converges fast when the window is near-degenerate, which
    /// is what the gate must catch). Measured against the eigenvalue figure ([`Self::inverse_condition`]) on 16-point
    /// windows of orthoglide and random: 0.4 % on the bench window, at most 33 % above it (an over-estimate, as a
    /// Rayleigh quotient is); exactly singular windows give 0. `None` (singular) when the factorisation fails.
    pub fn solve_with_conditioning(&self) -> Option<(SVector<f64, N>, f64)> {
        let s = self.column_scale();
        let scaled = self.scaled_jtj();
        let cholesky = scaled.cholesky()?;
        let step = -cholesky
            .solve(&self.jte.component_mul(&s))
            .component_mul(&s);
        if !step.iter().all(|x| x.is_finite()) {
            return None;
        }
        const ITERATIONS: usize = 4;
        // A start vector with components along every eigenvector in practice.
        let start = SVector::<f64, N>::from_fn(|i, _| 1.0 + 0.37 * i as f64);
        let mut x = start.normalize();
        for _ in 0..ITERATIONS {
            x = (scaled * x).normalize();
        }
        let lambda_max = x.dot(&(scaled * x));
        let mut y = start.normalize();
        for _ in 0..ITERATIONS {
            let next = cholesky.solve(&y);
            let norm = next.norm();
            if !norm.is_finite() || norm == 0.0 {
                return Some((step, 0.0));
            }
            y = next / norm;
        }
        let lambda_min = y.dot(&(scaled * y));
        let inverse_condition = if lambda_max > 0.0 {
            (lambda_min.max(0.0) / lambda_max).sqrt()
        } else {
            0.0
        };
        Some((step, inverse_condition))
    }

    /// The conditioning estimate of [`Self::solve_with_conditioning`] alone (0 when singular): a quarter of the cost
    /// of the exact eigenvalue figure.
    pub fn fast_inverse_condition(&self) -> f64 {
        self.solve_with_conditioning().map_or(0.0, |(_, c)| c)
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
        let (fast_step, fast_condition) = ne.solve_with_conditioning().unwrap();
        assert!((fast_step - x_true).norm() < 1e-12);
        assert!((fast_condition - ne.inverse_condition()).abs() < 0.05 * ne.inverse_condition());
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
