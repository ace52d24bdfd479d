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
//!
//! In the source: the search's driver in `identify/search.rs`, its groups of hypotheses and their order in
//! `identify/groups.rs`, the verification in `identify/verify.rs`, the judgement of what is verified (the noise and
//! model error, acceptance and rank, blob sizes, rivals and symmetry) in `identify/judgement.rs`, what the target alone
//! decides in `identify/target_facts.rs`, and the correction of the disks' centres in `identify/centres.rs`.

mod centres;
mod groups;
pub(crate) mod index;
mod judgement;
pub(crate) mod lattice;
mod search;
pub(crate) mod sparse;
pub(crate) mod spatial;
mod target_facts;
mod verify;

use nalgebra::Vector2;
use roitrack_core::{CameraModel, MotionState, Target};

use crate::matching::{DetectedBlob, MatchError};
pub(crate) use judgement::{NOMINAL_AREA_FACTOR, whole_view_points};
use search::identify_search;
pub(crate) use search::{lattice_promise, on_lattice};

#[cfg(doc)]
use roitrack_core::stats::f_equal_dof_upper_quantile;
#[cfg(doc)]
use roitrack_estimators::relabelling_is_rival;

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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};
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
