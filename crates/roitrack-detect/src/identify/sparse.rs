//! Hypotheses for targets that are not grids (a few points in any planar layout): three target points and three
//! image blobs that are neighbours give an affine map of the target's plane into the image, which predicts where the
//! other points are; a triple whose predictions land on blobs is a hypothesis, to be verified by a pose.

use nalgebra::{Matrix2, Vector2};

use super::index::{Hypotheses, NearestDistance, PointIndex};
use super::{MAX_SEED_BLOBS, NOMINAL_AREA_FACTOR};

/// What the search needs of the target: in-plane points and diameters (m, if known).
pub(crate) struct PlanarModel<'a> {
    pub plane_m: &'a [Vector2<f64>],
    pub diameters_m: &'a [Option<f64>],
    /// The camera's focal length (px): how much perspective bends an affine prediction.
    pub focal_px: f64,
}

/// The sine of the largest tilt of the target's plane to the image plane the predictions allow for (60 degrees).
const MAX_TILT_SIN: f64 = 0.866;

/// Seeds times model triples from which the search is split between two threads: about a millisecond's work
/// (a thread costs a few tens of microseconds to start).
const MIN_SEED_TRIPLES_FOR_TWO_THREADS: usize = 400;

/// The cells of the distance field the predictions are first tested against (px), and the largest distance it
/// holds: a gate is a few px to a few tens.
const FIELD_CELL_PX: f64 = 3.0;
const FIELD_CAP_PX: f64 = 64.0;

/// Target points used as the first point of a triple: all of a small target, else a few spread ones.
fn anchors(model: &PlanarModel) -> Vec<usize> {
    let n = model.plane_m.len();
    if n <= 8 {
        return (0..n).collect();
    }
    let centre = model.plane_m.iter().sum::<Vector2<f64>>() / n as f64;
    let mut by_distance: Vec<usize> = (0..n).collect();
    by_distance.sort_by(|&a, &b| {
        (model.plane_m[b] - centre)
            .norm()
            .total_cmp(&(model.plane_m[a] - centre).norm())
    });
    // The outermost (hull-like) points and the most central one.
    let mut chosen: Vec<usize> = by_distance[..4].to_vec();
    chosen.push(by_distance[n - 1]);
    chosen
}

/// The `k` nearest other points of `i` in a small point set.
pub(crate) fn nearest_points<const D: usize>(
    points: &[nalgebra::SVector<f64, D>],
    i: usize,
    k: usize,
) -> Vec<usize> {
    let mut others: Vec<usize> = (0..points.len()).filter(|&j| j != i).collect();
    others.sort_by(|&a, &b| {
        (points[a] - points[i])
            .norm()
            .total_cmp(&(points[b] - points[i]).norm())
    });
    others.truncate(k);
    others
}

/// Do the blobs of a triple have the sizes the points' diameters give them under an affine map of area scale
/// `scale` (px² per m²)? Up to the nominal diameters' common error, and each within a threshold's error (a factor
/// 2.5 in area) of the others' scale.
fn sizes_agree(
    diameters_m: &[Option<f64>],
    areas_px: &[f64],
    triple: [(usize, usize); 3],
    scale: f64,
) -> bool {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for &(p, b) in &triple {
        if let Some(d) = diameters_m[p] {
            let r = areas_px[b] / (scale * std::f64::consts::FRAC_PI_4 * d * d);
            // `f64::min` and `max` as comparisons (a NaN ratio changes neither), without their NaN handling: a few
            // instructions each, tens of thousands of triples a search.
            if r < lo {
                lo = r;
            }
            if r > hi {
                hi = r;
            }
        }
    }
    // No diameter known: nothing to check.
    !lo.is_finite()
        || (hi <= 2.5 * lo
            && lo <= 1.25 * NOMINAL_AREA_FACTOR
            && hi >= 1.0 / (1.25 * NOMINAL_AREA_FACTOR))
}

