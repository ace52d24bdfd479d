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
mod refine;
mod rivals;
mod search;
mod triples;

use nalgebra::{Matrix3, Rotation3};
use thiserror::Error;

use super::Observation;
use super::model_error::ModelEffect;
use roitrack_core::{MotionState, SpatioTemporalModel, Target};

pub(crate) use refine::{apply_pose_step, pose_step_is_negligible};
pub use refine::{refine_static_pose, static_model_residual};
pub use rivals::{MODEL_SPREAD_SIGMAS, is_rival, relabelling_is_rival};
use search::{Search, search_static_pose};

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

#[cfg(test)]
mod tests {
    use super::triples::FEW_POINTS;
    use super::*;
    use nalgebra::{Vector2, Vector3};
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
