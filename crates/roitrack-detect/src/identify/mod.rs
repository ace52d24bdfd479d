//! Which blob is which target point, with no prior: hypothesise correspondences, verify each with a pose.
//!
//! Hypotheses come from the target's structure. A grid (square or hexagonal: the points on a lattice) is matched by
//! growing a lattice through the blobs from a seed and laying it on the target's lattice every way the lattice allows
//! (`identify/lattice.rs` in the source); any other planar layout by triples of neighbouring points mapped onto
//! triples of neighbouring blobs (`identify/sparse.rs`); one spread in depth (at least 4 points) by quadruples of
//! neighbouring points and blobs, through an affine camera (`identify/spatial.rs`). A target nearly flat (pins off a
//! plate, a post on a grid) is searched as a planar one on its best plane. None needs every point to be seen nor the
//! blobs to be only the target's.
//!
//! Every hypothesis is verified the same way: the static pose from its correspondences (intrinsics and distortion
//! known), then the projection of every target point with that pose. A point projected well inside the image must
//! have a blob there (within a quarter of the projected spacing); the correspondences grow to all such blobs and the
//! pose is solved again. The files are nominal: a camera file a few percent off, diameters drawn to spec or missing.
//! So a hypothesis is accepted when its residual is what the centroid noise and a model at the bounds users' files
//! stay within explain ([`ModelResidual::bound_px2`](roitrack_estimators::ModelResidual::bound_px2)), nearly every point it predicts in view is found, and the
//! blobs' sizes agree with the diameters up to one common scale (a nominal diameter off by up to 2x). The best
//! accepted hypothesis wins; another one as good with a different labelling is either the target's own symmetry (a
//! rigid motion of the target onto itself, such as a half turn of a grid without a marked point): then the labelling
//! is ambiguous and a canonical one is returned, flagged; or it is not, and nothing is returned, since the view
//! cannot tell which part of the target it shows. "As good": on the same blobs, as the static pose judges its rivals
//! (noise and model error, [`relabelling_is_rival`]); on other blobs, a residual cost within what noise makes the
//! ratio of two fits' costs at one chance in a thousand ([`f_equal_dof_upper_quantile`]).
//!
//! Which side: a printed target is seen from its front, the side of -z in its frame when its plane is z = 0 (OpenCV's
//! convention for calibration boards: x to the right, y down, z into the board). A hypothesis that sees the target
//! from its back is kept, but loses to one as good from the front: a layout that is its own mirror image (a square
//! grid) fits both ways, with labels mirrored, and the front's is taken; a layout that is not (a hexagonal grid of
//! an even number of columns, a target file written with y up) fits from one side only, and that side is taken.
//!
//! Canonical labelling of a symmetric target: among the equally good labellings, the one that projects the point of
//! the lowest id nearest the image's top-left corner (smallest u + v).
//!
//! The centre of a disk's image is not the image of the disk's centre: under perspective the nearer half of the disk
//! looks larger, and the area centroid of the projected ellipse is displaced towards it. Once the pose is known, each
//! matched blob's centre is corrected by that displacement (computed from the pose and the disk's diameter, by the
//! area centroid of the projected outline) and the pose solved again.

pub(crate) mod index;
pub(crate) mod lattice;
pub(crate) mod sparse;
pub(crate) mod spatial;

use nalgebra::{Vector2, Vector3};
use roitrack_core::stats::f_equal_dof_upper_quantile;
use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
use roitrack_estimators::{
    Observation, best_static_pose, relabelling_is_rival, static_model_residual,
};
use std::collections::HashMap;

use crate::matching::{DetectedBlob, MatchError};
use index::PointIndex;
use lattice::{TargetLattice, grow, placements};
use sparse::{PlanarModel, TripleSearch};
use spatial::quadruple_hypotheses;

/// The centroid noise (px per coordinate) a hypothesis is judged against: that of real photographs' centres, near
/// the top of their spread (measured in docs/results.md, "Design measurements behind the code").
const IDENTIFY_NOISE_PX: f64 = 0.3;

/// A grid of at most this many points is also searched as a sparse layout (by triples) when its lattice growth
/// gives no accepted fit: a few points grow a lattice from few neighbours, and one stray blob among them (a large
/// disk in the middle of a 2 x 2 plate) misleads the growth. The triple search costs about the square of the
/// points, so larger grids rely on their growth, which their many neighbours make robust.
const SMALL_LATTICE_POINTS: usize = 16;

/// A target of at most this many points has every search verified, even after an accepted labelling of all its
/// points (see `identify_search`): a few points are matched by a few blobs of clutter too (a 2 x 2 plate's four dots
/// against three of them and a large disk), and their searches are cheap.
const ALWAYS_SEARCHED_POINTS: usize = 6;

/// The model error a hypothesis's residual is allowed (and a rival's advantage over the best), in standard
/// deviations of [`MODEL_UNCERTAINTY`]: the bounds users' camera and target files stay within.
///
/// [`MODEL_UNCERTAINTY`]: roitrack_estimators::MODEL_UNCERTAINTY
const MODEL_BOUND_SIGMAS: f64 = 2.0;

/// How sure the residuals must make the best labelling against a rival on as many points for the rival to be
/// dismissed ([`f_equal_dof_upper_quantile`]).
const RIVAL_CONFIDENCE: f64 = 0.999;

/// The fraction of the target points a hypothesis predicts in view that must have a blob for it to be accepted:
/// a few may be hidden, cut by glare or merged with clutter.
const MIN_FOUND_FRACTION: f64 = 0.85;

/// The fewest points a hypothesis of a target of `n` points can match when the target is wholly in view and
/// accepted: all but the [`MIN_FOUND_FRACTION`] acceptance leaves missing.
pub(crate) fn whole_view_points(n: usize) -> usize {
    n - (n as f64 * (1.0 - MIN_FOUND_FRACTION)).floor() as usize
}

/// Blobs (in the order given: strongest first from the photo detector) that seed the triple and quadruple searches.
pub const MAX_SEED_BLOBS: usize = 200;

/// The target identified among the blobs ([`identify`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// The static pose (velocity zero).
    pub state: MotionState,
    /// (target point index, blob index), by point index.
    pub pairs: Vec<(usize, usize)>,
    /// For each pair, the blob's centre corrected for the perspective displacement of a disk's centre (raw px): the
    /// image of the target point's centre as measured.
    pub centres_px: Vec<Vector2<f64>>,
    /// RMS reprojection residual (px, per coordinate) of the pose with the corrected centres.
    pub residual_rms_px: f64,
    /// The target's symmetry leaves the labelling undecided: this is the canonical one (see the module's docs).
    pub ambiguous: bool,
    /// Target points predicted well inside the image that had no blob.
    pub missing: usize,
    /// Hypotheses verified.
    pub hypotheses: usize,
}