/// A triple of neighbouring target points, `p0` and two of its nearest, with what every prediction from it needs.
struct ModelTriple {
    p: [usize; 3],
    /// The inverse of the matrix of the in-plane edges `p1 - p0`, `p2 - p0` (m): the affine map of a triple of blobs
    /// is `F` times this.
    inverse_edges: Matrix2<f64>,
    /// The other points, nearest `p0` first: their coordinates in the triple's affine frame (the offset from `p0`
    /// as `a (p1 - p0) + b (p2 - p0)`, so that a triple of blobs predicts the point at `b0 + a f1 + b f2` without
    /// forming its map) and their offsets' square norms (m², which set their gates).
    others: Vec<(Vector2<f64>, f64)>,
}

/// How much wider than the extension's gate (px, and relatively) a prediction's first test is: the test predicts
/// from the triple's affine frame, in the distance field's cells, where the extension predicts through the map, in
/// px, and the two round differently (by about 1e-10 px at most for frames of thousands of px), as does the test's
/// gate, its terms widened each. A test only refuses a triple the extension would refuse, so it must never find a
/// blob missing that the extension finds within its gate.
const FIRST_TEST_SLACK_PX: f64 = 1e-6;
const FIRST_TEST_SLACK: f64 = 1e-9;

/// Candidate correspondences (target point, blob), each the matches of one triple's affine predictions covering at
/// least `min_matched` points: one search ([`TripleSearch`]).
#[cfg(test)]
pub(crate) fn triple_hypotheses(
    model: &PlanarModel,
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
    min_matched: usize,
) -> Vec<Vec<(usize, usize)>> {
    triple_hypotheses_counted(model, ideal, areas_px, index, min_matched).0
}

/// The work of a [`TripleSearch`].
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(crate) struct TripleWork {
    /// Triples of correspondences (seed blobs on target points) whose sizes agree: each had its predictions tested.
    pub triples: usize,
    /// Predictions tested for a blob within their gate.
    pub predictions: usize,
    /// Triples extended (their predictions matched to blobs one by one).
    pub extended: usize,
}

impl TripleWork {
    fn add(&mut self, other: &TripleWork) {
        self.triples += other.triples;
        self.predictions += other.predictions;
        self.extended += other.extended;
    }
}

/// [`triple_hypotheses`] and its work.
#[cfg(test)]
pub(crate) fn triple_hypotheses_counted(
    model: &PlanarModel,
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
    min_matched: usize,
) -> (Vec<Vec<(usize, usize)>>, TripleWork) {
    let model = PlanarModel {
        plane_m: model.plane_m,
        diameters_m: model.diameters_m,
        focal_px: model.focal_px,
    };
    let mut search = TripleSearch::new(model, ideal, areas_px, index);
    let hypotheses = search.hypotheses(min_matched);
    (hypotheses, search.work)
}

/// A triple of correspondences (seed blobs `b` on the points of model triple `triple`) whose sizes agree, as far as
/// the search has taken it: its first tests made up to `next` (of the model triple's others), `misses` of them
/// missed; the tests' gates (px: a base and a factor of the square distance from the anchor, m²).
#[derive(Debug, Clone, Copy)]
struct Pending {
    b: [u32; 3],
    triple: u32,
    next: u32,
    misses: u32,
    test_base_px: f64,
    test_bend: f64,
}

