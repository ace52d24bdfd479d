//! Initialisation from a full frame: detect the blobs, identify the target among them with no prior
//! ([`identify`](mod@crate::identify)), and time each matched blob by the camera's time model.

use roitrack_core::{CameraModel, Measurement, MotionState, Target};
use roitrack_image::{CentroidOptions, Frame, detect_blobs};
use thiserror::Error;

/// A blob detected in a full frame: raw (distorted) pixel centre and area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectedBlob {
    /// Its centre's column (raw, distorted pixels; pixel (i, j) is centred on (i, j)).
    pub u_px: f64,
    /// Its centre's row (raw, distorted pixels).
    pub v_px: f64,
    /// Its area (px²): a centroid's pixel count, or a photograph blob's ellipse area. Identification compares it
    /// with the area a target point's diameter predicts.
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

impl From<&roitrack_image::photo::PhotoBlob> for DetectedBlob {
    /// A photograph's blob, its area that of its ellipse.
    fn from(b: &roitrack_image::photo::PhotoBlob) -> Self {
        Self {
            u_px: b.u_px,
            v_px: b.v_px,
            area_px: b.area_px,
        }
    }
}

impl From<&roitrack_image::photo::RoughBlob> for DetectedBlob {
    /// A photograph's blob as the thresholds see it, before its centre is measured.
    fn from(b: &roitrack_image::photo::RoughBlob) -> Self {
        Self {
            u_px: b.u_px,
            v_px: b.v_px,
            area_px: b.area_px,
        }
    }
}

/// Why the target was not identified among the blobs of a frame or a photograph ([`find_target`],
/// [`match_full_frame`], [`crate::identify::identify`]).
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_detect::matching::{DetectedBlob, MatchError, match_full_frame};
///
/// // Three blobs cannot show a 16-point target: identification takes 6 at least.
/// let blobs = [DetectedBlob { u_px: 500.0, v_px: 500.0, area_px: 30.0 }; 3];
/// let e = match_full_frame(&CameraModel::canonical(), &Target::grid4x4(), &blobs).unwrap_err();
/// assert_eq!(e, MatchError::TooFewBlobs { found: 3, expected: 16, required: 6 });
/// ```
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MatchError {
    /// Fewer blobs than identification takes: as many as the target has points, 6 at most.
    #[error("found {found} blobs, the target has {expected} points: need at least {required}")]
    TooFewBlobs {
        /// The blobs given.
        found: usize,
        /// The target's points.
        expected: usize,
        /// The fewest blobs identification takes (and the fewest points a match must have).
        required: usize,
    },
    /// The target has fewer than 4 points: any three blobs are the image of three points in some pose, so no
    /// labelling can be checked.
    #[error(
        "a target of 3 points cannot be identified among blobs: any three blobs are its image in some pose (give a \
         fourth point, or measurements with the points' ids)"
    )]
    ThreePoints,
    /// The blobs' convex hull has another number of corners than the target's: the view is not of the whole target.
    /// Identification, which takes partial views, never returns it.
    #[error(
        "the blobs' convex hull has {image} corners, the target's has {model}: the view is not of the whole target"
    )]
    HullMismatch {
        /// Corners of the blobs' convex hull.
        image: usize,
        /// Corners of the target's convex hull.
        model: usize,
    },
    /// No hypothesis was accepted: none matched enough points with few enough target points missing or of the
    /// wrong size, at a residual the centroid noise and the model's error explain.
    #[error(
        "no match hypothesis fits: best residual {residual_px:.2} px with {matched} of {expected} points matched"
    )]
    NoFit {
        /// The RMS reprojection residual (px, per coordinate) of the best-ranked hypothesis verified; infinite if
        /// none was.
        residual_px: f64,
        /// The target points that hypothesis matched to blobs (0 if none was verified).
        matched: usize,
        /// The target's points.
        expected: usize,
    },
    /// The target's symmetry leaves the labelling undecided (it has no key point of another diameter):
    /// [`match_full_frame`] refuses it, since tracking needs each point's true identity.
    #[error(
        "the match is ambiguous (the target is symmetric and has no key blob): mark one point with a larger diameter in \
         the target file"
    )]
    Ambiguous,
    /// Placements of the target not related by its symmetry fit the blobs equally well: the view shows too little
    /// of the target to tell which part it is.
    #[error(
        "the view does not tell which part of the target it shows: several placements of the target fit the blobs \
         equally well (show more of the target, with at least one of its edges)"
    )]
    PartialView,
    /// A blob's centre could not be undistorted. Identification, which leaves such a blob out, never returns it.
    #[error("a blob could not be undistorted: {0}")]
    Undistortion(#[from] roitrack_core::CameraError),
    /// The frame is not of the camera model's size ([`find_target`]).
    #[error(
        "the frame is {frame_width} x {frame_height} px, the camera's image {camera_width} x {camera_height} px"
    )]
    FrameSize {
        /// The frame's width (px).
        frame_width: u32,
        /// The frame's height (px).
        frame_height: u32,
        /// The camera model's image width (px).
        camera_width: u32,
        /// The camera model's image height (px).
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
/// use roitrack_image::{CentroidOptions, Frame};
/// use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};
/// use roitrack_detect::find_target;
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

/// The result of a full-frame initialisation ([`match_full_frame`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FullFrameMatch {
    /// The static pose of the target in the camera frame (velocity and angular velocity zero).
    pub state: MotionState,
    /// For each matched model point (index into the target's points), the blob index.
    pub pairs: Vec<(usize, usize)>,
    /// The pose's RMS reprojection residual (px, per coordinate), against the blobs' centres corrected for the
    /// perspective displacement of a disk's centre.
    pub residual_rms_px: f64,
}

/// Matches blobs to the target's points and solves the static pose ([`find_target`] detects the blobs of a frame and
/// calls it, with an example): [`crate::identify::identify`], refusing a labelling that the target's symmetry leaves
/// undecided ([`MatchError::Ambiguous`]), since tracking needs each point's true identity.
pub fn match_full_frame(
    camera: &CameraModel,
    target: &Target,
    blobs: &[DetectedBlob],
) -> Result<FullFrameMatch, MatchError> {
    let found = crate::identify::identify(camera, target, blobs)?;
    if found.ambiguous {
        return Err(MatchError::Ambiguous);
    }
    Ok(FullFrameMatch {
        state: found.state,
        pairs: found.pairs,
        residual_rms_px: found.residual_rms_px,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};
    use roitrack_core::TargetPoint;

    fn bench(in_plane_deg: f64) -> MotionState {
        let bench = MotionState::bench();
        MotionState::at_rest(
            bench.cam_r_obj
                * Rotation3::from_axis_angle(&Vector3::z_axis(), in_plane_deg.to_radians()),
            bench.cam_t_obj_m,
        )
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
        // Ten of sixteen blobs: six points predicted in view have none.
        let few = &b[..10];
        assert!(matches!(
            match_full_frame(&camera, &target, few),
            Err(MatchError::NoFit { .. })
        ));
        assert!(matches!(
            match_full_frame(&camera, &target, &b[..3]),
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
}
