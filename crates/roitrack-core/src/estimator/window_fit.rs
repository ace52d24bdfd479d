//! Fits of the 12-dof state to a window of timed observations: the normal equations, one step of the paper's
//! virtual visual servoing loop, and Levenberg-Marquardt to convergence. Pure functions on slices, no allocation:
//! the [`super::Tracker`] calls them, and so do the benchmarks.

use super::normal_equations::NormalEquations;
use super::window::Observation;
use crate::{JacobianKind, MotionState, SpatioTemporalModel, TargetPoint};

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
    let mut ne = NormalEquations::<12>::default();
    for o in window {
        let p = &points[o.point_index].point_in_obj_m;
        match model.project_with_jacobian(kind, state, p, o.t_s - t_ref_s) {
            Some(pp) => ne.add(&pp.jacobian, &(pp.pixel - o.ideal_px), 1.0),
            None => ne.cost = f64::INFINITY,
        }
    }
    ne
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
    let ne = window_normal_equations(model, points, kind, state, t_ref_s, window);
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
    let accumulate = |s: &MotionState| {
        window_normal_equations(model, points, JacobianKind::Exact, s, t_ref_s, window)
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
        if candidate_ne.cost <= ne.cost {
            let converged = ne.cost - candidate_ne.cost <= 1e-12 * ne.cost + 1e-24;
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