/// Hypotheses for a planar target that is not a lattice: candidate correspondences (target point, blob), each the
/// matches of one triple's affine predictions, made in tiers of decreasing fewest points ([`Self::hypotheses`]).
///
/// The work is in the wrong triples: each seed blob and two of its neighbours against each triple of neighbouring
/// target points, tens of thousands for a few dozen points and blobs. Three things keep it small without changing the
/// hypotheses made. A triple of correspondences is tried once, not once per order of its two neighbours (swapping
/// both the points and the blobs is the same map). Before a triple's extension (which takes the nearest unused
/// blob of every prediction, in the points' order), its predictions are tested for any blob at all within their
/// gates, nearest the anchor first: a prediction with no blob is a miss in the extension too, and once more miss
/// than the fewest points allow the triple is refused; the nearest predictions have the smallest gates, so a wrong
/// triple misses from its first tests on. And a search for fewer points resumes the one for more where it stopped:
/// a refused triple's tests from its last miss, a triple whose extension failed from its extension, a triple whose
/// extension was kept not at all (its extension for fewer points is the same, and the caller has it).
pub(crate) struct TripleSearch<'a> {
    model: PlanarModel<'a>,
    ideal: &'a [Vector2<f64>],
    areas_px: &'a [f64],
    index: &'a PointIndex,
    /// The smallest target spacing (m), for the prediction gate.
    spacing_m: f64,
    triples: Vec<ModelTriple>,
    field: NearestDistance,
    /// The seeds, in one or two parts (each searched on its own thread).
    parts: Vec<std::ops::Range<usize>>,
    /// Per part, the triples a search for fewer points may still have to take further, in the order they were
    /// first met; `None` before the first search.
    pending: Option<Vec<Vec<Pending>>>,
    /// The work so far.
    pub work: TripleWork,
}

impl<'a> TripleSearch<'a> {
    /// The search for `model` among the blobs `ideal` (undistorted px) of areas `areas_px` (px²), indexed by
    /// `index`.
    pub fn new(
        model: PlanarModel<'a>,
        ideal: &'a [Vector2<f64>],
        areas_px: &'a [f64],
        index: &'a PointIndex,
    ) -> Self {
        let n = model.plane_m.len();
        let mut spacing_m = f64::INFINITY;
        for (k, p) in model.plane_m.iter().enumerate() {
            for q in &model.plane_m[k + 1..] {
                spacing_m = spacing_m.min((p - q).norm());
            }
        }
        let model_k = (n - 1).min(4);
        // Each unordered pair of neighbours once (see above).
        let triples: Vec<ModelTriple> = anchors(&model)
            .into_iter()
            .flat_map(|p0| {
                let near = nearest_points(model.plane_m, p0, model_k);
                let mut t = Vec::new();
                for (k, &p1) in near.iter().enumerate() {
                    for &p2 in &near[k + 1..] {
                        let (e1, e2) = (
                            model.plane_m[p1] - model.plane_m[p0],
                            model.plane_m[p2] - model.plane_m[p0],
                        );
                        let cross = e1.x * e2.y - e1.y * e2.x;
                        if cross.abs() <= 0.1 * e1.norm() * e2.norm() {
                            continue;
                        }
                        let Some(inverse_edges) = Matrix2::from_columns(&[e1, e2]).try_inverse()
                        else {
                            continue;
                        };
                        let mut others: Vec<(Vector2<f64>, f64)> = (0..n)
                            .filter(|&p| p != p0 && p != p1 && p != p2)
                            .map(|p| {
                                let offset = model.plane_m[p] - model.plane_m[p0];
                                (inverse_edges * offset, offset.norm_squared())
                            })
                            .collect();
                        others.sort_by(|a, b| a.1.total_cmp(&b.1));
                        t.push(ModelTriple {
                            p: [p0, p1, p2],
                            inverse_edges,
                            others,
                        });
                    }
                }
                t
            })
            .collect();
        // Cells of a fraction of the smallest gates: fine enough to answer most tests from one cell, coarse enough
        // for the field to stay in the cache. Only the time depends on it.
        let field = NearestDistance::new(index, FIELD_CELL_PX, FIELD_CAP_PX);
        // Seeds among the first blobs only (detectors list the strongest first): the search grows with the square of
        // the seeds' neighbourhoods, and a cluttered frame of thousands of blobs must not take seconds. A large
        // search is split between two threads, the seeds' first half and their second.
        let seeds = ideal.len().min(MAX_SEED_BLOBS);
        let parts = if seeds * triples.len() < MIN_SEED_TRIPLES_FOR_TWO_THREADS {
            std::iter::once(0..seeds).collect()
        } else {
            vec![0..seeds / 2, seeds / 2..seeds]
        };
        Self {
            model,
            ideal,
            areas_px,
            index,
            spacing_m,
            triples,
            field,
            parts,
            pending: None,
            work: TripleWork::default(),
        }
    }

