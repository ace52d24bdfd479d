//! The rigid target: model points (metres, object frame) with ids and optional blob diameters.

use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// Why a set of model points cannot be a target.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TargetError {
    #[error("a target needs at least {required} points, got {actual}")]
    TooFewPoints { required: usize, actual: usize },
    #[error("point id {id} appears more than once")]
    DuplicateId { id: u32 },
    #[error("point id {id}: {field} must be a finite number, got {value}")]
    NotFinite {
        id: u32,
        field: &'static str,
        value: f64,
    },
    #[error("point id {id}: diameter must be positive, got {value} m")]
    NotPositiveDiameter { id: u32, value: f64 },
    #[error(
        "the target points are collinear (spread across the line {spread_m:.3e} m): the pose about that line is unobservable"
    )]
    Collinear { spread_m: f64 },
}

/// One model point: its id (as in the measurements) and position in the object frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetPoint {
    pub id: u32,
    pub point_in_obj_m: Vector3<f64>,
    /// Diameter of the blob's disk (m), if known. The key blob is the one with the largest diameter.
    pub diameter_m: Option<f64>,
}

/// A validated rigid target: at least 4 points, unique ids, finite coordinates, not all on one line.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    points: Vec<TargetPoint>,
    index_of_id: HashMap<u32, usize>,
    /// For a planar target: its plane's frame and the points in it (computed once: the static pose solver uses them).
    plane: Option<TargetPlane>,
}

/// The plane of a planar target: `point_in_obj = centre + obj_r_plane (x, y, 0)`.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetPlane {
    pub centre_m: Vector3<f64>,
    /// Columns: the two in-plane axes (largest spread first) and their cross product.
    pub obj_r_plane: Matrix3<f64>,
    /// Each point's (x, y) in the plane (m), in the order of [`Target::points`].
    pub points_in_plane_m: Vec<nalgebra::Vector2<f64>>,
}

/// Minimum number of points of a target (a pose needs 3 non-collinear points; 4 make it unique for planar targets).
pub const MIN_TARGET_POINTS: usize = 4;

/// Points spread less than this across their best-fit line are collinear (m).
const COLLINEAR_TOLERANCE_M: f64 = 1e-6;

impl Target {
    pub fn new(points: Vec<TargetPoint>) -> Result<Self, TargetError> {
        if points.len() < MIN_TARGET_POINTS {
            return Err(TargetError::TooFewPoints {
                required: MIN_TARGET_POINTS,
                actual: points.len(),
            });
        }
        let mut index_of_id = HashMap::with_capacity(points.len());
        for (index, p) in points.iter().enumerate() {
            for (field, value) in [
                ("x", p.point_in_obj_m.x),
                ("y", p.point_in_obj_m.y),
                ("z", p.point_in_obj_m.z),
            ] {
                if !value.is_finite() {
                    return Err(TargetError::NotFinite {
                        id: p.id,
                        field,
                        value,
                    });
                }
            }
            if let Some(d) = p.diameter_m {
                if !d.is_finite() {
                    return Err(TargetError::NotFinite {
                        id: p.id,
                        field: "diameter",
                        value: d,
                    });
                }
                if d <= 0.0 {
                    return Err(TargetError::NotPositiveDiameter { id: p.id, value: d });
                }
            }
            if index_of_id.insert(p.id, index).is_some() {
                return Err(TargetError::DuplicateId { id: p.id });
            }
        }
        let mut target = Self {
            points,
            index_of_id,
            plane: None,
        };
        let spread = target.principal_spreads_m();
        if spread[1] < COLLINEAR_TOLERANCE_M {
            return Err(TargetError::Collinear {
                spread_m: spread[1],
            });
        }
        if target.is_planar() {
            let (centre_m, obj_r_plane) = target.principal_frame();
            let points_in_plane_m = target
                .points
                .iter()
                .map(|p| {
                    let q = obj_r_plane.transpose() * (p.point_in_obj_m - centre_m);
                    nalgebra::Vector2::new(q.x, q.y)
                })
                .collect();
            target.plane = Some(TargetPlane {
                centre_m,
                obj_r_plane,
                points_in_plane_m,
            });
        }
        Ok(target)
    }

    /// The bundled target "grid4x4" of SPEC section 6: a planar 4 x 4 grid of pitch 20 mm centred on the origin,
    /// id = 4 r + c at ((c - 1.5) 0.02, (r - 1.5) 0.02, 0); 6 mm blobs, except the 9 mm key blob 0.
    pub fn grid4x4() -> Self {
        let points = (0..16u32)
            .map(|id| {
                let (r, c) = ((id / 4) as f64, (id % 4) as f64);
                TargetPoint {
                    id,
                    point_in_obj_m: Vector3::new((c - 1.5) * 0.020, (r - 1.5) * 0.020, 0.0),
                    diameter_m: Some(if id == 0 { 0.009 } else { 0.006 }),
                }
            })
            .collect();
        Self::new(points).expect("grid4x4 is a valid target")
    }

