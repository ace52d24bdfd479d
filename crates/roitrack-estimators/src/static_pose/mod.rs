//! The static pose (6 dof, velocity zero) from one set of correspondences with no prior, for every target of three or
//! more points that are not on one line: planar, nearly planar or spread in depth, with no switch between them.
//!
//! Hypothesise and verify, then refine:
//!
//! 1. **Hypotheses**: the minimal solver ([`p3p`], at most four poses) on the triple of points whose images span the
//!    largest triangle (the best conditioned), then on further triples while no hypothesis fits the noise.
//! 2. **Verification**: each hypothesis is taken to the nearest minimum of the object-space error over every point
//!    ([`object_space`]: the squared distances of the posed points from their rays, the translation eliminated),
//!    at a cost that does not depend on the number of points.
//! 3. **Refinement**: the minima that could rival the best are refined by Gauss-Newton on the reprojection error (the
//!    maximum-likelihood pose for Gaussian centroid noise), i.e. 6-dof virtual visual servoing to convergence.
//!
//! A pose can be ambiguous: three points are posed exactly by up to four poses, and a small or distant target (planar
//! or not) can be fitted about as well by its mirror tilt. Every refined minimum whose cost exceeds the best's by
//! less than [`AMBIGUITY_CHI2`] times the noise variance is returned beside it, best first; the caller decides with
//! more data (the next cycle or frame) and never takes the first silently.

mod object_space;
mod p3p;

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector2, Vector3};
use thiserror::Error;

use super::Observation;
use super::model_error::{
    ModelEffect, ModelResidual, cost_difference_effect, model_residual, relabelling_effect,
};
use object_space::ObjectSpaceCost;
use roitrack_core::solver::{
    self, DampingSchedule, LeastSquaresProblem, Method, ResidualSink, SolverOptions,
};
use roitrack_core::{MotionState, SpatioTemporalModel, Target};

/// Why no static pose could be found.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum InitError {
    /// Fewer distinct points were observed than a pose needs.
    #[error("a static pose needs at least {required} distinct points, got {actual}")]
    TooFewPoints {
        /// The least number of distinct points a static pose needs (3).
        required: usize,
        /// The number of distinct points observed.
        actual: usize,
    },
    /// The observations fix no pose: points at one place or seen on one line, parallel rays, non-finite pixels, or
    /// no pose with the points in front of the camera.
    #[error("no static pose: {reason}")]
    Degenerate {
        /// Which of those, in words.
        reason: &'static str,
    },
}

/// A fitted static pose and how well it fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseFit {
    /// Pose, velocity zero.
    pub state: MotionState,
    /// Σ |e|² over the observations (px², ideal pixels).
    pub cost_px2: f64,
    /// RMS reprojection residual (px, per coordinate).
    pub residual_rms_px: f64,
    /// Estimated reciprocal condition number of the fit's column-scaled normal equations (1 perfect, 0 singular):
    /// how well the observations fix the pose.
    pub inverse_condition: f64,
    /// Linearisations the refinement took.
    pub iterations: usize,
    /// Whether the refinement reached a minimum of the cost.
    pub converged: bool,
    /// For a rival of the best pose ([`StaticPoses`]): how its cost's excess over the best's could move if the
    /// camera and target were off the user's files as users' files are ([`super::MODEL_UNCERTAINTY`]), given what the
    /// best's residual shows of that; zero for the best.
    pub model_effect: ModelEffect,
}

/// Twice the log-likelihood ratio (the cost difference in units of the noise variance) below which a second minimum
/// is as good as the best. The hardest case is a twin that fits noise-free pixels exactly as well as the truth (a
/// small planar target's mirror tilt): then the noise alone decides, and the cost difference is that of two χ²
/// variables of 6 degrees of freedom (each minimum absorbs the noise along its own 6 pose directions), which exceeds
/// 16 with a chance of 2.3e-3, 24 with 8.5e-5 and 30 with 6.7e-6 (simulated, 2e7 draws). A twin that fits worse
/// on noise-free pixels by D stands out by D ± 2√D and is rarer still.
pub const AMBIGUITY_CHI2: f64 = 30.0;

/// What is known of the centroid noise the poses are judged against ([`solve_static_pose`]).
///
/// ```
/// use roitrack_estimators::PixelNoise;
/// assert_eq!(PixelNoise::from(0.2), PixelNoise::Assumed(0.2));
/// assert_eq!(PixelNoise::Measured(0.3).px(), 0.3);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PixelNoise {
    /// A value given, not measured (a configuration's default): the residual may show more, and with few points
    /// its degrees of freedom cannot tell how much more, so the variance taken is the 95 % upper bound the residual
    /// allows.
    Assumed(f64),
    /// Measured with many degrees of freedom (the scatter of repeated measurements): whatever the residual shows
    /// beyond it is the model's own error, taken at its estimate.
    Measured(f64),
}

impl PixelNoise {
    /// The noise (px per coordinate).
    pub fn px(&self) -> f64 {
        match *self {
            Self::Assumed(px) | Self::Measured(px) => px,
        }
    }
}

