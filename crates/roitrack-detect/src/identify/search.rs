//! The search's driver: the blobs prepared once, the hypotheses of the target's kind made group after group in
//! order of promise and verified, the search stopped as soon as what is accepted cannot be rivalled, then the best
//! labelling judged against its rivals and the canonical one of a symmetric target chosen.

use nalgebra::{Vector2, Vector3};
use roitrack_core::{CameraModel, SpatioTemporalModel, Target};
use roitrack_estimators::relabelling_is_rival;

use super::centres::finish;
use super::groups::{HypothesisGroups, grown_lattices, in_tiers, lattice_hypotheses};
use super::index::PointIndex;
use super::judgement::{
    IDENTIFY_NOISE_PX, MODEL_BOUND_SIGMAS, related_by_symmetry, rival_quantile, same_blobs,
};
use super::sparse::{PlanarModel, TripleSearch};
use super::spatial::quadruple_hypotheses;
use super::target_facts::TargetFacts;
use super::verify::{Verified, Verifier};
use super::{Identification, Work};
#[cfg(doc)]
use super::{identify, identify_if_promising};
use crate::matching::{DetectedBlob, MatchError};

/// A grid of at most this many points is also searched as a sparse layout (by triples) when its lattice growth
/// gives no accepted fit: a few points grow a lattice from few neighbours, and one stray blob among them (a large
/// disk in the middle of a 2 x 2 plate) misleads the growth. The triple search costs about the square of the
/// points, so larger grids rely on their growth, which their many neighbours make robust.
pub(super) const SMALL_LATTICE_POINTS: usize = 16;

/// A target of at most this many points has every search verified, even after an accepted labelling of all its
/// points (see `identify_search`): a few points are matched by a few blobs of clutter too (a 2 x 2 plate's four dots
/// against three of them and a large disk), and their searches are cheap.
const ALWAYS_SEARCHED_POINTS: usize = 6;

/// The blobs as the searches take them: their undistorted centres (NaN where undistortion fails), their areas and
/// an index of the centres by cells of twice the median blob's size. `blobs` must not be empty.
fn blob_geometry(
    camera: &CameraModel,
    blobs: &[DetectedBlob],
) -> (Vec<Vector2<f64>>, Vec<f64>, PointIndex) {
    let ideal: Vec<Vector2<f64>> = blobs
        .iter()
        .map(|b| {
            camera
                .undistort_pixel(&Vector2::new(b.u_px, b.v_px))
                .unwrap_or(Vector2::repeat(f64::NAN))
        })
        .collect();
    let areas_px: Vec<f64> = blobs.iter().map(|b| b.area_px).collect();
    let typical_px = {
        let mut d: Vec<f64> = areas_px.iter().map(|a| a.sqrt()).collect();
        // The median's value: the same whichever of equal values lands there, so selected, not sorted.
        let middle = d.len() / 2;
        d.select_nth_unstable_by(middle, f64::total_cmp);
        d[middle].max(4.0)
    };
    let index = PointIndex::new(&ideal, 2.0 * typical_px);
    (ideal, areas_px, index)
}

/// Whether the target's points lie on a lattice in a plane, so that [`lattice_promise`] judges blobs for it.
pub(crate) fn on_lattice(target: &Target) -> bool {
    let facts = TargetFacts::of(target);
    facts.planar.is_some() && facts.lattice.is_some()
}

