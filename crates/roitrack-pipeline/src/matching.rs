//! Initialisation from a full frame: match detected blobs to the target's model points with no prior, then solve the
//! static pose.
//!
//! For a planar target the convex hull is preserved by perspective (all points in front of the camera), so the hull
//! vertices of the image blobs correspond to the hull vertices of the model, in the same cyclic order (reversed if the
//! target is seen from its back). The key blob (the target's unique largest diameter, matched to the largest blob)
//! fixes the cyclic shift; without one every shift is tried and an ambiguous best is refused. Each hypothesis gives a
//! pose from the hull correspondences; the model points projected with it are matched to their nearest blobs, and the
//! hypothesis matching most blobs with the smallest residual wins.

use nalgebra::{Vector2, Vector3};
use roitrack_core::estimator::{Observation, solve_static_pose};
use roitrack_core::{CameraModel, Measurement, MotionState, SpatioTemporalModel, Target};
use roitrack_image::{CentroidOptions, Frame, detect_blobs};
use thiserror::Error;

/// A blob detected in a full frame: raw (distorted) pixel centre and area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectedBlob {
    pub u_px: f64,
    pub v_px: f64,
    pub area_px: f64,
}

impl From<&roitrack_image::Centroid> for DetectedBlob {
    fn from(c: &roitrack_image::Centroid) -> Self {
        Self {
            u_px: c.u_px,
            v_px: c.v_px,
            area_px: f64::from(c.area_px),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Error)]
pub enum MatchError {
    #[error("found {found} blobs, the target has {expected} points: need at least {required}")]
    TooFewBlobs {
        found: usize,
        expected: usize,
        required: usize,
    },
    #[error("automatic matching needs a planar target (this one is not)")]
    NotPlanar,
    #[error(
        "the blobs' convex hull has {image} corners, the target's has {model}: the view is not of the whole target"
    )]
    HullMismatch { image: usize, model: usize },
    #[error(
        "no match hypothesis fits: best residual {residual_px:.2} px with {matched} of {expected} points matched"
    )]
    NoFit {
        residual_px: f64,
        matched: usize,
        expected: usize,
    },
    #[error(
        "the match is ambiguous (the target is symmetric and has no key blob): mark one point with a larger diameter in \
         the target file"
    )]
    Ambiguous,
    #[error("a blob could not be undistorted: {0}")]
    Undistortion(#[from] roitrack_core::CameraError),
    #[error(
        "the frame is {frame_width} x {frame_height} px, the camera's image {camera_width} x {camera_height} px"
    )]
    FrameSize {
        frame_width: u32,
        frame_height: u32,
        camera_width: u32,
        camera_height: u32,
    },
}

/// The target found in a full frame ([`find_target`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TargetDetection {
    /// When the pose holds (s): the frame's time, or for a rolling shutter the time of the matched blobs' mean row.
    pub t_s: f64,
    /// The static pose (velocity zero).
    pub state: MotionState,
    /// One measurement per matched target point: its blob's centre (raw pixels) at its own time (time model).
    pub measurements: Vec<Measurement>,
    /// RMS reprojection residual of the pose (px, per coordinate).
    pub residual_rms_px: f64,
    /// Blobs detected in the frame, matched or not.
    pub blobs_detected: usize,
}

