//! Offline rolling-shutter refinement: a frame's pose fitted again from its own blobs, each at its row's time, with
//! the twist (and accelerations) taken from the poses of the frames around it rather than from a causal filter.
//!
//! Why: with a rolling shutter a frame's blobs are read milliseconds apart, and the pose fitted from them depends on
//! the twist assumed over the readout (a twist error of 1 m/s across the rows moved about 11 mm in depth on a 0.5 m
//! target). A causal filter's twist lags the motion by its angular acceleration and jerk; a central difference of
//! the poses of the neighbouring frames does not (a 5-point stencil leaves an error of order jerk'' T⁴, where a ±1
//! frame difference leaves jerk T²/6, too much at 30 Hz). Pure math, no I/O: the buffering of frames lives in the
//! pipeline.

use nalgebra::{Matrix6, Rotation3, SMatrix, SVector, Vector2, Vector3};

use super::static_pose::{apply_pose_step, pose_step_is_negligible};
use super::{Observation, RobustLoss};
use roitrack_core::solver::{
    self, DampingSchedule, LeastSquaresProblem, Method, ResidualSink, SolverOptions,
};
use roitrack_core::{Acceleration, MotionState, SpatioTemporalModel, Target, so3};

/// Most poses a stencil takes: the frame and two on either side.
pub const MAX_STENCIL_POSES: usize = 5;

/// A pose at a time (a frame's estimate at the mean time of its blobs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedPose {
    /// The pose's time (s).
    pub t_s: f64,
    /// The object's orientation in the camera frame (c_R_o).
    pub cam_r_obj: Rotation3<f64>,
    /// The object's origin in the camera frame (m).
    pub cam_t_obj_m: Vector3<f64>,
}

/// The twist and accelerations at one pose's time, by finite differences of the poses around it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StencilMotion {
    /// Velocity of the object's origin, camera frame (m/s).
    pub velocity_mps: Vector3<f64>,
    /// Angular velocity, camera frame (rad/s): the derivative of `log(R(t) R(t_c)ᵀ)`, as [`MotionState`] takes it.
    pub angular_velocity_radps: Vector3<f64>,
    /// The second derivatives (with three poses or more, always the case here).
    pub acceleration: Acceleration,
    /// The first-derivative weight of each pose (1/s), in the order given: a pose error `e_j` moves the twist by
    /// `Σ w_j e_j`, so independent pose covariances `P_j` give the twist covariance `Σ w_j² P_j`.
    pub velocity_weights_per_s: [f64; MAX_STENCIL_POSES],
}

/// The first and second derivative weights, at offset 0, of the polynomial through values at `offsets_s`
/// (Lagrange's basis differentiated; a uniform 5-point stencil gives (1, -8, 0, 8, -1) / 12T).
fn derivative_weights(offsets_s: &[f64]) -> ([f64; MAX_STENCIL_POSES], [f64; MAX_STENCIL_POSES]) {
    let n = offsets_s.len();
    let mut first = [0.0; MAX_STENCIL_POSES];
    let mut second = [0.0; MAX_STENCIL_POSES];
    for j in 0..n {
        let dj = offsets_s[j];
        // L_j(x) = Π_{m≠j} (x - d_m) / (d_j - d_m); its derivatives at 0 by sums over the factors left out.
        let denominator: f64 = (0..n)
            .filter(|&m| m != j)
            .map(|m| dj - offsets_s[m])
            .product();
        let others: Vec<usize> = (0..n).filter(|&m| m != j).collect();
        let mut d1 = 0.0;
        let mut d2 = 0.0;
        for (a, &ma) in others.iter().enumerate() {
            let without_a: f64 = others
                .iter()
                .filter(|&&m| m != ma)
                .map(|&m| -offsets_s[m])
                .product();
            d1 += without_a;
            for &mb in &others[a + 1..] {
                let without_ab: f64 = others
                    .iter()
                    .filter(|&&m| m != ma && m != mb)
                    .map(|&m| -offsets_s[m])
                    .product();
                d2 += 2.0 * without_ab;
            }
        }
        first[j] = d1 / denominator;
        second[j] = d2 / denominator;
    }
    (first, second)
}

