//! The constant-acceleration model's state transition over an interval, applied without forming the matrix.

use super::*;

/// The transition `F` of the error state over `dt_s`, applied to one column. With `E = Exp(φ)`, `φ = W dt + ½ Α dt²`
/// the rotation increment and `J = J_l(φ)` (the left Jacobian of SO(3)), on (v, w, dV, dW, dA, dΑ):
///
/// ```text
/// F = [ I  0  dt·I  0      ½dt²·I  0       ]
///     [ 0  E  0     J·dt   0       J·½dt²  ]
///     [ 0  0  I     0      dt·I    0       ]
///     [ 0  0  0     I      0       dt·I    ]
///     [ 0  0  0     0      I       0       ]
///     [ 0  0  0     0      0       I       ]
/// ```
///
/// and its top-left 12 x 12 block without the accelerations ([`MotionState::transition_jacobian`]).
pub(super) struct Transition {
    pub(super) dt_s: f64,
    pub(super) half_dt2: f64,
    /// `E`, `J dt` and `J ½dt²`.
    pub(super) e: nalgebra::Matrix3<f64>,
    pub(super) b: nalgebra::Matrix3<f64>,
    pub(super) b_half_dt: nalgebra::Matrix3<f64>,
}

impl Transition {
    /// The transition of `state`, with the accelerations `acceleration`, over `dt_s`.
    pub(super) fn new(state: &MotionState, acceleration: &Acceleration, dt_s: f64) -> Self {
        let half_dt2 = 0.5 * dt_s * dt_s;
        let rotation_increment =
            state.angular_velocity_radps * dt_s + acceleration.angular_radps2 * half_dt2;
        let j_l = so3::left_jacobian(&rotation_increment);
        Self {
            dt_s,
            half_dt2,
            e: *so3::exp(&rotation_increment).matrix(),
            b: j_l * dt_s,
            b_half_dt: j_l * half_dt2,
        }
    }

    /// `F x` in place.
    #[inline]
    pub(super) fn apply<const N: usize>(&self, column: &mut [f64]) {
        const { assert!(N == 12 || N == 18, "the error state has 12 or 18 entries") };
        let old: [f64; N] = column.try_into().expect("a column of N rows");
        for k in 0..3 {
            let mut translation = old[k] + old[6 + k] * self.dt_s;
            let mut rotation = 0.0;
            for l in 0..3 {
                rotation += self.e[(k, l)] * old[3 + l] + self.b[(k, l)] * old[9 + l];
            }
            if N == 18 {
                translation += old[12 + k] * self.half_dt2;
                for l in 0..3 {
                    rotation += self.b_half_dt[(k, l)] * old[15 + l];
                }
                column[6 + k] = old[6 + k] + old[12 + k] * self.dt_s;
                column[9 + k] = old[9 + k] + old[15 + k] * self.dt_s;
            }
            column[k] = translation;
            column[3 + k] = rotation;
        }
    }

    /// `P Fᵀ` in place, `p` the column-major entries of an `N x N` matrix (`p[i + N j]` is row i, column j): column
    /// j of the product is the combination of P's columns that row j of F holds.
    #[inline]
    pub(super) fn apply_from_the_right<const N: usize>(&self, p: &mut [f64]) {
        const { assert!(N == 12 || N == 18, "the error state has 12 or 18 entries") };
        let old_rotation: [f64; 54] =
            std::array::from_fn(|k| if k < 3 * N { p[3 * N + k] } else { 0.0 });
        for k in 0..3 {
            for i in 0..N {
                let mut translation = p[i + N * k] + p[i + N * (6 + k)] * self.dt_s;
                let mut rotation = 0.0;
                for l in 0..3 {
                    rotation += old_rotation[i + N * l] * self.e[(k, l)]
                        + p[i + N * (9 + l)] * self.b[(k, l)];
                }
                if N == 18 {
                    translation += p[i + N * (12 + k)] * self.half_dt2;
                    for l in 0..3 {
                        rotation += p[i + N * (15 + l)] * self.b_half_dt[(k, l)];
                    }
                }
                p[i + N * k] = translation;
                p[i + N * (3 + k)] = rotation;
            }
        }
        if N == 18 {
            for k in 0..3 {
                for i in 0..N {
                    p[i + N * (6 + k)] += p[i + N * (12 + k)] * self.dt_s;
                    p[i + N * (9 + k)] += p[i + N * (15 + k)] * self.dt_s;
                }
            }
        }
    }
}