impl From<f64> for PixelNoise {
    fn from(px: f64) -> Self {
        Self::Assumed(px)
    }
}

/// At most this many poses are returned (the minimal problem's four solutions).
pub const MAX_STATIC_POSES: usize = 4;

/// The static poses that fit the observations, best first ([`solve_static_pose`]): one, or several when the pose is
/// ambiguous.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticPoses {
    fits: [PoseFit; MAX_STATIC_POSES],
    len: usize,
    runner_up: Option<PoseFit>,
}

impl StaticPoses {
    /// The best fit (smallest reprojection cost).
    pub fn best(&self) -> &PoseFit {
        &self.fits[0]
    }

    /// Every fit that is as good as the best within the noise, best first (the best included).
    pub fn as_slice(&self) -> &[PoseFit] {
        &self.fits[..self.len]
    }

    /// Whether more than one pose fits as well as the best: the observations cannot tell them apart.
    pub fn is_ambiguous(&self) -> bool {
        self.len > 1
    }

    /// The best of the minima left out (their costs beyond the bound), if one came near enough to be refined: a
    /// caller who learns more of the noise can judge it again.
    pub fn runner_up(&self) -> Option<&PoseFit> {
        self.runner_up.as_ref()
    }
}

/// The nearest rotation to `m` (polar decomposition by SVD).
fn nearest_rotation(m: &Matrix3<f64>) -> Option<Rotation3<f64>> {
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        let mut u = u;
        u.column_mut(2).neg_mut();
        r = u * v_t;
    }
    Some(Rotation3::from_matrix_unchecked(r))
}

/// The 6-dof static problem: the pose that best projects the model points onto the observations, every observation
/// taken at the same pose (its time ignored, the velocity zero).
struct StaticPoseProblem<'a> {
    model: &'a SpatioTemporalModel,
    target: &'a Target,
    obs: &'a [Observation],
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

/// Triples of points tried at most (each gives up to four hypotheses), beyond [`FEW_POINTS`] points.
const MAX_TRIPLES: usize = 8;

/// Observations of at most this many points are tried with every triple of them.
const FEW_POINTS: usize = 6;

/// Points the triples are drawn from: the best-spread few in the image.
const SPREAD_POINTS: usize = 6;

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
pub fn static_model_residual(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    state: &MotionState,
) -> Option<ModelResidual> {
    let problem = StaticPoseProblem { model, target, obs };
    model_residual(&problem, model, target, obs, |_| 0.0, state)
}

/// Whether another labelling of the same measurements fits as well as the best within the noise and the user's model
/// error, by the rule [`solve_static_pose`] judges its rivals with ([`is_rival`]): `best_obs` and `rival_obs` hold the
/// same pixels in the same order, each with its labelling's target points, `best` and `rival` their static poses
/// (minima), `noise_px` the centroid noise assumed (px per coordinate); the variance is the larger of it and the
/// upper 95 % bound the best's residual sets; `model_sigmas` how many standard deviations of the model's error
/// ([`super::MODEL_UNCERTAINTY`]) may favour the wrong labelling ([`MODEL_SPREAD_SIGMAS`] for the static pose's own
/// rivals). A relabelling of a target onto itself (a symmetry) fits as well by
/// construction; this tells near-symmetries (a rectangle turned a quarter) from the true one.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, relabelling_is_rival, solve_static_pose};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target, TargetPoint};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// // A rectangle 14 x 12 cm: turned a quarter, it is nearly itself.
/// let corners = [(-0.07, -0.06), (0.07, -0.06), (0.07, 0.06), (-0.07, 0.06)];
/// let target = Target::new(corners.iter().enumerate().map(|(i, &(x, y))| TargetPoint {
///     id: i as u32, point_in_obj_m: Vector3::new(x, y, 0.0), diameter_m: None }).collect()).unwrap();
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.3, 0.2, 0.1), Vector3::new(0.0, 0.0, 0.6));
/// let pixels: Vec<_> = target.points().iter()
///     .map(|p| model.project(&truth, &p.point_in_obj_m, 0.0).unwrap()).collect();
/// let labelled = |shift: usize| -> Vec<Observation> {
///     (0..4).map(|k| Observation { t_s: 0.0, point_index: (k + shift) % 4, ideal_px: pixels[k] }).collect()
/// };
/// let (best_obs, rival_obs) = (labelled(0), labelled(1));
/// let best = solve_static_pose(&model, &target, &best_obs, 0.3).unwrap().best().state;
/// let rival = solve_static_pose(&model, &target, &rival_obs, 0.3).unwrap().best().state;
/// assert!(!relabelling_is_rival(&model, &target, (&best_obs, &best), (&rival_obs, &rival), 0.3, 2.0));
/// ```
pub fn relabelling_is_rival(
    model: &SpatioTemporalModel,
    target: &Target,
    (best_obs, best): (&[Observation], &MotionState),
    (rival_obs, rival): (&[Observation], &MotionState),
    noise_px: f64,
    model_sigmas: f64,
) -> bool {
    let best_problem = StaticPoseProblem {
        model,
        target,
        obs: best_obs,
    };
    let rival_problem = StaticPoseProblem {
        model,
        target,
        obs: rival_obs,
    };
    let (Some(best_cost), Some(rival_cost)) = (
        reprojection_cost_px2(&best_problem, best),
        reprojection_cost_px2(&rival_problem, rival),
    ) else {
        // A labelling that does not project is no rival.
        return false;
    };
    let dof = (2 * best_obs.len()).saturating_sub(6) as f64;
    let per_dof = roitrack_core::stats::chi2_lower_5_percent(dof);
    let variance_px2 = if per_dof > 0.0 {
        (noise_px * noise_px).max(best_cost / per_dof)
    } else {
        return true;
    };
    let effect = relabelling_effect(
        model,
        target,
        (&best_problem, best_obs, best),
        (&rival_problem, rival_obs, rival),
        variance_px2,
    )
    .unwrap_or_default();
    effect.least_excess_px2(rival_cost - best_cost, model_sigmas) <= AMBIGUITY_CHI2 * variance_px2
}