/// The twist and accelerations at `poses[centre]`'s time from finite differences of `poses` (time order, at most
/// [`MAX_STENCIL_POSES`], on any spacing); `None` without a pose on each side of the centre (a one-sided difference
/// at the ends of a track would extrapolate), with more than [`MAX_STENCIL_POSES`] or with times out of order.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{TimedPose, stencil_motion};
///
/// // Moving at 0.2 m/s along x and turning at 1 rad/s about y, 30 frames a second.
/// let poses: Vec<TimedPose> = (-2..=2)
///     .map(|k| {
///         let t_s = k as f64 / 30.0;
///         TimedPose {
///             t_s,
///             cam_r_obj: Rotation3::new(Vector3::new(0.0, t_s, 0.0)),
///             cam_t_obj_m: Vector3::new(0.2 * t_s, 0.0, 0.5),
///         }
///     })
///     .collect();
/// let motion = stencil_motion(&poses, 2).unwrap();
/// assert!((motion.velocity_mps - Vector3::new(0.2, 0.0, 0.0)).norm() < 1e-12);
/// assert!((motion.angular_velocity_radps - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-9);
/// ```
pub fn stencil_motion(poses: &[TimedPose], centre: usize) -> Option<StencilMotion> {
    if centre == 0 || centre + 1 >= poses.len() {
        return None;
    }
    motion_of_polynomial(poses, centre)
}

/// The twist and accelerations at `poses[0]`'s time from it and the poses after it (3 to [`MAX_STENCIL_POSES`], in
/// time order): the first frames of a track, where no pose precedes. The polynomial's derivatives are extrapolated to
/// its end, so they are less accurate than a central stencil's (a 3-pose end difference leaves jerk T²/3), but the
/// filter starting a track knows no twist at all, and a rolling shutter's frame fitted with none is millimetres off in
/// depth. `None` with fewer than 3 poses, more than [`MAX_STENCIL_POSES`] or times out of order.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{TimedPose, stencil_motion_at_start};
///
/// // Accelerating along x at 2 m/s² from 0.1 m/s, 30 frames a second: a quadratic, exact for 3 poses.
/// let poses: Vec<TimedPose> = (0..3)
///     .map(|k| {
///         let t_s = k as f64 / 30.0;
///         TimedPose {
///             t_s,
///             cam_r_obj: Rotation3::identity(),
///             cam_t_obj_m: Vector3::new(0.1 * t_s + t_s * t_s, 0.0, 0.5),
///         }
///     })
///     .collect();
/// let motion = stencil_motion_at_start(&poses).unwrap();
/// assert!((motion.velocity_mps - Vector3::new(0.1, 0.0, 0.0)).norm() < 1e-9);
/// assert!((motion.acceleration.linear_mps2 - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-6);
/// ```
pub fn stencil_motion_at_start(poses: &[TimedPose]) -> Option<StencilMotion> {
    if poses.len() < 3 {
        return None;
    }
    motion_of_polynomial(poses, 0)
}

/// The derivatives at `poses[centre]` of the polynomial through `poses`; `None` with more than
/// [`MAX_STENCIL_POSES`] or times out of order.
fn motion_of_polynomial(poses: &[TimedPose], centre: usize) -> Option<StencilMotion> {
    if poses.len() > MAX_STENCIL_POSES || poses.windows(2).any(|w| w[1].t_s <= w[0].t_s) {
        return None;
    }
    let c = &poses[centre];
    let mut offsets_s = [0.0; MAX_STENCIL_POSES];
    for (o, p) in offsets_s.iter_mut().zip(poses) {
        *o = p.t_s - c.t_s;
    }
    let (first, second) = derivative_weights(&offsets_s[..poses.len()]);
    let mut motion = StencilMotion {
        velocity_mps: Vector3::zeros(),
        angular_velocity_radps: Vector3::zeros(),
        acceleration: Acceleration {
            linear_mps2: Vector3::zeros(),
            angular_radps2: Vector3::zeros(),
        },
        velocity_weights_per_s: first,
    };
    let inverse_centre = c.cam_r_obj.inverse();
    for (j, p) in poses.iter().enumerate() {
        // Rotations as left increments from the centre's, the tangent MotionState's twist lives in.
        let turn = so3::log(&(p.cam_r_obj * inverse_centre));
        motion.velocity_mps += p.cam_t_obj_m * first[j];
        motion.angular_velocity_radps += turn * first[j];
        motion.acceleration.linear_mps2 += p.cam_t_obj_m * second[j];
        motion.acceleration.angular_radps2 += turn * second[j];
    }
    motion
        .velocity_mps
        .iter()
        .chain(motion.angular_velocity_radps.iter())
        .all(|x| x.is_finite())
        .then_some(motion)
}