/// A verified hypothesis.
#[derive(Debug, Clone)]
struct Verified {
    state: MotionState,
    pairs: Vec<(usize, usize)>,
    residual_px: f64,
    /// The largest residual (RMS px per coordinate) the noise and the model's error explain at this pose: computed
    /// when first asked ([`Verified::accepted`]), since it costs as much as the pose and only the hypotheses
    /// ranked best are ever asked.
    residual_bound_px: std::cell::OnceCell<f64>,
    visible: usize,
    missing: usize,
    size_mismatches: usize,
    /// The matched blobs' areas over those the target file's diameters predict (their median; 1 without diameters).
    area_scale: f64,
    /// How far the matched blobs' sizes spread about that common scale ([`SizeSpread`]).
    size_spread: SizeSpread,
    /// The pose sees the target from its back (+z of the object frame).
    from_back: bool,
}

impl Verified {
    fn accepted(&self, verifier: &Verifier, min_matched: usize) -> bool {
        let matched = self.pairs.len();
        matched >= min_matched
            && self.missing as f64 <= (1.0 - MIN_FOUND_FRACTION) * self.visible as f64
            && self.size_mismatches as f64 <= 0.1 * matched as f64
            && self.residual_px
                <= *self
                    .residual_bound_px
                    .get_or_init(|| verifier.residual_bound_px(&self.pairs, &self.state))
    }

    /// Better first: more points, fewer missing, fewer sizes wrong, smaller residual.
    fn rank(&self, other: &Self) -> std::cmp::Ordering {
        other
            .pairs
            .len()
            .cmp(&self.pairs.len())
            .then(self.missing.cmp(&other.missing))
            .then(self.size_mismatches.cmp(&other.size_mismatches))
            .then(self.from_back.cmp(&other.from_back))
            .then(self.residual_px.total_cmp(&other.residual_px))
    }
}

/// A hypothesis's static pose and how well it fits.
#[derive(Clone, Copy)]
struct Fitted {
    state: MotionState,
    /// RMS reprojection residual (px per coordinate).
    residual_px: f64,
    /// The pose sees the target from its back (+z of the object frame).
    from_back: bool,
}

/// A labelling: (point, blob) pairs in the points' order.
type Labelling = Vec<(usize, usize)>;

/// Everything the verification needs, computed once.
struct Verifier<'a> {
    camera: &'a CameraModel,
    target: &'a Target,
    model: SpatioTemporalModel,
    ideal: &'a [Vector2<f64>],
    areas_px: &'a [f64],
    index: &'a PointIndex,
    /// For each target point, its nearest other point (for the projected spacing).
    nearest_point: &'a [usize],
    front_normal: Option<Vector3<f64>>,
    centre_m: Vector3<f64>,
    /// Residual bounds computed ([`Work::bounds`]).
    bounds: std::cell::Cell<usize>,
    /// The static pose of every labelling verified so far, by its sorted pairs ([`Self::pose_of`]).
    poses: std::cell::RefCell<HashMap<Labelling, Option<Fitted>>>,
}

impl Verifier<'_> {
    /// The observations of `pairs`, in the order of their blobs.
    fn observations(&self, pairs: &[(usize, usize)]) -> Vec<Observation> {
        let mut by_blob = pairs.to_vec();
        by_blob.sort_unstable_by_key(|&(_, b)| b);
        by_blob
            .iter()
            .map(|&(point_index, b)| Observation {
                t_s: 0.0,
                point_index,
                ideal_px: self.ideal[b],
            })
            .collect()
    }

    /// The static pose, its residual, and whether it sees the target from its back.
    fn pose(&self, pairs: &[(usize, usize)], centres: &[Vector2<f64>]) -> Option<Fitted> {
        let obs: Vec<Observation> = pairs
            .iter()
            .zip(centres)
            .map(|(&(point_index, _), c)| Observation {
                t_s: 0.0,
                point_index,
                ideal_px: *c,
            })
            .collect();
        let fit = best_static_pose(&self.model, self.target, &obs, IDENTIFY_NOISE_PX).ok()?;
        let state = fit.state;
        if state.cam_t_obj_m.z <= 0.0 || !state.cam_t_obj_m.iter().all(|x| x.is_finite()) {
            return None;
        }
        let from_back = self.front_normal.is_some_and(|front| {
            let camera_in_obj = state.cam_r_obj.inverse() * (-state.cam_t_obj_m);
            (camera_in_obj - self.centre_m).dot(&front) <= 0.0
        });
        Some(Fitted {
            state,
            residual_px: fit.residual_rms_px,
            from_back,
        })
    }

    /// The residual (RMS px per coordinate) the noise explains at one chance in a thousand, plus what a model at the
    /// bounds users' files stay within leaves, for the static pose `state` of `pairs`; 0 if a point does not project
    /// (no residual is accepted then).
    fn residual_bound_px(&self, pairs: &[(usize, usize)], state: &MotionState) -> f64 {
        self.bounds.set(self.bounds.get() + 1);
        let mut sorted = pairs.to_vec();
        sorted.sort_unstable();
        let obs: Vec<Observation> = sorted
            .iter()
            .map(|&(point_index, b)| Observation {
                t_s: 0.0,
                point_index,
                ideal_px: self.ideal[b],
            })
            .collect();
        static_model_residual(&self.model, self.target, &obs, state)
            .map_or(-1.0, |model_residual| {
                model_residual.bound_rms_px(IDENTIFY_NOISE_PX, MODEL_BOUND_SIGMAS)
            })
    }

    /// The static pose of the labelling `sorted` (pairs in order) on the blobs' centres, solved once per labelling: a
    /// small target's search verifies every hypothesis, and most of them, grown by projection and matching, end in
    /// one of a few labellings (a 4 x 4 grid: about 5,000 hypotheses, each solving the pose of its whole labelling
    /// again from every start).
    fn pose_of(&self, sorted: &[(usize, usize)]) -> Option<Fitted> {
        if let Some(fitted) = self.poses.borrow().get(sorted) {
            return *fitted;
        }
        let centres: Vec<Vector2<f64>> = sorted.iter().map(|&(_, b)| self.ideal[b]).collect();
        let fitted = self.pose(sorted, &centres);
        self.poses.borrow_mut().insert(sorted.to_vec(), fitted);
        fitted
    }

    /// Verifies a hypothesis: pose, then every point projected, matched, the pose solved again.
    fn verify(&self, pairs: &[(usize, usize)]) -> Option<Verified> {
        let mut current: Vec<(usize, usize)> = pairs.to_vec();
        current.sort_unstable();
        let mut fitted = self.pose_of(&current)?;
        let mut result = None;
        for _ in 0..2 {
            let verified = self.project_and_match(&fitted.state)?;
            // The same correspondences (by point index, as matched): the pose is already theirs, and final.
            let settled = verified.pairs == current;
            if !settled {
                current.clone_from(&verified.pairs);
                fitted = self.pose_of(&current)?;
            }
            result = Some(Verified {
                state: fitted.state,
                residual_px: fitted.residual_px,
                from_back: fitted.from_back,
                ..verified
            });
            if settled {
                break;
            }
        }
        result
    }

    /// Matches every target point the pose projects well inside the image to the nearest unused blob within a
    /// quarter of its projected spacing, checking its size.
    fn project_and_match(&self, state: &MotionState) -> Option<Verified> {
        let points = self.target.points();
        // Each point in the camera frame once: its projection (as `SpatioTemporalModel::project` makes it), depth
        // and direction.
        let in_cam: Vec<Vector3<f64>> = points
            .iter()
            .map(|p| state.point_in_cam_at(&p.point_in_obj_m, 0.0))
            .collect();
        let projected: Vec<Option<(Vector2<f64>, f64)>> = in_cam
            .iter()
            .map(|c| {
                self.model
                    .intrinsics
                    .pixel_from_cam(c)
                    .map(|ideal| (ideal, c.z))
            })
            .collect();
        let focal = self
            .camera
            .intrinsics
            .fx_px
            .max(self.camera.intrinsics.fy_px);
        let front_in_cam = self.front_normal.map(|n| state.cam_r_obj * n);
        let mut used = vec![false; self.ideal.len()];
        let mut pairs = Vec::new();
        // Each matched blob's area over the area its point's diameter predicts at the pose, and what pixel
        // quantisation makes of their logarithms' spread ([`SizeSpread`]).
        let mut area_ratios: Vec<f64> = Vec::new();
        let mut quantisation = 0.0;
        let (mut visible, mut missing) = (0, 0);
        for (i, p) in points.iter().enumerate() {
            let Some((ideal, depth)) = projected[i] else {
                continue;
            };
            let Some((neighbour, _)) = projected[self.nearest_point[i]] else {
                continue;
            };
            let spacing = (neighbour - ideal).norm();
            let radius_px = p.diameter_m.map_or(0.0, |d| 0.5 * focal * d / depth);
            let raw = self.camera.distort_pixel(&ideal);
            let margin = radius_px + 2.0;
            let inside = raw.x >= margin
                && raw.y >= margin
                && raw.x <= f64::from(self.camera.width_px) - 1.0 - margin
                && raw.y <= f64::from(self.camera.height_px) - 1.0 - margin;
            let found = self
                .index
                .nearest(&ideal, (0.25 * spacing).max(1.5), |b| !used[b]);
            match found {
                Some((b, _)) => {
                    if inside {
                        visible += 1;
                    }
                    if let Some(d) = p.diameter_m {
                        // The disk's area foreshortened by its tilt to the line of sight.
                        let normal =
                            front_in_cam.map_or(1.0, |n| n.dot(&in_cam[i].normalize()).abs());
                        let expected =
                            std::f64::consts::FRAC_PI_4 * (focal * d / depth).powi(2) * normal;
                        area_ratios.push(self.areas_px[b] / expected);
                        quantisation += SizeSpread::quantisation(self.areas_px[b]);
                    }
                    used[b] = true;
                    pairs.push((i, b));
                }
                None if inside => {
                    visible += 1;
                    missing += 1;
                }
                None => {}
            }
        }
        let (size_mismatches, area_scale) = size_mismatches(&mut area_ratios);
        let size_spread = SizeSpread::of_sorted(&area_ratios, quantisation);
        (pairs.len() >= 4).then_some(Verified {
            state: *state,
            pairs,
            residual_px: f64::INFINITY,
            residual_bound_px: std::cell::OnceCell::new(),
            visible,
            missing,
            size_mismatches,
            area_scale,
            size_spread,
            from_back: false,
        })
    }
}