/// The plain reprojection cost (px²) of `state` on `problem`'s observations; `None` if a point does not project.
fn reprojection_cost_px2(problem: &StaticPoseProblem, state: &MotionState) -> Option<f64> {
    let cost = solver::normal_equations(problem, state).cost_px2();
    cost.is_finite().then_some(cost)
}

/// The static pose from scratch (see the module's docs): every pose that fits the observations as well as the best
/// within the noise, best first. `noise` is the centroid noise (px per coordinate) the fits are judged against, as
/// a value ([`PixelNoise::Assumed`]) or measured ([`PixelNoise::Measured`]); a larger residual (the user's model off
/// the truth) widens the judgement to what the residual shows. Observation
/// times are ignored (as if simultaneous); each point should appear once.
///
/// Needs 3 distinct points whose images are not on one line; 3 points are posed exactly by up to four poses, all
/// returned.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, solve_static_pose};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// // Seen from any side, with no prior.
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.5, -0.3, 2.0), Vector3::new(-0.02, 0.01, 0.7));
/// let obs: Vec<Observation> = (0..16)
///     .map(|i| Observation {
///         t_s: 0.0,
///         point_index: i,
///         ideal_px: model.project(&truth, &target.points()[i].point_in_obj_m, 0.0).unwrap(),
///     })
///     .collect();
/// let poses = solve_static_pose(&model, &target, &obs, 0.1).unwrap();
/// assert!(!poses.is_ambiguous());
/// let fit = poses.best();
/// assert!(fit.converged && (fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-9);
/// ```
pub fn solve_static_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    noise: impl Into<PixelNoise>,
) -> Result<StaticPoses, InitError> {
    search_static_pose(model, target, obs, noise.into(), Search::Whole)
}

/// The best static pose of [`solve_static_pose`]'s search, without its rivals: for a caller that ranks many
/// labellings by their fits (identification verifies thousands on a small regular grid) and needs of each only its
/// best pose. Observations of more than 4 points are searched as many points are (triples until one fits the noise,
/// and each minimum's mirror twin), not by every triple of them; no rival's model effect is computed.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::{Observation, best_static_pose};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.5, -0.3, 2.0), Vector3::new(-0.02, 0.01, 0.7));
/// let obs: Vec<Observation> = [0, 3, 5, 6, 9, 12]
///     .into_iter()
///     .map(|i| Observation {
///         t_s: 0.0,
///         point_index: i,
///         ideal_px: model.project(&truth, &target.points()[i].point_in_obj_m, 0.0).unwrap(),
///     })
///     .collect();
/// let fit = best_static_pose(&model, &target, &obs, 0.1).unwrap();
/// assert!((fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-9);
/// ```
pub fn best_static_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    noise: impl Into<PixelNoise>,
) -> Result<PoseFit, InitError> {
    search_static_pose(model, target, obs, noise.into(), Search::BestOnly)
        .map(|poses| *poses.best())
}

/// How much of the static pose [`search_static_pose`] finds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Search {
    /// Every pose that rivals the best ([`solve_static_pose`]).
    Whole,
    /// The best alone ([`best_static_pose`]).
    BestOnly,
}

/// Observations of at most this many points are tried with every triple of them by [`best_static_pose`] (four
/// triples).
const FEW_POINTS_BEST_ONLY: usize = 4;