/// A pose fitted by [`refit_pose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseRefit {
    /// The pose at the reference time, with the twist it was fitted with.
    pub state: MotionState,
    /// Covariance of the pose's error (v, w): `σ² (Jᵀ W J)⁻¹` with σ the centroid noise and W the robust weights.
    pub pose_covariance: Matrix6<f64>,
    /// RMS of the weighted residual at the fitted pose (px, per coordinate).
    pub residual_rms_px: f64,
    /// Linearisations the solver took.
    pub iterations: usize,
    /// The solver converged (its last step negligible).
    pub converged: bool,
}

/// The residuals (predicted minus observed ideal pixels, `[u0, v0, u1, v1, ...]`) of `obs` seen from `state` at
/// `t_ref_s`, moved under its twist and `acceleration`, and their Jacobian with respect to a pose correction (v, w)
/// (as [`MotionState::corrected`] applies it); `None` if a point is behind the camera or out of the target.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, pose_residuals};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// let state = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6));
/// let ideal_px = model.project(&state, &target.points()[0].point_in_obj_m, 0.0).unwrap();
/// let obs = [Observation { t_s: 1.0, point_index: 0, ideal_px }];
/// let (residuals, jacobian) = pose_residuals(&model, &target, &obs, 1.0, &state, None).unwrap();
/// assert!(residuals.norm() < 1e-12);
/// assert_eq!(jacobian.shape(), (2, 6));
/// ```
pub fn pose_residuals(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    t_ref_s: f64,
    state: &MotionState,
    acceleration: Option<&Acceleration>,
) -> Option<(
    nalgebra::DVector<f64>,
    nalgebra::OMatrix<f64, nalgebra::Dyn, nalgebra::U6>,
)> {
    let mut residuals = nalgebra::DVector::zeros(2 * obs.len());
    let mut jacobian = nalgebra::OMatrix::<f64, nalgebra::Dyn, nalgebra::U6>::zeros(2 * obs.len());
    for (i, o) in obs.iter().enumerate() {
        let (residual, j) = observation_residual(model, target, o, t_ref_s, state, acceleration)?;
        residuals.fixed_rows_mut::<2>(2 * i).copy_from(&residual);
        jacobian.fixed_view_mut::<2, 6>(2 * i, 0).copy_from(&j);
    }
    Some((residuals, jacobian))
}

/// Gauss-Newton on the 6-dof pose of `initial` at `t_ref_s` from `obs` (each at its own time), its twist and
/// `acceleration` held; Huber weights at `noise_px` scales keep a stray blob from pulling the pose. `None` with
/// fewer than 4 observations, a point behind the camera, or a singular fit.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, refit_pose};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// let truth = MotionState {
///     velocity_mps: Vector3::new(0.5, -0.3, 0.2),
///     angular_velocity_radps: Vector3::new(0.0, 2.0, 0.0),
///     ..MotionState::at_rest(Rotation3::from_euler_angles(0.2, -0.1, 0.3), Vector3::new(0.01, 0.0, 0.6))
/// };
/// // A rolling shutter: each blob read 1 ms after the one before.
/// let obs: Vec<Observation> = (0..16)
///     .map(|i| {
///         let t_s = 1.0 + 1e-3 * i as f64;
///         let ideal_px = model.project(&truth, &target.points()[i].point_in_obj_m, t_s - 1.0).unwrap();
///         Observation { t_s, point_index: i, ideal_px }
///     })
///     .collect();
/// let start = MotionState { cam_t_obj_m: Vector3::new(0.0, 0.0, 0.62), ..truth };
/// let fit = refit_pose(&model, &target, &obs, 1.0, &start, None, 0.1, 10).unwrap();
/// assert!(fit.converged && (fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-9);
/// ```
#[allow(clippy::too_many_arguments)]
pub fn refit_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    t_ref_s: f64,
    initial: &MotionState,
    acceleration: Option<&Acceleration>,
    noise_px: f64,
    max_iterations: usize,
) -> Option<PoseRefit> {
    // A noise of zero or NaN would weigh nothing or everything.
    if obs.len() < 4 || noise_px.is_nan() || noise_px <= 0.0 {
        return None;
    }
    let mut problem = RollingPoseProblem {
        model,
        target,
        obs,
        t_ref_s,
        acceleration,
        noise_px,
    };
    let options = SolverOptions {
        max_iterations,
        method: Method::LevenbergMarquardt(DampingSchedule::GAUSS_NEWTON_FIRST),
    };
    let fit = solver::solve(&mut problem, *initial, &options);
    let ne = &fit.normal_equations;
    if !ne.cost_px2().is_finite() {
        return None;
    }
    Some(PoseRefit {
        state: fit.params,
        pose_covariance: ne.covariance(noise_px)?,
        residual_rms_px: (ne.weighted_cost_px2() / (2 * obs.len()) as f64).sqrt(),
        iterations: fit.report.iterations,
        converged: fit.report.converged,
    })
}

