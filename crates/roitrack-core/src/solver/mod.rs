//! One nonlinear least-squares solver for every fit in roitrack: the static pose, the tracker's initialisation, the
//! batch baseline and the paper's virtual visual servoing loop.
//!
//! A fit is a [`LeastSquaresProblem`]: it hands the solver each measurement's 2 x N Jacobian, residual and weight at
//! a parameter value ([`LeastSquaresProblem::linearize`]), and says how a step changes the parameters
//! ([`LeastSquaresProblem::apply_step`]). [`solve`] runs one of two [`Method`]s and returns the parameters with a
//! [`SolverReport`] (converged or not, iterations, final cost, and why it stopped):
//!
//! - [`Method::LevenbergMarquardt`]: damped Gauss-Newton steps on the column-scaled normal equations, each kept only
//!   if it lowers the cost, until the cost stops decreasing, the step is negligible or the damping runs away. Its
//!   [`DampingSchedule`] is the one knob: [`DampingSchedule::WINDOW`] (start damped, relax after each success) for the
//!   12-dof window fits, [`DampingSchedule::GAUSS_NEWTON_FIRST`] (undamped until a step fails) for the 6-dof static
//!   pose, whose closed-form start is close.
//! - [`Method::Servo`]: the paper's control law `δ = -λ L⁺ e`: a fixed number of undamped steps scaled by the gain
//!   λ, every one applied (no cost check: the paper's loop), refused on an ill-conditioned system. Before each step the
//!   problem may re-weight itself ([`LeastSquaresProblem::reweight`]), which makes it iteratively reweighted least
//!   squares for a robust loss.
//!
//! Nothing allocates: the normal equations are fixed-size and accumulated in batches (`normal_equations.rs`), and
//! factorised by a fixed-size Cholesky factor (`cholesky.rs`), both private to this module.

mod cholesky;
mod normal_equations;

use nalgebra::{SMatrix, SVector, Vector2};

pub use normal_equations::NormalEquations;
pub(crate) use normal_equations::NormalEquationsBuilder;

/// Receives the linearised measurements of a problem (see [`LeastSquaresProblem::linearize`]).
pub trait ResidualSink<const N: usize> {
    /// One measurement: its 2 x N Jacobian `d e / d params`, its residual `e` = predicted - measured (px) and its
    /// weight (>= 0; 1 for plain least squares).
    fn add(&mut self, jacobian: &SMatrix<f64, 2, N>, residual: &Vector2<f64>, weight: f64);
    /// A measurement that cannot be evaluated at these parameters (a point behind the camera): the cost is infinite,
    /// so a step that leads there is refused.
    fn add_unevaluable(&mut self);
}

/// A nonlinear least-squares problem in `N` parameters: minimise `Σ w_i |e_i(params)|²`.
///
/// See [`NormalEquations`] for a complete example of a problem.
pub trait LeastSquaresProblem<const N: usize> {
    /// The parameters (a pose, a 12-dof state, ...), changed by steps in an N-dimensional tangent space.
    type Params: Copy;

    /// Hands every measurement's Jacobian, residual and weight at `params` to `sink`.
    fn linearize<S: ResidualSink<N>>(&self, params: &Self::Params, sink: &mut S);

    /// The parameters after a step (the solver's steps solve `JᵀWJ step = -JᵀWe`).
    fn apply_step(&self, params: &Self::Params, step: &SVector<f64, N>) -> Self::Params;

    /// Whether parameters are usable (finite): a [`Method::Servo`] step that leads elsewhere is refused.
    fn is_valid(&self, _params: &Self::Params) -> bool {
        true
    }

    /// Called before each [`Method::Servo`] step at the current parameters, so that a robust problem can set its
    /// weights (iteratively reweighted least squares). Does nothing by default.
    fn reweight(&mut self, _params: &Self::Params) {}

    /// Whether an undamped step is so small that the next would be far below the noise: the solver takes it and stops
    /// without evaluating the cost again. Never, by default.
    fn step_is_negligible(&self, _step: &SVector<f64, N>) -> bool {
        false
    }
}