fn search_static_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    noise: PixelNoise,
    search: Search,
) -> Result<StaticPoses, InitError> {
    let noise_px = noise.px();
    let too_few = || InitError::TooFewPoints {
        required: 3,
        actual: distinct_points(obs),
    };
    if obs.len() < 3 {
        return Err(too_few());
    }
    let n = obs.len();
    let view = CentredView::new(model, target, obs)?;
    let cost =
        ObjectSpaceCost::new(&view.centred, &view.bearings).ok_or(InitError::Degenerate {
            reason: "the observations' rays are parallel",
        })?;
    let mut triples = match Triples::new(obs, &view.image) {
        Ok(triples) => triples,
        Err(TriplesError::TooFewPoints) => return Err(too_few()),
        Err(TriplesError::OnALine) => {
            return Err(InitError::Degenerate {
                reason: "the points are seen on one line (the target edge-on)",
            });
        }
    };
    // A normalised-image error of 1 is this many pixels.
    let focal_px = model.intrinsics.fx_px.max(model.intrinsics.fy_px);
    let noise_normalised = noise_px / focal_px;
    let dof = (2 * n).saturating_sub(6).max(1) as f64;
    // A few points constrain the pose weakly: a view of them can hold minima that neither one triple nor a mirror
    // tilt reaches, so all their triples are tried (at most 20, for 6 points).
    let few = match search {
        Search::Whole => n <= FEW_POINTS,
        Search::BestOnly => n <= FEW_POINTS_BEST_ONLY,
    };
    let mut minima = minima_from_triples(&view, &cost, &mut triples, noise_normalised, dof, few);
    add_mirror_twins(&view.centred, &cost, &mut minima);
    let Some(best) = minima.best() else {
        return Err(InitError::Degenerate {
            reason: "no pose puts the points in front of the camera",
        });
    };
    // Refine, in the image, every minimum that could rival the best there; the object-space error only ranks them.
    let depth2 = mean_squared_depth(&view.centred, &best.0, &cost.translation(&best.0));
    let margin = 4.0 * AMBIGUITY_CHI2;
    let keep_below = best.1 * (1.0 + margin / dof) + margin * noise_normalised.powi(2) * depth2;
    let problem = StaticPoseProblem { model, target, obs };
    let fits = refine_in_image(&problem, &view, &cost, &minima, keep_below);
    let Some(&best_fit) = fits.first() else {
        return Err(InitError::Degenerate {
            reason: "no pose puts the points in front of the camera",
        });
    };
    if search == Search::BestOnly {
        return Ok(StaticPoses {
            fits: [best_fit; MAX_STATIC_POSES],
            len: 1,
            runner_up: None,
        });
    }
    let variance_px2 = rival_variance_px2(noise, &best_fit, n);
    Ok(rivals_of_best(&problem, fits, variance_px2))
}

/// The observations as the object-space search sees them: the model points centred on their centroid and scaled to
/// unit RMS (every quantity of the hypotheses is then of order one), and their images in normalised coordinates,
/// also as bearings (z = 1).
struct CentredView {
    centre_m: Vector3<f64>,
    scale_m: f64,
    centred: Vec<Vector3<f64>>,
    image: Vec<Vector2<f64>>,
    bearings: Vec<Vector3<f64>>,
}

impl CentredView {
    /// Err when the points are all at one place or an observation is not a finite pixel.
    fn new(
        model: &SpatioTemporalModel,
        target: &Target,
        obs: &[Observation],
    ) -> Result<Self, InitError> {
        let points = target.points();
        let n = obs.len();
        let centre_m = obs
            .iter()
            .map(|o| points[o.point_index].point_in_obj_m)
            .sum::<Vector3<f64>>()
            / n as f64;
        let scale_m = (obs
            .iter()
            .map(|o| (points[o.point_index].point_in_obj_m - centre_m).norm_squared())
            .sum::<f64>()
            / n as f64)
            .sqrt();
        if !(scale_m > 0.0 && scale_m.is_finite()) {
            return Err(InitError::Degenerate {
                reason: "the observed points are all at one place",
            });
        }
        let centred: Vec<Vector3<f64>> = obs
            .iter()
            .map(|o| (points[o.point_index].point_in_obj_m - centre_m) / scale_m)
            .collect();
        let image: Vec<Vector2<f64>> = obs
            .iter()
            .map(|o| model.intrinsics.normalized_from_pixel(&o.ideal_px))
            .collect();
        if !image.iter().all(|m| m.x.is_finite() && m.y.is_finite()) {
            return Err(InitError::Degenerate {
                reason: "an observation is not a finite pixel",
            });
        }
        let bearings: Vec<Vector3<f64>> =
            image.iter().map(|m| Vector3::new(m.x, m.y, 1.0)).collect();
        Ok(CentredView {
            centre_m,
            scale_m,
            centred,
            image,
            bearings,
        })
    }
}

/// The mean squared distance of the centred points from the camera at rotation `r` and translation `t` (both of the
/// centred problem).
fn mean_squared_depth(centred: &[Vector3<f64>], r: &Rotation3<f64>, t: &Vector3<f64>) -> f64 {
    centred
        .iter()
        .map(|x| (r * x + t).norm_squared())
        .sum::<f64>()
        / centred.len() as f64
}

