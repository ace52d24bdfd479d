//! A fixed-size Cholesky factorisation `A = L Lᵀ` for the small normal equations of the control step.
//!
//! Why not nalgebra's `Cholesky`: its triangular solves are written for any storage and any dimension and index
//! through generic views. The control step factors one 12 x 12 matrix and solves five times with it (the step and
//! four inverse iterations of the conditioning figure), and a profile put a third of the step in nalgebra's
//! triangular solves; these solves take less than half their time (measured in docs/results.md, "Design
//! measurements behind the code"). Results agree with nalgebra's to round-off (tested below).

use nalgebra::{SMatrix, SVector};

/// The lower factor `L` of a symmetric positive definite `N x N` matrix, kept both by rows and by columns so that both
/// triangular solves run as independent multiply-adds along contiguous memory (no dependent dot-product chains).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedCholesky<const N: usize> {
    /// `by_row[i][k] = L[i][k]` for `k < i` (other entries unused).
    by_row: [[f64; N]; N],
    /// `by_column[k][i] = L[i][k]` for `i > k` (other entries unused).
    by_column: [[f64; N]; N],
    /// `1 / L[i][i]`.
    inverse_diagonal: [f64; N],
}

impl<const N: usize> FixedCholesky<N> {
    /// Factorises the symmetric matrix whose upper triangle (and diagonal) is `upper(i, j)` for `i <= j`. `None` when
    /// the matrix is not positive definite to working precision (a pivot not positive or not finite).
    #[inline]
    pub fn factor_upper(upper: impl Fn(usize, usize) -> f64) -> Option<Self> {
        // Left-looking (dot products of rows of L): 300 ns for 12 x 12 against 360 ns right-looking (outer-product
        // updates of the trailing matrix), same loop, same machine.
        let mut by_row = [[0.0; N]; N];
        let mut inverse_diagonal = [0.0; N];
        for j in 0..N {
            let row_j = by_row[j];
            let mut pivot = upper(j, j);
            for &l in &row_j[..j] {
                pivot -= l * l;
            }
            if !(pivot > 0.0 && pivot.is_finite()) {
                return None;
            }
            let inv = 1.0 / pivot.sqrt();
            inverse_diagonal[j] = inv;
            for (i, row_i) in by_row.iter_mut().enumerate().skip(j + 1) {
                let mut v = upper(j, i);
                for (&a, &b) in row_i[..j].iter().zip(&row_j[..j]) {
                    v -= a * b;
                }
                row_i[j] = v * inv;
            }
        }
        let mut by_column = [[0.0; N]; N];
        for (i, row) in by_row.iter().enumerate() {
            for (k, &l) in row[..i].iter().enumerate() {
                by_column[k][i] = l;
            }
        }
        Some(Self {
            by_row,
            by_column,
            inverse_diagonal,
        })
    }

    /// Factorises a symmetric matrix (only its upper triangle is read).
    #[inline]
    pub fn factor(a: &SMatrix<f64, N, N>) -> Option<Self> {
        Self::factor_upper(|i, j| a[(i, j)])
    }

    /// Solves `L Lᵀ x = b`.
    #[inline]
    pub fn solve(&self, b: &SVector<f64, N>) -> SVector<f64, N> {
        let mut y: [f64; N] = (*b).into();
        // Forward, L y = b, column by column of L.
        for k in 0..N {
            let yk = y[k] * self.inverse_diagonal[k];
            y[k] = yk;
            for (v, &l) in y[k + 1..].iter_mut().zip(&self.by_column[k][k + 1..]) {
                *v -= l * yk;
            }
        }
        // Backward, Lᵀ x = y, column by column of Lᵀ (row by row of L).
        for i in (0..N).rev() {
            let xi = y[i] * self.inverse_diagonal[i];
            y[i] = xi;
            for (v, &l) in y[..i].iter_mut().zip(&self.by_row[i][..i]) {
                *v -= l * xi;
            }
        }
        SVector::from(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(seed: usize) -> SMatrix<f64, 12, 12> {
        let j = SMatrix::<f64, 24, 12>::from_fn(|r, c| {
            (((r * 31 + c * 17 + seed * 7) % 23) as f64 - 11.0) * (1.0 + c as f64)
        });
        j.transpose() * j + SMatrix::identity() * 1e-3
    }

    #[test]
    fn agrees_with_nalgebra() {
        for seed in 0..5 {
            let a = spd(seed);
            let b = SVector::<f64, 12>::from_fn(|i, _| (i as f64 - 5.5) * 0.3 + seed as f64);
            let ours = FixedCholesky::factor(&a).unwrap().solve(&b);
            let reference = a.cholesky().unwrap().solve(&b);
            assert!(
                (ours - reference).norm() <= 1e-9 * reference.norm(),
                "{ours} vs {reference}"
            );
            assert!((a * ours - b).norm() <= 1e-8 * b.norm());
        }
    }

    #[test]
    fn reads_only_the_upper_triangle() {
        let a = spd(1);
        let mut upper_only = a;
        for i in 0..12 {
            for j in 0..i {
                upper_only[(i, j)] = f64::NAN;
            }
        }
        let b = SVector::<f64, 12>::repeat(1.0);
        let x = FixedCholesky::factor(&upper_only).unwrap().solve(&b);
        assert!((a * x - b).norm() <= 1e-8);
    }

    #[test]
    fn rejects_matrices_that_are_not_positive_definite() {
        // A parameter that no measurement sees: a zero row and column.
        let mut a = spd(2);
        for i in 0..12 {
            a[(i, 7)] = 0.0;
            a[(7, i)] = 0.0;
        }
        assert!(FixedCholesky::factor(&a).is_none());
        let negative = -SMatrix::<f64, 3, 3>::identity();
        assert!(FixedCholesky::factor(&negative).is_none());
        let mut nan = SMatrix::<f64, 3, 3>::identity();
        nan[(1, 1)] = f64::NAN;
        assert!(FixedCholesky::factor(&nan).is_none());
        assert!(FixedCholesky::factor(&SMatrix::<f64, 3, 3>::zeros()).is_none());
    }
}