/// How the Levenberg-Marquardt damping `μ` (added to the unit diagonal of the column-scaled normal equations) evolves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DampingSchedule {
    /// `μ` of the first step (0: Gauss-Newton).
    pub initial: f64,
    /// After a step that lowered the cost: `μ <- max(μ * decrease, min)`.
    pub decrease: f64,
    /// The floor of `μ` after a success (0: back to Gauss-Newton).
    pub min: f64,
    /// After a step that raised the cost: `μ <- μ * increase`, or `first_increase` when `μ` was 0.
    pub increase: f64,
    /// `μ` after a failed undamped (`μ = 0`) step, where multiplying would leave it 0.
    pub first_increase: f64,
    /// The solver stops when `μ` exceeds this: no descent direction is left.
    pub max: f64,
    /// Whether stopping on `max` counts as converged (at a minimum to machine precision) or as a failure.
    pub max_means_converged: bool,
    /// A step is kept when the new cost is at most `(1 + cost_slack) x` the old one plus `cost_slack_px2`.
    pub cost_slack: f64,
    /// The absolute slack (px²) added to the relative one, so that at a cost near zero, where the relative slack is
    /// nothing, a step is not refused for rounding.
    pub cost_slack_px2: f64,
    /// Converged when a kept step lowered the cost by at most this fraction of it (plus 1e-24 px²); `None`: never on
    /// the cost.
    pub relative_decrease: Option<f64>,
}

impl DampingSchedule {
    /// For fits from a rough start (the 12-dof window fits): start at `μ = 1e-4`, divide by 10 after a success (down
    /// to 1e-10), multiply by 10 after a failure (giving up beyond 1e8); converged when the cost decreases by less
    /// than 1e-12 of itself.
    pub const WINDOW: Self = Self {
        initial: 1e-4,
        decrease: 0.1,
        min: 1e-10,
        increase: 10.0,
        first_increase: 10.0,
        max: 1e8,
        max_means_converged: false,
        cost_slack: 0.0,
        cost_slack_px2: 0.0,
        relative_decrease: Some(1e-12),
    };

    /// For fits from a close start (the static pose from its closed form): Gauss-Newton while steps lower the cost
    /// (to 1e-12 of it), damping from 1e-6 only after a failure; converged on a negligible step, or when the damping
    /// exceeds 1e6 (no descent left: at a minimum to machine precision).
    pub const GAUSS_NEWTON_FIRST: Self = Self {
        initial: 0.0,
        decrease: 0.0,
        min: 0.0,
        increase: 10.0,
        first_increase: 1e-6,
        max: 1e6,
        max_means_converged: true,
        cost_slack: 1e-12,
        cost_slack_px2: 1e-30,
        relative_decrease: None,
    };
}

/// How [`solve`] iterates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Damped Gauss-Newton, each step kept only if the cost does not rise.
    LevenbergMarquardt(DampingSchedule),
    /// The paper's control law: undamped steps scaled by `gain`, all applied, refused when the reciprocal condition
    /// number of the column-scaled system is below `min_inverse_condition`.
    Servo {
        /// λ: the fraction of each Gauss-Newton step applied (1: the full step).
        gain: f64,
        /// The degeneracy gate: the least reciprocal condition number (0 to 1) of the column-scaled normal equations
        /// at which a step is still taken.
        min_inverse_condition: f64,
    },
}

/// Options of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverOptions {
    /// Most linearisations (and steps tried).
    pub max_iterations: usize,
    /// Levenberg-Marquardt with its damping schedule, or the paper's servo law.
    pub method: Method,
}

impl SolverOptions {
    /// Levenberg-Marquardt with the [`DampingSchedule::WINDOW`] schedule.
    pub fn levenberg_marquardt(max_iterations: usize) -> Self {
        Self {
            max_iterations,
            method: Method::LevenbergMarquardt(DampingSchedule::WINDOW),
        }
    }