    /// The hypotheses that cover at least `min_matched` points (in the order one search for them would make them),
    /// less those the calls before (each for more points) made: call it with decreasing `min_matched`.
    pub fn hypotheses(&mut self, min_matched: usize) -> Vec<Vec<(usize, usize)>> {
        let pending = self.pending.take();
        let this = &*self;
        // Each part on its own thread (the first here); the second's hypotheses follow the first's, those already
        // made left out: the list is the one thread's.
        let run = |part: usize, pending: Option<Vec<Pending>>| match pending {
            None => this.first_search(this.parts[part].clone(), min_matched),
            Some(pending) => this.resume(pending, min_matched),
        };
        let mut pending: Vec<Option<Vec<Pending>>> = match pending {
            None => vec![None; self.parts.len()],
            Some(kept) => kept.into_iter().map(Some).collect(),
        };
        let results = if pending.len() == 1 {
            vec![run(0, pending.pop().flatten())]
        } else {
            let second_pending = pending.pop().flatten();
            let first_pending = pending.pop().flatten();
            std::thread::scope(|scope| {
                let second = scope.spawn(|| run(1, second_pending));
                let first = run(0, first_pending);
                vec![
                    first,
                    second
                        .join()
                        .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
                ]
            })
        };
        let mut merged: Option<Hypotheses> = None;
        let mut kept = Vec::new();
        for (hypotheses, work, part_pending) in results {
            self.work.add(&work);
            kept.push(part_pending);
            match &mut merged {
                None => merged = Some(hypotheses),
                Some(first) => first.append(hypotheses),
            }
        }
        self.pending = Some(kept);
        merged.map_or_else(Vec::new, |h| h.list)
    }

    /// The first search, over the seeds `seeds`: its hypotheses, its work and the triples a search for fewer points
    /// may take further.
    fn first_search(
        &self,
        seeds: std::ops::Range<usize>,
        min_matched: usize,
    ) -> (Hypotheses, TripleWork, Vec<Pending>) {
        let (model, ideal, areas_px, index) = (&self.model, self.ideal, self.areas_px, self.index);
        let mut hypotheses = Hypotheses::default();
        let mut work = TripleWork::default();
        let mut pending = Vec::new();
        // Any distance: a sparse target's blobs may be far apart; the nearest twelve are enough.
        let image_radius = 1e6;
        for b0 in seeds {
            if !ideal[b0].x.is_finite() {
                continue;
            }
            let near = index.similar_neighbours(b0, 12, image_radius, areas_px, 3.0, 6);
            for &b1 in &near {
                for &b2 in &near {
                    if b1 == b2 {
                        continue;
                    }
                    let (f1, f2) = (ideal[b1] - ideal[b0], ideal[b2] - ideal[b0]);
                    let image_cross = f1.x * f2.y - f1.y * f2.x;
                    if image_cross.abs() < 0.05 * f1.norm() * f2.norm() {
                        continue;
                    }
                    let image_edges = Matrix2::from_columns(&[f1, f2]);
                    let cells = self.cells_of(b0, f1, f2);
                    for (t, triple) in self.triples.iter().enumerate() {
                        let [p0, p1, p2] = triple.p;
                        let map = image_edges * triple.inverse_edges;
                        let scale = map.determinant().abs();
                        // The blobs' sizes must agree with the map's scale, to the nominal diameters' error, and
                        // with each other, to a threshold's.
                        if !sizes_agree(
                            model.diameters_m,
                            areas_px,
                            [(p0, b0), (p1, b1), (p2, b2)],
                            scale,
                        ) {
                            continue;
                        }
                        work.triples += 1;
                        let (base_gate_px, bend) = self.gate_terms(scale);
                        // The gate widened by the slack, its two terms each.
                        let state = Pending {
                            b: [b0 as u32, b1 as u32, b2 as u32],
                            triple: t as u32,
                            next: 0,
                            misses: 0,
                            test_base_px: base_gate_px * (1.0 + FIRST_TEST_SLACK)
                                + FIRST_TEST_SLACK_PX,
                            test_bend: bend * (1.0 + FIRST_TEST_SLACK),
                        };
                        if let Some(state) = self.take_further(
                            state,
                            &cells,
                            min_matched,
                            &mut hypotheses,
                            &mut work,
                        ) {
                            pending.push(state);
                        }
                    }
                }
            }
        }
        (hypotheses, work, pending)
    }

