//! Rival poses: which minima could be the true pose beside the best, and whether a relabelling rivals a fit.

use crate::Observation;
use crate::model_error::{cost_difference_effect, relabelling_effect};
use roitrack_core::{MotionState, SpatioTemporalModel, Target};

use super::refine::{StaticPoseProblem, reprojection_cost_px2};
use super::{AMBIGUITY_CHI2, MAX_STATIC_POSES, PixelNoise, PoseFit, StaticPoses};

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
///
/// [`super::MODEL_UNCERTAINTY`]: crate::MODEL_UNCERTAINTY
/// [`solve_static_pose`]: super::solve_static_pose
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

/// The variance (px²) rivals are judged against: the larger of the given noise's and what the best's residual over
/// `n` observations says of it, model error included. A few points leave few degrees of freedom and a residual that
/// often shows far less than the noise: for an assumed noise the variance is its upper 95 % confidence bound, not
/// its estimate (for 4 points, 19.5 times the residual per degree of freedom; for 16, 1.7 times).
pub(super) fn rival_variance_px2(noise: PixelNoise, best_fit: &PoseFit, n: usize) -> f64 {
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
pub(super) fn rivals_of_best(
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
