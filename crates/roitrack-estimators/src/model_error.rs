//! How far the error of the user's own model (a camera file a little off, a target drawn to spec) could move the
//! cost difference of two fits of the same measurements: a pose and a rival (its mirror twin, say). Noise moves that
//! difference at random; a model's error moves it the same way at every measurement, and a rival that fits a little
//! worse on the user's model may be the truth on the true one.
//!
//! The model parameters are the intrinsics (fx, fy, cx, cy), the first radial distortion coefficient k1 (which moves
//! each undistorted observation by about `-f m |m|²` per unit, `m` its normalised coordinates) and every target
//! coordinate. At each fit's minimum the fit's own parameters need not move to first order, so the cost difference
//! changes by `gᵀ δθ` with `g = 2 (J_θ,rivalᵀ e_rival - J_θ,bestᵀ e_best)`. The parameters' prior ([`MODEL_UNCERTAINTY`],
//! independent Gaussians) is narrowed by what the best fit's residual already shows of them: a model off by `δθ`
//! leaves the residual `P J_θ δθ` at the best fit (`P` removes what the fit's own parameters absorb), so with noise
//! variance `σ²` the posterior precision is `Σ⁻¹ + (P J_θ)ᵀ (P J_θ) / σ²`. The spread is `sqrt(gᵀ Σ_post g)`. Target
//! coordinates are taken point by point (each point's error shows at its own measurements), the intrinsics together.

use nalgebra::{Matrix3, SMatrix, SVector, Vector2, Vector3};

use super::Observation;
use roitrack_core::solver::{LeastSquaresProblem, ResidualSink};
use roitrack_core::stats::{chi2_upper_0_1_percent, chi2_upper_quantile};
use roitrack_core::{MotionState, SpatioTemporalModel, Target};

/// How far users' camera and target files are off the truth, as standard deviations: focal lengths and the principal
/// point's coordinates by 1 % of themselves, k1 by 0.025, each target coordinate by 0.25 mm (half the bounds that
/// calibrations, nominal lens data and drawings stay within: 2 %, 0.05, 0.5 mm).
pub const MODEL_UNCERTAINTY: ModelUncertainty = ModelUncertainty {
    focal_fraction: 0.01,
    principal_point_fraction: 0.01,
    k1: 0.025,
    target_m: 0.25e-3,
};

/// Standard deviations of the error of a camera and target model ([`MODEL_UNCERTAINTY`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelUncertainty {
    /// Of fx and fy, as a fraction of them.
    pub focal_fraction: f64,
    /// Of cx and cy, as a fraction of them.
    pub principal_point_fraction: f64,
    /// Of the first radial distortion coefficient.
    pub k1: f64,
    /// Of each target coordinate (m).
    pub target_m: f64,
}

/// Each measurement's Jacobian and plain residual, as a problem linearises them.
struct Rows<const N: usize> {
    rows: Vec<Option<(SMatrix<f64, 2, N>, Vector2<f64>)>>,
}

impl<const N: usize> ResidualSink<N> for Rows<N> {
    fn add(&mut self, jacobian: &SMatrix<f64, 2, N>, residual: &Vector2<f64>, _weight: f64) {
        self.rows.push(Some((*jacobian, *residual)));
    }

    fn add_unevaluable(&mut self) {
        self.rows.push(None);
    }
}

fn rows<const N: usize, P: LeastSquaresProblem<N, Params = MotionState>>(
    problem: &P,
    state: &MotionState,
    count: usize,
) -> Vec<Option<(SMatrix<f64, 2, N>, Vector2<f64>)>> {
    let mut sink = Rows {
        rows: Vec::with_capacity(count),
    };
    problem.linearize(state, &mut sink);
    sink.rows
}

/// The residual's derivatives against the intrinsics and k1 (2 x 5) and against the observation's model point (2 x 3),
/// for the point seen at `state` `d_s` after its reference time.
fn model_jacobians(
    model: &SpatioTemporalModel,
    state: &MotionState,
    point_in_obj_m: &Vector3<f64>,
    d_s: f64,
    observed_px: &Vector2<f64>,
) -> Option<(SMatrix<f64, 2, 5>, SMatrix<f64, 2, 3>)> {
    let k = &model.intrinsics;
    let (r, _) = state.pose_at(d_s);
    let p = state.point_in_cam_at(point_in_obj_m, d_s);
    if p.z <= 0.0 {
        return None;
    }
    let (xz, yz) = (p.x / p.z, p.y / p.z);
    let m = k.normalized_from_pixel(observed_px);
    let r2 = m.norm_squared();
    let intrinsics = SMatrix::<f64, 2, 5>::new(
        xz,
        0.0,
        1.0,
        0.0,
        k.fx_px * m.x * r2,
        0.0,
        yz,
        0.0,
        1.0,
        k.fy_px * m.y * r2,
    );
    Some((intrinsics, k.pixel_jacobian_wrt_cam(&p) * r.matrix()))
}

