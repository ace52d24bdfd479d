//! Fits of the 12-dof state to a window of timed observations: the normal equations, one step of the paper's
//! virtual visual servoing loop, and Levenberg-Marquardt to convergence. Pure functions on slices, no allocation:
//! the [`super::Tracker`] calls them, and so do the benchmarks.

use super::normal_equations::{NormalEquations, NormalEquationsBuilder};
use super::window::Observation;
use crate::{JacobianKind, MotionState, SpatioTemporalModel, TargetPoint};

/// A robust loss for the window fits (M-estimator by iteratively reweighted least squares). Residuals are measured in
/// units of an automatic scale: the noise level or, when larger, the median residual of the window (a robust
/// estimate of the spread that outliers do not inflate).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RobustLoss {
    /// Plain least squares.
    None,
    /// Huber, k = 1.345 scales (95 % efficiency on Gaussian noise): outliers weigh as `k / r`.
    Huber,
    /// Tukey's biweight, c = 4.685 scales (95 % efficiency): outliers beyond c weigh nothing.
    #[default]
    Tukey,
}

impl RobustLoss {
    pub const HUBER_K: f64 = 1.345;
    pub const TUKEY_C: f64 = 4.685;

    /// IRLS weight of a residual of `r` scales.
    #[inline]
    pub fn weight(&self, r: f64) -> f64 {
        match self {
            Self::None => 1.0,
            Self::Huber => {
                if r <= Self::HUBER_K {
                    1.0
                } else {
                    Self::HUBER_K / r
                }
            }
            Self::Tukey => {
                if r >= Self::TUKEY_C {
                    0.0
                } else {
                    let q = 1.0 - (r / Self::TUKEY_C).powi(2);
                    q * q
                }
            }
        }
    }
}

/// Largest window whose median residual sets the robust scale (a stack buffer: no allocation).
const MAX_SCALE_SAMPLES: usize = 128;

/// The median of the norm of a 2-D Gaussian residual, in standard deviations per axis.
pub const MEDIAN_NORM_PER_SIGMA: f64 = 1.1774;

/// The median residual norm (px) of the window at `state` (its first [`MAX_SCALE_SAMPLES`] measurements); `None` when
/// no point projects.
pub fn median_residual_px(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    state: &MotionState,
    t_ref_s: f64,
    window: &[Observation],
) -> Option<f64> {
    let mut norms = [0.0f64; MAX_SCALE_SAMPLES];
    let mut n = 0;
    for o in window.iter().take(MAX_SCALE_SAMPLES) {
        if let Some(px) = model.project(
            state,
            &points[o.point_index].point_in_obj_m,
            o.t_s - t_ref_s,
        ) {
            norms[n] = (px - o.ideal_px).norm();
            n += 1;
        }
    }
    if n == 0 {
        return None;
    }
    let (_, median, _) = norms[..n].select_nth_unstable_by(n / 2, f64::total_cmp);
    Some(*median)
}

/// The robust scale (px per axis) for a median residual norm: `median / MEDIAN_NORM_PER_SIGMA`, never below
/// `floor_px`.
pub fn scale_from_median_px(median_px: f64, floor_px: f64) -> f64 {
    (median_px / MEDIAN_NORM_PER_SIGMA).max(floor_px)
}

/// The robust scale (px per axis) of the window's residuals at `state` ([`scale_from_median_px`] of the
/// [`median_residual_px`]), never below `noise_px`.
pub fn robust_scale_px(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    state: &MotionState,
    t_ref_s: f64,
    window: &[Observation],
    noise_px: f64,
) -> f64 {
    median_residual_px(model, points, state, t_ref_s, window)
        .map_or(noise_px, |median| scale_from_median_px(median, noise_px))
}

/// `JᵀJ` and `Jᵀe` of the window at `state` (reference time `t_ref_s`), with `e` = projection - measurement (px).
/// A point behind the camera makes the cost infinite.
pub fn window_normal_equations(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    kind: JacobianKind,
    state: &MotionState,
    t_ref_s: f64,
    window: &[Observation],
) -> NormalEquations<12> {
    weighted_window_normal_equations(
        model,
        points,
        kind,
        state,
        t_ref_s,
        window,
        RobustLoss::None,
        1.0,
    )
}

/// [`window_normal_equations`] with each measurement weighted by `loss` at its residual in units of `scale_px`.
#[allow(clippy::too_many_arguments)]
pub fn weighted_window_normal_equations(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    kind: JacobianKind,
    state: &MotionState,
    t_ref_s: f64,
    window: &[Observation],
    loss: RobustLoss,
    scale_px: f64,
) -> NormalEquations<12> {
    let mut builder = NormalEquationsBuilder::<12>::default();
    for o in window {
        let p = &points[o.point_index].point_in_obj_m;
        match model.project_with_jacobian(kind, state, p, o.t_s - t_ref_s) {
            Some(pp) => {
                let e = pp.pixel - o.ideal_px;
                let w = loss.weight(e.norm() / scale_px);
                builder.add(&pp.jacobian, &e, w);
            }
            None => builder.set_infinite_cost(),
        }
    }
    builder.finish()
}