/// Finds and identifies the target in a full frame with no prior, and solves its static pose: blob detection
/// ([`detect_blobs`] with `options`' threshold and area limits), matching ([`match_full_frame`]), each blob timed by
/// the camera's time model.
///
/// ```
/// use rand::SeedableRng;
/// use rand_chacha::ChaCha8Rng;
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_image::{CentroidOptions, Frame, RenderScratch, RoiRenderer, SensorModel};
/// use roitrack_pipeline::find_target;
/// use nalgebra::{Rotation3, Vector3};
///
/// let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.2, -0.1, 0.4), Vector3::new(0.01, 0.0, 0.6));
/// let renderer = RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
/// let mut frame = Frame::default();
/// let mut rng = ChaCha8Rng::seed_from_u64(1);
/// renderer.render_frame(&|_t| truth, 0.5, &mut rng, &mut RenderScratch::new(), &mut frame);
///
/// let found = find_target(&camera, &target, &frame, &CentroidOptions::default()).unwrap();
/// assert_eq!(found.measurements.len(), 16);
/// assert!((found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-3);
/// assert_eq!(found.t_s, 0.5);
/// ```
pub fn find_target(
    camera: &CameraModel,
    target: &Target,
    frame: &Frame,
    options: &CentroidOptions,
) -> Result<TargetDetection, MatchError> {
    if (frame.width, frame.height) != (camera.width_px, camera.height_px) {
        return Err(MatchError::FrameSize {
            frame_width: frame.width,
            frame_height: frame.height,
            camera_width: camera.width_px,
            camera_height: camera.height_px,
        });
    }
    let blobs: Vec<DetectedBlob> = detect_blobs(&frame.pixels, frame.width, frame.height, options)
        .iter()
        .map(DetectedBlob::from)
        .collect();
    let found = match_full_frame(camera, target, &blobs)?;
    let time = &camera.time;
    let measurements: Vec<Measurement> = found
        .pairs
        .iter()
        .map(|&(point_index, blob_index)| {
            let blob = &blobs[blob_index];
            Measurement {
                t_s: time.blob_time_s(frame.t_s, blob.v_px),
                id: target.points()[point_index].id,
                u_px: blob.u_px,
                v_px: blob.v_px,
            }
        })
        .collect();
    let mean_row_px =
        measurements.iter().map(|m| m.v_px).sum::<f64>() / measurements.len().max(1) as f64;
    Ok(TargetDetection {
        t_s: time.blob_time_s(frame.t_s, mean_row_px),
        state: found.state,
        measurements,
        residual_rms_px: found.residual_rms_px,
        blobs_detected: blobs.len(),
    })
}

/// The result of a full-frame initialisation.
#[derive(Debug, Clone, PartialEq)]
pub struct FullFrameMatch {
    pub state: MotionState,
    /// For each matched model point (index into the target's points), the blob index.
    pub pairs: Vec<(usize, usize)>,
    pub residual_rms_px: f64,
}

/// Residual (px) above which a hypothesis is not a fit.
const MAX_FIT_RESIDUAL_PX: f64 = 2.0;

/// Points of a planar target in its own plane, and the plane's front normal (object frame, see
/// [`match_full_frame`]); `None` for a non-planar target.
fn plane_coordinates(target: &Target) -> Option<(Vec<Vector2<f64>>, Vector3<f64>)> {
    let plane = target.plane()?;
    let normal: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
    let front = if normal.z > 0.0 { -normal } else { normal };
    Some((plane.points_in_plane_m.clone(), front))
}

/// Indices of the convex hull vertices in counter-clockwise order (in the coordinates' own sense). Points within 3 %
/// of the point spread of the line through their neighbours count as collinear (noise on an edge's blobs must not make
/// them corners) and are excluded.
pub(crate) fn convex_hull(points: &[Vector2<f64>]) -> Vec<usize> {
    let n = points.len();
    if n < 3 {
        return (0..n).collect();
    }
    let spread = points
        .iter()
        .map(|p| (p - points[0]).norm())
        .fold(0.0, f64::max)
        .max(1e-300);
    let tolerance = 0.03 * spread;
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .x
            .total_cmp(&points[b].x)
            .then(points[a].y.total_cmp(&points[b].y))
    });
    let cross = |o: usize, a: usize, b: usize| {
        let (oa, ob) = (points[a] - points[o], points[b] - points[o]);
        oa.x * ob.y - oa.y * ob.x
    };
    let mut hull: Vec<usize> = Vec::with_capacity(2 * n);
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &usize>> = if pass == 0 {
            Box::new(idx.iter())
        } else {
            Box::new(idx.iter().rev())
        };
        for &i in iter {
            while hull.len() >= start + 2 && {
                let o = hull[hull.len() - 2];
                cross(o, hull[hull.len() - 1], i) <= tolerance * (points[i] - points[o]).norm()
            } {
                hull.pop();
            }
            hull.push(i);
        }
        hull.pop();
    }
    hull
}

