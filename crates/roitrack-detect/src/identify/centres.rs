//! The chosen labelling's centres corrected for the perspective displacement of a disk's centre, and its pose
//! solved again on them.

use nalgebra::Vector2;

use super::Identification;
use super::judgement::BLOB_AREA_FACTOR;
use super::verify::{Verified, Verifier};

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
pub(super) fn finish(
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