/// How the excess cost of a rival over the best fit could change with the model's error (the camera's and the
/// target's, off as [`MODEL_UNCERTAINTY`] says files are): along the direction that lowers it fastest, by `-s slope_px2 + s² curvature_px2` for a model `s` standard deviations
/// off (the posterior ones, given what the best's residual shows).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ModelEffect {
    /// The first-order change per standard deviation (px²): the spread `sqrt(gᵀ Σ_post g)` of the module's docs.
    pub slope_px2: f64,
    /// The second-order change per squared standard deviation along that direction (px²): the rival's own residual
    /// grows with the model's change (positive) as far as the best's does not.
    pub curvature_px2: f64,
}

impl ModelEffect {
    /// The smallest excess `excess_px2 - s slope + s² curvature` over models at most `sigmas` standard deviations off.
    pub fn least_excess_px2(&self, excess_px2: f64, sigmas: f64) -> f64 {
        let at = |s: f64| excess_px2 - s * self.slope_px2 + s * s * self.curvature_px2;
        let mut least = at(0.0).min(at(sigmas));
        if self.curvature_px2 > 0.0 {
            let vertex = self.slope_px2 / (2.0 * self.curvature_px2);
            if vertex > 0.0 && vertex < sigmas {
                least = least.min(at(vertex));
            }
        }
        least
    }
}

/// What the model's parameters do to one fit's residual: `(P J_θ)ᵀ (P J_θ)` for the intrinsics (`P` removing what
/// the fit absorbs) and `J_Xᵀ J_X` per target point, and twice the residual times `J`.
struct Sensitivity {
    intrinsics_shown: SMatrix<f64, 5, 5>,
    points_shown: Vec<Matrix3<f64>>,
    /// `(P J_X)ᵀ (P J_X)` per target point: what of a point's error the fit's own parameters do not absorb.
    points_left: Vec<Matrix3<f64>>,
    intrinsics_gradient: SVector<f64, 5>,
    points_gradient: Vec<Vector3<f64>>,
}

fn sensitivity<const N: usize, P: LeastSquaresProblem<N, Params = MotionState>>(
    problem: &P,
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    offset_s: &impl Fn(&Observation) -> f64,
    state: &MotionState,
) -> Option<Sensitivity> {
    let fit_rows = rows(problem, state, obs.len());
    if fit_rows.len() != obs.len() {
        return None;
    }
    let mut ata = SMatrix::<f64, N, N>::zeros();
    let mut at_theta = SMatrix::<f64, N, 5>::zeros();
    let mut theta_t_theta = SMatrix::<f64, 5, 5>::zeros();
    let mut intrinsics_gradient = SVector::<f64, 5>::zeros();
    let mut points_gradient = vec![Vector3::zeros(); target.len()];
    let mut points_shown = vec![Matrix3::zeros(); target.len()];
    let mut at_points = vec![SMatrix::<f64, N, 3>::zeros(); target.len()];
    for (o, row) in obs.iter().zip(&fit_rows) {
        let (j, e) = (*row)?;
        let point = &target.points()[o.point_index].point_in_obj_m;
        let (theta, x) = model_jacobians(model, state, point, offset_s(o), &o.ideal_px)?;
        ata += j.transpose() * j;
        at_theta += j.transpose() * theta;
        theta_t_theta += theta.transpose() * theta;
        intrinsics_gradient += 2.0 * theta.transpose() * e;
        points_gradient[o.point_index] += 2.0 * x.transpose() * e;
        points_shown[o.point_index] += x.transpose() * x;
        at_points[o.point_index] += j.transpose() * x;
    }
    let ata_inverse = ata.try_inverse()?;
    let points_left = points_shown
        .iter()
        .zip(&at_points)
        .map(|(shown, at)| shown - at.transpose() * ata_inverse * at)
        .collect();
    Some(Sensitivity {
        intrinsics_shown: theta_t_theta - at_theta.transpose() * ata_inverse * at_theta,
        points_shown,
        points_left,
        intrinsics_gradient,
        points_gradient,
    })
}