    /// `iterations` steps of the paper's control law with gain λ and a degeneracy gate.
    pub fn servo(iterations: usize, gain: f64, min_inverse_condition: f64) -> Self {
        Self {
            max_iterations: iterations,
            method: Method::Servo {
                gain,
                min_inverse_condition,
            },
        }
    }
}

/// Why [`solve`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// A kept step lowered the cost by less than the schedule's relative tolerance.
    CostConverged,
    /// The step was negligible ([`LeastSquaresProblem::step_is_negligible`], or a servo step under 1e-12).
    StepNegligible,
    /// `max_iterations` reached.
    MaxIterations,
    /// The damping exceeded the schedule's maximum: no step lowers the cost.
    DampingLimit,
    /// The normal equations could not be factorised (singular, or not finite).
    SingularSystem,
    /// The cost at the current parameters is infinite (a measurement could not be evaluated).
    NonFiniteCost,
    /// Servo: the system's reciprocal condition number was under the gate; the step was not applied.
    IllConditioned,
    /// Servo: the step led to invalid parameters ([`LeastSquaresProblem::is_valid`]); it was not applied.
    InvalidStep,
}

impl StopReason {
    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Self::CostConverged => "cost converged",
            Self::StepNegligible => "negligible step",
            Self::MaxIterations => "iteration limit",
            Self::DampingLimit => "damping limit",
            Self::SingularSystem => "singular system",
            Self::NonFiniteCost => "infinite cost",
            Self::IllConditioned => "ill-conditioned",
            Self::InvalidStep => "invalid step",
        }
    }
}

/// What a [`solve`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverReport {
    /// Whether the parameters are at a minimum of the cost (Levenberg-Marquardt), or every servo step was applied.
    pub converged: bool,
    /// Linearisations done (steps tried).
    pub iterations: usize,
    /// Steps applied to the parameters.
    pub steps_applied: usize,
    /// Weighted cost Σ w |e|² (px²) at the initial parameters.
    pub initial_cost_px2: f64,
    /// Weighted cost Σ w |e|² (px²) in the returned normal equations ([`Solution::normal_equations`]).
    pub final_cost_px2: f64,
    /// Why the solver stopped.
    pub stop: StopReason,
    /// Servo: the reciprocal condition number of the last system solved (1 perfect, 0 singular).
    pub inverse_condition: Option<f64>,
}

/// The result of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution<P, const N: usize> {
    /// The parameters reached: the last kept (Levenberg-Marquardt) or applied (servo) ones.
    pub params: P,
    /// The normal equations last evaluated at parameters that were kept: at `params`, except after a negligible
    /// step (taken without evaluating again) and after a servo step (they are those the step was solved from, which
    /// gives its covariance).
    pub normal_equations: NormalEquations<N>,
    /// How the solve went: iterations, costs, why it stopped.
    pub report: SolverReport,
}

/// The normal equations of `problem` at `params` (`JᵀWJ`, `JᵀWe`, cost).
pub fn normal_equations<const N: usize, P: LeastSquaresProblem<N>>(
    problem: &P,
    params: &P::Params,
) -> NormalEquations<N> {
    let mut builder = NormalEquationsBuilder::<N>::default();
    problem.linearize(params, &mut builder);
    builder.finish()
}