    /// A search for fewer points resumed from the triples `pending` of a part's search for more.
    fn resume(
        &self,
        pending: Vec<Pending>,
        min_matched: usize,
    ) -> (Hypotheses, TripleWork, Vec<Pending>) {
        let mut hypotheses = Hypotheses::default();
        let mut work = TripleWork::default();
        let ideal = self.ideal;
        let kept = pending
            .into_iter()
            .filter_map(|state| {
                let [b0, b1, b2] = state.b.map(|b| b as usize);
                let cells = self.cells_of(b0, ideal[b1] - ideal[b0], ideal[b2] - ideal[b0]);
                self.take_further(state, &cells, min_matched, &mut hypotheses, &mut work)
            })
            .collect();
        (hypotheses, work, kept)
    }

    /// A third of the smallest spacing, plus what perspective adds to the affine prediction at a point `d` from the
    /// anchor: the plane's depth changes across `d` by `d sin(tilt)`, of a depth `f / sqrt(scale)`, which moves the
    /// point by that fraction of its `d sqrt(scale)` px offset (a tilt up to 60 degrees). The gate (px) of a point
    /// `d` (m) from the anchor is `base + bend d²` for a map of area scale `scale` (px² per m²).
    fn gate_terms(&self, scale: f64) -> (f64, f64) {
        (
            0.3 * self.spacing_m * scale.sqrt(),
            MAX_TILT_SIN * scale / self.model.focal_px,
        )
    }

    /// The first tests' predictions from seed `b0` and image edges `f1`, `f2` (px) in the distance field's cells (see
    /// `FIRST_TEST_SLACK`): the anchor and the edges.
    fn cells_of(&self, b0: usize, f1: Vector2<f64>, f2: Vector2<f64>) -> [Vector2<f64>; 3] {
        let per_px = self.field.cells_per_px();
        [
            self.field.cells_of(&self.ideal[b0]),
            f1 * per_px,
            f2 * per_px,
        ]
    }

