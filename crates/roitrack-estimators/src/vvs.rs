//! The paper's estimator: virtual visual servoing on the spatio-temporal model. At each control step the state is
//! predicted with its own twist to the newest measurement's time, then `iterations` steps `δ = -λ L⁺ e` are taken on
//! the window (1 iteration: the paper's loop; more: Gauss-Newton), with the exact interaction matrix or the paper's
//! first-order one (eqs. 17-24), each refused on a degenerate window. With a robust loss, every step is weighted at the
//! window's median residual scale (IRLS).

use super::problem::ResidualFigures;
use super::track::{Law, Step, Track, TrackCore};
use super::{
    ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport, TrackError, TrackStatus,
    TrackerConfig,
};
use roitrack_core::solver::{self, SolverOptions, StopReason};
use roitrack_core::{CameraModel, JacobianKind, Measurement, MotionState, Target};

/// Settings of the virtual visual servoing loop.
///
/// ```
/// use roitrack_core::JacobianKind;
/// use roitrack_estimators::{EstimatorConfig, TrackerConfig, VvsSettings};
/// // The paper's loop: its own interaction matrix, gain 0.5, one iteration per control step.
/// let paper = VvsSettings { jacobian: JacobianKind::Paper, gain: 0.5, iterations: 1 };
/// let config = TrackerConfig { estimator: EstimatorConfig::Vvs(paper), ..TrackerConfig::default() };
/// assert!(config.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VvsSettings {
    /// Interaction matrix: `Exact` (default) or the paper's eqs. 17-24.
    pub jacobian: JacobianKind,
    /// Gain λ of the update `δ = -λ L⁺ e` (1 = a full Gauss-Newton step), in (0, 2].
    pub gain: f64,
    /// Iterations per control step (1 = the paper).
    pub iterations: usize,
}

impl Default for VvsSettings {
    fn default() -> Self {
        Self {
            jacobian: JacobianKind::Exact,
            gain: 1.0,
            iterations: 1,
        }
    }
}

#[derive(Debug, Clone)]
struct VvsLaw {
    settings: VvsSettings,
}

impl Law for VvsLaw {
    fn begin_track(&mut self, _core: &TrackCore, _covariance: Option<super::Matrix12>) {}

    fn control_step(&mut self, core: &mut TrackCore, t_new_s: f64) -> Step {
        let predicted = core.state.predicted(t_new_s - core.t_ref_s);
        core.t_ref_s = t_new_s;
        let options = SolverOptions::servo(
            self.settings.iterations,
            self.settings.gain,
            core.config.min_inverse_condition,
        );
        let mut problem = core
            .window_problem(t_new_s)
            .with_jacobian(self.settings.jacobian)
            .with_loss(core.config.robust, 1.0);
        let fit = solver::solve(&mut problem, predicted, &options);
        // A window with too little redundancy is not used either: its exact fit follows every centroid's noise.
        let underdetermined = core.is_underdetermined(core.scratch.len());
        core.state = if underdetermined {
            predicted
        } else {
            fit.params
        };
        let refused = underdetermined
            || matches!(
                fit.report.stop,
                StopReason::SingularSystem | StopReason::IllConditioned | StopReason::InvalidStep
            );
        let inverse_condition = fit.report.inverse_condition.unwrap_or(1.0);
        Step {
            inverse_condition,
            measurements_used: core.scratch.len(),
            iterations: fit.report.steps_applied,
            status: if refused {
                TrackStatus::Degenerate
            } else {
                TrackStatus::Tracking
            },
            covariance: core.window_covariance(&fit.normal_equations, inverse_condition),
            acceleration: None,
        }
    }

    /// The newest measurement beyond Tukey's c at the window's robust scale (it weighed nothing), or a residual that
    /// the noise cannot explain (the state does not fit its own window).
    fn is_disputed(&self, core: &TrackCore, residuals: &ResidualFigures) -> bool {
        core.newest_beyond_robust_scale(residuals) || core.residual_inconsistent(residuals)
    }
}

/// The paper's virtual visual servoing loop (see the [module documentation](self)).
///
/// ```
/// use roitrack_estimators::{Estimator, TrackerConfig, VvsEstimator, VvsSettings};
/// use roitrack_core::{CameraModel, Target};
///
/// let vvs = VvsEstimator::new(
///     CameraModel::canonical(),
///     Target::grid4x4(),
///     TrackerConfig::default(),
///     VvsSettings { gain: 0.5, ..VvsSettings::default() },
/// )
/// .unwrap();
/// assert_eq!(vvs.state(), None);
/// ```
#[derive(Debug, Clone)]
pub struct VvsEstimator(Track<VvsLaw>);

impl VvsEstimator {
    /// The loop for `camera` and `target` with the common options of `config` and its `settings` (which replace
    /// `config.estimator`).
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
        settings: VvsSettings,
    ) -> Result<Self, ConfigError> {
        Track::new(
            camera,
            target,
            config,
            EstimatorConfig::Vvs(settings),
            VvsLaw { settings },
        )
        .map(Self)
    }
}

super::delegate_estimator!(VvsEstimator);