/// The standard deviations of the intrinsics and k1 ([`MODEL_UNCERTAINTY`] for this camera).
fn intrinsics_prior(model: &SpatioTemporalModel) -> SVector<f64, 5> {
    let u = MODEL_UNCERTAINTY;
    let k = &model.intrinsics;
    SVector::<f64, 5>::new(
        u.focal_fraction * k.fx_px,
        u.focal_fraction * k.fy_px,
        // (Of the coordinates taken as at least a tenth of the focal length: a camera file with its principal point
        // at 0 is no more certain of it, and a prior of zero spread would leave no model term at all.)
        u.principal_point_fraction * k.cx_px.abs().max(0.1 * k.fx_px),
        u.principal_point_fraction * k.cy_px.abs().max(0.1 * k.fy_px),
        u.k1,
    )
}

/// The residual cost (px², summed over coordinates) that a model off as [`MODEL_UNCERTAINTY`] says models are leaves,
/// on average, at a fit: `E|P J_θ δθ|²` over the intrinsics with k1, and over every target coordinate, `P` removing
/// what the fit's own parameters absorb. A fit on the user's model has this on top of the noise's share. `problem`
/// is the fit's least-squares problem without a robust loss (its observations, in order, are `obs`), `state` at its
/// minimum, `offset_s` each observation's time after the state's reference time. `None` when a point does not
/// project or the fit is degenerate.
pub(crate) fn model_residual<const N: usize, P: LeastSquaresProblem<N, Params = MotionState>>(
    problem: &P,
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    offset_s: impl Fn(&Observation) -> f64,
    state: &MotionState,
) -> Option<ModelResidual> {
    let s = sensitivity(problem, model, target, obs, &offset_s, state)?;
    let prior = intrinsics_prior(model);
    let intrinsics: f64 = (0..5)
        .map(|k| prior[k] * prior[k] * s.intrinsics_shown[(k, k)])
        .sum();
    let target_m2 = MODEL_UNCERTAINTY.target_m * MODEL_UNCERTAINTY.target_m;
    let points: f64 = s.points_left.iter().map(|m| target_m2 * m.trace()).sum();
    Some(ModelResidual {
        intrinsics_px2: intrinsics.max(0.0),
        target_px2: points.max(0.0),
        coordinates: 2 * obs.len(),
        dof: (2 * obs.len()).saturating_sub(N),
    })
}

/// What the error of the user's own camera and target files ([`MODEL_UNCERTAINTY`], one standard deviation) leaves
/// on average in a fit's residual cost beyond the noise's share (px², summed over coordinates), in its two kinds:
/// the camera's, a few parameters shared by every measurement (a systematic error), and the target's, independent
/// from point to point (it acts as more noise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelResidual {
    /// Of the intrinsics (focal lengths, principal point) and k1.
    pub intrinsics_px2: f64,
    /// Of the target points' coordinates.
    pub target_px2: f64,
    /// Coordinates measured (twice the observations).
    pub coordinates: usize,
    /// Degrees of freedom of the residual: coordinates less the fit's parameters.
    pub dof: usize,
}

impl ModelResidual {
    /// The largest residual cost (px², summed over coordinates) a fit on a model as good as users' files are leaves:
    /// the noise's (`noise_px` per coordinate) but at one chance in a thousand, plus the model's at `model_sigmas`
    /// standard deviations. The camera's error, a few parameters shared by every point, is taken that many standard
    /// deviations off; the target's, independent from point to point, as a sum of `dof` squared errors at the
    /// chi-square quantile with the tail of `model_sigmas` Gaussian sigmas ([`chi2_upper_quantile`]).
    ///
    /// Why not every point that many sigmas off at once: that is far rarer than the quantile says, and so taken, a
    /// 16-point grid 0.4 m from a 1500 px camera was allowed 1.7 px RMS, enough to fit a 4 x 4 patch of another grid
    /// seen at a slant (1.1 px now, its noise's share 0.4 px).
    pub fn bound_px2(&self, noise_px: f64, model_sigmas: f64) -> f64 {
        let dof = self.dof.max(1) as f64;
        noise_px * noise_px * chi2_upper_0_1_percent(dof)
            + self.target_px2 / dof * chi2_upper_quantile(dof, model_sigmas)
            + model_sigmas * model_sigmas * self.intrinsics_px2
    }

