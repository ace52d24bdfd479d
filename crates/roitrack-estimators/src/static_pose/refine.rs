//! The static pose refined on the reprojection error (Gauss-Newton on the 6-dof pose), and the residual it leaves.

use nalgebra::{SMatrix, SVector};

use crate::Observation;
use crate::model_error::{ModelEffect, ModelResidual, model_residual};
use roitrack_core::solver::{
    self, DampingSchedule, LeastSquaresProblem, Method, ResidualSink, SolverOptions,
};
use roitrack_core::{MotionState, SpatioTemporalModel, Target};

use super::PoseFit;

/// The 6-dof static problem: the pose that best projects the model points onto the observations, every observation
/// taken at the same pose (its time ignored, the velocity zero).
pub(super) struct StaticPoseProblem<'a> {
    pub(super) model: &'a SpatioTemporalModel,
    pub(super) target: &'a Target,
    pub(super) obs: &'a [Observation],
}

impl LeastSquaresProblem<6> for StaticPoseProblem<'_> {
    type Params = MotionState;

    fn linearize<S: ResidualSink<6>>(&self, state: &MotionState, sink: &mut S) {
        let points = self.target.points();
        let r = state.cam_r_obj.matrix();
        for o in self.obs {
            let op = r * points[o.point_index].point_in_obj_m;
            let p = op + state.cam_t_obj_m;
            let Some(pixel) = self.model.intrinsics.pixel_from_cam(&p) else {
                sink.add_unevaluable();
                continue;
            };
            // d(u,v)/dP [I, -[OP]x]
            let d = self.model.intrinsics.pixel_jacobian_wrt_cam(&p);
            let rot = -(d * roitrack_core::so3::hat(&op));
            let mut j = SMatrix::<f64, 2, 6>::zeros();
            j.fixed_view_mut::<2, 3>(0, 0).copy_from(&d);
            j.fixed_view_mut::<2, 3>(0, 3).copy_from(&rot);
            sink.add(&j, &(pixel - o.ideal_px), 1.0);
        }
    }

    fn apply_step(&self, state: &MotionState, step: &SVector<f64, 6>) -> MotionState {
        apply_pose_step(state, step)
    }

    fn step_is_negligible(&self, step: &SVector<f64, 6>) -> bool {
        pose_step_is_negligible(step)
    }
}

/// A pose correction (v, w) applied to `state`, its twist left as it is: the step of every 6-dof pose problem.
pub(crate) fn apply_pose_step(state: &MotionState, step: &SVector<f64, 6>) -> MotionState {
    let mut delta = roitrack_core::Vector12::zeros();
    delta.fixed_rows_mut::<6>(0).copy_from(step);
    state.corrected(&delta)
}

/// Gauss-Newton on a pose converges about quadratically: after a step this small (1e-6 m and rad) the next is about
/// 1e-9, far below the noise, so it is taken without checking the cost.
pub(crate) fn pose_step_is_negligible(step: &SVector<f64, 6>) -> bool {
    step.fixed_rows::<3>(0).norm() < 1e-6 && step.fixed_rows::<3>(3).norm() < 1e-6
}

/// Gauss-Newton on the 6-dof pose, all observations taken as simultaneous, with Levenberg-Marquardt safeguarding
/// ([`DampingSchedule::GAUSS_NEWTON_FIRST`]): a step that raises the cost is retried with damping. Converged to the
/// accuracy of a converged VVS (about 1e-9 m and rad, far below the noise) after 2 to 4 iterations from the closed
/// form.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, refine_static_pose};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.2, -0.1, 0.3), Vector3::new(0.01, 0.0, 0.6));
/// let obs: Vec<Observation> = (0..16)
///     .map(|i| Observation {
///         t_s: 0.0,
///         point_index: i,
///         ideal_px: model.project(&truth, &target.points()[i].point_in_obj_m, 0.0).unwrap(),
///     })
///     .collect();
/// let start = MotionState::at_rest(Rotation3::from_euler_angles(0.25, -0.1, 0.3), Vector3::new(0.0, 0.0, 0.65));
/// let fit = refine_static_pose(&model, &target, &obs, &start, 20);
/// assert!(fit.converged);
/// assert!((fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-9);
/// ```
pub fn refine_static_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    initial: &MotionState,
    max_iterations: usize,
) -> PoseFit {
    let mut problem = StaticPoseProblem { model, target, obs };
    let options = SolverOptions {
        max_iterations,
        method: Method::LevenbergMarquardt(DampingSchedule::GAUSS_NEWTON_FIRST),
    };
    let fit = solver::solve(
        &mut problem,
        MotionState::at_rest(initial.cam_r_obj, initial.cam_t_obj_m),
        &options,
    );
    let ne = fit.normal_equations;
    PoseFit {
        state: fit.params,
        cost_px2: ne.cost_px2(),
        residual_rms_px: ne.residual_rms_px(),
        model_effect: ModelEffect::default(),
        inverse_condition: ne.fast_inverse_condition(),
        iterations: fit.report.iterations,
        converged: fit.report.converged,
    }
}

/// What the error of the user's own camera and target files ([`super::MODEL_UNCERTAINTY`]: what calibrations,
/// nominal lens data and drawings are off by, one standard deviation) leaves on average in the residual of the static
/// pose `state` fitted to `obs`, beyond the noise's share: what of the model's error the pose cannot absorb; its
/// [`ModelResidual::bound_px2`] is the residual a fit on a model as good as users' files are stays within. `None` if
/// a point does not project or the pose is degenerate.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, static_model_residual};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// let state = MotionState::at_rest(Rotation3::from_euler_angles(0.4, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.5));
/// let obs: Vec<Observation> = (0..16)
///     .map(|i| Observation {
///         t_s: 0.0,
///         point_index: i,
///         ideal_px: model.project(&state, &target.points()[i].point_in_obj_m, 0.0).unwrap(),
///     })
///     .collect();
/// let residual = static_model_residual(&model, &target, &obs, &state).unwrap();
/// // Far more than nothing, far less than a pixel at each of the 32 coordinates.
/// let cost_px2 = residual.intrinsics_px2 + residual.target_px2;
/// assert!(cost_px2 > 1e-3 && cost_px2 < 32.0);
/// // With 0.3 px of noise, the largest residual such a fit leaves, as an RMS per coordinate.
/// let bound_px = residual.bound_rms_px(0.3, 2.0);
/// assert!(bound_px > 0.3 && bound_px < 1.5);
/// ```
///
/// [`super::MODEL_UNCERTAINTY`]: crate::MODEL_UNCERTAINTY
pub fn static_model_residual(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    state: &MotionState,
) -> Option<ModelResidual> {
    let problem = StaticPoseProblem { model, target, obs };
    model_residual(&problem, model, target, obs, |_| 0.0, state)
}

/// The plain reprojection cost (px²) of `state` on `problem`'s observations; `None` if a point does not project.
pub(super) fn reprojection_cost_px2(
    problem: &StaticPoseProblem,
    state: &MotionState,
) -> Option<f64> {
    let cost = solver::normal_equations(problem, state).cost_px2();
    cost.is_finite().then_some(cost)
}