/// Minimises the problem's cost from `initial` (see the [module documentation](self)).
///
/// ```
/// use nalgebra::{SMatrix, SVector, Vector2};
/// use roitrack_core::solver::{
///     LeastSquaresProblem, ResidualSink, SolverOptions, StopReason, solve,
/// };
///
/// /// Fit `(a, b)` of `y = exp(a x) + b` to exact samples of `a = 0.7, b = -0.2`.
/// struct Exponential([(f64, f64); 2]);
/// impl LeastSquaresProblem<2> for Exponential {
///     type Params = [f64; 2];
///     fn linearize<S: ResidualSink<2>>(&self, &[a, b]: &[f64; 2], sink: &mut S) {
///         let [(x0, y0), (x1, y1)] = self.0;
///         let j = SMatrix::<f64, 2, 2>::new(x0 * (a * x0).exp(), 1.0, x1 * (a * x1).exp(), 1.0);
///         let e = Vector2::new((a * x0).exp() + b - y0, (a * x1).exp() + b - y1);
///         sink.add(&j, &e, 1.0);
///     }
///     fn apply_step(&self, p: &[f64; 2], step: &SVector<f64, 2>) -> [f64; 2] {
///         [p[0] + step[0], p[1] + step[1]]
///     }
/// }
/// let truth = |x: f64| (0.7 * x).exp() - 0.2;
/// let mut problem = Exponential([(0.5, truth(0.5)), (2.0, truth(2.0))]);
/// let fit = solve(&mut problem, [0.0, 0.0], &SolverOptions::levenberg_marquardt(50));
/// assert!(fit.report.converged, "{:?}", fit.report);
/// assert!((fit.params[0] - 0.7).abs() < 1e-8 && (fit.params[1] + 0.2).abs() < 1e-8);
/// assert!(fit.report.final_cost_px2 < 1e-20);
/// ```
pub fn solve<const N: usize, P: LeastSquaresProblem<N>>(
    problem: &mut P,
    initial: P::Params,
    options: &SolverOptions,
) -> Solution<P::Params, N> {
    match options.method {
        Method::LevenbergMarquardt(schedule) => {
            levenberg_marquardt(problem, initial, options.max_iterations, &schedule)
        }
        Method::Servo {
            gain,
            min_inverse_condition,
        } => servo(
            problem,
            initial,
            options.max_iterations,
            gain,
            min_inverse_condition,
        ),
    }
}

fn levenberg_marquardt<const N: usize, P: LeastSquaresProblem<N>>(
    problem: &P,
    initial: P::Params,
    max_iterations: usize,
    schedule: &DampingSchedule,
) -> Solution<P::Params, N> {
    let mut params = initial;
    let mut ne = normal_equations(problem, &params);
    let initial_cost_px2 = ne.weighted_cost;
    let mut damping = schedule.initial;
    let (mut iterations, mut steps_applied) = (0, 0);
    let stop = loop {
        if iterations >= max_iterations {
            break StopReason::MaxIterations;
        }
        if !ne.cost.is_finite() {
            break StopReason::NonFiniteCost;
        }
        iterations += 1;
        let Some(step) = ne.solve(damping) else {
            break StopReason::SingularSystem;
        };
        let candidate = problem.apply_step(&params, &step);
        if damping == 0.0 && problem.step_is_negligible(&step) {
            params = candidate;
            steps_applied += 1;
            break StopReason::StepNegligible;
        }
        let candidate_ne = normal_equations(problem, &candidate);
        if candidate_ne.weighted_cost
            <= ne.weighted_cost * (1.0 + schedule.cost_slack) + schedule.cost_slack_px2
        {
            let converged = schedule.relative_decrease.is_some_and(|tolerance| {
                ne.weighted_cost - candidate_ne.weighted_cost
                    <= tolerance * ne.weighted_cost + 1e-24
            });
            params = candidate;
            ne = candidate_ne;
            steps_applied += 1;
            damping = (damping * schedule.decrease).max(schedule.min);
            if converged {
                break StopReason::CostConverged;
            }
        } else {
            damping = if damping == 0.0 {
                schedule.first_increase
            } else {
                damping * schedule.increase
            };
            if damping > schedule.max {
                break StopReason::DampingLimit;
            }
        }
    };
    let converged = match stop {
        StopReason::CostConverged | StopReason::StepNegligible => true,
        StopReason::DampingLimit => schedule.max_means_converged,
        _ => false,
    };
    Solution {
        params,
        normal_equations: ne,
        report: SolverReport {
            converged,
            iterations,
            steps_applied,
            initial_cost_px2,
            final_cost_px2: ne.weighted_cost,
            stop,
            inverse_condition: None,
        },
    }
}

/// Servo steps under this norm (in the parameters' units) end the loop: the next would change nothing.
const NEGLIGIBLE_SERVO_STEP: f64 = 1e-12;