/// The minima of the object-space error reached from the P3P hypotheses of the triples, best conditioned first:
/// until one fits the noise (each coordinate's noise `noise_normalised` times the point's distance, over `dof`
/// degrees of freedom), or, when none does (a gross error in the data, or a user's model off the truth), until two
/// triples in a row find nothing better. With `few` points every triple is tried.
fn minima_from_triples(
    view: &CentredView,
    cost: &ObjectSpaceCost,
    triples: &mut Triples<'_>,
    noise_normalised: f64,
    dof: f64,
    few: bool,
) -> Minima {
    let mut minima = Minima::default();
    let mut stale = 0;
    while let Some(triple) = triples.next(&view.image) {
        let solutions = p3p::p3p(
            &triple.map(|k| view.bearings[k]),
            &triple.map(|k| view.centred[k]),
        );
        let previous_best = minima.best_cost();
        for (r, _) in solutions.as_slice() {
            let (r, e) = cost.minimise(r, 30);
            minima.add(r, e);
        }
        let Some(best) = minima.best() else { continue };
        // The object-space error that the noise alone explains: each coordinate's noise times the point's distance.
        let depth2 = mean_squared_depth(&view.centred, &best.0, &cost.translation(&best.0));
        let noise_cost = noise_normalised.powi(2) * depth2;
        if !few && best.1 <= noise_cost * (dof + 6.0 * (2.0 * dof).sqrt() + 10.0) {
            break;
        }
        if few {
            continue;
        }
        let improved = previous_best.is_none_or(|p| best.1 < p * (1.0 - 1e-9));
        stale = if improved { 0 } else { stale + 1 };
        if stale >= 2 {
            break;
        }
    }
    minima
}

/// Adds each of the two best minima's mirror twin: a target seen small is fitted about as well by its depths
/// reflected about its centre, which for a planar target is another pose (the plane tilted the other way). One
/// triple's hypotheses do not always reach it, and the ambiguity must not go unseen.
fn add_mirror_twins(centred: &[Vector3<f64>], cost: &ObjectSpaceCost, minima: &mut Minima) {
    let normal = thinnest_direction(centred);
    for (r, _) in minima.sorted().into_iter().take(2) {
        let sight = cost.translation(&r).normalize();
        let mirrored = (Matrix3::identity() - 2.0 * sight * sight.transpose())
            * r.matrix()
            * (Matrix3::identity() - 2.0 * normal * normal.transpose());
        let start = Rotation3::from_matrix_unchecked(mirrored);
        // The search has often found the twin already (the bench's 16 points: both within 0.026 rad of the mirrored
        // starts, a third of the static pose's time spent walking there again).
        if minima.near(&start, MIRROR_FOUND_RAD) {
            continue;
        }
        let (twin, e) = cost.minimise(&start, 30);
        minima.add(twin, e);
    }
}

/// The minima whose object-space cost is at most `keep_below` (at most [`MAX_STATIC_POSES`] + 1 of them), refined
/// in the image, back in the target's metres; the finite and distinct ones, best first.
fn refine_in_image(
    problem: &StaticPoseProblem<'_>,
    view: &CentredView,
    cost: &ObjectSpaceCost,
    minima: &Minima,
    keep_below: f64,
) -> Vec<PoseFit> {
    let mut fits: Vec<PoseFit> = Vec::with_capacity(MAX_STATIC_POSES + 1);
    for &(r, _) in minima
        .sorted()
        .iter()
        .filter(|(_, e)| *e <= keep_below)
        .take(MAX_STATIC_POSES + 1)
    {
        let t_m = cost.translation(&r) * view.scale_m - r * view.centre_m;
        let fit = refine_static_pose(
            problem.model,
            problem.target,
            problem.obs,
            &MotionState::at_rest(r, t_m),
            50,
        );
        let finite = fit.cost_px2.is_finite() && fit.state.is_finite();
        let duplicate = fits.iter().any(|f| same_pose(&f.state, &fit.state));
        if finite && !duplicate {
            fits.push(fit);
        }
    }
    fits.sort_by(|a, b| a.cost_px2.total_cmp(&b.cost_px2));
    fits
}

/// The variance (px²) rivals are judged against: the larger of the given noise's and what the best's residual over
/// `n` observations says of it, model error included. A few points leave few degrees of freedom and a residual that
/// often shows far less than the noise: for an assumed noise the variance is its upper 95 % confidence bound, not
/// its estimate (for 4 points, 19.5 times the residual per degree of freedom; for 16, 1.7 times).
fn rival_variance_px2(noise: PixelNoise, best_fit: &PoseFit, n: usize) -> f64 {
    let noise_px = noise.px();
    let residual_dof = (2 * n).saturating_sub(6) as f64;
    let per_dof = match noise {
        PixelNoise::Assumed(_) => roitrack_core::stats::chi2_lower_5_percent(residual_dof),
        PixelNoise::Measured(_) => residual_dof,
    };
    if per_dof > 0.0 {
        (noise_px * noise_px).max(best_fit.cost_px2 / per_dof)
    } else {
        // Three points: every pose that puts them on their rays fits exactly.
        f64::INFINITY
    }
}