    /// Takes the triple `state` (its seeds in cells: `cells`, [`Self::cells_of`]) as far as a search for `min_matched`
    /// points does: its first tests resumed (until
    /// more miss than `min_matched` allows), then its extension, whose hypothesis `hypotheses` keeps if it covers
    /// `min_matched` points. The state to resume from for fewer points: `None` once the extension was kept (or the
    /// triple can give nothing more).
    #[inline]
    fn take_further(
        &self,
        mut state: Pending,
        &[anchor_cells, f1_cells, f2_cells]: &[Vector2<f64>; 3],
        min_matched: usize,
        hypotheses: &mut Hypotheses,
        work: &mut TripleWork,
    ) -> Option<Pending> {
        let (model, ideal, index, field) = (&self.model, self.ideal, self.index, &self.field);
        let n = model.plane_m.len();
        // Misses an extension may have and still keep its hypothesis.
        let allowed_misses = n.saturating_sub(min_matched);
        let triple = &self.triples[state.triple as usize];
        let [b0, b1, b2] = state.b.map(|b| b as usize);
        let (test_base_px, test_bend) = (state.test_base_px, state.test_bend);
        let mut misses = state.misses as usize;
        let mut next = state.next as usize;
        for &(frame, d2_m2) in &triple.others[next..] {
            next += 1;
            work.predictions += 1;
            let predicted_cells = anchor_cells + f1_cells * frame.x + f2_cells * frame.y;
            let gate_px = test_base_px + test_bend * d2_m2;
            if !field.any_within_cells(index, &predicted_cells, gate_px) {
                misses += 1;
                if misses > allowed_misses {
                    break;
                }
            }
        }
        (state.next, state.misses) = (next as u32, misses as u32);
        if misses > allowed_misses {
            return Some(state);
        }
        work.extended += 1;
        let [p0, p1, p2] = triple.p;
        let (f1, f2) = (ideal[b1] - ideal[b0], ideal[b2] - ideal[b0]);
        let map = Matrix2::from_columns(&[f1, f2]) * triple.inverse_edges;
        let (base_gate_px, bend) = self.gate_terms(map.determinant().abs());
        let gate =
            |p: usize| base_gate_px + bend * (model.plane_m[p] - model.plane_m[p0]).norm_squared();
        let kept = hypotheses.extend_and_keep(
            index,
            Some(field),
            vec![(p0, b0), (p1, b1), (p2, b2)],
            n,
            gate,
            min_matched,
            |p| ideal[b0] + map * (model.plane_m[p] - model.plane_m[p0]),
        );
        (!kept).then_some(state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The search as it was made before the triples were tested first and taken once: every ordered pair of
    /// neighbours on both sides, each extended. The reference the faster search must equal.
    fn reference(
        model: &PlanarModel,
        ideal: &[Vector2<f64>],
        areas_px: &[f64],
        index: &PointIndex,
        min_matched: usize,
    ) -> (Vec<Vec<(usize, usize)>>, usize) {
        let n = model.plane_m.len();
        let mut hypotheses = Hypotheses::default();
        let mut spacing_m = f64::INFINITY;
        for (k, p) in model.plane_m.iter().enumerate() {
            for q in &model.plane_m[k + 1..] {
                spacing_m = spacing_m.min((p - q).norm());
            }
        }
        let mut ordered = 0;
        for b0 in 0..ideal.len().min(MAX_SEED_BLOBS) {
            let near = index.similar_neighbours(b0, 12, 1e6, areas_px, 3.0, 6);
            for &b1 in &near {
                for &b2 in &near {
                    let (f1, f2) = (ideal[b1] - ideal[b0], ideal[b2] - ideal[b0]);
                    if b1 == b2 || (f1.x * f2.y - f1.y * f2.x).abs() < 0.05 * f1.norm() * f2.norm()
                    {
                        continue;
                    }
                    for p0 in anchors(model) {
                        let near_p = nearest_points(model.plane_m, p0, (n - 1).min(4));
                        for &p1 in &near_p {
                            for &p2 in &near_p {
                                let (e1, e2) = (
                                    model.plane_m[p1] - model.plane_m[p0],
                                    model.plane_m[p2] - model.plane_m[p0],
                                );
                                if p1 == p2
                                    || (e1.x * e2.y - e1.y * e2.x).abs()
                                        <= 0.1 * e1.norm() * e2.norm()
                                {
                                    continue;
                                }
                                let map = Matrix2::from_columns(&[f1, f2])
                                    * Matrix2::from_columns(&[e1, e2]).try_inverse().unwrap();
                                let scale = map.determinant().abs();
                                let seeds = [(p0, b0), (p1, b1), (p2, b2)];
                                if !sizes_agree(model.diameters_m, areas_px, seeds, scale) {
                                    continue;
                                }
                                ordered += 1;
                                let gate = |p: usize| {
                                    let d_m = (model.plane_m[p] - model.plane_m[p0]).norm();
                                    0.3 * spacing_m * scale.sqrt()
                                        + MAX_TILT_SIN * d_m * d_m * scale / model.focal_px
                                };
                                hypotheses.extend_and_keep(
                                    index,
                                    None,
                                    seeds.to_vec(),
                                    n,
                                    gate,
                                    min_matched,
                                    |p| ideal[b0] + map * (model.plane_m[p] - model.plane_m[p0]),
                                );
                            }
                        }
                    }
                }
            }
        }
        (hypotheses.list, ordered)
    }

    /// Random-dot targets seen under random affine views with noise, missing dots and clutter: the search makes
    /// exactly the reference's hypotheses, tries each triple once, and extends only a few of them.
    #[test]
    fn makes_the_reference_hypotheses_with_a_fraction_of_the_work() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        for case in 0..6 {
            let n = rng.random_range(12..=30);
            let mut plane_m: Vec<Vector2<f64>> = Vec::new();
            while plane_m.len() < n {
                let p = Vector2::new(rng.random_range(0.0..0.16), rng.random_range(0.0..0.12));
                if plane_m.iter().all(|q| (q - p).norm() >= 0.018) {
                    plane_m.push(p);
                }
            }
            let diameters_m = vec![Some(0.008); n];
            let model = PlanarModel {
                plane_m: &plane_m,
                diameters_m: &diameters_m,
                focal_px: 620.0,
            };
            // An affine view: 1000-1500 px per m, turned, foreshortened up to 2:1.
            let angle: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let (c, s) = (angle.cos(), angle.sin());
            let squash = rng.random_range(0.5..1.0);
            let scale_px = rng.random_range(1000.0..1500.0);
            let map =
                Matrix2::new(c, -s, s, c) * Matrix2::new(scale_px, 0.0, 0.0, scale_px * squash);
            let area_px = std::f64::consts::FRAC_PI_4 * (0.008 * scale_px).powi(2) * squash;
            let mut ideal: Vec<Vector2<f64>> = Vec::new();
            let mut areas_px = Vec::new();
            for p in &plane_m {
                // A few dots hidden.
                if rng.random_range(0.0..1.0) < 0.08 {
                    continue;
                }
                ideal.push(
                    Vector2::new(320.0, 240.0)
                        + map * (p - Vector2::new(0.08, 0.06))
                        + Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)),
                );
                areas_px.push(area_px * rng.random_range(0.8..1.25));
            }
            for _ in 0..(10 + 5 * case) {
                ideal.push(Vector2::new(
                    rng.random_range(0.0..640.0),
                    rng.random_range(0.0..480.0),
                ));
                areas_px.push(area_px * rng.random_range(0.5..2.0));
            }
            let index = PointIndex::new(&ideal, 20.0);
            for min_matched in [super::super::whole_view_points(n), 6] {
                let (made, work) =
                    triple_hypotheses_counted(&model, &ideal, &areas_px, &index, min_matched);
                let (mut expected, ordered) =
                    reference(&model, &ideal, &areas_px, &index, min_matched);
                let mut made_sorted = made.clone();
                made_sorted.sort();
                expected.sort();
                assert_eq!(made_sorted, expected, "case {case}, {min_matched} points");
                assert!(!made.is_empty(), "case {case}: the target is found");
                // Each triple once: half the ordered pairs.
                assert_eq!(2 * work.triples, ordered, "case {case}");
                if min_matched > 6 {
                    // A whole view: most triples fail their first predictions and are never extended (without the
                    // test first, every triple would be).
                    assert!(
                        work.extended * 5 <= work.triples,
                        "case {case}: {} of {} extended",
                        work.extended,
                        work.triples
                    );
                    assert!(
                        work.predictions <= 10 * work.triples,
                        "case {case}: {work:?}"
                    );
                }
            }
            // One search resumed for fewer points tier after tier (every point, a whole view, 6) makes at each
            // tier what a search of its own for that many points makes and the tiers before did not, in its order.
            let resumed_model = PlanarModel {
                plane_m: &plane_m,
                diameters_m: &diameters_m,
                focal_px: 620.0,
            };
            let mut resumed = TripleSearch::new(resumed_model, &ideal, &areas_px, &index);
            let mut above = n + 1;
            let mut made_in_all = 0;
            for fewest in [n, super::super::whole_view_points(n), 6] {
                let made = resumed.hypotheses(fewest);
                let mut expected = triple_hypotheses(&model, &ideal, &areas_px, &index, fewest);
                expected.retain(|h| h.len() < above);
                assert_eq!(made, expected, "case {case}, {fewest} points");
                made_in_all += made.len();
                above = fewest;
            }
            assert!(made_in_all > 0, "case {case}");
        }
    }
}