/// How far a matched blob's area may be from what its point's diameter predicts, as a factor either way, once the
/// blobs' common scale is taken out: a threshold finds a disk's edge anywhere from its dark to its bright side, which
/// moves a small disk's area by up to about a factor 2.
const BLOB_AREA_FACTOR: f64 = 2.0;

/// How far the common scale of the matched blobs' areas may be from the target file's diameters, as a factor either
/// way: nominal diameters may be off by up to 2x (a factor 4 in area) and the threshold adds its factor 2.
pub(crate) const NOMINAL_AREA_FACTOR: f64 = crate::photo::NOMINAL_DIAMETER_AREA * BLOB_AREA_FACTOR;

/// How far a labelling's blob sizes spread about their common scale: `Σ (ln rᵢ - ln r̃)²` over the matched blobs
/// whose points have a diameter (`rᵢ` a blob's area over the area its point's diameter predicts, `r̃` their median),
/// and the part of it that pixel quantisation alone makes: a thresholded disk of `A` px² gains or loses about a
/// uniform fraction of each pixel along its perimeter `2 √(π A)`, a variance of `2 √(π A) / 12` px² in its area,
/// `2 √(π A) / (12 A²)` in its logarithm.
///
/// Two labellings of the same blobs that tie on every count ([`size_mismatches`] allows a factor 2 in area, the
/// threshold's reach) may still differ in their sizes: a key dot 20-40 % larger than the rest is within that factor
/// of the others, yet a labelling that puts it on a small point leaves it, and the small blob put on the key point,
/// far off the common scale. The spreads are compared as two variances on as many blobs (`f_equal_dof_upper_quantile`):
/// relative sizes tell the labellings apart whatever the file's nominal diameters, which only move the common scale.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct SizeSpread {
    sum_sq: f64,
    quantisation: f64,
    count: usize,
}

impl SizeSpread {
    /// The spread of `ratios`, sorted ([`size_mismatches`] sorts them), whose blobs' quantisation adds up to
    /// `quantisation`.
    fn of_sorted(ratios: &[f64], quantisation: f64) -> Self {
        if ratios.len() < 3 {
            return Self::default();
        }
        let median = ratios[ratios.len() / 2].ln();
        Self {
            sum_sq: ratios.iter().map(|r| (r.ln() - median).powi(2)).sum(),
            quantisation,
            count: ratios.len(),
        }
    }

    /// What pixel quantisation makes of the variance of the logarithm of a blob's area of `area_px2`.
    fn quantisation(area_px2: f64) -> f64 {
        2.0 * (std::f64::consts::PI * area_px2).sqrt() / (12.0 * area_px2 * area_px2)
    }

    /// The degrees of freedom of the spread (one scale taken out); `None` for too few blobs to compare.
    fn dof(&self) -> Option<f64> {
        (self.count >= 3).then(|| (self.count - 1) as f64)
    }

    /// Whether this labelling's sizes fit worse than `other`'s over as many blobs, by more than `quantile` gives
    /// for [`Self::dof`] (the upper quantile of the ratio of two variances of as many degrees of freedom, asked
    /// only when needed): `other`'s spread floored at what quantisation makes, so that two nearly exact fits are
    /// never told apart by their rounding.
    fn worse_than(&self, other: &Self, quantile: impl FnOnce(f64) -> f64) -> bool {
        let floor = other.sum_sq.max(other.quantisation);
        match self.dof() {
            Some(dof) if self.count == other.count && self.sum_sq > floor => {
                self.sum_sq > quantile(dof) * floor
            }
            _ => false,
        }
    }
}

