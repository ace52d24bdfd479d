//! The search: hypotheses from triples, their object-space minima (mirror twins included), the rivals refined.

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};

use crate::Observation;
use roitrack_core::{MotionState, SpatioTemporalModel, Target};

use super::object_space::ObjectSpaceCost;
use super::p3p;
use super::refine::{StaticPoseProblem, refine_static_pose};
use super::rivals::{rival_variance_px2, rivals_of_best};
use super::triples::{FEW_POINTS, Triples, TriplesError};
use super::{AMBIGUITY_CHI2, InitError, MAX_STATIC_POSES, PixelNoise, PoseFit, StaticPoses};

/// How much of the static pose [`search_static_pose`] finds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Search {
    /// Every pose that rivals the best ([`solve_static_pose`]).
    Whole,
    /// The best alone ([`best_static_pose`]).
    BestOnly,
}

/// Observations of at most this many points are tried with every triple of them by [`best_static_pose`] (four
/// triples).
const FEW_POINTS_BEST_ONLY: usize = 4;

pub(super) fn search_static_pose(
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

/// The unit direction along which points (centred) spread least: a planar target's normal.
fn thinnest_direction(centred: &[Vector3<f64>]) -> Vector3<f64> {
    let scatter = centred
        .iter()
        .fold(Matrix3::zeros(), |s, x| s + x * x.transpose());
    let eig = scatter.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    eig.eigenvectors.column(k).into_owned()
}

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