    pub fn points(&self) -> &[TargetPoint] {
        &self.points
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Index (into [`Self::points`]) of the point with this id.
    pub fn index_of(&self, id: u32) -> Option<usize> {
        self.index_of_id.get(&id).copied()
    }

    /// The key blob: the unique point with the largest diameter, if the diameters single one out.
    pub fn key_point(&self) -> Option<&TargetPoint> {
        let largest = self
            .points
            .iter()
            .filter_map(|p| p.diameter_m)
            .fold(f64::NEG_INFINITY, f64::max);
        let mut with_largest = self.points.iter().filter(|p| p.diameter_m == Some(largest));
        match (with_largest.next(), with_largest.next()) {
            (Some(p), None) if largest.is_finite() => Some(p),
            _ => None,
        }
    }

    /// The plane of a planar target (`None` if the points are not on one plane).
    pub fn plane(&self) -> Option<&TargetPlane> {
        self.plane.as_ref()
    }

    /// Centroid and scatter matrix (mean of the outer products of the centred points) of the points.
    fn centroid_and_scatter(&self) -> (Vector3<f64>, Matrix3<f64>) {
        let n = self.points.len() as f64;
        let centre = self
            .points
            .iter()
            .map(|p| p.point_in_obj_m)
            .sum::<Vector3<f64>>()
            / n;
        let mut scatter = Matrix3::zeros();
        for p in &self.points {
            let d = p.point_in_obj_m - centre;
            scatter += d * d.transpose();
        }
        (centre, scatter / n)
    }

    /// Centroid and principal axes (columns, largest spread first, the third their cross product).
    fn principal_frame(&self) -> (Vector3<f64>, Matrix3<f64>) {
        let (centre, scatter) = self.centroid_and_scatter();
        let eig = scatter.symmetric_eigen();
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let e1 = eig.eigenvectors.column(order[0]).into_owned();
        let e2 = eig.eigenvectors.column(order[1]).into_owned();
        (centre, Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]))
    }

    /// Standard deviations of the points along their three principal axes, largest first (m).
    pub fn principal_spreads_m(&self) -> [f64; 3] {
        let (_, scatter) = self.centroid_and_scatter();
        let mut eig: Vec<f64> = scatter
            .symmetric_eigenvalues()
            .iter()
            .map(|e| e.max(0.0).sqrt())
            .collect();
        eig.sort_by(|a, b| b.total_cmp(a));
        [eig[0], eig[1], eig[2]]
    }

    /// Whether all points lie on one plane (to 1e-6 m).
    pub fn is_planar(&self) -> bool {
        self.principal_spreads_m()[2] < COLLINEAR_TOLERANCE_M
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(id: u32, x: f64, y: f64, z: f64) -> TargetPoint {
        TargetPoint {
            id,
            point_in_obj_m: Vector3::new(x, y, z),
            diameter_m: None,
        }
    }

    #[test]
    fn grid4x4_matches_the_spec() {
        let t = Target::grid4x4();
        assert_eq!(t.len(), 16);
        assert!(t.is_planar());
        let p6 = t.points()[t.index_of(6).unwrap()];
        // id 6: r = 1, c = 2.
        assert!((p6.point_in_obj_m - Vector3::new(0.01, -0.01, 0.0)).norm() < 1e-15);
        assert_eq!(t.key_point().unwrap().id, 0);
        assert_eq!(t.key_point().unwrap().diameter_m, Some(0.009));
    }

    #[test]
    fn refuses_bad_targets() {
        let three = vec![
            point(0, 0., 0., 0.),
            point(1, 1., 0., 0.),
            point(2, 0., 1., 0.),
        ];
        assert!(matches!(
            Target::new(three.clone()),
            Err(TargetError::TooFewPoints { actual: 3, .. })
        ));
        let mut dup = three.clone();
        dup.push(point(1, 1., 1., 0.));
        assert_eq!(Target::new(dup), Err(TargetError::DuplicateId { id: 1 }));
        let line: Vec<_> = (0..5)
            .map(|i| point(i, i as f64 * 0.01, 2.0 * i as f64 * 0.01, 0.0))
            .collect();
        assert!(matches!(
            Target::new(line),
            Err(TargetError::Collinear { .. })
        ));
        let mut nan = three.clone();
        nan.push(point(3, f64::NAN, 1., 0.));
        assert!(matches!(
            Target::new(nan),
            Err(TargetError::NotFinite {
                id: 3,
                field: "x",
                ..
            })
        ));
        let mut ok = three;
        ok.push(point(3, 1., 1., 0.2));
        let t = Target::new(ok).unwrap();
        assert!(!t.is_planar());
        assert!(t.key_point().is_none());
    }
}