/// Matched blobs whose size disagrees with their points' diameters (`ratios`: each blob's area over the predicted
/// one; reordered). The diameters of a target file are nominal: a common scale (the median ratio) within
/// [`NOMINAL_AREA_FACTOR`] is taken out, and each blob must then be within [`BLOB_AREA_FACTOR`] of its prediction;
/// beyond that common scale every blob disagrees. Also returns the common scale (1 without diameters).
fn size_mismatches(ratios: &mut [f64]) -> (usize, f64) {
    if ratios.is_empty() {
        return (0, 1.0);
    }
    ratios.sort_by(f64::total_cmp);
    let common = ratios[ratios.len() / 2];
    if !(1.0 / NOMINAL_AREA_FACTOR..=NOMINAL_AREA_FACTOR).contains(&common) {
        return (ratios.len(), common);
    }
    let mismatches = ratios
        .iter()
        .filter(|&&r| !(1.0 / BLOB_AREA_FACTOR..=BLOB_AREA_FACTOR).contains(&(r / common)))
        .count();
    (mismatches, common)
}

/// A target thinner than this fraction of its width (its spreads across and along its best plane) is identified as a
/// planar one, on its best plane ([`Target::best_plane`]): the in-plane predictions of the lattice and triple searches
/// miss a point standing off the plane by at most its height times the view's tilt, and the pose that verifies
/// every hypothesis is solved in 3-D.
const NEARLY_PLANAR: f64 = 0.1;

/// Points of a planar or nearly planar target in its best plane and its front normal (object frame); `None` for a
/// target spread in depth.
fn plane_and_front(target: &Target) -> Option<(Vec<Vector2<f64>>, Vector3<f64>)> {
    let [widest, _, thinnest] = target.principal_spreads_m();
    if thinnest > NEARLY_PLANAR * widest {
        return None;
    }
    let plane = target.best_plane();
    let normal: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
    // The front is the side of negative z in the object frame (a board's printed side faces the camera that sees
    // its x axis to the right and y axis down).
    let front = if normal.z > 0.0 { -normal } else { normal };
    Some((plane.points_in_plane_m.clone(), front))
}

/// What identification needs of a target that depends on the target alone: its plane, lattice and each point's
/// nearest neighbour (the last two cost the square of the points: a quarter of the time of identifying a 336-point
/// grid). Kept for the last target identified on each thread, as a tracker identifies one target frame after frame.
#[derive(Debug)]
struct TargetFacts {
    target: Target,
    /// [`plane_and_front`].
    planar: Option<(Vec<Vector2<f64>>, Vector3<f64>)>,
    /// The lattice of a planar target's points, if they are on one.
    lattice: Option<TargetLattice>,
    /// For each point, its nearest other point (the first of equally near ones).
    nearest_point: Vec<usize>,
    /// The centroid of the points (object frame, m).
    centre_m: Vector3<f64>,
}

impl TargetFacts {
    /// The facts of `target`: computed, or those kept if they are of the same target.
    fn of(target: &Target) -> std::rc::Rc<Self> {
        thread_local! {
            static LAST: std::cell::RefCell<Option<std::rc::Rc<TargetFacts>>> =
                const { std::cell::RefCell::new(None) };
        }
        LAST.with(|last| {
            let mut last = last.borrow_mut();
            if let Some(facts) = last.as_ref().filter(|f| f.target == *target) {
                return facts.clone();
            }
            let facts = std::rc::Rc::new(Self::compute(target));
            *last = Some(facts.clone());
            facts
        })
    }

    fn compute(target: &Target) -> Self {
        let points = target.points();
        let n = points.len();
        let nearest_point: Vec<usize> = (0..n)
            .map(|i| {
                (0..n)
                    .filter(|&j| j != i)
                    .min_by(|&a, &b| {
                        (points[a].point_in_obj_m - points[i].point_in_obj_m)
                            .norm()
                            .total_cmp(
                                &(points[b].point_in_obj_m - points[i].point_in_obj_m).norm(),
                            )
                    })
                    .unwrap_or(0)
            })
            .collect();
        let centre_m = points
            .iter()
            .map(|p| p.point_in_obj_m)
            .sum::<Vector3<f64>>()
            / n.max(1) as f64;
        let planar = plane_and_front(target);
        let lattice = planar
            .as_ref()
            .and_then(|(plane, _)| TargetLattice::of(plane));
        Self {
            target: target.clone(),
            planar,
            lattice,
            nearest_point,
            centre_m,
        }
    }
}

/// Do two hypotheses match the same blobs (to other points)?
fn same_blobs(a: &Verified, b: &Verified) -> bool {
    let blobs = |v: &Verified| {
        let mut blobs: Vec<usize> = v.pairs.iter().map(|&(_, b)| b).collect();
        blobs.sort_unstable();
        blobs
    };
    blobs(a) == blobs(b)
}

/// Is `to` the same labelling as `from` up to a rigid motion of the target onto itself (points onto points of the
/// same diameter)?
fn related_by_symmetry(target: &Target, from: &Verified, to: &Verified) -> bool {
    // The motion that takes each point of `from` to the point `to` gives the same blob: compose the two poses.
    let motion_r = to.state.cam_r_obj.inverse() * from.state.cam_r_obj;
    let motion_t = to.state.cam_r_obj.inverse() * (from.state.cam_t_obj_m - to.state.cam_t_obj_m);
    let points = target.points();
    let spread = target.principal_spreads_m()[0].max(1e-9);
    points.iter().all(|p| {
        let moved = motion_r * p.point_in_obj_m + motion_t;
        points.iter().any(|q| {
            (q.point_in_obj_m - moved).norm() < 0.02 * spread
                && match (p.diameter_m, q.diameter_m) {
                    (Some(a), Some(b)) => (a - b).abs() <= 1e-3 * a.max(b),
                    (None, None) => true,
                    _ => false,
                }
        })
    })
}

/// Identifies the target among `blobs` (raw pixel centres and areas) with no prior; see the module's documentation.
/// List the strongest blobs first: for targets that are not grids only the first [`MAX_SEED_BLOBS`] (200) seed the
/// search (every blob can be matched).
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_detect::identify::identify;
/// use roitrack_detect::matching::DetectedBlob;
///
/// let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.3, -0.2, 2.5), Vector3::new(0.01, 0.0, 0.6));
/// let mut blobs: Vec<DetectedBlob> = target.points().iter().map(|p| {
///     let px = camera.raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, 0.0)).unwrap();
///     let d_px = 1500.0 * p.diameter_m.unwrap() / 0.6;
///     DetectedBlob { u_px: px.x, v_px: px.y, area_px: std::f64::consts::FRAC_PI_4 * d_px * d_px }
/// }).collect();
/// blobs.push(DetectedBlob { u_px: 100.0, v_px: 900.0, area_px: 200.0 }); // clutter
/// let found = identify(&camera, &target, &blobs).unwrap();
/// assert!(!found.ambiguous && found.pairs.len() == 16);
/// assert!((found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-3);
/// ```
pub fn identify(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
) -> Result<Identification, MatchError> {
    identify_counted(camera, target, blobs).0
}

/// [`identify`], and the hypotheses it verified: the work its search did.
pub(crate) fn identify_counted(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
) -> (Result<Identification, MatchError>, usize) {
    let (found, work) = identify_if_promising(camera, target, blobs, 0);
    // A search that asks for no promise always ends with a result or an error.
    (
        found.expect("a search asking no promise stopped"),
        work.hypotheses,
    )
}