/// The pose of [`refit_pose`] as a least-squares problem: every blob at its own time under the given twist and
/// accelerations, weighted by Huber's loss at the noise.
struct RollingPoseProblem<'a> {
    model: &'a SpatioTemporalModel,
    target: &'a Target,
    obs: &'a [Observation],
    t_ref_s: f64,
    acceleration: Option<&'a Acceleration>,
    noise_px: f64,
}

impl LeastSquaresProblem<6> for RollingPoseProblem<'_> {
    type Params = MotionState;

    fn linearize<S: ResidualSink<6>>(&self, state: &MotionState, sink: &mut S) {
        for o in self.obs {
            match observation_residual(
                self.model,
                self.target,
                o,
                self.t_ref_s,
                state,
                self.acceleration,
            ) {
                Some((residual, jacobian)) => {
                    let weight = RobustLoss::Huber.weight(residual.norm() / self.noise_px);
                    sink.add(&jacobian, &residual, weight);
                }
                None => sink.add_unevaluable(),
            }
        }
    }

    fn apply_step(&self, state: &MotionState, step: &SVector<f64, 6>) -> MotionState {
        apply_pose_step(state, step)
    }

    fn step_is_negligible(&self, step: &SVector<f64, 6>) -> bool {
        pose_step_is_negligible(step)
    }
}