/// The best of `fits` (sorted, not empty) with its rivals, the minima whose cost is within the ambiguity bound of
/// the best against `variance_px2` once the model's error is allowed for, and the best of the others as the runner-up.
fn rivals_of_best(
    problem: &StaticPoseProblem<'_>,
    mut fits: Vec<PoseFit>,
    variance_px2: f64,
) -> StaticPoses {
    let best_fit = fits[0];
    // How far the model's error could move each rival's excess, given what the best's residual shows of it.
    for fit in &mut fits[1..] {
        fit.model_effect = cost_difference_effect(
            problem,
            problem.model,
            problem.target,
            problem.obs,
            |_| 0.0,
            &best_fit.state,
            &fit.state,
            variance_px2,
        )
        .unwrap_or_default();
    }
    let mut poses = StaticPoses {
        fits: [best_fit; MAX_STATIC_POSES],
        len: 1,
        runner_up: None,
    };
    for fit in &fits[1..] {
        if is_rival(fit, &best_fit, variance_px2) {
            if poses.len < MAX_STATIC_POSES {
                poses.fits[poses.len] = *fit;
                poses.len += 1;
            }
        } else if poses.runner_up.is_none() {
            poses.runner_up = Some(*fit);
        }
    }
    poses
}

/// The unit direction along which points (centred) spread least: a planar target's normal.
fn thinnest_direction(centred: &[Vector3<f64>]) -> Vector3<f64> {
    let scatter = centred
        .iter()
        .fold(Matrix3::zeros(), |s, x| s + x * x.transpose());
    let eig = scatter.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    eig.eigenvectors.column(k).into_owned()
}

/// Whether `fit` fits as well as `best` within the noise (cost excess below [`AMBIGUITY_CHI2`] times `variance_px2`)
/// for some model error within [`MODEL_SPREAD_SIGMAS`] standard deviations ([`PoseFit::model_effect`]).
pub fn is_rival(fit: &PoseFit, best: &PoseFit, variance_px2: f64) -> bool {
    let excess_px2 = fit.cost_px2 - best.cost_px2;
    fit.model_effect
        .least_excess_px2(excess_px2, MODEL_SPREAD_SIGMAS)
        <= AMBIGUITY_CHI2 * variance_px2
}

/// Standard deviations of the model's error ([`PoseFit::model_effect`]) within which a rival's excess cost must stay
/// above the noise's bound: at 4, a model error that favours the wrong pose by more has a chance of about 3e-5.
pub const MODEL_SPREAD_SIGMAS: f64 = 4.0;

/// How many distinct points the observations hold.
fn distinct_points(obs: &[Observation]) -> usize {
    let mut seen: Vec<usize> = obs.iter().map(|o| o.point_index).collect();
    seen.sort_unstable();
    seen.dedup();
    seen.len()
}

/// Two poses equal to well below any noise (the same minimum reached twice).
fn same_pose(a: &MotionState, b: &MotionState) -> bool {
    roitrack_core::so3::angle_between(&a.cam_r_obj, &b.cam_r_obj) < 1e-6
        && (a.cam_t_obj_m - b.cam_t_obj_m).norm() <= 1e-6 * a.cam_t_obj_m.norm().max(1e-9)
}

/// Two minima of the object-space error nearer than this (rad) are one: the minimisation stops at a millionth of the
/// cost, a few hundred-thousandths of a radian from the minimum, and no view tells poses this close apart.
const SAME_MINIMUM_RAD: f64 = 1e-4;

/// A mirrored start (see [`solve_static_pose`]) this near (rad) a minimum already found is not walked from: the walk
/// ends there (on the bench's 16 points the twins lay 0.025 rad from their mirrored starts, and the walks ended on
/// them). A minimum within 3 degrees of one found would be missed, and the one found stands for it.
const MIRROR_FOUND_RAD: f64 = 0.05;

/// The distinct minima of the object-space error found so far, with their costs.
#[derive(Default)]
struct Minima {
    found: Vec<(Rotation3<f64>, f64)>,
}

impl Minima {
    fn add(&mut self, r: Rotation3<f64>, cost: f64) {
        if !cost.is_finite() {
            return;
        }
        match self
            .found
            .iter_mut()
            .find(|(q, _)| roitrack_core::so3::angle_between(q, &r) < SAME_MINIMUM_RAD)
        {
            Some(same) if cost < same.1 => *same = (r, cost),
            Some(_) => {}
            None => self.found.push((r, cost)),
        }
    }

    /// Whether a minimum lies within `radius_rad` of `r`.
    fn near(&self, r: &Rotation3<f64>, radius_rad: f64) -> bool {
        self.found
            .iter()
            .any(|(q, _)| roitrack_core::so3::angle_between(q, r) < radius_rad)
    }