/// [`identify`] if the blobs are promising: the search stops (`None`) before verifying anything when its first
/// group of hypotheses (the one verified first: the largest grown lattice's placements, or the seeds' extensions
/// matching the most points) puts fewer than `min_promise` target points on blobs. The work says how many it put
/// ([`Work::promise`]) and how many hypotheses were verified. A search with no hypothesis at all promises 0 and
/// fails as [`identify`] does.
pub(crate) fn identify_if_promising(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
    min_promise: usize,
) -> (Option<Result<Identification, MatchError>>, Work) {
    let mut work = Work::default();
    let found = identify_search(camera, target, blobs, min_promise, &mut work);
    (found.transpose(), work)
}

/// What a search did.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Work {
    /// The most target points a hypothesis of the first group put on blobs (0: none).
    pub promise: usize,
    /// Hypotheses verified.
    pub hypotheses: usize,
    /// Hypotheses whose residual bound (the model error's share) was computed: only those ranked best and their
    /// rivals.
    pub bounds: usize,
}

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
fn identify_search(
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
    let planar = &facts.planar;
    let min_matched = n.clamp(4, 6);
    if blobs.len() < min_matched {
        return Err(MatchError::TooFewBlobs {
            found: blobs.len(),
            expected: n,
            required: min_matched,
        });
    }
    let (ideal, areas_px, index) = blob_geometry(camera, blobs);
    let points = target.points();
    let verifier = Verifier {
        camera,
        target,
        model: SpatioTemporalModel::new(camera.intrinsics),
        ideal: &ideal,
        areas_px: &areas_px,
        index: &index,
        nearest_point: &facts.nearest_point,
        front_normal: planar.as_ref().map(|(_, front)| *front),
        centre_m: facts.centre_m,
        bounds: std::cell::Cell::new(0),
        poses: Default::default(),
    };
    let lattice = facts.lattice.clone();
    let diameters: Vec<Option<f64>> = points.iter().map(|p| p.diameter_m).collect();
    let (ideal_ref, areas_ref, index_ref, diameters_ref) = (&ideal, &areas_px, &index, &diameters);
    let plane_ref: &[Vector2<f64>] = planar.as_ref().map_or(&[], |(plane, _)| plane);
    // Only called for a planar target (`plane_ref` its points in its plane).
    let triples = move || {
        let model = PlanarModel {
            plane_m: plane_ref,
            diameters_m: diameters_ref,
            focal_px: camera.intrinsics.fx_px.max(camera.intrinsics.fy_px),
        };
        // One search, resumed tier after tier for fewer points.
        let mut search = TripleSearch::new(model, ideal_ref, areas_ref, index_ref);
        in_tiers(n, min_matched, true, move |fewest| {
            search.hypotheses(fewest)
        })
    };
    let hypothesis_groups: HypothesisGroups = match (planar, lattice) {
        (Some(_), Some(lattice)) => {
            let grown = lattice_hypotheses(lattice, &ideal, &areas_px, &index);
            if n <= SMALL_LATTICE_POINTS {
                // Made when the search reaches them (after the lattice's groups).
                Box::new(grown.chain(std::iter::once_with(triples).flatten()))
            } else {
                grown
            }
        }
        (None, _) => {
            let spread: Vec<Vector3<f64>> = points.iter().map(|p| p.point_in_obj_m).collect();
            in_tiers(n, min_matched, false, move |fewest| {
                quadruple_hypotheses(&spread, ideal_ref, areas_ref, index_ref, fewest)
            })
        }
        (Some(_), None) => triples(),
    };
    // Groups in order of promise (the largest grown lattice first): a large target's search stops at the first that
    // gives an accepted fit.
    let mut verified: Vec<Verified> = Vec::new();
    let mut first_group = true;
    for group in hypothesis_groups {
        if first_group && !group.is_empty() {
            first_group = false;
            work.promise = group.iter().map(Vec::len).max().unwrap_or(0);
            if work.promise < min_promise {
                return Ok(None);
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
        let accepted = |v: &Verified| v.accepted(&verifier, min_matched);
        let complete = |v: &Verified| v.pairs.len() == n && v.missing == 0 && accepted(v);
        if n > SMALL_LATTICE_POINTS && verified.iter().any(accepted)
            || n > ALWAYS_SEARCHED_POINTS && verified.iter().any(complete)
        {
            break;
        }
    }
    verified.sort_by(Verified::rank);
    let Some(best) = verified
        .iter()
        .find(|v| v.accepted(&verifier, min_matched))
        .cloned()
    else {
        let best = verified.first();
        work.bounds = verifier.bounds.get();
        return Err(MatchError::NoFit {
            residual_px: best.map_or(f64::INFINITY, |b| b.residual_px),
            matched: best.map_or(0, |b| b.pairs.len()),
            expected: n,
        });
    };
    // A labelling the geometry cannot tell from the best (as many points, missing and mismatched sizes, a residual
    // within the rivals' ratio) but whose blob sizes fit significantly better is the best: a key dot a little larger
    // than the rest decides what the layout alone cannot.
    // A rival on as many points is told apart from the best only if its cost is larger than noise makes the ratio
    // of two fits' costs on as many degrees of freedom, at one chance in a thousand: with 4 points (2 degrees of
    // freedom) a rival a little less than 32 times the best's residual might be the truth.
    let dof = (2 * best.pairs.len()).saturating_sub(6) as f64;
    let rival_cost_ratio = rival_quantile(dof);
    // The sizes' quantile, asked only when a tie is there to break (it costs about 0.1 ms); every spread compared
    // has the best's number of blobs, hence its degrees of freedom.
    let size_quantile_cell = std::cell::OnceCell::new();
    let size_quantile = |dof: f64| *size_quantile_cell.get_or_init(|| rival_quantile(dof));
    let sizes_better = verified
        .iter()
        .filter(|v| {
            v.from_back == best.from_back
                && v.pairs.len() == best.pairs.len()
                && v.missing == best.missing
                && v.size_mismatches == best.size_mismatches
                && best.size_spread.worse_than(&v.size_spread, size_quantile)
                && v.residual_px.powi(2) <= rival_cost_ratio * best.residual_px.powi(2)
                && v.accepted(&verifier, min_matched)
        })
        .min_by(|a, b| a.size_spread.sum_sq.total_cmp(&b.size_spread.sum_sq))
        .cloned();
    let best = sizes_better.unwrap_or(best);
    let mut best_pairs = best.pairs.clone();
    best_pairs.sort_unstable();
    let mut equals: Vec<&Verified> = vec![&best];
    for v in &verified {
        // What ranks it below the best is checked first: it is cheaper than whether it is accepted.
        let as_good = v.from_back == best.from_back
            && v.pairs.len() == best.pairs.len()
            && v.missing == best.missing
            && v.size_mismatches == best.size_mismatches
            && !v.size_spread.worse_than(&best.size_spread, size_quantile)
            && v.accepted(&verifier, min_matched)
            && if same_blobs(&best, v) {
                // The same measurements labelled otherwise: judged as the static pose judges its rivals, the
                // user's model error included.
                relabelling_is_rival(
                    &verifier.model,
                    target,
                    (&verifier.observations(&best.pairs), &best.state),
                    (&verifier.observations(&v.pairs), &v.state),
                    IDENTIFY_NOISE_PX,
                    MODEL_BOUND_SIGMAS,
                )
            } else {
                v.residual_px.powi(2) <= rival_cost_ratio * best.residual_px.powi(2)
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
            if !related_by_symmetry(target, &best, v) {
                work.bounds = verifier.bounds.get();
                return Err(MatchError::PartialView);
            }
            equals.push(v);
        }
    }
    let ambiguous = equals.len() > 1;
    // The canonical labelling: the lowest id projected nearest the top-left corner.
    let lowest = (0..n).min_by_key(|&i| points[i].id).unwrap_or(0);
    let chosen = equals
        .iter()
        .min_by(|a, b| {
            let corner = |v: &Verified| {
                camera
                    .raw_pixel_from_cam(
                        &v.state.point_in_cam_at(&points[lowest].point_in_obj_m, 0.0),
                    )
                    .map_or(f64::INFINITY, |p| p.x + p.y)
            };
            corner(a).total_cmp(&corner(b))
        })
        .copied()
        .unwrap_or(&best)
        .clone();
    work.bounds = verifier.bounds.get();
    Ok(Some(finish(&verifier, chosen, ambiguous, work.hypotheses)))
}

/// [`f_equal_dof_upper_quantile`] at [`RIVAL_CONFIDENCE`], kept per degrees of freedom on the thread: it sums a density
/// over 8,192 cells (longer than a small target's whole identification once its hypotheses are made; measured in
/// docs/results.md, "Design measurements behind the code"), and a photograph's or a video's identifications ask it
/// again and again for the same few counts of points. The same value as computed afresh: the function is deterministic.
fn rival_quantile(dof: f64) -> f64 {
    thread_local! {
        static KEPT: std::cell::RefCell<Vec<(u64, f64)>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    KEPT.with(|kept| {
        let mut kept = kept.borrow_mut();
        if let Some(&(_, q)) = kept.iter().find(|(d, _)| *d == dof.to_bits()) {
            return q;
        }
        let q = f_equal_dof_upper_quantile(dof, RIVAL_CONFIDENCE);
        // A target has at most a few hundred points: the list stays short, but is bounded all the same.
        if kept.len() >= 64 {
            kept.clear();
        }
        kept.push((dof.to_bits(), q));
        q
    })
}

/// Groups of hypotheses (lists of (target point, blob) pairs) in the order they are verified; a group is made only
/// when the search reaches it (a large target's search stops at the first group that gives an accepted fit).
type HypothesisGroups<'a> = Box<dyn Iterator<Item = Vec<Vec<(usize, usize)>>> + 'a>;

/// Hypotheses grouped by how many points they match, most first: a group is verified only if the larger ones gave
/// no accepted fit (rivals as good as the best have as many points, so they are in its group).
fn by_size(mut hypotheses: Vec<Vec<(usize, usize)>>) -> HypothesisGroups<'static> {
    hypotheses.sort_by_key(|h| std::cmp::Reverse(h.len()));
    let mut groups: Vec<Vec<Vec<(usize, usize)>>> = Vec::new();
    for h in hypotheses {
        match groups.last_mut() {
            Some(group) if group[0].len() == h.len() => group.push(h),
            _ => groups.push(vec![h]),
        }
    }
    Box::new(groups.into_iter())
}

/// The hypotheses of a search by seeds (triples, quadruples) that covers at least `fewest` points each
/// (`make(fewest)`, asked for fewer points each time: what it made for more points before may be left out),
/// grouped by size ([`by_size`]), made in tiers for a target of more than [`SMALL_LATTICE_POINTS`]: with
/// `complete_first`, first only those that match every point; then, if none of these is accepted, those that match a
/// whole view's worth of points (as many as acceptance allows missing: 85 %); then the rest. Each seed's extension
/// gives up as soon as too many points miss for its tier, so a wrong seed among clutter costs a few predictions instead
/// of nearly one per target point (for the complete tier, one miss refuses it); the hypotheses and their order are
/// those of one search down to `min_matched`, since a larger target's search stops at the first group that gives an
/// accepted fit, the largest first. A labelling of every point, accepted, is thus never searched beyond: any rival
/// that could beat or tie it must explain every point too, and every such hypothesis is in the complete tier (an
/// extension that matches every point misses none, whatever its tier allows). The complete tier pays when a view has
/// a point hidden; the triple search resumes its work for the next tier ([`TripleSearch`]), the quadruple search,
/// whose cost of a view with a point hidden has not been measured, does not ask for it.
fn in_tiers<'a>(
    n: usize,
    min_matched: usize,
    complete_first: bool,
    make: impl FnMut(usize) -> Vec<Vec<(usize, usize)>> + 'a,
) -> HypothesisGroups<'a> {
    let whole_view = whole_view_points(n);
    let make = std::rc::Rc::new(std::cell::RefCell::new(make));
    // The hypotheses of at least `fewest` points and fewer than `above`, grouped, made when the search reaches them.
    let tier = |fewest: usize, above: usize| {
        let make = std::rc::Rc::clone(&make);
        std::iter::once_with(move || {
            let mut made = (make.borrow_mut())(fewest);
            made.retain(|h| h.len() < above);
            by_size(made)
        })
        .flatten()
    };
    if n <= SMALL_LATTICE_POINTS || whole_view <= min_matched {
        return Box::new(tier(min_matched, n + 1));
    }
    if complete_first {
        Box::new(
            tier(n, n + 1)
                .chain(tier(whole_view, n))
                .chain(tier(min_matched, whole_view)),
        )
    } else {
        Box::new(tier(whole_view, n + 1).chain(tier(min_matched, whole_view)))
    }
}

