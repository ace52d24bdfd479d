//! The batch baseline (after Ait-Aider et al.): at each control step, Levenberg-Marquardt of the 12 parameters to
//! convergence on the window, from the state predicted to the newest measurement's time; a degenerate window (badly
//! conditioned, or with fewer than 4 equations beyond the 12 unknowns) keeps the prediction.

use super::problem::ResidualFigures;
use super::track::{Law, Step, Track, TrackCore};
use super::{
    ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport, TrackError, TrackStatus,
    TrackerConfig,
};
use roitrack_core::{CameraModel, Measurement, MotionState, Target};

/// Levenberg-Marquardt iterations of a control step.
const MAX_ITERATIONS: usize = 30;

#[derive(Debug, Clone)]
struct BatchLaw;

impl Law for BatchLaw {
    fn begin_track(&mut self, _core: &TrackCore, _covariance: Option<super::Matrix12>) {}

    fn control_step(&mut self, core: &mut TrackCore, t_new_s: f64) -> Step {
        let predicted = core.state.predicted(t_new_s - core.t_ref_s);
        core.t_ref_s = t_new_s;
        let fit = core
            .window_problem(t_new_s)
            .with_loss(core.config.robust, 1.0)
            .fit_robustly(predicted, MAX_ITERATIONS);
        let ne = fit.normal_equations;
        let inverse_condition = ne.fast_inverse_condition();
        let status = if core.is_degenerate(inverse_condition)
            || core.is_underdetermined(ne.count())
            || !fit.params.is_finite()
        {
            core.state = predicted;
            TrackStatus::Degenerate
        } else {
            core.state = fit.params;
            TrackStatus::Tracking
        };
        Step {
            inverse_condition,
            measurements_used: ne.count(),
            iterations: fit.report.iterations,
            status,
            covariance: core.window_covariance(&ne, inverse_condition),
            acceleration: None,
        }
    }

    /// The newest measurement beyond Tukey's c at the window's robust scale (it weighed nothing), or a residual that
    /// the noise cannot explain (the state does not fit its own window).
    fn is_disputed(&self, core: &TrackCore, residuals: &ResidualFigures) -> bool {
        core.newest_beyond_robust_scale(residuals) || core.residual_inconsistent(residuals)
    }
}

/// The batch baseline: a full 12-dof fit of every window (see the [module documentation](self)).
///
/// ```
/// use roitrack_estimators::{BatchEstimator, Estimator, TrackerConfig, WindowMode};
/// use roitrack_core::{CameraModel, Target};
///
/// let config = TrackerConfig { window: WindowMode::Last(32), ..TrackerConfig::default() };
/// let batch = BatchEstimator::new(CameraModel::canonical(), Target::grid4x4(), config).unwrap();
/// assert_eq!(batch.config().window, WindowMode::Last(32));
/// ```
#[derive(Debug, Clone)]
pub struct BatchEstimator(Track<BatchLaw>);

impl BatchEstimator {
    /// The baseline for `camera` and `target` with the common options of `config` (its `estimator` becomes
    /// [`EstimatorConfig::Batch`]).
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
    ) -> Result<Self, ConfigError> {
        Track::new(camera, target, config, EstimatorConfig::Batch, BatchLaw).map(Self)
    }
}

super::delegate_estimator!(BatchEstimator);