/// One observation's residual (predicted minus observed ideal pixel) seen from `state` at `t_ref_s`, moved under its
/// twist and `acceleration`, and its Jacobian with respect to a pose correction (v, w).
fn observation_residual(
    model: &SpatioTemporalModel,
    target: &Target,
    o: &Observation,
    t_ref_s: f64,
    state: &MotionState,
    acceleration: Option<&Acceleration>,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, 6>)> {
    let d_s = o.t_s - t_ref_s;
    // Under constant accelerations the pose d later is Exp((W + ½Α d) d) R, t + (V + ½A d) d: the constant-twist
    // model with the twist averaged over d, whose pose Jacobian is the same.
    let moved = match acceleration {
        Some(a) => MotionState {
            velocity_mps: state.velocity_mps + a.linear_mps2 * (0.5 * d_s),
            angular_velocity_radps: state.angular_velocity_radps + a.angular_radps2 * (0.5 * d_s),
            ..*state
        },
        None => *state,
    };
    let p = &target.points().get(o.point_index)?.point_in_obj_m;
    let projected =
        model.project_with_jacobian(roitrack_core::JacobianKind::Exact, &moved, p, d_s)?;
    Some((
        projected.pixel - o.ideal_px,
        projected.jacobian.fixed_view::<2, 6>(0, 0).into_owned(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use roitrack_core::{CameraModel, Vector12};

    fn scene() -> (SpatioTemporalModel, Target, MotionState, Acceleration) {
        let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
        let state = MotionState {
            cam_r_obj: Rotation3::from_euler_angles(0.3, -0.2, 0.1),
            cam_t_obj_m: Vector3::new(0.02, -0.01, 0.55),
            velocity_mps: Vector3::new(0.8, -0.4, 0.3),
            angular_velocity_radps: Vector3::new(1.5, -3.0, 2.0),
        };
        let acceleration = Acceleration {
            linear_mps2: Vector3::new(10.0, -5.0, 3.0),
            angular_radps2: Vector3::new(20.0, 5.0, -10.0),
        };
        (model, Target::grid4x4(), state, acceleration)
    }

    fn observations(
        model: &SpatioTemporalModel,
        target: &Target,
        truth: &MotionState,
        acceleration: &Acceleration,
    ) -> Vec<Observation> {
        (0..target.len())
            .map(|i| {
                // Rows read over 20 ms around the reference time.
                let d_s = -0.01 + 0.02 * i as f64 / (target.len() - 1) as f64;
                let at = acceleration.predicted(truth, d_s);
                Observation {
                    t_s: 2.0 + d_s,
                    point_index: i,
                    ideal_px: model
                        .project(&at, &target.points()[i].point_in_obj_m, 0.0)
                        .unwrap(),
                }
            })
            .collect()
    }

    #[test]
    fn the_pose_jacobian_matches_central_finite_differences() {
        let (model, target, state, acceleration) = scene();
        let obs = observations(&model, &target, &state, &acceleration);
        let shifted = MotionState {
            cam_t_obj_m: state.cam_t_obj_m + Vector3::new(0.003, 0.001, -0.004),
            ..state
        };
        // The grid's 16 points: 32 residuals.
        let residuals = |at: &MotionState, accel: Option<&Acceleration>| {
            let (r, j) = pose_residuals(&model, &target, &obs, 2.0, at, accel).unwrap();
            (
                nalgebra::SVector::<f64, 32>::from_column_slice(r.as_slice()),
                nalgebra::SMatrix::<f64, 32, 6>::from_column_slice(j.as_slice()),
            )
        };
        for accel in [None, Some(&acceleration)] {
            roitrack_testkit::jacobian::check_at(
                "pose residuals",
                &shifted,
                &nalgebra::Vector6::repeat(1.0),
                |at, d| {
                    let delta = Vector12::from_iterator(d.iter().copied().chain([0.0; 6]));
                    residuals(&at.corrected(&delta), accel).0
                },
                &residuals(&shifted, accel).1,
            );
        }
    }

    #[test]
    fn the_refit_recovers_an_accelerating_pose_from_rolling_rows() {
        let (model, target, truth, acceleration) = scene();
        let obs = observations(&model, &target, &truth, &acceleration);
        let start = MotionState {
            cam_r_obj: so3::exp(&Vector3::new(0.02, -0.01, 0.03)) * truth.cam_r_obj,
            cam_t_obj_m: truth.cam_t_obj_m + Vector3::new(0.01, -0.005, 0.02),
            ..truth
        };
        let fit = refit_pose(
            &model,
            &target,
            &obs,
            2.0,
            &start,
            Some(&acceleration),
            0.1,
            20,
        )
        .unwrap();
        assert!(fit.converged);
        assert!((fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-9);
        assert!(so3::angle_between(&fit.state.cam_r_obj, &truth.cam_r_obj) < 1e-9);
        assert!(fit.residual_rms_px < 1e-6);
        // A covariance: symmetric, positive, sub-millimetre at 0.1 px.
        let sd_m = fit.pose_covariance[(2, 2)].sqrt();
        assert!(sd_m > 0.0 && sd_m < 1e-3, "{sd_m}");
        // Without the accelerations, the rows' quadratic motion leaves the pose off.
        let lagged = refit_pose(&model, &target, &obs, 2.0, &start, None, 0.1, 20).unwrap();
        assert!((lagged.state.cam_t_obj_m - truth.cam_t_obj_m).norm() > 1e-6);
    }

    #[test]
    fn the_stencil_is_exact_for_polynomials_of_its_order_on_uneven_times() {
        let times_s = [-0.068, -0.033, 0.0, 0.034, 0.066];
        let position = |t: f64| {
            Vector3::new(
                0.1 + 0.5 * t + 4.0 * t * t + 20.0 * t.powi(3) - 90.0 * t.powi(4),
                -0.2 * t,
                0.5,
            )
        };
        let poses: Vec<TimedPose> = times_s
            .iter()
            .map(|&t_s| TimedPose {
                t_s,
                cam_r_obj: Rotation3::new(Vector3::new(0.0, 0.0, 2.0 * t_s + 3.0 * t_s * t_s)),
                cam_t_obj_m: position(t_s),
            })
            .collect();
        let motion = stencil_motion(&poses, 2).unwrap();
        assert!((motion.velocity_mps - Vector3::new(0.5, -0.2, 0.0)).norm() < 1e-10);
        assert!((motion.acceleration.linear_mps2 - Vector3::new(8.0, 0.0, 0.0)).norm() < 1e-8);
        assert!((motion.angular_velocity_radps - Vector3::new(0.0, 0.0, 2.0)).norm() < 1e-10);
        assert!((motion.acceleration.angular_radps2 - Vector3::new(0.0, 0.0, 6.0)).norm() < 1e-8);
        // The weights of a derivative sum to zero (a constant has none).
        assert!(motion.velocity_weights_per_s.iter().sum::<f64>().abs() < 1e-9);
        // Three poses, the fallback at a track's second frame: still central, exact for a parabola's slope.
        let three = stencil_motion(&poses[1..4], 1).unwrap();
        assert!((three.angular_velocity_radps.z - 2.0).abs() < 1e-10);
        // No pose on one side: refused.
        assert!(stencil_motion(&poses[2..], 0).is_none());
        assert!(stencil_motion(&poses[..3], 2).is_none());
    }
}