/// The diameter (m) a point's disk has, from the target file's `diameter_m` and the matched blobs' common area scale
/// against the file ([`Verified::area_scale`]): the file's, unless the blobs disagree with it by more than a
/// threshold explains (a nominal diameter off), then the blobs' own. The displacement of a disk's centre grows with
/// the square of its diameter: a file twice off would move the centres by four times the displacement.
fn diameter_seen_m(diameter_m: f64, area_scale: f64) -> f64 {
    if (1.0 / BLOB_AREA_FACTOR..=BLOB_AREA_FACTOR).contains(&area_scale) {
        diameter_m
    } else {
        diameter_m * area_scale.sqrt()
    }
}

/// Corrects the matched centres for the perspective displacement of a disk's centre and solves the pose again.
fn finish(
    verifier: &Verifier,
    chosen: Verified,
    ambiguous: bool,
    hypotheses: usize,
) -> Identification {
    let camera = verifier.camera;
    let points = verifier.target.points();
    let mut pairs = chosen.pairs.clone();
    pairs.sort_unstable();
    let raw: Vec<Vector2<f64>> = pairs
        .iter()
        .map(|&(_, b)| camera.distort_pixel(&verifier.ideal[b]))
        .collect();
    let mut state = chosen.state;
    let mut residual = chosen.residual_px;
    let mut centres = raw.clone();
    // Once: the displacement changes by far less than it is (hundredths of a pixel) with the pose it moves.
    if let Some(front) = verifier.front_normal {
        let corrected: Vec<Vector2<f64>> = pairs
            .iter()
            .zip(&raw)
            .map(|(&(p, _), r)| {
                let point = &points[p];
                point
                    .diameter_m
                    .map(|d| diameter_seen_m(d, chosen.area_scale))
                    .and_then(|d| {
                        roitrack_core::projection::disk_centre_displacement_px(
                            camera,
                            &state,
                            &point.point_in_obj_m,
                            &front,
                            d,
                        )
                    })
                    .map_or(*r, |shift| r - shift)
            })
            .collect();
        let ideal: Option<Vec<Vector2<f64>>> = corrected
            .iter()
            .map(|c| camera.undistort_pixel(c).ok())
            .collect();
        if let Some(refitted) = ideal.and_then(|ideal| verifier.pose(&pairs, &ideal)) {
            state = refitted.state;
            residual = refitted.residual_px;
            centres = corrected;
        }
    }
    Identification {
        state,
        pairs,
        centres_px: centres,
        residual_rms_px: residual,
        ambiguous,
        missing: chosen.missing,
        hypotheses,
    }
}