fn servo<const N: usize, P: LeastSquaresProblem<N>>(
    problem: &mut P,
    initial: P::Params,
    max_iterations: usize,
    gain: f64,
    min_inverse_condition: f64,
) -> Solution<P::Params, N> {
    let mut params = initial;
    let mut ne = NormalEquations::default();
    let mut initial_cost_px2 = None;
    let mut inverse_condition = None;
    let (mut iterations, mut steps_applied) = (0, 0);
    let stop = loop {
        if iterations >= max_iterations {
            break StopReason::MaxIterations;
        }
        iterations += 1;
        problem.reweight(&params);
        ne = normal_equations(problem, &params);
        initial_cost_px2.get_or_insert(ne.weighted_cost);
        let solved = ne.solve_with_conditioning();
        let condition = solved.map_or(0.0, |(_, c)| c);
        inverse_condition = Some(condition);
        let Some((step, _)) = solved else {
            break StopReason::SingularSystem;
        };
        if condition < min_inverse_condition {
            break StopReason::IllConditioned;
        }
        let candidate = problem.apply_step(&params, &(step * gain));
        if !problem.is_valid(&candidate) {
            break StopReason::InvalidStep;
        }
        params = candidate;
        steps_applied += 1;
        if step.norm() < NEGLIGIBLE_SERVO_STEP {
            break StopReason::StepNegligible;
        }
    };
    Solution {
        params,
        normal_equations: ne,
        report: SolverReport {
            converged: matches!(stop, StopReason::MaxIterations | StopReason::StepNegligible),
            iterations,
            steps_applied,
            initial_cost_px2: initial_cost_px2.unwrap_or(0.0),
            final_cost_px2: ne.weighted_cost,
            stop,
            inverse_condition,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `e(x) = A x - b` for a fixed well-conditioned A: one Gauss-Newton step lands on the solution.
    struct Linear {
        rows: Vec<(SMatrix<f64, 2, 3>, Vector2<f64>)>,
        reweighted: usize,
    }

    impl Linear {
        fn new(x_true: SVector<f64, 3>) -> Self {
            let rows = (0..5)
                .map(|k| {
                    let a = SMatrix::<f64, 2, 3>::from_fn(|i, j| {
                        ((k * 7 + i * 3 + j * 5) % 11) as f64 - 5.0
                    });
                    (a, a * x_true)
                })
                .collect();
            Self {
                rows,
                reweighted: 0,
            }
        }
    }

    impl LeastSquaresProblem<3> for Linear {
        type Params = SVector<f64, 3>;
        fn linearize<S: ResidualSink<3>>(&self, x: &Self::Params, sink: &mut S) {
            for (a, b) in &self.rows {
                sink.add(a, &(a * x - b), 1.0);
            }
        }
        fn apply_step(&self, x: &Self::Params, step: &SVector<f64, 3>) -> Self::Params {
            x + step
        }
        fn reweight(&mut self, _x: &Self::Params) {
            self.reweighted += 1;
        }
        fn step_is_negligible(&self, step: &SVector<f64, 3>) -> bool {
            step.norm() < 1e-12
        }
    }

    #[test]
    fn levenberg_marquardt_stops_converged_at_the_solution() {
        let x_true = SVector::<f64, 3>::new(1.0, -2.0, 0.5);
        let mut problem = Linear::new(x_true);
        for schedule in [DampingSchedule::WINDOW, DampingSchedule::GAUSS_NEWTON_FIRST] {
            let options = SolverOptions {
                max_iterations: 50,
                method: Method::LevenbergMarquardt(schedule),
            };
            let fit = solve(&mut problem, SVector::zeros(), &options);
            assert!(fit.report.converged, "{:?}", fit.report);
            assert!((fit.params - x_true).norm() < 1e-9, "{}", fit.params);
            assert!(fit.report.final_cost_px2 < 1e-18);
            assert!(fit.report.initial_cost_px2 > 1.0);
            assert!(fit.report.iterations < 50);
        }
        // No servo reweighting in Levenberg-Marquardt.
        assert_eq!(problem.reweighted, 0);
    }

    #[test]
    fn iteration_limit_is_reported() {
        let mut problem = Linear::new(SVector::<f64, 3>::new(1.0, -2.0, 0.5));
        let fit = solve(
            &mut problem,
            SVector::zeros(),
            &SolverOptions::levenberg_marquardt(1),
        );
        assert_eq!(fit.report.stop, StopReason::MaxIterations);
        assert!(!fit.report.converged);
        assert_eq!(fit.report.iterations, 1);
    }

    #[test]
    fn servo_takes_gain_scaled_steps_and_reweights_before_each() {
        let x_true = SVector::<f64, 3>::new(1.0, -2.0, 0.5);
        let mut problem = Linear::new(x_true);
        let fit = solve(
            &mut problem,
            SVector::zeros(),
            &SolverOptions::servo(1, 0.5, 0.0),
        );
        // One step of half the Gauss-Newton step: halfway on a linear problem.
        assert!((fit.params - 0.5 * x_true).norm() < 1e-12);
        assert_eq!(fit.report.steps_applied, 1);
        assert_eq!(fit.report.stop, StopReason::MaxIterations);
        assert_eq!(problem.reweighted, 1);
        let condition = fit.report.inverse_condition.unwrap();
        assert!(condition > 0.0 && condition <= 1.0);
        // The gate refuses the step and leaves the parameters.
        let gated = solve(
            &mut problem,
            SVector::zeros(),
            &SolverOptions::servo(3, 1.0, 0.999_999),
        );
        assert_eq!(gated.report.stop, StopReason::IllConditioned);
        assert_eq!(gated.params, SVector::<f64, 3>::zeros());
        assert_eq!(gated.report.steps_applied, 0);
    }

    #[test]
    fn a_singular_system_stops_the_solver() {
        /// The third parameter never appears.
        struct Blind;
        impl LeastSquaresProblem<3> for Blind {
            type Params = SVector<f64, 3>;
            fn linearize<S: ResidualSink<3>>(&self, x: &Self::Params, sink: &mut S) {
                let a = SMatrix::<f64, 2, 3>::new(1.0, 2.0, 0.0, 3.0, -1.0, 0.0);
                sink.add(&a, &(a * x - Vector2::new(1.0, 1.0)), 1.0);
            }
            fn apply_step(&self, x: &Self::Params, step: &SVector<f64, 3>) -> Self::Params {
                x + step
            }
        }
        for options in [
            SolverOptions::servo(2, 1.0, 0.0),
            SolverOptions {
                max_iterations: 5,
                method: Method::LevenbergMarquardt(DampingSchedule::GAUSS_NEWTON_FIRST),
            },
        ] {
            let fit = solve(&mut Blind, SVector::zeros(), &options);
            assert_eq!(fit.report.stop, StopReason::SingularSystem, "{options:?}");
            assert!(!fit.report.converged);
            assert_eq!(fit.params, SVector::<f64, 3>::zeros());
        }
    }

    #[test]
    fn an_unevaluable_candidate_is_refused() {
        /// A parabola whose cost is undefined for x > 1: the minimum at x = 2 is out of reach.
        struct Fenced;
        impl LeastSquaresProblem<1> for Fenced {
            type Params = f64;
            fn linearize<S: ResidualSink<1>>(&self, x: &f64, sink: &mut S) {
                if *x > 1.0 {
                    sink.add_unevaluable();
                } else {
                    sink.add(
                        &SMatrix::<f64, 2, 1>::new(1.0, 0.0),
                        &Vector2::new(x - 2.0, 0.0),
                        1.0,
                    );
                }
            }
            fn apply_step(&self, x: &f64, step: &SVector<f64, 1>) -> f64 {
                x + step[0]
            }
        }
        let fit = solve(&mut Fenced, 0.0, &SolverOptions::levenberg_marquardt(200));
        assert!(fit.params <= 1.0 && fit.params > 0.9, "{}", fit.params);
        assert!(fit.report.final_cost_px2.is_finite());
    }
}
