//! Hypotheses for targets that are not grids (a few points in any planar layout): three target points and three
//! image blobs that are neighbours give an affine map of the target's plane into the image, which predicts where the
//! other points are; a triple whose predictions land on blobs is a hypothesis, to be verified by a pose.

use nalgebra::{Matrix2, Vector2};

use super::index::{Hypotheses, PointIndex};
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
    let ratios: Vec<f64> = triple
        .iter()
        .filter_map(|&(p, b)| {
            diameters_m[p].map(|d| areas_px[b] / (scale * std::f64::consts::FRAC_PI_4 * d * d))
        })
        .collect();
    let (lo, hi) = ratios.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &r| {
        (lo.min(r), hi.max(r))
    });
    ratios.is_empty()
        || (hi <= 2.5 * lo
            && lo <= 1.25 * NOMINAL_AREA_FACTOR
            && hi >= 1.0 / (1.25 * NOMINAL_AREA_FACTOR))
}

/// Candidate correspondences (target point, blob), each the matches of one triple's affine predictions covering at
/// least `min_matched` points.
pub(crate) fn triple_hypotheses(
    model: &PlanarModel,
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
    min_matched: usize,
) -> Vec<Vec<(usize, usize)>> {
    let n = model.plane_m.len();
    let mut hypotheses = Hypotheses::default();
    // The smallest target spacing, for the prediction gate.
    let mut spacing_m = f64::INFINITY;
    for (k, p) in model.plane_m.iter().enumerate() {
        for q in &model.plane_m[k + 1..] {
            spacing_m = spacing_m.min((p - q).norm());
        }
    }
    let model_k = (n - 1).min(4);
    let triples: Vec<(usize, usize, usize)> = anchors(model)
        .into_iter()
        .flat_map(|p0| {
            let near = nearest_points(model.plane_m, p0, model_k);
            let mut t = Vec::new();
            for &p1 in &near {
                for &p2 in &near {
                    let (e1, e2) = (
                        model.plane_m[p1] - model.plane_m[p0],
                        model.plane_m[p2] - model.plane_m[p0],
                    );
                    let cross = e1.x * e2.y - e1.y * e2.x;
                    if p1 != p2 && cross.abs() > 0.1 * e1.norm() * e2.norm() {
                        t.push((p0, p1, p2));
                    }
                }
            }
            t
        })
        .collect();
    // Any distance: a sparse target's blobs may be far apart; the nearest twelve are enough.
    let image_radius = 1e6;
    // Seeds among the first blobs only (detectors list the strongest first): the search grows with the square of
    // the seeds' neighbourhoods, and a cluttered frame of thousands of blobs must not take seconds.
    for b0 in 0..ideal.len().min(MAX_SEED_BLOBS) {
        if !ideal[b0].x.is_finite() {
            continue;
        }
        let near: Vec<usize> = index
            .neighbours(b0, 12, image_radius)
            .into_iter()
            .map(|(b, _)| b)
            .filter(|&b| areas_px[b] < 3.0 * areas_px[b0] && areas_px[b] > areas_px[b0] / 3.0)
            .take(6)
            .collect();
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
                for &(p0, p1, p2) in &triples {
                    let (e1, e2) = (
                        model.plane_m[p1] - model.plane_m[p0],
                        model.plane_m[p2] - model.plane_m[p0],
                    );
                    let Some(inverse) = Matrix2::from_columns(&[e1, e2]).try_inverse() else {
                        continue;
                    };
                    let map = Matrix2::from_columns(&[f1, f2]) * inverse;
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
                    // A third of the smallest spacing, plus what perspective adds to the affine prediction at a
                    // point `d` from the anchor: the plane's depth changes across `d` by `d sin(tilt)`, of a depth
                    // `f / sqrt(scale)`, which moves the point by that fraction of its `d sqrt(scale)` px offset
                    // (a tilt up to 60 degrees).
                    let gate = |p: usize| {
                        let d_m = (model.plane_m[p] - model.plane_m[p0]).norm();
                        0.3 * spacing_m * scale.sqrt()
                            + MAX_TILT_SIN * d_m * d_m * scale / model.focal_px
                    };
                    hypotheses.extend_and_keep(
                        index,
                        vec![(p0, b0), (p1, b1), (p2, b2)],
                        n,
                        gate,
                        min_matched,
                        |p| ideal[b0] + map * (model.plane_m[p] - model.plane_m[p0]),
                    );
                }
            }
        }
    }
    hypotheses.list
}
