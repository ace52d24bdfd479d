//! The one Jacobian checker: every hand-written Jacobian in roitrack is tested against central differences of the
//! function it differentiates, by [`check_jacobian`].
//!
//! # Where
//!
//! At the *identity* state the caller names (no rotation, the optical axis, time zero: where formulas have their
//! special cases), at [`NEAR`] states drawn within `1e-3` of it (where series expansions and small-angle branches
//! take over), and at [`RANDOM`] states drawn over the whole range the caller gives, from a fixed seed so that a
//! failure repeats.
//!
//! # Step and tolerance
//!
//! The caller gives the function as `f(state, δ)` of a perturbation `δ` of the `N` inputs, and each input's typical
//! size `scale[k]` (1 for inputs of unit size; the size of a step that moves the output as much as a unit step of
//! the others, for inputs that act through a small factor). Column `k` is checked in those units:
//!
//! - step `h = STEP · scale[k]`, with [`STEP`] = 1e-6 (near ε^(1/3) ≈ 6e-6, which balances the truncation error
//!   `h² f'''/6` of central differences against the round-off `ε |f| / h`);
//! - numeric column `(f(δ = h e_k) - f(δ = -h e_k)) / (2h)`, compared with the analytic column, both times
//!   `scale[k]`;
//! - they agree when `|numeric - analytic| · scale[k] ≤ RELATIVE · |J S| + ROUND_OFF · |f(state, 0)|`: [`RELATIVE`]
//!   = 1e-6 of the Jacobian's (Frobenius) norm in those units, plus [`ROUND_OFF`] = 1e-9 of the output's size for
//!   the round-off of the differences (about 2e-10 at this step). A wrong term in a formula is off by far more; a
//!   right one is within about 1e-9.

use nalgebra::{SMatrix, SVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::fmt::Debug;

/// The step of the central differences, in units of each input's scale.
pub const STEP: f64 = 1e-6;
/// The tolerance relative to the Jacobian's norm (in the inputs' units).
pub const RELATIVE: f64 = 1e-6;
/// The tolerance relative to the output's size, for the round-off of the differences.
pub const ROUND_OFF: f64 = 1e-9;
/// How many states near the identity are checked, each within `1e-3` of it.
pub const NEAR: usize = 4;
/// How many random states are checked.
pub const RANDOM: usize = 16;
/// How far from the identity the near states are drawn (the `spread` given to `draw`).
pub const NEAR_SPREAD: f64 = 1e-3;

/// Checks `jacobian(state)` against central differences of `f(state, δ)` (a function of the perturbation `δ` of the
/// `N` inputs at `state`) at `identity`, at [`NEAR`] states `draw(rng, 1e-3)` and at [`RANDOM`] states
/// `draw(rng, 1.0)`, by the rule of the module docs; `scale` is each input's typical size. Panics naming `what`,
/// the state, the column and both values at the first disagreement. Returns the number of states checked.
///
/// `draw(rng, spread)` returns a state at a distance of about `spread` from the identity, in the caller's units:
/// `spread = 1` covers the whole range the Jacobian is used over.
///
/// ```
/// use nalgebra::{Matrix1, Vector1};
/// use rand::Rng;
/// use roitrack_testkit::check_jacobian;
///
/// // d sin(x) / dx = cos(x), about 0 and out to ±3.
/// let checked = check_jacobian(
///     "sin",
///     0.0,
///     |rng, spread| rng.random_range(-3.0..3.0) * spread,
///     &Vector1::new(1.0),
///     |x: &f64, d: &Vector1<f64>| Vector1::new((x + d[0]).sin()),
///     |x: &f64| Matrix1::new(x.cos()),
/// );
/// assert_eq!(checked, 21);
/// ```
pub fn check_jacobian<S: Debug, const M: usize, const N: usize>(
    what: &str,
    identity: S,
    draw: impl Fn(&mut ChaCha8Rng, f64) -> S,
    scale: &SVector<f64, N>,
    f: impl Fn(&S, &SVector<f64, N>) -> SVector<f64, M>,
    jacobian: impl Fn(&S) -> SMatrix<f64, M, N>,
) -> usize {
    let mut rng = ChaCha8Rng::seed_from_u64(0x1AC0_B1A5);
    let mut states = vec![identity];
    states.extend((0..NEAR).map(|_| draw(&mut rng, NEAR_SPREAD)));
    states.extend((0..RANDOM).map(|_| draw(&mut rng, 1.0)));
    for state in &states {
        check_at(what, state, scale, &f, &jacobian(state));
    }
    states.len()
}

/// Checks `analytic` against central differences of `f(state, δ)` at one `state`, by the rule of the module docs.
/// For Jacobians checked at states the caller lists (rows of reference data, say); [`check_jacobian`] draws them.
pub fn check_at<S: Debug, const M: usize, const N: usize>(
    what: &str,
    state: &S,
    scale: &SVector<f64, N>,
    f: impl Fn(&S, &SVector<f64, N>) -> SVector<f64, M>,
    analytic: &SMatrix<f64, M, N>,
) {
    let scaled = analytic * SMatrix::<f64, N, N>::from_diagonal(scale);
    let value = f(state, &SVector::zeros());
    let tolerance = RELATIVE * scaled.norm() + ROUND_OFF * value.norm();
    for k in 0..N {
        let h = STEP * scale[k];
        let mut delta = SVector::<f64, N>::zeros();
        delta[k] = h;
        let numeric = (f(state, &delta) - f(state, &-delta)) / (2.0 * h) * scale[k];
        let error = (numeric - scaled.column(k)).norm();
        assert!(
            error <= tolerance,
            "{what}: at {state:?}, column {k}: central differences {numeric:?}, analytic {:?} (in units of the \
             input's scale {}): off by {error:e}, tolerance {tolerance:e}",
            scaled.column(k),
            scale[k]
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};
    use rand::Rng;

    fn rotation(x: &f64, d: &Vector2<f64>) -> Vector2<f64> {
        let (s, c) = (x + d[0]).sin_cos();
        Vector2::new(c, s) * (1.0 + d[1])
    }

    fn draw(rng: &mut ChaCha8Rng, spread: f64) -> f64 {
        rng.random_range(-3.0..3.0) * spread
    }

    #[test]
    fn a_right_jacobian_passes_everywhere() {
        let right = |x: &f64| Matrix2::new(-x.sin(), x.cos(), x.cos(), x.sin());
        let checked = check_jacobian(
            "rotation",
            0.0,
            draw,
            &Vector2::repeat(1.0),
            rotation,
            right,
        );
        assert_eq!(checked, 1 + NEAR + RANDOM);
    }

    #[test]
    #[should_panic(expected = "column 0")]
    fn a_jacobian_off_by_a_small_term_fails() {
        let wrong = |x: &f64| Matrix2::new(-x.sin() + 1e-4, x.cos(), x.cos(), x.sin());
        check_jacobian(
            "rotation",
            0.0,
            draw,
            &Vector2::repeat(1.0),
            rotation,
            wrong,
        );
    }
}