/// What one step of the virtual visual servoing loop did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VvsStep {
    /// The state after the step (unchanged if the step was refused).
    pub state: MotionState,
    /// Reciprocal condition number of the window's column-scaled Jacobian.
    pub inverse_condition: f64,
    /// Whether the update was applied (refused on a degenerate window or a non-finite result).
    pub applied: bool,
    /// Norm of the Gauss-Newton step (before the gain).
    pub step_norm: f64,
    /// Residual RMS (px) of the window before the step.
    pub residual_rms_px: f64,
    /// The window's normal equations before the step (their inverse scaled by σ² is the step's covariance).
    pub normal_equations: NormalEquations<12>,
}

/// One iteration `δ = -λ L⁺ e` on the window (the paper's control step with `gain` = λ), refused when the window is
/// degenerate (reciprocal condition number below `min_inverse_condition`).
#[allow(clippy::too_many_arguments)]
pub fn vvs_iteration(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    kind: JacobianKind,
    state: &MotionState,
    t_ref_s: f64,
    window: &[Observation],
    gain: f64,
    min_inverse_condition: f64,
) -> VvsStep {
    robust_vvs_iteration(
        model,
        points,
        kind,
        state,
        t_ref_s,
        window,
        gain,
        min_inverse_condition,
        RobustLoss::None,
        1.0,
    )
}

/// [`vvs_iteration`] with an M-estimator: one IRLS iteration, the weights taken at `state` with the residual scale
/// `scale_px` (see [`robust_scale_px`]).
#[allow(clippy::too_many_arguments)]
pub fn robust_vvs_iteration(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    kind: JacobianKind,
    state: &MotionState,
    t_ref_s: f64,
    window: &[Observation],
    gain: f64,
    min_inverse_condition: f64,
    loss: RobustLoss,
    scale_px: f64,
) -> VvsStep {
    let ne = weighted_window_normal_equations(
        model, points, kind, state, t_ref_s, window, loss, scale_px,
    );
    let solved = ne.solve_with_conditioning();
    let inverse_condition = solved.map_or(0.0, |(_, c)| c);
    let refused = VvsStep {
        state: *state,
        inverse_condition,
        applied: false,
        step_norm: 0.0,
        residual_rms_px: ne.residual_rms_px(),
        normal_equations: ne,
    };
    let Some((step, _)) = solved.filter(|_| inverse_condition >= min_inverse_condition) else {
        return refused;
    };
    let candidate = state.corrected(&(step * gain));
    if !candidate.is_finite() {
        return refused;
    }
    VvsStep {
        state: candidate,
        applied: true,
        step_norm: step.norm(),
        ..refused
    }
}

/// Levenberg-Marquardt of the 12 parameters on the window, to convergence (relative cost decrease below 1e-12) or
/// `max_iterations`: the final state, its normal equations and the iterations done.
pub fn levenberg_marquardt(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    initial: MotionState,
    t_ref_s: f64,
    window: &[Observation],
    max_iterations: usize,
) -> (MotionState, NormalEquations<12>, usize) {
    robust_levenberg_marquardt(
        model,
        points,
        initial,
        t_ref_s,
        window,
        max_iterations,
        RobustLoss::None,
        1.0,
    )
}

/// [`levenberg_marquardt`] on the robust (weighted) cost, with a fixed residual scale `scale_px`.
#[allow(clippy::too_many_arguments)]
pub fn robust_levenberg_marquardt(
    model: &SpatioTemporalModel,
    points: &[TargetPoint],
    initial: MotionState,
    t_ref_s: f64,
    window: &[Observation],
    max_iterations: usize,
    loss: RobustLoss,
    scale_px: f64,
) -> (MotionState, NormalEquations<12>, usize) {
    let accumulate = |s: &MotionState| {
        weighted_window_normal_equations(
            model,
            points,
            JacobianKind::Exact,
            s,
            t_ref_s,
            window,
            loss,
            scale_px,
        )
    };
    let mut state = initial;
    let mut ne = accumulate(&state);
    let mut damping = 1e-4;
    let mut iterations = 0;
    while iterations < max_iterations && ne.cost.is_finite() {
        iterations += 1;
        let Some(step) = ne.solve(damping) else { break };
        let candidate = state.corrected(&step);
        let candidate_ne = accumulate(&candidate);
        if candidate_ne.weighted_cost <= ne.weighted_cost {
            let converged =
                ne.weighted_cost - candidate_ne.weighted_cost <= 1e-12 * ne.weighted_cost + 1e-24;
            state = candidate;
            ne = candidate_ne;
            damping = (damping * 0.1).max(1e-10);
            if converged {
                break;
            }
        } else {
            damping *= 10.0;
            if damping > 1e8 {
                break;
            }
        }
    }
    (state, ne, iterations)
}