/// Matches blobs to the target's points and solves the static pose ([`find_target`] detects the blobs of a frame and
/// calls it, with an example). Blobs may include extra ones (reflections);
/// every model point should be visible.
pub fn match_full_frame(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
) -> Result<FullFrameMatch, MatchError> {
    let n = target.len();
    let required = n.max(4);
    if blobs.len() < required {
        return Err(MatchError::TooFewBlobs {
            found: blobs.len(),
            expected: n,
            required,
        });
    }
    let Some((plane, front)) = plane_coordinates(target) else {
        return Err(MatchError::NotPlanar);
    };
    let model = SpatioTemporalModel::new(camera.intrinsics);
    let ideal: Vec<Vector2<f64>> = blobs
        .iter()
        .map(|b| camera.undistort_pixel(&Vector2::new(b.u_px, b.v_px)))
        .collect::<Result<_, _>>()?;
    let centre = target
        .points()
        .iter()
        .map(|p| p.point_in_obj_m)
        .sum::<Vector3<f64>>()
        / n as f64;
    let model_hull = convex_hull(&plane);
    let image_hull = convex_hull(&ideal);
    let m = model_hull.len();
    // Extra blobs (reflections) may add hull corners: try every subset of the image hull of the model's size, in
    // hull order. More than MAX_EXTRA_CORNERS extra corners is not a view of this target.
    if m < 4 || image_hull.len() < m || image_hull.len() > m + MAX_EXTRA_CORNERS {
        return Err(MatchError::HullMismatch {
            image: image_hull.len(),
            model: m,
        });
    }
    let key_point = target.key_point().and_then(|k| target.index_of(k.id));
    let mut hypotheses: Vec<Hypothesis> = Vec::new();
    for subset in combinations(image_hull.len(), m) {
        let corners: Vec<usize> = subset.iter().map(|&k| image_hull[k]).collect();
        for reversed in [false, true] {
            for shift in 0..m {
                let corner = |k: usize| {
                    let j = (k + shift) % m;
                    corners[if reversed { (m - j) % m } else { j }]
                };
                let obs: Vec<Observation> = (0..m)
                    .map(|k| Observation {
                        t_s: 0.0,
                        point_index: model_hull[k],
                        ideal_px: ideal[corner(k)],
                    })
                    .collect();
                let Ok(fit) = solve_static_pose(&model, target, &obs) else {
                    continue;
                };
                // The blobs are seen from the front: a mirror hypothesis (the target seen from its back) fits a
                // symmetric target equally well and is refused here.
                let camera_in_obj = fit.state.cam_r_obj.inverse() * (-fit.state.cam_t_obj_m);
                if fit.state.cam_t_obj_m.z <= 0.0
                    || (front.z != 0.0 && (camera_in_obj - centre).dot(&front) <= 0.0)
                {
                    continue;
                }
                hypotheses.push(score_hypothesis(
                    &model, target, &ideal, blobs, key_point, fit.state,
                ));
            }
        }
    }
    // Most points matched, then the key blob on the largest blob, then the smallest residual.
    hypotheses.sort_by(|a, b| {
        b.matched
            .cmp(&a.matched)
            .then(b.key_consistent.cmp(&a.key_consistent))
            .then(a.residual_px.total_cmp(&b.residual_px))
    });
    let Some(best) = hypotheses.first().cloned() else {
        return Err(MatchError::NoFit {
            residual_px: f64::INFINITY,
            matched: 0,
            expected: n,
        });
    };
    if best.matched < n {
        return Err(MatchError::NoFit {
            residual_px: best.residual_px,
            matched: best.matched,
            expected: n,
        });
    }
    // A different hypothesis that is as good in every respect means the target's symmetry is unbroken.
    let mut best_pairs = best.pairs.clone();
    best_pairs.sort_unstable();
    let rival = hypotheses.iter().skip(1).any(|h| {
        let mut p = h.pairs.clone();
        p.sort_unstable();
        h.matched == best.matched
            && h.key_consistent == best.key_consistent
            && h.residual_px < 3.0 * best.residual_px.max(0.05)
            && p != best_pairs
    });
    if rival {
        return Err(MatchError::Ambiguous);
    }
    let (pairs, matched) = (best.pairs, best.matched);
    let obs: Vec<Observation> = pairs
        .iter()
        .map(|&(point_index, blob)| Observation {
            t_s: 0.0,
            point_index,
            ideal_px: ideal[blob],
        })
        .collect();
    let fit = solve_static_pose(&model, target, &obs).map_err(|_| MatchError::NoFit {
        residual_px: f64::INFINITY,
        matched,
        expected: n,
    })?;
    if fit.residual_rms_px > MAX_FIT_RESIDUAL_PX {
        return Err(MatchError::NoFit {
            residual_px: fit.residual_rms_px,
            matched,
            expected: n,
        });
    }
    Ok(FullFrameMatch {
        state: fit.state,
        pairs,
        residual_rms_px: fit.residual_rms_px,
    })
}