/// The promise of `blobs` for a target on a lattice, at the cost of the lattice's growth alone: the blobs in their
/// largest grown lattice, at most the target's points (0 when no lattice grows): at least the most target points a
/// placement of that lattice puts on blobs, which [`Work::promise`] counts for the search of [`identify`]. `None` for a target on no lattice: its first hypotheses (triples or
/// quadruples) cost about as much as its whole search. A caller choosing between sets of blobs (the polarities of
/// a photograph) ranks them by it before it measures their centres precisely: rough centres, a few tenths of a pixel
/// off, grow the same lattices.
///
/// The promise is given up to `cap` (the smaller of the two): a caller that only compares it with a threshold (the
/// size of a whole view, another polarity's promise) needs no more, and the growth stops at a lattice that large
/// (the largest grows to its last node otherwise: a target's whole lattice, where the ranking needed a fifth of it).
/// The lattices grown before are the same either way, so the capped promise is the full one's, capped.
pub(crate) fn lattice_promise(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
    cap: usize,
) -> Option<usize> {
    if !on_lattice(target) {
        return None;
    }
    if target.len() < 4 || blobs.len() < target.len().clamp(4, 6) {
        return Some(0);
    }
    let (ideal, areas_px, index) = blob_geometry(camera, blobs);
    // The largest grown lattice's nodes, as many as the target has at most: an upper bound of the points its
    // placements put on blobs (computing those costs as much again as the growth, for a ranking that the growth
    // alone decides: a polarity's chance lattices are small).
    // A lattice of as many nodes as the target has points cannot be beaten, nor one of `cap` nodes exceed the
    // answer: the growth stops at the fewer (and at 4 at the least, the smallest lattice counted, which the cap
    // below then lowers).
    let enough = cap.clamp(4, target.len());
    let grown = grown_lattices(&ideal, &areas_px, &index, enough);
    Some(
        grown
            .first()
            .map_or(0, |g| g.nodes.len().min(target.len()).min(cap)),
    )
}

/// The search of [`identify_if_promising`]: `Ok(None)` when it stopped for too small a promise.
pub(super) fn identify_search(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
    min_promise: usize,
    work: &mut Work,
) -> Result<Option<Identification>, MatchError> {
    let n = target.len();
    // Any three blobs are the image of three points in some pose: only a fourth point can be checked.
    if n < 4 {
        return Err(MatchError::ThreePoints);
    }
    let facts = TargetFacts::of(target);
    let min_matched = n.clamp(4, 6);
    if blobs.len() < min_matched {
        return Err(MatchError::TooFewBlobs {
            found: blobs.len(),
            expected: n,
            required: min_matched,
        });
    }
    let (ideal, areas_px, index) = blob_geometry(camera, blobs);
    let verifier = Verifier {
        camera,
        target,
        model: SpatioTemporalModel::new(camera.intrinsics),
        ideal: &ideal,
        areas_px: &areas_px,
        index: &index,
        nearest_point: &facts.nearest_point,
        front_normal: facts.planar.as_ref().map(|(_, front)| *front),
        centre_m: facts.centre_m,
        bounds: std::cell::Cell::new(0),
        poses: Default::default(),
    };
    let diameters: Vec<Option<f64>> = target.points().iter().map(|p| p.diameter_m).collect();
    let groups = hypothesis_groups(&verifier, &facts, &diameters, min_matched);
    let outcome = verify_groups(&verifier, groups, min_matched, min_promise, work)
        .map(|verified| judge(&verifier, verified, min_matched, work.hypotheses));
    work.bounds = verifier.bounds.get();
    outcome.transpose()
}

/// The hypotheses of the target's kind, in groups in order of promise: a lattice's growths (and for a small grid,
/// the triple search after them), a planar layout's triples, a 3-D layout's quadruples.
fn hypothesis_groups<'a>(
    verifier: &Verifier<'a>,
    facts: &'a TargetFacts,
    diameters: &'a [Option<f64>],
    min_matched: usize,
) -> HypothesisGroups<'a> {
    let Verifier {
        camera,
        target,
        ideal,
        areas_px,
        index,
        ..
    } = *verifier;
    let n = target.len();
    let plane: &[Vector2<f64>] = facts.planar.as_ref().map_or(&[], |(plane, _)| plane);
    // Only called for a planar target (`plane` its points in its plane).
    let triples = move || {
        let model = PlanarModel {
            plane_m: plane,
            diameters_m: diameters,
            focal_px: camera.intrinsics.fx_px.max(camera.intrinsics.fy_px),
        };
        // One search, resumed tier after tier for fewer points.
        let mut search = TripleSearch::new(model, ideal, areas_px, index);
        in_tiers(n, min_matched, true, move |fewest| {
            search.hypotheses(fewest)
        })
    };
    match (&facts.planar, facts.lattice.clone()) {
        (Some(_), Some(lattice)) => {
            let grown = lattice_hypotheses(lattice, ideal, areas_px, index);
            if n <= SMALL_LATTICE_POINTS {
                // Made when the search reaches them (after the lattice's groups).
                Box::new(grown.chain(std::iter::once_with(triples).flatten()))
            } else {
                grown
            }
        }
        (None, _) => {
            let spread: Vec<Vector3<f64>> =
                target.points().iter().map(|p| p.point_in_obj_m).collect();
            in_tiers(n, min_matched, false, move |fewest| {
                quadruple_hypotheses(&spread, ideal, areas_px, index, fewest)
            })
        }
        (Some(_), None) => triples(),
    }
}

