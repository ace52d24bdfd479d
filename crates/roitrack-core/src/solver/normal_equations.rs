//! Gauss-Newton normal equations, accumulated measurement by measurement in batches (no allocation), with a
//! conditioning figure and a damped, column-scaled solve. The builder is the solver's [`ResidualSink`]; problems never
//! see it.

use nalgebra::{SMatrix, SVector, Vector2};

use super::ResidualSink;
use super::cholesky::FixedCholesky;

/// `JᵀWJ` and `JᵀWe` of a least-squares problem with `N` parameters at one parameter value, with its cost: what
/// [`super::normal_equations`] and every [`super::solve`] return. Read-only outside the solver.
///
/// ```
/// use nalgebra::{SMatrix, SVector, Vector2};
/// use roitrack_core::solver::{LeastSquaresProblem, ResidualSink, normal_equations};
///
/// /// Fit `x` to two measurements `(x0, x1) = (1, 3)`: residuals `x - (1, 3)`.
/// struct Mean;
/// impl LeastSquaresProblem<1> for Mean {
///     type Params = f64;
///     fn linearize<S: ResidualSink<1>>(&self, x: &f64, sink: &mut S) {
///         let j = SMatrix::<f64, 2, 1>::new(1.0, 1.0);
///         sink.add(&j, &Vector2::new(x - 1.0, x - 3.0), 1.0);
///     }
///     fn apply_step(&self, x: &f64, step: &SVector<f64, 1>) -> f64 {
///         x + step[0]
///     }
/// }
/// let ne = normal_equations(&Mean, &0.0);
/// assert_eq!(ne.count(), 1);
/// assert_eq!(ne.cost_px2(), 10.0);
/// assert!((ne.residual_rms_px() - 5f64.sqrt()).abs() < 1e-15);
/// // The Gauss-Newton step to the mean, 2, and the conditioning of a single parameter, 1.
/// let (step, inverse_condition) = ne.solve_with_conditioning().unwrap();
/// assert!((step[0] - 2.0).abs() < 1e-12 && (inverse_condition - 1.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEquations<const N: usize> {
    /// Upper triangle of `JᵀWJ` (the lower one is not maintained: use [`Self::symmetric_jtj`]).
    pub(crate) jtj: SMatrix<f64, N, N>,
    pub(crate) jte: SVector<f64, N>,
    /// Σ w |e|² (px²); infinite when a measurement could not be evaluated.
    pub(crate) weighted_cost: f64,
    /// Σ |e|² (px²), unweighted; infinite when a measurement could not be evaluated.
    pub(crate) cost: f64,
    /// Number of 2-row blocks (measurements) added.
    pub(crate) count: usize,
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
    /// Σ |e|² (px²), unweighted; infinite when a measurement could not be evaluated (a point behind the camera).
    pub fn cost_px2(&self) -> f64 {
        self.cost
    }

    /// Σ w |e|² (px²), the cost the solver minimises (the weights of a robust loss applied).
    pub fn weighted_cost_px2(&self) -> f64 {
        self.weighted_cost
    }

    /// Number of measurements (2-row blocks) in the equations.
    pub fn count(&self) -> usize {
        self.count
    }

    /// `JᵀWe`: minus the gradient direction of the cost.
    pub fn jte(&self) -> &SVector<f64, N> {
        &self.jte
    }

    /// `σ² (JᵀWJ)⁻¹`: the covariance of the least-squares estimate for measurements of standard deviation `sigma_px`
    /// per axis; `None` when `JᵀWJ` is singular.
    pub fn covariance(&self, sigma_px: f64) -> Option<SMatrix<f64, N, N>> {
        self.symmetric_jtj()
            .try_inverse()
            .map(|inv| inv * (sigma_px * sigma_px))
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
    pub(crate) fn column_scale(&self) -> SVector<f64, N> {
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

    /// The undamped Gauss-Newton step and an estimate of the reciprocal condition number (as
    /// [`Self::inverse_condition`]) from one Cholesky factorisation: λmax by power iteration, λmin by inverse
    /// iteration on the factor, a few iterations each (Rayleigh quotients: λmin is over-estimated by a few percent at
    /// most when the two smallest eigenvalues are close, and converges fast when the window is near-degenerate, which
    /// is what the gate must catch). Measured against the eigenvalue figure ([`Self::inverse_condition`]) on 16-point
    /// windows of orthoglide and random: 0.4 % on the bench window, at most 33 % above it (an over-estimate, as a
    /// Rayleigh quotient is); exactly singular windows give 0. `None` (singular) when the factorisation fails.
    pub fn solve_with_conditioning(&self) -> Option<(SVector<f64, N>, f64)> {
        let s = self.column_scale();
        let scaled = self.scaled_jtj();
        let cholesky = FixedCholesky::factor(&scaled)?;
        let step = -cholesky
            .solve(&self.jte.component_mul(&s))
            .component_mul(&s);
        if !step.iter().all(|x| x.is_finite()) {
            return None;
        }
        const ITERATIONS: usize = 4;
        // A start vector with components along every eigenvector in practice. The two iterations are independent
        // chains, run in one loop so that the processor overlaps them; they are not normalised on the way (the
        // Rayleigh quotients do not depend on the scale): the power iterate grows at most N⁴ (unit diagonal), the
        // inverse one λmin⁻⁴, which overflows only for windows singular to working precision (reported as 0).
        let start = SVector::<f64, N>::from_fn(|i, _| 1.0 + 0.37 * i as f64);
        let (mut x, mut y) = (start, start);
        for _ in 0..ITERATIONS {
            x = scaled * x;
            y = cholesky.solve(&y);
        }
        let rayleigh = |v: &SVector<f64, N>| v.dot(&(scaled * v)) / v.norm_squared();
        let lambda_max = rayleigh(&x);
        let lambda_min = rayleigh(&y);
        if !(lambda_min.is_finite() && lambda_max.is_finite()) {
            return Some((step, 0.0));
        }
        let inverse_condition = if lambda_max > 0.0 {
            (lambda_min.max(0.0) / lambda_max).sqrt()
        } else {
            0.0
        };
        Some((step, inverse_condition))
    }

    /// An estimate of the reciprocal condition number of the column-scaled `JᵀWJ` (0 when singular) from one
    /// Cholesky factorisation, λmax by power iteration and λmin by inverse iteration: a quarter of the cost of the
    /// exact eigenvalue figure ([`Self::inverse_condition`]), which it may over-estimate (λmin is a Rayleigh
    /// quotient). The servo's degeneracy gate uses the same estimate.
    pub fn fast_inverse_condition(&self) -> f64 {
        self.solve_with_conditioning().map_or(0.0, |(_, c)| c)
    }

    /// The Gauss-Newton step `-(JᵀJ + μ D)⁻¹ Jᵀe` with Levenberg-Marquardt damping `μ = damping` on the unit-diagonal
    /// scaled problem (0 = Gauss-Newton). `None` if the system cannot be factorised (singular or not finite).
    pub(crate) fn solve(&self, damping: f64) -> Option<SVector<f64, N>> {
        let s = self.column_scale();
        let mut scaled = self.scaled_jtj();
        for i in 0..N {
            scaled[(i, i)] += damping;
        }
        let rhs = self.jte.component_mul(&s);
        let scaled_step = FixedCholesky::factor(&scaled)?.solve(&rhs);
        let step = -scaled_step.component_mul(&s);
        step.iter().all(|x| x.is_finite()).then_some(step)
    }
}

/// Measurements buffered by a [`NormalEquationsBuilder`] before they are folded into the normal equations.
const BATCH_MEASUREMENTS: usize = 16;
const BATCH_ROWS: usize = 2 * BATCH_MEASUREMENTS;

/// Builds [`NormalEquations`] one measurement (2 rows) at a time.
///
/// Why batches: the weighted rows are buffered column by column, and every 16 measurements each entry of the upper
/// triangle of `JᵀJ` is one dot product over 32 rows, four at a time in registers. In the control step of a
/// 16-measurement window this is faster than adding each measurement's `JᵀJ` to the sums as it comes (its loads and
/// stores of the 78 sums interleaved with the projections), although the latter alone is faster in a loop of its
/// own: what counts is the whole step (measured in docs/results.md, "Design measurements behind the code").
#[derive(Debug, Clone, Copy)]
pub(crate) struct NormalEquationsBuilder<const N: usize> {
    folded: NormalEquations<N>,
    /// `columns[i][k]`: column i of the buffered rows, each row scaled by the square root of its weight.
    columns: [[f64; BATCH_ROWS]; N],
    /// The buffered residuals, scaled as their rows.
    residuals: [f64; BATCH_ROWS],
    rows: usize,
}

impl<const N: usize> Default for NormalEquationsBuilder<N> {
    fn default() -> Self {
        Self {
            folded: NormalEquations::default(),
            columns: [[0.0; BATCH_ROWS]; N],
            residuals: [0.0; BATCH_ROWS],
            rows: 0,
        }
    }
}

impl<const N: usize> NormalEquationsBuilder<N> {
    /// Adds one measurement: its 2 x N Jacobian, residual `e` = predicted - measured (px), and weight (>= 0).
    #[inline]
    pub fn add(&mut self, jacobian: &SMatrix<f64, 2, N>, residual: &Vector2<f64>, weight: f64) {
        let r2 = residual.norm_squared();
        self.folded.weighted_cost += weight * r2;
        self.folded.cost += r2;
        self.folded.count += 1;
        // √w on both the rows and the residuals gives Σ w JᵀJ and Σ w Jᵀe.
        let root = weight.sqrt();
        let k = self.rows;
        for (column, pair) in self
            .columns
            .iter_mut()
            .zip(jacobian.as_slice().chunks_exact(2))
        {
            column[k] = pair[0] * root;
            column[k + 1] = pair[1] * root;
        }
        self.residuals[k] = residual.x * root;
        self.residuals[k + 1] = residual.y * root;
        self.rows += 2;
        if self.rows == BATCH_ROWS {
            self.fold();
        }
    }

    /// Marks the problem infinitely costly (a point behind the camera): weighted or not, no step may lead there.
    pub fn set_infinite_cost(&mut self) {
        self.folded.cost = f64::INFINITY;
        self.folded.weighted_cost = f64::INFINITY;
    }

    /// The normal equations of every measurement added.
    pub fn finish(&mut self) -> NormalEquations<N> {
        self.fold();
        self.folded
    }

    /// Folds the buffered rows into the sums: each entry of the upper triangle is a dot product over the batch.
    fn fold(&mut self) {
        if self.rows == 0 {
            return;
        }
        // A partial batch: zero rows add nothing, and the dot products keep their fixed length.
        for column in &mut self.columns {
            column[self.rows..].fill(0.0);
        }
        self.residuals[self.rows..].fill(0.0);
        for j in 0..N {
            let column_j = &self.columns[j];
            // Four dot products at a time against column j: four independent sums in flight, column j loaded once.
            let mut i = 0;
            while i + 4 <= j + 1 {
                let sums = dot4(
                    [
                        &self.columns[i],
                        &self.columns[i + 1],
                        &self.columns[i + 2],
                        &self.columns[i + 3],
                    ],
                    column_j,
                );
                for (g, sum) in sums.into_iter().enumerate() {
                    self.folded.jtj[(i + g, j)] += sum;
                }
                i += 4;
            }
            // The rest of the column, and the residual, padded with column j itself (its sum is discarded).
            let padded = |g: usize| {
                if i + g <= j {
                    &self.columns[i + g]
                } else if g == 3 {
                    &self.residuals
                } else {
                    column_j
                }
            };
            let sums = dot4([padded(0), padded(1), padded(2), padded(3)], column_j);
            for (g, &sum) in sums.iter().enumerate().take(3) {
                if i + g <= j {
                    self.folded.jtj[(i + g, j)] += sum;
                }
            }
            self.folded.jte[j] += sums[3];
        }
        self.rows = 0;
    }
}

impl<const N: usize> ResidualSink<N> for NormalEquationsBuilder<N> {
    #[inline]
    fn add(&mut self, jacobian: &SMatrix<f64, 2, N>, residual: &Vector2<f64>, weight: f64) {
        NormalEquationsBuilder::add(self, jacobian, residual, weight);
    }

    #[inline]
    fn add_unevaluable(&mut self) {
        self.set_infinite_cost();
    }
}

/// Four dot products `a[g] · b` over a batch, by pairs of lanes (one SIMD register each): strict floating point
/// cannot reorder a single sum, so the independent sums are what keeps the multipliers busy.
#[inline(always)]
fn dot4(a: [&[f64; BATCH_ROWS]; 4], b: &[f64; BATCH_ROWS]) -> [f64; 4] {
    let mut lanes = [[0.0; 2]; 4];
    for k in (0..BATCH_ROWS).step_by(2) {
        for g in 0..4 {
            lanes[g][0] += a[g][k] * b[k];
            lanes[g][1] += a[g][k + 1] * b[k + 1];
        }
    }
    lanes.map(|l| l[0] + l[1])
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
        let mut builder = NormalEquationsBuilder::<3>::default();
        for k in 0..5 {
            let a =
                SMatrix::<f64, 2, 3>::from_fn(|i, j| ((k * 7 + i * 3 + j * 5) % 11) as f64 - 5.0);
            let b = a * x_true;
            builder.add(&a, &(-b), 1.0);
        }
        let ne = builder.finish();
        let step = ne.solve(0.0).unwrap();
        assert!((step - x_true).norm() < 1e-12);
        assert!(ne.inverse_condition() > 0.01);
        let (fast_step, fast_condition) = ne.solve_with_conditioning().unwrap();
        assert!((fast_step - x_true).norm() < 1e-12);
        assert!((fast_condition - ne.inverse_condition()).abs() < 0.05 * ne.inverse_condition());
    }

    #[test]
    fn singular_problems_report_zero_conditioning() {
        let mut builder = NormalEquationsBuilder::<3>::default();
        // The third parameter never appears: a zero column.
        let a = SMatrix::<f64, 2, 3>::new(1.0, 2.0, 0.0, 3.0, -1.0, 0.0);
        builder.add(&a, &Vector2::new(1.0, 1.0), 1.0);
        let ne = builder.finish();
        assert!(ne.inverse_condition() < 1e-12);
        // Two equal columns.
        let mut builder = NormalEquationsBuilder::<2>::default();
        builder.add(
            &SMatrix::<f64, 2, 2>::new(1.0, 1.0, 2.0, 2.0),
            &Vector2::new(1.0, 0.0),
            1.0,
        );
        let ne = builder.finish();
        assert!(ne.inverse_condition() < 1e-7);
    }

    #[test]
    fn batches_give_the_weighted_sums_of_the_measurements() {
        // 0, 1, 15, 16, 17, 40 measurements: empty, partial, exactly one batch, a batch and a remainder, several.
        for count in [0usize, 1, 15, 16, 17, 40] {
            let mut builder = NormalEquationsBuilder::<12>::default();
            let mut jtj = SMatrix::<f64, 12, 12>::zeros();
            let mut jte = SVector::<f64, 12>::zeros();
            let mut weighted_cost = 0.0;
            for k in 0..count {
                let j = SMatrix::<f64, 2, 12>::from_fn(|r, c| {
                    ((k * 13 + r * 7 + c * 3) % 17) as f64 - 8.0 + 0.1 * c as f64
                });
                let e = Vector2::new(k as f64 * 0.3 - 2.0, 1.0 - k as f64 * 0.1);
                let w = [1.0, 0.25, 0.0, 0.7][k % 4];
                builder.add(&j, &e, w);
                jtj += j.transpose() * j * w;
                jte += j.transpose() * e * w;
                weighted_cost += w * e.norm_squared();
            }
            let ne = builder.finish();
            assert_eq!(ne.count, count);
            let scale = 1.0 + jtj.norm();
            assert!(
                (ne.symmetric_jtj() - jtj).norm() <= 1e-12 * scale,
                "count {count}"
            );
            assert!(
                (ne.jte - jte).norm() <= 1e-12 * (1.0 + jte.norm()),
                "count {count}"
            );
            assert!((ne.weighted_cost - weighted_cost).abs() <= 1e-12 * (1.0 + weighted_cost));
        }
    }
}