/// Extra hull corners tolerated (from reflections or stray blobs outside the target).
const MAX_EXTRA_CORNERS: usize = 3;

/// A match hypothesis and how well it explains the blobs.
#[derive(Debug, Clone)]
struct Hypothesis {
    /// (model point index, blob index)
    pairs: Vec<(usize, usize)>,
    matched: usize,
    /// The key model point is paired with the largest of the paired blobs.
    key_consistent: bool,
    residual_px: f64,
}

/// All `k`-subsets of `0..n`, each in increasing order.
fn combinations(n: usize, k: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    let mut current = Vec::with_capacity(k);
    fn recurse(
        start: usize,
        n: usize,
        k: usize,
        current: &mut Vec<usize>,
        out: &mut Vec<Vec<usize>>,
    ) {
        if current.len() == k {
            out.push(current.clone());
            return;
        }
        for i in start..n {
            current.push(i);
            recurse(i + 1, n, k, current, out);
            current.pop();
        }
    }
    recurse(0, n, k, &mut current, &mut out);
    out
}

/// Projects every model point with a hypothesised pose and pairs it with the nearest unused blob within a gate of a
/// third of the smallest projected point spacing.
fn score_hypothesis(
    model: &SpatioTemporalModel,
    target: &Target,
    ideal: &[Vector2<f64>],
    blobs: &[DetectedBlob],
    key_point: Option<usize>,
    state: MotionState,
) -> Hypothesis {
    let projected: Vec<Option<Vector2<f64>>> = target
        .points()
        .iter()
        .map(|p| model.project(&state, &p.point_in_obj_m, 0.0))
        .collect();
    let mut spacing = f64::INFINITY;
    for (i, a) in projected.iter().enumerate() {
        for b in projected.iter().skip(i + 1) {
            if let (Some(a), Some(b)) = (a, b) {
                spacing = spacing.min((a - b).norm());
            }
        }
    }
    let gate = spacing / 3.0;
    let mut used = vec![false; ideal.len()];
    let mut pairs = Vec::with_capacity(projected.len());
    let mut sum = 0.0;
    for (i, p) in projected.iter().enumerate() {
        let Some(p) = p else { continue };
        let best = (0..ideal.len())
            .filter(|&b| !used[b])
            .map(|b| (b, (ideal[b] - p).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((b, d)) = best
            && d < gate
        {
            used[b] = true;
            pairs.push((i, b));
            sum += d * d;
        }
    }
    let matched = pairs.len();
    let residual_px = if matched == 0 {
        f64::INFINITY
    } else {
        (sum / (2 * matched) as f64).sqrt()
    };
    let key_consistent = key_point.is_some_and(|key| {
        let largest = pairs
            .iter()
            .max_by(|a, b| blobs[a.1].area_px.total_cmp(&blobs[b.1].area_px))
            .map(|p| p.0);
        largest == Some(key)
    });
    Hypothesis {
        pairs,
        matched,
        key_consistent,
        residual_px,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};
    use roitrack_core::TargetPoint;

    fn bench(in_plane_deg: f64) -> MotionState {
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 5f64.to_radians())
            * Rotation3::from_axis_angle(&Vector3::y_axis(), (-15f64).to_radians())
            * Rotation3::from_axis_angle(&Vector3::x_axis(), 10f64.to_radians())
            * Rotation3::from_axis_angle(&Vector3::z_axis(), in_plane_deg.to_radians());
        MotionState::at_rest(r, Vector3::new(0.02, -0.01, 0.6))
    }

    /// Blobs as a detector would report them: shuffled, areas from the diameters, small noise.
    fn blobs(
        camera: &CameraModel,
        target: &Target,
        state: &MotionState,
        seed: usize,
    ) -> Vec<DetectedBlob> {
        let mut out: Vec<DetectedBlob> = target
            .points()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let px = camera
                    .raw_pixel_from_cam(&state.point_in_cam_at(&p.point_in_obj_m, 0.0))
                    .unwrap();
                let d_px = 1500.0 * p.diameter_m.unwrap_or(0.006) / 0.6;
                let wiggle = 0.05 * (((i * 7 + seed * 13) % 11) as f64 / 11.0 - 0.5);
                DetectedBlob {
                    u_px: px.x + wiggle,
                    v_px: px.y - wiggle,
                    area_px: std::f64::consts::PI * d_px * d_px / 4.0,
                }
            })
            .collect();
        // A deterministic shuffle.
        for i in (1..out.len()).rev() {
            out.swap(i, (i * 31 + seed * 17) % (i + 1));
        }
        out
    }

    #[test]
    fn matches_grid4x4_at_any_in_plane_rotation() {
        let camera = CameraModel::canonical();
        let target = Target::grid4x4();
        for (k, angle) in [0.0, 37.0, 90.0, 145.0, 180.0, 260.0, 315.0]
            .into_iter()
            .enumerate()
        {
            let truth = bench(angle);
            let b = blobs(&camera, &target, &truth, k);
            let m = match_full_frame(&camera, &target, &b).unwrap();
            let dp = (m.state.cam_t_obj_m - truth.cam_t_obj_m).norm();
            let dr = roitrack_core::so3::angle_between(&m.state.cam_r_obj, &truth.cam_r_obj);
            assert!(dp < 1e-4 && dr < 1e-3, "angle {angle}: {dp} m {dr} rad");
            assert_eq!(m.pairs.len(), 16);
            for &(point, blob) in &m.pairs {
                let p = target.points()[point].point_in_obj_m;
                let px = camera
                    .raw_pixel_from_cam(&truth.point_in_cam_at(&p, 0.0))
                    .unwrap();
                assert!(
                    (px.x - b[blob].u_px).abs() < 0.1,
                    "angle {angle}: point {point} got blob {blob}"
                );
            }
        }
    }

    #[test]
    fn extra_blobs_are_ignored_and_missing_ones_refused() {
        let camera = CameraModel::canonical();
        let target = Target::grid4x4();
        let truth = bench(20.0);
        let mut b = blobs(&camera, &target, &truth, 3);
        // A reflection inside the grid.
        let c = (b[0].u_px + b[1].u_px) / 2.0;
        b.push(DetectedBlob {
            u_px: c,
            v_px: b[0].v_px + 3.0,
            area_px: 10.0,
        });
        let m = match_full_frame(&camera, &target, &b);
        assert!(m.is_ok(), "{m:?}");
        let few = &b[..10];
        assert!(matches!(
            match_full_frame(&camera, &target, few),
            Err(MatchError::TooFewBlobs { .. })
        ));
    }

    #[test]
    fn a_symmetric_target_without_key_is_ambiguous() {
        let camera = CameraModel::canonical();
        let points: Vec<TargetPoint> = Target::grid4x4()
            .points()
            .iter()
            .map(|p| TargetPoint {
                diameter_m: Some(0.006),
                ..*p
            })
            .collect();
        let target = Target::new(points).unwrap();
        let b = blobs(&camera, &target, &bench(10.0), 1);
        assert_eq!(
            match_full_frame(&camera, &target, &b),
            Err(MatchError::Ambiguous)
        );
    }

    #[test]
    fn hull_of_a_grid_is_its_four_corners() {
        let (plane, front) = plane_coordinates(&Target::grid4x4()).unwrap();
        assert_eq!(front, Vector3::new(0.0, 0.0, -1.0));
        let mut hull = convex_hull(&plane);
        hull.sort_unstable();
        assert_eq!(hull, vec![0, 3, 12, 15]);
    }
}