    fn best(&self) -> Option<(Rotation3<f64>, f64)> {
        self.found
            .iter()
            .copied()
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    fn best_cost(&self) -> Option<f64> {
        self.best().map(|(_, c)| c)
    }

    fn sorted(&self) -> Vec<(Rotation3<f64>, f64)> {
        let mut v = self.found.clone();
        v.sort_by(|a, b| a.1.total_cmp(&b.1));
        v
    }
}

/// The triples of observations the hypotheses come from, best conditioned first: the largest image triangle (the
/// point farthest from the centroid, the point farthest from it, the point farthest from their line), then (made
/// only if asked for) the other triples of a few well-spread points by decreasing image area. Triples of one point
/// twice, or whose images are nearly on a line, are left out.
struct Triples<'a> {
    obs: &'a [Observation],
    first: Option<[usize; 3]>,
    /// The other triples, best last (taken by `pop`); made at the first request after the first triple.
    others: Option<Vec<[usize; 3]>>,
    largest_area: f64,
}

enum TriplesError {
    TooFewPoints,
    OnALine,
}

/// Twice the signed area of the image triangle `a, b, c`.
fn signed_area(image: &[Vector2<f64>], a: usize, b: usize, c: usize) -> f64 {
    let (e1, e2) = (image[b] - image[a], image[c] - image[a]);
    e1.x * e2.y - e1.y * e2.x
}

/// The observation that maximises `score` among those of points not in `skip`.
fn farthest(obs: &[Observation], score: impl Fn(usize) -> f64, skip: &[usize]) -> Option<usize> {
    (0..obs.len())
        .filter(|&k| {
            skip.iter()
                .all(|&s| obs[s].point_index != obs[k].point_index)
        })
        .max_by(|&a, &b| score(a).total_cmp(&score(b)))
}

impl<'a> Triples<'a> {
    fn new(obs: &'a [Observation], image: &[Vector2<f64>]) -> Result<Self, TriplesError> {
        let centroid = image.iter().sum::<Vector2<f64>>() / image.len() as f64;
        let i0 = farthest(obs, |k| (image[k] - centroid).norm_squared(), &[])
            .ok_or(TriplesError::TooFewPoints)?;
        let i1 = farthest(obs, |k| (image[k] - image[i0]).norm_squared(), &[i0])
            .ok_or(TriplesError::TooFewPoints)?;
        let i2 = farthest(obs, |k| signed_area(image, i0, i1, k).abs(), &[i0, i1])
            .ok_or(TriplesError::TooFewPoints)?;
        let largest_area = signed_area(image, i0, i1, i2).abs();
        // Nearly on a line: a triangle whose height is below a millionth of its base.
        if largest_area.is_nan() || largest_area <= 1e-6 * (image[i1] - image[i0]).norm_squared() {
            return Err(TriplesError::OnALine);
        }
        Ok(Self {
            obs,
            first: Some([i0, i1, i2]),
            others: None,
            largest_area,
        })
    }

    fn next(&mut self, image: &[Vector2<f64>]) -> Option<[usize; 3]> {
        if let Some(first) = self.first.take() {
            return Some(first);
        }
        if self.others.is_none() {
            self.others = Some(self.make_others(image));
        }
        self.others.as_mut()?.pop()
    }

