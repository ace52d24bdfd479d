//! The static baseline: at each control step, the static pose (PnP) of the newest centroid of each point as if they
//! were simultaneous, and the velocity by finite differences of consecutive poses. What a tracker that ignores the
//! acquisition times does.

use super::problem::ResidualFigures;
use super::static_pose::refine_static_pose;
use super::track::{Law, Step, Track, TrackCore};
use super::{
    ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport, TrackError, TrackStatus,
    TrackerConfig, WindowMode,
};
use roitrack_core::{CameraModel, Measurement, MotionState, Target, so3};

/// Gauss-Newton iterations of each static pose.
const MAX_ITERATIONS: usize = 20;

#[derive(Debug, Clone)]
struct StaticLaw {
    /// The previous pose and its time, for the finite differences.
    previous: Option<(f64, MotionState)>,
}

impl Law for StaticLaw {
    fn begin_track(&mut self, _core: &TrackCore, _covariance: Option<super::Matrix12>) {
        self.previous = None;
    }

    fn control_step(&mut self, core: &mut TrackCore, t_new_s: f64) -> Step {
        core.fill_scratch(WindowMode::NewestPerPoint);
        let fit = refine_static_pose(
            &core.model,
            &core.target,
            &core.scratch,
            &core.state,
            MAX_ITERATIONS,
        );
        let mut state = fit.state;
        if let Some((t_prev, prev)) = self.previous {
            let dt = t_new_s - t_prev;
            if dt > 0.0 {
                state.velocity_mps = (state.cam_t_obj_m - prev.cam_t_obj_m) / dt;
                state.angular_velocity_radps =
                    so3::log(&(state.cam_r_obj * prev.cam_r_obj.inverse())) / dt;
            }
        }
        let status = if core.is_degenerate(fit.inverse_condition) || !state.is_finite() {
            TrackStatus::Degenerate
        } else {
            self.previous = Some((t_new_s, state));
            core.state = state;
            TrackStatus::Tracking
        };
        core.t_ref_s = t_new_s;
        Step {
            inverse_condition: fit.inverse_condition,
            measurements_used: core.scratch.len(),
            iterations: fit.iterations,
            status,
            covariance: None,
            acceleration: None,
        }
    }

    /// A static fit has no gate: nothing is disputed.
    fn is_disputed(&self, _core: &TrackCore, _residuals: &ResidualFigures) -> bool {
        false
    }

    fn simultaneous_residuals(&self) -> bool {
        true
    }
}

/// The static baseline (see the [module documentation](self)).
///
/// ```
/// use roitrack_estimators::{Estimator, StaticEstimator, TrackerConfig};
/// use roitrack_core::{CameraModel, Target};
///
/// let baseline = StaticEstimator::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default());
/// assert!(baseline.is_ok());
/// ```
#[derive(Debug, Clone)]
pub struct StaticEstimator(Track<StaticLaw>);

impl StaticEstimator {
    /// The baseline for `camera` and `target` with the common options of `config` (its `estimator` becomes
    /// [`EstimatorConfig::Static`]).
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
    ) -> Result<Self, ConfigError> {
        Track::new(
            camera,
            target,
            config,
            EstimatorConfig::Static,
            StaticLaw { previous: None },
        )
        .map(Self)
    }
}

super::delegate_estimator!(StaticEstimator);