/// The hypotheses verified group after group, until what is accepted cannot be rivalled; `None` when the first
/// group promises fewer than `min_promise` points (its size then in `work.promise`).
fn verify_groups(
    verifier: &Verifier<'_>,
    groups: HypothesisGroups<'_>,
    min_matched: usize,
    min_promise: usize,
    work: &mut Work,
) -> Option<Vec<Verified>> {
    let n = verifier.target.len();
    // Groups in order of promise (the largest grown lattice first): a large target's search stops at the first that
    // gives an accepted fit.
    let mut verified: Vec<Verified> = Vec::new();
    let mut first_group = true;
    for group in groups {
        if first_group && !group.is_empty() {
            first_group = false;
            work.promise = group.iter().map(Vec::len).max().unwrap_or(0);
            if work.promise < min_promise {
                return None;
            }
        }
        work.hypotheses += group.len();
        verified.extend(group.iter().filter_map(|pairs| verifier.verify(pairs)));
        // A small target's every search is verified: a rival found by another search than the best's must be seen to
        // be compared (a stray blob can mislead a lattice grown from a few neighbours). Except once an accepted
        // labelling explains every point of a target of more than `ALWAYS_SEARCHED_POINTS`: a rival must then
        // explain them all too, n blobs in the target's layout, which the lattice's placements (the twins among them)
        // have already laid; the triple search would verify thousands of partial labellings of a regular grid (a 4 x 4
        // grid seen whole: about 4,200) that cannot rival it.
        let accepted = |v: &Verified| v.accepted(verifier, min_matched);
        let complete = |v: &Verified| v.pairs.len() == n && v.missing == 0 && accepted(v);
        if n > SMALL_LATTICE_POINTS && verified.iter().any(accepted)
            || n > ALWAYS_SEARCHED_POINTS && verified.iter().any(complete)
        {
            break;
        }
    }
    Some(verified)
}

/// The labelling the verified hypotheses support: the best accepted one against its rivals (a rival the geometry
/// cannot tell from it and not its symmetric twin is a partial view), the canonical one of a symmetric target's
/// twins.
fn judge(
    verifier: &Verifier<'_>,
    mut verified: Vec<Verified>,
    min_matched: usize,
    hypotheses: usize,
) -> Result<Identification, MatchError> {
    verified.sort_by(Verified::rank);
    let Some(best) = verified
        .iter()
        .find(|v| v.accepted(verifier, min_matched))
        .cloned()
    else {
        let best = verified.first();
        return Err(MatchError::NoFit {
            residual_px: best.map_or(f64::INFINITY, |b| b.residual_px),
            matched: best.map_or(0, |b| b.pairs.len()),
            expected: verifier.target.len(),
        });
    };
    // A rival on as many points is told apart from the best only if its cost is larger than noise makes the ratio
    // of two fits' costs on as many degrees of freedom, at one chance in a thousand: with 4 points (2 degrees of
    // freedom) a rival a little less than 32 times the best's residual might be the truth.
    let dof = (2 * best.pairs.len()).saturating_sub(6) as f64;
    let rival_cost_ratio = rival_quantile(dof);
    // The sizes' quantile, asked only when a tie is there to break (it costs about 0.1 ms); every spread compared
    // has the best's number of blobs, hence its degrees of freedom.
    let size_quantile_cell = std::cell::OnceCell::new();
    let size_quantile = |dof: f64| *size_quantile_cell.get_or_init(|| rival_quantile(dof));
    let judged = Judged {
        verifier,
        min_matched,
        rival_cost_ratio,
        size_quantile: &size_quantile,
    };
    let best = judged.sizes_decide(&verified, best);
    let equals = judged.equals_of(&verified, &best)?;
    let ambiguous = equals.len() > 1;
    let chosen = canonical(verifier, &equals).unwrap_or(&best).clone();
    Ok(finish(verifier, chosen, ambiguous, hypotheses))
}