    /// [`Self::bound_px2`] as an RMS per coordinate (px).
    pub fn bound_rms_px(&self, noise_px: f64, model_sigmas: f64) -> f64 {
        (self.bound_px2(noise_px, model_sigmas) / self.coordinates.max(1) as f64).sqrt()
    }
}

/// How a model off as [`MODEL_UNCERTAINTY`] says models are could change `cost(rival) - cost(best)`, given what the
/// best fit's residual shows of it (see the module's docs and [`ModelEffect`]). `problem` is the fits' least-squares
/// problem without a robust loss (its observations, in order, are `obs`), both states at its minima, `offset_s` each
/// observation's time after the states' reference time, `noise_variance_px2` the noise per coordinate. `None` when a
/// point does not project.
#[allow(clippy::too_many_arguments)]
pub(crate) fn cost_difference_effect<
    const N: usize,
    P: LeastSquaresProblem<N, Params = MotionState>,
>(
    problem: &P,
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    offset_s: impl Fn(&Observation) -> f64,
    best: &MotionState,
    rival: &MotionState,
    noise_variance_px2: f64,
) -> Option<ModelEffect> {
    let b = sensitivity(problem, model, target, obs, &offset_s, best)?;
    let r = sensitivity(problem, model, target, obs, &offset_s, rival)?;
    effect_of_sensitivities(model, target, &b, &r, noise_variance_px2)
}

/// [`cost_difference_effect`] for a rival that explains the same measurements with other correspondences: the best's
/// and the rival's problems and observations (the same pixels in the same order, other target points).
pub(crate) fn relabelling_effect<
    const N: usize,
    P: LeastSquaresProblem<N, Params = MotionState>,
>(
    model: &SpatioTemporalModel,
    target: &Target,
    (best_problem, best_obs, best): (&P, &[Observation], &MotionState),
    (rival_problem, rival_obs, rival): (&P, &[Observation], &MotionState),
    noise_variance_px2: f64,
) -> Option<ModelEffect> {
    let b = sensitivity(best_problem, model, target, best_obs, &|_| 0.0, best)?;
    let r = sensitivity(rival_problem, model, target, rival_obs, &|_| 0.0, rival)?;
    effect_of_sensitivities(model, target, &b, &r, noise_variance_px2)
}

fn effect_of_sensitivities(
    model: &SpatioTemporalModel,
    target: &Target,
    b: &Sensitivity,
    r: &Sensitivity,
    noise_variance_px2: f64,
) -> Option<ModelEffect> {
    let u = MODEL_UNCERTAINTY;
    let prior = intrinsics_prior(model);
    // The posterior covariances, and the direction (in their metric) that lowers the excess fastest.
    let precision = SMatrix::<f64, 5, 5>::from_diagonal(&prior.map(|s| 1.0 / (s * s)))
        + b.intrinsics_shown / noise_variance_px2;
    let intrinsics_covariance = precision.try_inverse()?;
    let g = r.intrinsics_gradient - b.intrinsics_gradient;
    let step = intrinsics_covariance * g;
    let mut slope2 = g.dot(&step);
    let mut curvature = step.dot(&((r.intrinsics_shown - b.intrinsics_shown) * step));
    let point_prior = Matrix3::identity() / (u.target_m * u.target_m);
    for i in 0..target.len() {
        let Some(covariance) = (point_prior + b.points_shown[i] / noise_variance_px2).try_inverse()
        else {
            continue;
        };
        let g = r.points_gradient[i] - b.points_gradient[i];
        let step = covariance * g;
        slope2 += g.dot(&step);
        curvature += step.dot(&((r.points_shown[i] - b.points_shown[i]) * step));
    }
    let slope_px2 = slope2.max(0.0).sqrt();
    // `step` moves one posterior standard deviation times the slope: per unit step, divide by the slope squared.
    let curvature_px2 = if slope_px2 > 0.0 {
        curvature / (slope_px2 * slope_px2)
    } else {
        0.0
    };
    Some(ModelEffect {
        slope_px2,
        curvature_px2,
    })
}