    /// The triples of the well-spread points (the first triple's and the farthest from the chosen ones, in turn)
    /// other than the first, best last.
    fn make_others(&self, image: &[Vector2<f64>]) -> Vec<[usize; 3]> {
        let mut spread: Vec<usize> = Vec::with_capacity(SPREAD_POINTS);
        // Rebuild the first triple (taken by now) from the same rule.
        let centroid = image.iter().sum::<Vector2<f64>>() / image.len() as f64;
        let obs = self.obs;
        for _ in 0..3 {
            let next = match spread.len() {
                0 => farthest(obs, |k| (image[k] - centroid).norm_squared(), &spread),
                1 => farthest(
                    obs,
                    |k| (image[k] - image[spread[0]]).norm_squared(),
                    &spread,
                ),
                _ => farthest(
                    obs,
                    |k| signed_area(image, spread[0], spread[1], k).abs(),
                    &spread,
                ),
            };
            spread.extend(next);
        }
        while spread.len() < SPREAD_POINTS {
            let nearest_chosen = |k: usize| {
                spread
                    .iter()
                    .map(|&s| (image[k] - image[s]).norm_squared())
                    .fold(f64::INFINITY, f64::min)
            };
            match farthest(obs, nearest_chosen, &spread) {
                Some(k) if nearest_chosen(k) > 0.0 => spread.push(k),
                _ => break,
            }
        }
        let mut others: Vec<([usize; 3], f64)> = Vec::new();
        for a in 0..spread.len() {
            for b in a + 1..spread.len() {
                for c in b + 1..spread.len() {
                    let area = signed_area(image, spread[a], spread[b], spread[c]).abs();
                    if (a, b, c) != (0, 1, 2) && area > 1e-3 * self.largest_area {
                        others.push(([spread[a], spread[b], spread[c]], area));
                    }
                }
            }
        }
        // Largest last: `pop` takes it first.
        others.sort_by(|x, y| x.1.total_cmp(&y.1));
        let skip = if self.obs.len() <= FEW_POINTS {
            0
        } else {
            others.len().saturating_sub(MAX_TRIPLES - 1)
        };
        others.into_iter().skip(skip).map(|(t, _)| t).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roitrack_core::{CameraModel, TargetPoint};

    fn observe(
        model: &SpatioTemporalModel,
        target: &Target,
        state: &MotionState,
    ) -> Vec<Observation> {
        target
            .points()
            .iter()
            .enumerate()
            .map(|(i, p)| Observation {
                t_s: 0.0,
                point_index: i,
                ideal_px: model.project(state, &p.point_in_obj_m, 0.0).unwrap(),
            })
            .collect()
    }

    fn assert_recovers(target: &Target, truth: &MotionState) {
        let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
        let poses =
            solve_static_pose(&model, target, &observe(&model, target, truth), 0.1).unwrap();
        assert!(!poses.is_ambiguous(), "{:?}", poses.as_slice());
        let fit = poses.best();
        let dt = (fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm();
        let dr = roitrack_core::so3::angle_between(&fit.state.cam_r_obj, &truth.cam_r_obj);
        assert!(dt < 1e-9 && dr < 1e-9, "dt {dt} m, dr {dr} rad");
        assert!(fit.residual_rms_px < 1e-8);
    }

    #[test]
    fn planar_grid_from_scratch_to_1e9() {
        let target = Target::grid4x4();
        assert_recovers(&target, &MotionState::bench());
        // Any in-plane rotation, and a strong tilt.
        for angle_deg in [0.0, 90.0, 180.0, 270.0, 33.0] {
            let mut s = MotionState::bench();
            s.cam_r_obj *=
                Rotation3::from_axis_angle(&Vector3::z_axis(), f64::to_radians(angle_deg));
            assert_recovers(&target, &s);
        }
        let mut s = MotionState::bench();
        s.cam_r_obj = Rotation3::from_euler_angles(0.9, -0.4, 2.0);
        assert_recovers(&target, &s);
    }

    #[test]
    fn non_planar_target_from_scratch() {
        let points = (0..8)
            .map(|i| TargetPoint {
                id: i,
                point_in_obj_m: Vector3::new(
                    0.03 * ((i & 1) as f64 - 0.5),
                    0.03 * (((i >> 1) & 1) as f64 - 0.5),
                    0.02 * (((i >> 2) & 1) as f64) + 0.001 * i as f64,
                ),
                diameter_m: None,
            })
            .collect();
        let target = Target::new(points).unwrap();
        assert_recovers(&target, &MotionState::bench());
    }

    /// [`best_static_pose`] finds [`solve_static_pose`]'s best on random views of random subsets of a 4 x 4 grid, with
    /// noise: the same pose beyond [`FEW_POINTS`] points (the same search), and within [`FEW_POINTS`] a pose whose cost
    /// exceeds the best's by less than what the noise makes of a rival ([`AMBIGUITY_CHI2`] times its variance).
    #[test]
    fn best_static_pose_is_the_whole_searchs_best() {
        use rand::{Rng, SeedableRng, seq::SliceRandom};
        let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
        let target = Target::grid4x4();
        let noise_px = 0.1;
        for seed in 0..200u64 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let truth = MotionState::at_rest(
                Rotation3::from_euler_angles(
                    rng.random_range(-0.9..0.9),
                    rng.random_range(-0.9..0.9),
                    rng.random_range(-3.1..3.1),
                ),
                Vector3::new(
                    rng.random_range(-0.05..0.05),
                    rng.random_range(-0.05..0.05),
                    rng.random_range(0.3..1.5),
                ),
            );
            let mut obs = observe(&model, &target, &truth);
            obs.shuffle(&mut rng);
            obs.truncate(rng.random_range(4..=16));
            for o in &mut obs {
                o.ideal_px += Vector2::new(
                    noise_px * rng.random_range(-1.7..1.7),
                    noise_px * rng.random_range(-1.7..1.7),
                );
            }
            let whole = *solve_static_pose(&model, &target, &obs, noise_px)
                .unwrap()
                .best();
            let best = best_static_pose(&model, &target, &obs, noise_px).unwrap();
            if obs.len() > FEW_POINTS {
                assert_eq!(best.state, whole.state, "seed {seed}");
            } else {
                let excess_px2 = best.cost_px2 - whole.cost_px2;
                assert!(
                    excess_px2 < AMBIGUITY_CHI2 * noise_px * noise_px,
                    "seed {seed}, {} points: {} px² above the best",
                    obs.len(),
                    excess_px2
                );
            }
        }
    }

    #[test]
    fn too_few_points() {
        let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
        let target = Target::grid4x4();
        let obs = observe(&model, &target, &MotionState::bench());
        assert!(matches!(
            solve_static_pose(&model, &target, &obs[..2], 0.1),
            Err(InitError::TooFewPoints {
                required: 3,
                actual: 2
            })
        ));
    }
}