/// What rivals are judged by.
struct Judged<'a, 'v> {
    verifier: &'a Verifier<'v>,
    min_matched: usize,
    /// The largest ratio of a rival's cost to the best's that the noise explains.
    rival_cost_ratio: f64,
    /// The quantile that tells blob sizes apart, by degrees of freedom.
    size_quantile: &'a dyn Fn(f64) -> f64,
}

impl Judged<'_, '_> {
    /// A labelling the geometry cannot tell from the best (as many points, missing and mismatched sizes, a residual
    /// within the rivals' ratio) but whose blob sizes fit significantly better is the best: a key dot a little larger
    /// than the rest decides what the layout alone cannot.
    fn sizes_decide(&self, verified: &[Verified], best: Verified) -> Verified {
        verified
            .iter()
            .filter(|v| {
                v.from_back == best.from_back
                    && v.pairs.len() == best.pairs.len()
                    && v.missing == best.missing
                    && v.size_mismatches == best.size_mismatches
                    && best
                        .size_spread
                        .worse_than(&v.size_spread, self.size_quantile)
                    && v.residual_px.powi(2) <= self.rival_cost_ratio * best.residual_px.powi(2)
                    && v.accepted(self.verifier, self.min_matched)
            })
            .min_by(|a, b| a.size_spread.sum_sq.total_cmp(&b.size_spread.sum_sq))
            .cloned()
            .unwrap_or(best)
    }

    /// The best and the labellings as good as it, each once: its symmetric twins; [`MatchError::PartialView`] if one
    /// is not a twin.
    fn equals_of<'b>(
        &self,
        verified: &'b [Verified],
        best: &'b Verified,
    ) -> Result<Vec<&'b Verified>, MatchError> {
        let verifier = self.verifier;
        let mut best_pairs = best.pairs.clone();
        best_pairs.sort_unstable();
        let mut equals: Vec<&Verified> = vec![best];
        for v in verified {
            // What ranks it below the best is checked first: it is cheaper than whether it is accepted.
            let as_good = v.from_back == best.from_back
                && v.pairs.len() == best.pairs.len()
                && v.missing == best.missing
                && v.size_mismatches == best.size_mismatches
                && !v
                    .size_spread
                    .worse_than(&best.size_spread, self.size_quantile)
                && v.accepted(verifier, self.min_matched)
                && if same_blobs(best, v) {
                    // The same measurements labelled otherwise: judged as the static pose judges its rivals, the
                    // user's model error included.
                    relabelling_is_rival(
                        &verifier.model,
                        verifier.target,
                        (&verifier.observations(&best.pairs), &best.state),
                        (&verifier.observations(&v.pairs), &v.state),
                        IDENTIFY_NOISE_PX,
                        MODEL_BOUND_SIGMAS,
                    )
                } else {
                    v.residual_px.powi(2) <= self.rival_cost_ratio * best.residual_px.powi(2)
                };
            let mut pairs = v.pairs.clone();
            pairs.sort_unstable();
            if pairs != best_pairs
                && as_good
                && equals.iter().all(|e| {
                    let mut p = e.pairs.clone();
                    p.sort_unstable();
                    p != pairs
                })
            {
                if !related_by_symmetry(verifier.target, best, v) {
                    return Err(MatchError::PartialView);
                }
                equals.push(v);
            }
        }
        Ok(equals)
    }
}

/// The canonical labelling among a symmetric target's twins: the lowest id projected nearest the top-left corner.
fn canonical<'b>(verifier: &Verifier<'_>, equals: &[&'b Verified]) -> Option<&'b Verified> {
    let points = verifier.target.points();
    let lowest = (0..points.len()).min_by_key(|&i| points[i].id).unwrap_or(0);
    equals
        .iter()
        .min_by(|a, b| {
            let corner = |v: &Verified| {
                verifier
                    .camera
                    .raw_pixel_from_cam(
                        &v.state.point_in_cam_at(&points[lowest].point_in_obj_m, 0.0),
                    )
                    .map_or(f64::INFINITY, |p| p.x + p.y)
            };
            corner(a).total_cmp(&corner(b))
        })
        .copied()
}
