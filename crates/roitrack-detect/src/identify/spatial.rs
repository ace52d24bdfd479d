//! Hypotheses for non-planar targets (points spread in depth, such as markers on a part or a tool): four target
//! points that are not coplanar and four neighbouring blobs determine an affine camera (the perspective camera to
//! first order for a target small against its distance), which predicts where the other points are; a quadruple
//! whose predictions land on blobs is a hypothesis, to be verified by a pose.

use nalgebra::{SMatrix, SVector, Vector2, Vector3};

use super::MAX_SEED_BLOBS;
use super::index::{Hypotheses, PointIndex};
use super::sparse::nearest_points;

/// Target points used as the first point of a quadruple: all of a small target, else a few spread ones.
fn anchors(points: &[Vector3<f64>]) -> Vec<usize> {
    let n = points.len();
    if n <= 8 {
        return (0..n).collect();
    }
    let centre = points.iter().sum::<Vector3<f64>>() / n as f64;
    let mut by_distance: Vec<usize> = (0..n).collect();
    by_distance.sort_by(|&a, &b| {
        (points[b] - centre)
            .norm()
            .total_cmp(&(points[a] - centre).norm())
    });
    by_distance.truncate(5);
    by_distance
}

/// The affine camera `x = A X + c` through four correspondences, `None` if the target points are coplanar.
fn affine_camera(
    model: &[Vector3<f64>; 4],
    image: &[Vector2<f64>; 4],
) -> Option<SMatrix<f64, 2, 4>> {
    // x - x0 = A (X - X0): three difference vectors determine A.
    let dx = SMatrix::<f64, 3, 3>::from_columns(&[
        model[1] - model[0],
        model[2] - model[0],
        model[3] - model[0],
    ]);
    let volume = dx.determinant().abs();
    let scale =
        (model[1] - model[0]).norm() * (model[2] - model[0]).norm() * (model[3] - model[0]).norm();
    if volume < 0.05 * scale {
        return None;
    }
    let inverse = dx.try_inverse()?;
    let du = SMatrix::<f64, 2, 3>::from_columns(&[
        image[1] - image[0],
        image[2] - image[0],
        image[3] - image[0],
    ]);
    let a = du * inverse;
    let c = image[0] - a * model[0];
    let mut camera = SMatrix::<f64, 2, 4>::zeros();
    camera.fixed_view_mut::<2, 3>(0, 0).copy_from(&a);
    camera.set_column(3, &c);
    Some(camera)
}

/// Candidate correspondences (target point, blob) covering at least `min_matched` points each.
pub(crate) fn quadruple_hypotheses(
    points: &[Vector3<f64>],
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
    min_matched: usize,
) -> Vec<Vec<(usize, usize)>> {
    let n = points.len();
    let mut spacing_m = f64::INFINITY;
    for (k, p) in points.iter().enumerate() {
        for q in &points[k + 1..] {
            spacing_m = spacing_m.min((p - q).norm());
        }
    }
    // Model quadruples: an anchor and three of its nearest, in every order, not coplanar.
    let mut quadruples = Vec::new();
    for p0 in anchors(points) {
        let near = nearest_points(points, p0, 4);
        for &p1 in &near {
            for &p2 in &near {
                for &p3 in &near {
                    if p1 != p2 && p2 != p3 && p1 != p3 {
                        quadruples.push([p0, p1, p2, p3]);
                    }
                }
            }
        }
    }
    let mut hypotheses = Hypotheses::default();
    // Seeds among the first blobs only (detectors list the strongest first): the search grows with the square of
    // the seeds' neighbourhoods, and a cluttered frame of thousands of blobs must not take seconds.
    for b0 in 0..ideal.len().min(MAX_SEED_BLOBS) {
        if !ideal[b0].x.is_finite() {
            continue;
        }
        let near = index.similar_neighbours(b0, 10, 1e6, areas_px, 4.0, 5);
        for &b1 in &near {
            for &b2 in &near {
                for &b3 in &near {
                    if b1 == b2 || b2 == b3 || b1 == b3 {
                        continue;
                    }
                    let image = [ideal[b0], ideal[b1], ideal[b2], ideal[b3]];
                    for quad in &quadruples {
                        let model = quad.map(|p| points[p]);
                        let Some(camera) = affine_camera(&model, &image) else {
                            continue;
                        };
                        // The map's scale (px per m) sets the gate: a third of the smallest spacing.
                        let a = camera.fixed_view::<2, 3>(0, 0);
                        let scale = (a.row(0).norm() * a.row(1).norm()).sqrt();
                        let gate = 0.3 * spacing_m * scale;
                        hypotheses.extend_and_keep(
                            index,
                            None,
                            quad.iter()
                                .zip([b0, b1, b2, b3])
                                .map(|(&p, b)| (p, b))
                                .collect(),
                            n,
                            |_| gate,
                            min_matched,
                            |p| {
                                camera
                                    * SVector::<f64, 4>::new(
                                        points[p].x,
                                        points[p].y,
                                        points[p].z,
                                        1.0,
                                    )
                            },
                        );
                    }
                }
            }
        }
    }
    hypotheses.list
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn affine_camera_reproduces_its_correspondences_and_refuses_coplanar_points() {
        let model = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.05, 0.0, 0.01),
            Vector3::new(0.0, 0.04, -0.02),
            Vector3::new(0.01, 0.01, 0.05),
        ];
        let image = [
            Vector2::new(100.0, 120.0),
            Vector2::new(160.0, 118.0),
            Vector2::new(98.0, 170.0),
            Vector2::new(111.0, 131.0),
        ];
        let camera = affine_camera(&model, &image).unwrap();
        for (m, i) in model.iter().zip(&image) {
            let x = camera * SVector::<f64, 4>::new(m.x, m.y, m.z, 1.0);
            assert!((x - i).norm() < 1e-9);
        }
        let flat = model.map(|p| Vector3::new(p.x, p.y, 0.0));
        assert!(affine_camera(&flat, &image).is_none());
    }
}