/// The lattice hypotheses: growth from a few seeds (each blob in one grown lattice at most), each lattice laid on the
/// target's every way; one group of hypotheses per grown lattice, the largest first.
fn lattice_hypotheses(
    lattice: TargetLattice,
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
) -> HypothesisGroups<'static> {
    let grown_sets = grown_lattices(ideal, areas_px, index, usize::MAX);
    // First the placements that put nearly every grown blob on the target; then, if none verifies, those that leave
    // up to half of them off it: stray blobs where the lattice goes on beyond the target (printed marks, clutter)
    // join the growth and stick out of the target.
    // Made as the search asks for them: the lenient ones are many, and seldom needed.
    let count = grown_sets.len();
    Box::new((0..2 * count).map(move |k| {
        let (min_fraction, slack) = if k < count { (0.9, 1) } else { (0.5, 3) };
        placements(&lattice, &grown_sets[k % count], min_fraction, slack)
    }))
}

/// The lattices grown among the blobs (at most 3, of 4 nodes or more), the largest first: growth from a few seeds,
/// each blob in one grown lattice at most; a growth stops at `enough` nodes and no seed is grown after it (the
/// largest is then that one, of `enough` nodes; before it, every growth is the whole growth).
fn grown_lattices(
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
    enough: usize,
) -> Vec<lattice::GrownLattice> {
    const SEEDS: usize = 12;
    let mut grown_sets: Vec<lattice::GrownLattice> = Vec::new();
    let mut covered = vec![false; ideal.len()];
    // Seeds: blobs whose neighbours are alike in size, tried from the most regular; a blob already in a grown
    // lattice is not a new seed.
    let mut near = Vec::new();
    let mut order: Vec<(usize, f64)> = (0..ideal.len())
        .filter(|&b| ideal[b].x.is_finite())
        .filter_map(|b| {
            index.neighbours_into(b, 4, 1e6, &mut near);
            if near.len() < 2 {
                return None;
            }
            let alike = near
                .iter()
                .filter(|&&(o, _)| {
                    areas_px[o] < 1.5 * areas_px[b] && areas_px[o] > areas_px[b] / 1.5
                })
                .count();
            let spread = near[near.len() - 1].1 / near[0].1.max(1e-9);
            Some((b, alike as f64 - 0.5 * spread))
        })
        .collect();
    order.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut attempts = 0;
    for &(seed, _) in &order {
        if attempts >= SEEDS {
            break;
        }
        if covered[seed] {
            continue;
        }
        attempts += 1;
        let near = index.neighbours(seed, 6, 1e6);
        let Some(&(first, d1)) = near.first() else {
            continue;
        };
        let e1 = ideal[first] - ideal[seed];
        let second = near.iter().skip(1).find(|&&(o, d)| {
            let e2 = ideal[o] - ideal[seed];
            (e1.x * e2.y - e1.y * e2.x).abs() > 0.5 * d1 * d
        });
        let Some(&(second, _)) = second else { continue };
        if covered[first] || covered[second] {
            continue;
        }
        let grown = grow(
            ideal, areas_px, index, &covered, seed, first, second, enough,
        );
        for &(_, _, b) in &grown.nodes {
            covered[b] = true;
        }
        let done = grown.nodes.len() >= enough;
        grown_sets.push(grown);
        if done {
            break;
        }
    }
    grown_sets.sort_by_key(|g| std::cmp::Reverse(g.nodes.len()));
    grown_sets
        .into_iter()
        .take(3)
        .filter(|g| g.nodes.len() >= 4)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;
    use roitrack_core::TargetPoint;

    /// Blobs at the projections of every target point, shuffled, with clutter.
    fn blobs_of(
        camera: &CameraModel,
        target: &Target,
        truth: &MotionState,
        clutter: usize,
    ) -> Vec<DetectedBlob> {
        let mut blobs: Vec<DetectedBlob> = target
            .points()
            .iter()
            .map(|p| {
                let px = camera
                    .raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, 0.0))
                    .unwrap();
                DetectedBlob {
                    u_px: px.x,
                    v_px: px.y,
                    area_px: 60.0,
                }
            })
            .collect();
        for k in 0..clutter {
            let (x, y) = (((k * 7919) % 997) as f64, ((k * 104_729) % 991) as f64);
            blobs.push(DetectedBlob {
                u_px: 15.0 + x,
                v_px: 17.0 + y,
                area_px: 55.0,
            });
        }
        for i in (1..blobs.len()).rev() {
            blobs.swap(i, (i * 31 + 7) % (i + 1));
        }
        blobs
    }

    #[test]
    fn identifies_a_non_planar_target_among_clutter() {
        let camera = CameraModel::canonical();
        let layout = [
            (0.0, 0.0, 0.0),
            (0.06, 0.0, 0.01),
            (0.0, 0.05, 0.02),
            (0.05, 0.06, -0.01),
            (0.02, 0.03, 0.05),
            (-0.03, 0.02, 0.03),
            (0.03, -0.03, 0.04),
            (0.07, 0.03, 0.06),
        ];
        let points: Vec<TargetPoint> = layout
            .iter()
            .enumerate()
            .map(|(i, &(x, y, z))| TargetPoint {
                id: 10 + i as u32,
                point_in_obj_m: Vector3::new(x, y, z),
                diameter_m: None,
            })
            .collect();
        let target = Target::new(points).unwrap();
        assert!(target.plane().is_none());
        for (k, angles) in [(0.3, -0.2, 0.5), (-0.4, 0.3, 2.0), (0.1, 0.5, -1.2)]
            .into_iter()
            .enumerate()
        {
            let truth = MotionState::at_rest(
                Rotation3::from_euler_angles(angles.0, angles.1, angles.2),
                Vector3::new(0.01, -0.02, 0.6),
            );
            let blobs = blobs_of(&camera, &target, &truth, 10 + 5 * k);
            let found = identify(&camera, &target, &blobs).unwrap();
            assert_eq!(found.pairs.len(), 8);
            assert!(!found.ambiguous);
            assert!(
                (found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-6,
                "pose {k}"
            );
            for &(p, b) in &found.pairs {
                let px = camera
                    .raw_pixel_from_cam(
                        &truth.point_in_cam_at(&target.points()[p].point_in_obj_m, 0.0),
                    )
                    .unwrap();
                assert!((px.x - blobs[b].u_px).abs() < 1e-9 && (px.y - blobs[b].v_px).abs() < 1e-9);
            }
        }
        // Four and five points in depth, alone in the image: identified, every point on its blob.
        for count in [4, 5] {
            let few = Target::new(target.points()[..count].to_vec()).unwrap();
            let truth = MotionState::at_rest(
                Rotation3::from_euler_angles(0.3, -0.2, 0.4),
                Vector3::new(0.01, 0.0, 0.5),
            );
            let found = identify(&camera, &few, &blobs_of(&camera, &few, &truth, 0)).unwrap();
            assert_eq!(found.pairs.len(), count);
            assert!((found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-6);
        }
        // Three points: any three blobs fit, so none is taken.
        let three = Target::new(target.points()[..3].to_vec()).unwrap();
        let blobs = blobs_of(
            &camera,
            &three,
            &MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6)),
            0,
        );
        assert_eq!(
            identify(&camera, &three, &blobs),
            Err(MatchError::ThreePoints)
        );
    }

    /// A hexagonal grid's search verifies its lattice's placements (the grid's half turn, mirrors and shifts by a
    /// row, about 20), but asks the residual bound (which costs as much as a pose) of only the few that rank best.
    /// A capped promise is the full promise, capped: growths stopped at the cap change nothing below it. On a
    /// grid seen whole among clutter, a third of its blobs, and random clutter alone (a chance lattice).
    #[test]
    fn capped_promise_is_the_full_promise_capped() {
        use roitrack_core::target::{CircleGrid, GridLayout};
        let camera = CameraModel::canonical();
        let target = Target::circle_grid(&CircleGrid {
            rows: 8,
            cols: 10,
            spacing_m: 0.025,
            diameter_m: 0.015,
            layout: GridLayout::Square,
        })
        .unwrap();
        let truth = MotionState::at_rest(
            Rotation3::from_euler_angles(0.3, -0.2, 0.4),
            Vector3::new(-0.1, -0.08, 0.6),
        );
        let whole = blobs_of(&camera, &target, &truth, 40);
        let part: Vec<DetectedBlob> = whole.iter().copied().step_by(3).collect();
        let mut state = 5u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let clutter: Vec<DetectedBlob> = (0..300)
            .map(|_| DetectedBlob {
                u_px: 1000.0 * uniform(),
                v_px: 1000.0 * uniform(),
                area_px: 40.0 + 20.0 * uniform(),
            })
            .collect();
        let mut promises = Vec::new();
        for blobs in [&whole, &part, &clutter] {
            let full = lattice_promise(&camera, &target, blobs, usize::MAX).unwrap();
            for cap in [0, 1, 3, 4, 5, 6, 9, 17, 40, 79, 80, 81, 1000] {
                assert_eq!(
                    lattice_promise(&camera, &target, blobs, cap).unwrap(),
                    full.min(cap),
                    "cap {cap}"
                );
            }
            promises.push(full);
        }
        // Caps below, at and above each promise were tried.
        assert_eq!(promises[0], 80, "{promises:?}");
        assert!(
            promises[1..].iter().all(|p| (6..79).contains(p)),
            "{promises:?}"
        );
    }

    #[test]
    fn residual_bounds_are_computed_for_the_best_ranked_hypotheses_only() {
        use roitrack_core::target::{CircleGrid, GridLayout};
        let camera = CameraModel::canonical();
        let target = Target::circle_grid(&CircleGrid {
            rows: 12,
            cols: 14,
            spacing_m: 0.012,
            diameter_m: 0.01,
            layout: GridLayout::Hexagonal,
        })
        .unwrap();
        let focal = camera.intrinsics.fx_px;
        for (k, angles) in [(0.25, -0.3, 0.1), (-0.2, 0.1, 1.3), (0.1, 0.35, -2.0)]
            .into_iter()
            .enumerate()
        {
            let truth = MotionState::at_rest(
                Rotation3::from_euler_angles(angles.0, angles.1, angles.2),
                Vector3::new(0.0, 0.0, 0.5),
            );
            let blobs: Vec<DetectedBlob> = target
                .points()
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let in_cam = truth.point_in_cam_at(&p.point_in_obj_m, 0.0);
                    let px = camera.raw_pixel_from_cam(&in_cam).unwrap();
                    // A little noise, the same for every run.
                    let wobble = 0.1 * ((i * 7 + k) as f64).sin();
                    DetectedBlob {
                        u_px: px.x + wobble,
                        v_px: px.y - wobble,
                        area_px: std::f64::consts::FRAC_PI_4 * (focal * 0.01 / in_cam.z).powi(2),
                    }
                })
                .collect();
            let (found, work) = identify_if_promising(&camera, &target, &blobs, 0);
            let found = found.unwrap().unwrap();
            assert_eq!(found.pairs.len(), target.len(), "view {k}");
            assert!(work.hypotheses >= 8, "view {k}: {work:?}");
            assert!(work.bounds <= 4, "view {k}: {work:?}");
        }
    }

    /// A 3 x 4 grid with one point on a 10 mm post is identified as the grid it mostly is, the post included.
    #[test]
    fn identifies_a_grid_with_a_point_off_its_plane() {
        let camera = CameraModel::canonical();
        let points: Vec<TargetPoint> = (0..12u32)
            .map(|id| TargetPoint {
                id,
                point_in_obj_m: Vector3::new(
                    0.025 * f64::from(id % 4),
                    0.025 * f64::from(id / 4),
                    if id == 6 { -0.01 } else { 0.0 },
                ),
                // The test's blobs all have one area: no diameter to check it against.
                diameter_m: None,
            })
            .collect();
        let target = Target::new(points).unwrap();
        assert!(target.plane().is_none());
        for angles in [(0.2, -0.3, 0.1), (-0.4, 0.2, 1.6)] {
            let truth = MotionState::at_rest(
                Rotation3::from_euler_angles(angles.0, angles.1, angles.2),
                Vector3::new(-0.03, -0.02, 0.5),
            );
            let blobs = blobs_of(&camera, &target, &truth, 8);
            let found = identify(&camera, &target, &blobs).unwrap();
            assert_eq!(found.pairs.len(), 12, "{angles:?}");
            assert!(
                (found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-6,
                "{angles:?}: {:?}",
                found.state.cam_t_obj_m
            );
        }
    }
}
