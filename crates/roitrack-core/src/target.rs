//! The rigid target: model points (metres, object frame) with ids and optional blob diameters.

use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// Why a set of model points cannot be a target.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TargetError {
    /// Fewer than [`MIN_TARGET_POINTS`] points: the pose would not be fixed.
    #[error("a target needs at least {required} points, got {actual}")]
    TooFewPoints {
        /// The least number of points a target has ([`MIN_TARGET_POINTS`]).
        required: usize,
        /// The number given.
        actual: usize,
    },
    /// Two points share an id, so a measurement's id would not name one point.
    #[error("point id {id} appears more than once")]
    DuplicateId {
        /// The id repeated.
        id: u32,
    },
    /// A coordinate or a diameter is NaN or infinite.
    #[error("point id {id}: {field} must be a finite number, got {value}")]
    NotFinite {
        /// The point's id.
        id: u32,
        /// `x`, `y`, `z` or `diameter`.
        field: &'static str,
        /// The value given (m).
        value: f64,
    },
    /// A blob diameter is zero or negative.
    #[error("point id {id}: diameter must be positive, got {value} m")]
    NotPositiveDiameter {
        /// The point's id.
        id: u32,
        /// The diameter given (m).
        value: f64,
    },
    /// All points lie on one line: the rotation about that line would be unobservable.
    #[error(
        "the target points are collinear (spread across the line {spread_m:.3e} m): the pose about that line is unobservable"
    )]
    Collinear {
        /// The points' standard deviation across their best-fit line (m), under a micrometre.
        spread_m: f64,
    },
    /// Two points are less than a micrometre apart: one blob would be the image of both.
    #[error(
        "points {first_id} and {second_id} are at one place ({distance_m:.1e} m apart): a blob cannot be two points"
    )]
    Coincident {
        /// The id of the point listed first.
        first_id: u32,
        /// The id of the point listed second.
        second_id: u32,
        /// Their distance (m).
        distance_m: f64,
    },
    /// A [`CircleGrid`] specification is refused ([`Target::circle_grid`]).
    #[error("circle grid: {0}")]
    CircleGrid(CircleGridError),
}

/// Why a [`CircleGrid`] specification cannot make a target (see [`Target::circle_grid`]).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CircleGridError {
    /// The grid has no rows or no columns.
    #[error("a grid needs at least 1 row and 1 column, got {rows} x {cols}")]
    NoRowsOrColumns {
        /// The rows given.
        rows: u32,
        /// The columns given.
        cols: u32,
    },
    /// The spacing or the diameter is zero, negative or not finite.
    #[error("{field} must be a finite positive length, got {value} m")]
    NotPositiveLength {
        /// `spacing` or `diameter`.
        field: &'static str,
        /// The value given (m).
        value: f64,
    },
    /// The circles are at least as wide as their spacing, so neighbours would touch or overlap.
    #[error(
        "the diameter ({diameter_m} m) must be smaller than the spacing ({spacing_m} m), or neighbouring circles touch"
    )]
    Overlapping {
        /// The circles' diameter given (m).
        diameter_m: f64,
        /// The spacing given (m).
        spacing_m: f64,
    },
    /// The grid has more than [`MAX_GRID_POINTS`] circles.
    #[error("{count} circles is more than the {max} a grid may have")]
    TooManyPoints {
        /// The number of circles the grid would have.
        count: u64,
        /// The most a grid may have ([`MAX_GRID_POINTS`]).
        max: u64,
    },
}

/// The arrangement of a [`CircleGrid`]'s circles; `S` is its `spacing_m`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GridLayout {
    /// A circle at every row and column: `(x, y) = (col S, row S)`.
    Square,
    /// A circle where `row + col` has the parity of `rows - 1` (the last row holds columns 0, 2, 4, ...), at
    /// `(x, y) = (col S / 2, row S sin 60°)`: each row is shifted by half a spacing against the next, and every
    /// circle's six neighbours are `S` away (equilateral triangles).
    ///
    /// Why that parity: seen from its front (the object's -z side, x to the right and y down), the bottom row then
    /// starts at the left edge, as the usual printed boards do (BoofCV's hexagonal grid: its row 0, with y up, at the
    /// bottom). The layout is not its own mirror image when `rows` is even, so the other parity would describe the
    /// board's back and every pose would see it from behind.
    Hexagonal,
}

/// A planar grid of equal circles: `rows` x `cols` positions `spacing_m` apart, `layout` saying which positions hold
/// a circle (see [`Target::circle_grid`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleGrid {
    /// Number of rows (along y), at least 1.
    pub rows: u32,
    /// Number of columns (along x), at least 1.
    pub cols: u32,
    /// Distance between the centres of neighbouring circles (m), in both layouts.
    pub spacing_m: f64,
    /// Diameter of every circle (m), smaller than the spacing.
    pub diameter_m: f64,
    /// Which positions hold a circle: all of them, or a hexagonal packing.
    pub layout: GridLayout,
}

/// Most circles a [`CircleGrid`] may have (far more than any printed target; keeps a typo from exhausting memory).
pub const MAX_GRID_POINTS: u64 = 1_000_000;

impl CircleGrid {
    /// How many circles the grid has.
    pub fn count(&self) -> u64 {
        let (rows, cols) = (u64::from(self.rows), u64::from(self.cols));
        match self.layout {
            GridLayout::Square => rows * cols,
            // Half the rows hold the even columns, the others the odd ones; the count does not depend on which.
            GridLayout::Hexagonal => rows.div_ceil(2) * cols.div_ceil(2) + (rows / 2) * (cols / 2),
        }
    }

    fn validate(&self) -> Result<(), CircleGridError> {
        if self.rows == 0 || self.cols == 0 {
            return Err(CircleGridError::NoRowsOrColumns {
                rows: self.rows,
                cols: self.cols,
            });
        }
        for (field, value) in [("spacing", self.spacing_m), ("diameter", self.diameter_m)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(CircleGridError::NotPositiveLength { field, value });
            }
        }
        if self.diameter_m >= self.spacing_m {
            return Err(CircleGridError::Overlapping {
                diameter_m: self.diameter_m,
                spacing_m: self.spacing_m,
            });
        }
        if self.count() > MAX_GRID_POINTS {
            return Err(CircleGridError::TooManyPoints {
                count: self.count(),
                max: MAX_GRID_POINTS,
            });
        }
        Ok(())
    }
}

/// One model point: its id (as in the measurements) and position in the object frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetPoint {
    /// The point's id, unique in its target: the `id` of the [`crate::Measurement`]s of its blob.
    pub id: u32,
    /// The point's position in the object frame (m).
    pub point_in_obj_m: Vector3<f64>,
    /// Diameter of the blob's disk (m), if known. The key blob is the one with the largest diameter.
    pub diameter_m: Option<f64>,
}

/// A validated rigid target: at least 3 points, unique ids, finite coordinates, no two at one place, not all on one
/// line.
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
    /// The points' centroid, the plane's origin (m, object frame).
    pub centre_m: Vector3<f64>,
    /// Columns: the two in-plane axes (largest spread first) and their cross product.
    pub obj_r_plane: Matrix3<f64>,
    /// Each point's (x, y) in the plane (m), in the order of [`Target::points`].
    pub points_in_plane_m: Vec<nalgebra::Vector2<f64>>,
}

impl TargetPlane {
    /// The plane of origin `centre_m` and frame `obj_r_plane`, with each of `points` in it.
    fn of_points(
        points: &[TargetPoint],
        centre_m: Vector3<f64>,
        obj_r_plane: Matrix3<f64>,
    ) -> Self {
        let points_in_plane_m = points
            .iter()
            .map(|p| {
                let q = obj_r_plane.transpose() * (p.point_in_obj_m - centre_m);
                nalgebra::Vector2::new(q.x, q.y)
            })
            .collect();
        Self {
            centre_m,
            obj_r_plane,
            points_in_plane_m,
        }
    }
}

/// Minimum number of points of a target: 3 points not on one line fix a pose up to at most four (see
/// [`Target::ambiguity`]); a fourth makes it unique in almost every view.
pub const MIN_TARGET_POINTS: usize = 3;

/// Points spread less than this across their best-fit line are collinear, and two points nearer than this are at one
/// place (m): a micrometre, far below any printed or machined target's tolerance.
const COLLINEAR_TOLERANCE_M: f64 = 1e-6;

/// Two points nearer than [`COLLINEAR_TOLERANCE_M`] (their indices and distance), if any: each point is compared
/// with those in its own and the neighbouring cells of a grid of that pitch, so a million-point grid takes
/// milliseconds.
fn coincident_pair(points: &[TargetPoint]) -> Option<(usize, usize, f64)> {
    let cell = |p: &Vector3<f64>| p.map(|x| (x / COLLINEAR_TOLERANCE_M).floor() as i64);
    let mut cells: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        let c = cell(&p.point_in_obj_m);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(others) = cells.get(&(c.x + dx, c.y + dy, c.z + dz)) else {
                        continue;
                    };
                    for &j in others {
                        let d = (points[j].point_in_obj_m - p.point_in_obj_m).norm();
                        if d < COLLINEAR_TOLERANCE_M {
                            return Some((j, i, d));
                        }
                    }
                }
            }
        }
        cells.entry((c.x, c.y, c.z)).or_default().push(i);
    }
    None
}

/// Why a target's pose can be ambiguous from a view of its points ([`Target::ambiguity`]), and what it costs.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetAmbiguity {
    /// Three points: up to four poses put them on the same three image points, in every view.
    ThreePoints,
    /// Rigid motions that take the target onto itself (points onto points of the same diameter), besides the
    /// identity: from unlabelled blobs the labelling, and so the pose, is known only up to these.
    Symmetric {
        /// The motions other than the identity that take the target onto itself.
        motions: Vec<Symmetry>,
    },
}

impl std::fmt::Display for TargetAmbiguity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::ThreePoints => write!(
                f,
                "a target of 3 points: up to four poses project them onto the same image points in every view, and \
                 any three blobs are its image in some pose; roitrack gives every pose that fits a view but starts \
                 no track and identifies no blobs from it (a fourth point makes the pose unique in almost every \
                 view)"
            ),
            Self::Symmetric { motions } => write!(
                f,
                "a symmetric target: {} rigid motion{} other than the identity take{} it onto itself, so from \
                 unlabelled blobs its pose is known only up to {} twins; detection returns one canonical labelling \
                 flagged ambiguous and a track keeps the labelling it started with (measurements with ids are \
                 not affected; a point of another size or off the pattern breaks the symmetry)",
                motions.len(),
                if motions.len() == 1 { "" } else { "s" },
                if motions.len() == 1 { "s" } else { "" },
                motions.len() + 1,
            ),
        }
    }
}

/// A rigid motion `x -> obj_r * x + obj_t_m` of the object frame that takes the target's points onto its points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Symmetry {
    /// The motion's rotation, in the object frame.
    pub obj_r: nalgebra::Rotation3<f64>,
    /// The motion's translation (m), in the object frame.
    pub obj_t_m: Vector3<f64>,
}

impl Target {
    /// Validates `points` into a target, refusing fewer than [`MIN_TARGET_POINTS`], duplicate ids, non-finite
    /// coordinates or diameters, non-positive diameters, two points within a micrometre of each other and points all
    /// on one line (within a micrometre). A planar target's plane ([`Self::plane`]) is computed here, once.
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
        if let Some((first, second, distance_m)) = coincident_pair(&points) {
            return Err(TargetError::Coincident {
                first_id: points[first].id,
                second_id: points[second].id,
                distance_m,
            });
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
            target.plane = Some(TargetPlane::of_points(
                &target.points,
                centre_m,
                obj_r_plane,
            ));
        }
        Ok(target)
    }

    /// The bundled target "grid4x4" (docs/model.md): a planar 4 x 4 grid of pitch 20 mm centred on the origin,
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

    /// A planar grid of equal circles in the plane z = 0, every point with the grid's diameter (so no key blob).
    ///
    /// Id 0 is the first circle of row 0 (at the origin, but for a hexagonal grid whose row 0 starts at column 1); the
    /// ids then run row by row (row 0 first), and within a row by increasing column, over the positions that hold a
    /// circle. With `S` the spacing:
    ///
    /// - [`GridLayout::Square`]: every position; circle `id = row * cols + col` at `(col S, row S, 0)`.
    /// - [`GridLayout::Hexagonal`]: the positions where `row + col` has the parity of `rows - 1` (the last row holds
    ///   columns 0, 2, 4, ..., the one before it columns 1, 3, 5, ...), at `(col S / 2, row S sin 60°, 0)`;
    ///   neighbouring centres are `S` apart. With an even number of rows, row 0 starts at column 1.
    ///
    /// Refuses (as [`TargetError::CircleGrid`]) no rows or columns, a spacing or diameter that is not a finite
    /// positive length, a diameter not smaller than the spacing and more than [`MAX_GRID_POINTS`] circles; and, as
    /// [`Target::new`] does, fewer than [`MIN_TARGET_POINTS`] circles and circles all on one line (a single row, say).
    ///
    /// ```
    /// use roitrack_core::Target;
    /// use roitrack_core::target::{CircleGrid, GridLayout};
    ///
    /// // 24 rows x 28 columns, hexagonal: 14 circles a row, 336 in all, 12 mm between neighbours.
    /// let spec = CircleGrid { rows: 24, cols: 28, spacing_m: 0.012, diameter_m: 0.006, layout: GridLayout::Hexagonal };
    /// let target = Target::circle_grid(&spec)?;
    /// assert_eq!(target.len(), 336);
    /// let p = |id| target.points()[target.index_of(id).unwrap()].point_in_obj_m;
    /// assert_eq!(p(0).as_slice(), &[0.006, 0.0, 0.0]); // row 0 starts at column 1
    /// assert_eq!(p(14).as_slice(), &[0.0, 0.012 * 60f64.to_radians().sin(), 0.0]); // row 1 at column 0
    /// // The last circle: row 23, column 26, at (26 S / 2, 23 S sin 60°) = (0.156, 0.2390) m.
    /// assert!((p(335).x - 0.156).abs() < 1e-12 && (p(335).y - 0.2390).abs() < 1e-4);
    /// # Ok::<(), roitrack_core::TargetError>(())
    /// ```
    pub fn circle_grid(spec: &CircleGrid) -> Result<Self, TargetError> {
        spec.validate().map_err(TargetError::CircleGrid)?;
        let s = spec.spacing_m;
        let row_pitch = match spec.layout {
            GridLayout::Square => s,
            GridLayout::Hexagonal => s * 60f64.to_radians().sin(),
        };
        let mut points = Vec::with_capacity(spec.count() as usize);
        for row in 0..spec.rows {
            for col in 0..spec.cols {
                let x = match spec.layout {
                    GridLayout::Square => f64::from(col) * s,
                    GridLayout::Hexagonal if (row + col) % 2 == (spec.rows - 1) % 2 => {
                        f64::from(col) * s / 2.0
                    }
                    GridLayout::Hexagonal => continue,
                };
                points.push(TargetPoint {
                    // At most MAX_GRID_POINTS points: the id fits.
                    id: points.len() as u32,
                    point_in_obj_m: Vector3::new(x, f64::from(row) * row_pitch, 0.0),
                    diameter_m: Some(spec.diameter_m),
                });
            }
        }
        Self::new(points)
    }

    /// The model points, in the order given to [`Self::new`].
    pub fn points(&self) -> &[TargetPoint] {
        &self.points
    }

    /// The number of model points (at least [`MIN_TARGET_POINTS`]).
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the target has no points: never, for a validated target (kept beside [`Self::len`] by convention).
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
        let points: Vec<Vector3<f64>> = self.points.iter().map(|p| p.point_in_obj_m).collect();
        principal_frame_of(&points).expect("a target has points")
    }
}

/// Centroid and principal axes of points (columns, largest spread first, the third their cross product); `None` for
/// no points.
fn principal_frame_of(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    if points.is_empty() {
        return None;
    }
    let centre = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let scatter = points.iter().fold(Matrix3::zeros(), |s, p| {
        s + (p - centre) * (p - centre).transpose()
    });
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let e1 = eig.eigenvectors.column(order[0]).into_owned();
    let e2 = eig.eigenvectors.column(order[1]).into_owned();
    Some((centre, Matrix3::from_columns(&[e1, e2, e1.cross(&e2)])))
}

impl Target {
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

    /// The plane most points lie on, for a target that is planar or nearly so (pins standing off a plate, a drawing's
    /// flat layout made with some depth): the points' principal plane, fitted again without the points farther from
    /// it than twice the median distance (a post standing off a plate must not tilt it), with every point projected
    /// into it. For an exactly planar target it is [`Self::plane`]. Its normal is the third column of
    /// `obj_r_plane`; how far each point lies off it is `(point - centre) · normal`.
    ///
    /// ```
    /// use nalgebra::Vector3;
    /// use roitrack_core::{Target, TargetPoint};
    ///
    /// // A 3 x 4 grid of 25 mm pitch with one point on a 10 mm post.
    /// let points: Vec<TargetPoint> = (0..12u32)
    ///     .map(|id| TargetPoint {
    ///         id,
    ///         point_in_obj_m: Vector3::new(0.025 * f64::from(id % 4), 0.025 * f64::from(id / 4), if id == 6 { 0.01 } else { 0.0 }),
    ///         diameter_m: None,
    ///     })
    ///     .collect();
    /// let target = Target::new(points)?;
    /// let plane = target.best_plane();
    /// // The plate's plane, not one tilted towards the post: every in-plane position is the drawing's.
    /// let normal = plane.obj_r_plane.column(2);
    /// assert!(normal.z.abs() > 1.0 - 1e-12);
    /// # Ok::<(), roitrack_core::TargetError>(())
    /// ```
    pub fn best_plane(&self) -> TargetPlane {
        if let Some(plane) = &self.plane {
            return plane.clone();
        }
        let (centre, frame) = self.principal_frame();
        let normal: Vector3<f64> = frame.column(2).into_owned();
        let distances: Vec<f64> = self
            .points
            .iter()
            .map(|p| (p.point_in_obj_m - centre).dot(&normal).abs())
            .collect();
        let mut sorted = distances.clone();
        sorted.sort_by(f64::total_cmp);
        let limit = 2.0 * sorted[sorted.len() / 2];
        let inliers: Vec<Vector3<f64>> = self
            .points
            .iter()
            .zip(&distances)
            .filter(|(_, d)| **d <= limit)
            .map(|(p, _)| p.point_in_obj_m)
            .collect();
        let (centre_m, obj_r_plane) = if inliers.len() >= 3 && inliers.len() < self.points.len() {
            principal_frame_of(&inliers).unwrap_or((centre, frame))
        } else {
            (centre, frame)
        };
        TargetPlane::of_points(&self.points, centre_m, obj_r_plane)
    }

    /// Whether all points lie on one plane (to 1e-6 m).
    pub fn is_planar(&self) -> bool {
        self.principal_spreads_m()[2] < COLLINEAR_TOLERANCE_M
    }

    /// Why the pose of this target can be ambiguous, if it can: 3 points, or a symmetric layout ([`Self::symmetries`];
    /// for a planar target, those that keep its front facing the same way).
    ///
    /// ```
    /// use roitrack_core::Target;
    /// use roitrack_core::target::{CircleGrid, GridLayout, TargetAmbiguity};
    ///
    /// // grid4x4's larger key blob breaks the square's symmetry.
    /// assert_eq!(Target::grid4x4().ambiguity(), None);
    /// // A plain square grid looks the same after each quarter turn.
    /// let spec = CircleGrid { rows: 4, cols: 4, spacing_m: 0.02, diameter_m: 0.006, layout: GridLayout::Square };
    /// match Target::circle_grid(&spec)?.ambiguity() {
    ///     Some(TargetAmbiguity::Symmetric { motions }) => assert_eq!(motions.len(), 3),
    ///     other => panic!("{other:?}"),
    /// }
    /// # Ok::<(), roitrack_core::TargetError>(())
    /// ```
    pub fn ambiguity(&self) -> Option<TargetAmbiguity> {
        if self.points.len() == 3 {
            return Some(TargetAmbiguity::ThreePoints);
        }
        let mut motions = self.symmetries(SYMMETRY_TOLERANCE);
        // A planar target's half turns about an axis in its plane show its back, which identification ranks below its
        // front (a printed side faces the camera): not an ambiguity.
        if let Some(plane) = &self.plane {
            let normal: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
            motions.retain(|m| (m.obj_r * normal).dot(&normal) > 0.0);
        }
        (!motions.is_empty()).then_some(TargetAmbiguity::Symmetric { motions })
    }

    /// The rigid motions other than the identity that take every point within `relative_tolerance` of the target's
    /// size onto a point of the same diameter (to a thousandth). A symmetry keeps the centroid and each point's
    /// distance from it, so the motions are found from two points (the farthest from the centroid and the one least
    /// in line with it) and every pair of points that could be their images, each motion then checked on all points.
    pub fn symmetries(&self, relative_tolerance: f64) -> Vec<Symmetry> {
        let (centre, _) = self.centroid_and_scatter();
        let size = self.principal_spreads_m()[0];
        let tolerance = relative_tolerance * size;
        let offsets: Vec<Vector3<f64>> = self
            .points
            .iter()
            .map(|p| p.point_in_obj_m - centre)
            .collect();
        let same_diameter =
            |i: usize, j: usize| match (self.points[i].diameter_m, self.points[j].diameter_m) {
                (Some(a), Some(b)) => (a - b).abs() <= 1e-3 * a.max(b),
                (None, None) => true,
                _ => false,
            };
        let Some(a) =
            (0..offsets.len()).max_by(|&i, &j| offsets[i].norm().total_cmp(&offsets[j].norm()))
        else {
            return Vec::new();
        };
        let Some(b) = (0..offsets.len()).max_by(|&i, &j| {
            offsets[i]
                .cross(&offsets[a])
                .norm()
                .total_cmp(&offsets[j].cross(&offsets[a]).norm())
        }) else {
            return Vec::new();
        };
        let frame = |u: &Vector3<f64>, v: &Vector3<f64>| -> Option<Matrix3<f64>> {
            let e1 = u.try_normalize(0.0)?;
            let e2 = (v - e1 * e1.dot(v)).try_normalize(0.0)?;
            Some(Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]))
        };
        let Some(from) = frame(&offsets[a], &offsets[b]) else {
            return Vec::new();
        };
        let lookup = PointLookup::new(&offsets, tolerance.max(COLLINEAR_TOLERANCE_M));
        let mut motions: Vec<Symmetry> = Vec::new();
        for a2 in 0..offsets.len() {
            if (offsets[a2].norm() - offsets[a].norm()).abs() > tolerance || !same_diameter(a, a2) {
                continue;
            }
            for b2 in 0..offsets.len() {
                if b2 == a2
                    || (offsets[b2].norm() - offsets[b].norm()).abs() > tolerance
                    || ((offsets[b2] - offsets[a2]).norm() - (offsets[b] - offsets[a]).norm()).abs()
                        > tolerance
                    || !same_diameter(b, b2)
                {
                    continue;
                }
                let Some(to) = frame(&offsets[a2], &offsets[b2]) else {
                    continue;
                };
                let r = nalgebra::Rotation3::from_matrix_unchecked(to * from.transpose());
                // The identity (nalgebra's angle loses half the digits near zero: compare the matrix).
                if (r.matrix() - Matrix3::identity()).amax() < 1e-9 {
                    continue;
                }
                let maps = (0..offsets.len()).all(|i| {
                    lookup
                        .near(&(r * offsets[i]))
                        .is_some_and(|j| same_diameter(i, j))
                });
                if maps
                    && motions
                        .iter()
                        .all(|m| (m.obj_r.matrix() - r.matrix()).amax() > 1e-6)
                {
                    motions.push(Symmetry {
                        obj_r: r,
                        obj_t_m: centre - r * centre,
                    });
                }
            }
        }
        motions
    }
}

/// How far (a fraction of the target's size) a moved point may be from a point for [`Target::ambiguity`] to count the
/// motion as a symmetry: a target drawn to spec and made to a few tenths of a millimetre in 100 mm is as symmetric
/// for identification as its drawing.
pub const SYMMETRY_TOLERANCE: f64 = 0.005;

/// The point nearest a position, within a tolerance, by a hash grid of that pitch.
struct PointLookup<'a> {
    points: &'a [Vector3<f64>],
    pitch: f64,
    cells: HashMap<(i64, i64, i64), Vec<usize>>,
}

impl<'a> PointLookup<'a> {
    fn new(points: &'a [Vector3<f64>], pitch: f64) -> Self {
        let mut cells: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            cells.entry(Self::cell_of(p, pitch)).or_default().push(i);
        }
        Self {
            points,
            pitch,
            cells,
        }
    }

    fn cell_of(p: &Vector3<f64>, pitch: f64) -> (i64, i64, i64) {
        let c = p.map(|x| (x / pitch).floor() as i64);
        (c.x, c.y, c.z)
    }

    fn near(&self, p: &Vector3<f64>) -> Option<usize> {
        let (x, y, z) = Self::cell_of(p, self.pitch);
        let mut best: Option<(usize, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for &i in self
                        .cells
                        .get(&(x + dx, y + dy, z + dz))
                        .into_iter()
                        .flatten()
                    {
                        let d = (self.points[i] - p).norm();
                        if d <= self.pitch && best.is_none_or(|(_, b)| d < b) {
                            best = Some((i, d));
                        }
                    }
                }
            }
        }
        best.map(|(i, _)| i)
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

    fn grid(rows: u32, cols: u32, layout: GridLayout) -> CircleGrid {
        CircleGrid {
            rows,
            cols,
            spacing_m: 0.012,
            diameter_m: 0.006,
            layout,
        }
    }

    fn position(t: &Target, id: u32) -> Vector3<f64> {
        t.points()[t.index_of(id).unwrap()].point_in_obj_m
    }

    #[test]
    fn hexagonal_grid_of_336_circles() {
        let t = Target::circle_grid(&grid(24, 28, GridLayout::Hexagonal)).unwrap();
        assert_eq!(t.len(), 336);
        assert!(t.is_planar());
        assert!(t.key_point().is_none());
        // Ids in order, row by row.
        let ids: Vec<u32> = t.points().iter().map(|p| p.id).collect();
        assert_eq!(ids, (0..336).collect::<Vec<_>>());
        let h = 0.012 * 3f64.sqrt() / 2.0;
        // Row 0: columns 1, 3, ..., 27 are ids 0-13 (the last row, 23, starts at column 0).
        for k in 0..14u32 {
            let expected = Vector3::new(f64::from(2 * k + 1) * 0.006, 0.0, 0.0);
            assert!((position(&t, k) - expected).norm() < 1e-15, "id {k}");
        }
        // Row 1: columns 0, 2, ..., 26 are ids 14-27.
        for k in 0..14u32 {
            let expected = Vector3::new(f64::from(2 * k) * 0.006, h, 0.0);
            assert!(
                (position(&t, 14 + k) - expected).norm() < 1e-15,
                "id {}",
                14 + k
            );
        }
        let last = position(&t, 335);
        assert!((last - Vector3::new(0.156, 23.0 * h, 0.0)).norm() < 1e-15);
        assert!((last.y - 0.2390).abs() < 1e-4);
        assert!(
            t.points()
                .iter()
                .all(|p| p.diameter_m == Some(0.006) && p.point_in_obj_m.z == 0.0)
        );
    }

    /// The printed board's front: BoofCV lays its hexagonal grid out with y up and row 0 at the bottom, row r holding
    /// the columns of r's parity, centred on the origin, so its front is seen from +z. Seen from the front both are
    /// the same picture: ours (x right, y down) must be BoofCV's (x right, y up) up to a shift, not its mirror.
    #[test]
    fn hexagonal_grid_is_the_printed_board_seen_from_its_front() {
        for (rows, cols) in [(24, 28), (5, 6), (6, 7), (8, 10)] {
            let spec = CircleGrid {
                rows,
                cols,
                spacing_m: 0.012,
                diameter_m: 0.01,
                layout: GridLayout::Hexagonal,
            };
            let ours = Target::circle_grid(&spec).unwrap();
            assert_eq!(ours.len() as u64, spec.count(), "{rows} x {cols}");
            let (space_x, space_y) = (0.006, 0.012 * 60f64.to_radians().sin());
            let (width, height) = (f64::from(cols - 1) * space_x, f64::from(rows - 1) * space_y);
            let mut boofcv_front_view = Vec::new();
            for row in 0..rows {
                for col in (row % 2..cols).step_by(2) {
                    let y_up = f64::from(row) * space_y - height / 2.0;
                    boofcv_front_view.push((f64::from(col) * space_x - width / 2.0, y_up));
                }
            }
            // Our front view: x right, y down; centred, with y turned up.
            let mut ours_front_view: Vec<(f64, f64)> = ours
                .points()
                .iter()
                .map(|p| {
                    (
                        p.point_in_obj_m.x - width / 2.0,
                        height / 2.0 - p.point_in_obj_m.y,
                    )
                })
                .collect();
            let key = |p: &(f64, f64)| ((p.1 * 1e6).round() as i64, (p.0 * 1e6).round() as i64);
            ours_front_view.sort_by_key(key);
            boofcv_front_view.sort_by_key(key);
            assert_eq!(ours_front_view.len(), boofcv_front_view.len());
            for (a, b) in ours_front_view.iter().zip(&boofcv_front_view) {
                assert!(
                    (a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12,
                    "{rows} x {cols}: {a:?} {b:?}"
                );
            }
        }
    }

    #[test]
    fn square_grid_6x6() {
        let t = Target::circle_grid(&grid(6, 6, GridLayout::Square)).unwrap();
        assert_eq!(t.len(), 36);
        for row in 0..6u32 {
            for col in 0..6u32 {
                let expected = Vector3::new(f64::from(col) * 0.012, f64::from(row) * 0.012, 0.0);
                assert!((position(&t, row * 6 + col) - expected).norm() < 1e-15);
            }
        }
        assert_eq!(position(&t, 0), Vector3::zeros());
    }

    /// Every circle's nearest neighbours are exactly one spacing away: 4 inside a square grid, 6 inside a hexagonal
    /// one, and none closer.
    #[test]
    fn neighbours_are_one_spacing_apart_in_both_layouts() {
        for (layout, inner_neighbours) in [(GridLayout::Square, 4), (GridLayout::Hexagonal, 6)] {
            let t = Target::circle_grid(&grid(7, 9, layout)).unwrap();
            let mut with_all = 0;
            for a in t.points() {
                let distances: Vec<f64> = t
                    .points()
                    .iter()
                    .filter(|b| b.id != a.id)
                    .map(|b| (b.point_in_obj_m - a.point_in_obj_m).norm())
                    .collect();
                let nearest = distances.iter().copied().fold(f64::INFINITY, f64::min);
                assert!((nearest - 0.012).abs() < 1e-12, "{layout:?} id {}", a.id);
                let neighbours = distances
                    .iter()
                    .filter(|&&d| (d - 0.012).abs() < 1e-12)
                    .count();
                assert!(neighbours <= inner_neighbours);
                with_all += usize::from(neighbours == inner_neighbours);
            }
            assert!(with_all > 0, "{layout:?}");
        }
        let t = Target::circle_grid(&grid(7, 9, GridLayout::Hexagonal)).unwrap();
        assert_eq!(t.len() as u64, grid(7, 9, GridLayout::Hexagonal).count());
        assert_eq!(t.len(), 4 * 5 + 3 * 4);
    }

    #[test]
    fn refuses_bad_grids() {
        let err = |spec: CircleGrid| Target::circle_grid(&spec).unwrap_err();
        assert_eq!(
            err(grid(0, 5, GridLayout::Square)),
            TargetError::CircleGrid(CircleGridError::NoRowsOrColumns { rows: 0, cols: 5 })
        );
        for (spacing_m, diameter_m, field) in [
            (0.0, 0.001, "spacing"),
            (f64::NAN, 0.001, "spacing"),
            (f64::INFINITY, 0.001, "spacing"),
            (0.01, -0.001, "diameter"),
            (0.01, 0.0, "diameter"),
        ] {
            let e = err(CircleGrid {
                spacing_m,
                diameter_m,
                ..grid(4, 4, GridLayout::Square)
            });
            assert!(
                matches!(e, TargetError::CircleGrid(CircleGridError::NotPositiveLength { field: f, .. }) if f == field),
                "{e}"
            );
        }
        let e = err(CircleGrid {
            diameter_m: 0.012,
            ..grid(4, 4, GridLayout::Square)
        });
        assert!(matches!(
            e,
            TargetError::CircleGrid(CircleGridError::Overlapping { .. })
        ));
        assert!(
            e.to_string().starts_with("circle grid: the diameter"),
            "{e}"
        );
        assert!(matches!(
            err(grid(100_000, 100_000, GridLayout::Square)),
            TargetError::CircleGrid(CircleGridError::TooManyPoints { .. })
        ));
        assert!(matches!(
            err(grid(u32::MAX, u32::MAX, GridLayout::Hexagonal)),
            TargetError::CircleGrid(CircleGridError::TooManyPoints { .. })
        ));
        // Fewer than 3 circles, and a single line of them.
        assert!(matches!(
            err(grid(1, 2, GridLayout::Square)),
            TargetError::TooFewPoints { actual: 2, .. }
        ));
        assert!(matches!(
            err(grid(2, 2, GridLayout::Hexagonal)),
            TargetError::TooFewPoints { actual: 2, .. }
        ));
        assert!(matches!(
            err(grid(1, 10, GridLayout::Square)),
            TargetError::Collinear { .. }
        ));
        assert!(matches!(
            err(grid(9, 1, GridLayout::Hexagonal)),
            TargetError::Collinear { .. }
        ));
        // The smallest grids that are targets.
        assert_eq!(
            Target::circle_grid(&grid(2, 2, GridLayout::Square))
                .unwrap()
                .len(),
            4
        );
        assert_eq!(
            Target::circle_grid(&grid(2, 3, GridLayout::Hexagonal))
                .unwrap()
                .len(),
            3
        );
    }

    #[test]
    fn refuses_bad_targets() {
        let three = vec![
            point(0, 0., 0., 0.),
            point(1, 1., 0., 0.),
            point(2, 0., 1., 0.),
        ];
        assert!(matches!(
            Target::new(three[..2].to_vec()),
            Err(TargetError::TooFewPoints { actual: 2, .. })
        ));
        assert_eq!(
            Target::new(three.clone()).unwrap().ambiguity(),
            Some(TargetAmbiguity::ThreePoints)
        );
        let mut twice = three.clone();
        twice.push(point(7, 1., 0., 4e-7));
        assert!(matches!(
            Target::new(twice),
            Err(TargetError::Coincident {
                first_id: 1,
                second_id: 7,
                ..
            })
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
        assert_eq!(t.ambiguity(), None);
    }

    #[test]
    fn symmetries_of_grids_and_bodies() {
        let count = |t: &Target| t.symmetries(SYMMETRY_TOLERANCE).len();
        // A square grid: 3 turns in its plane and 4 half turns about in-plane axes (its back).
        assert_eq!(
            count(&Target::circle_grid(&grid(4, 4, GridLayout::Square)).unwrap()),
            7
        );
        // A rectangle: a half turn in its plane and two about its axes.
        assert_eq!(
            count(&Target::circle_grid(&grid(3, 4, GridLayout::Square)).unwrap()),
            3
        );
        // The key blob of grid4x4 leaves only the flip about its diagonal through the key blob.
        assert_eq!(count(&Target::grid4x4()), 1);
        // A cube's corners: the 23 rotations of the cube.
        let cube: Vec<TargetPoint> = (0..8)
            .map(|i| {
                point(
                    i,
                    (i & 1) as f64 * 0.05,
                    ((i >> 1) & 1) as f64 * 0.05,
                    ((i >> 2) & 1) as f64 * 0.05,
                )
            })
            .collect();
        assert_eq!(count(&Target::new(cube.clone()).unwrap()), 23);
        // One corner raised: none (a body with no symmetry).
        let mut raised = cube;
        raised[5].point_in_obj_m.z += 0.01;
        let target = Target::new(raised).unwrap();
        assert_eq!(count(&target), 0);
        assert_eq!(target.ambiguity(), None);
        // Every symmetry found takes every point onto a point.
        let hex = Target::circle_grid(&grid(5, 6, GridLayout::Hexagonal)).unwrap();
        for m in hex.symmetries(SYMMETRY_TOLERANCE) {
            for p in hex.points() {
                let moved = m.obj_r * p.point_in_obj_m + m.obj_t_m;
                assert!(
                    hex.points()
                        .iter()
                        .any(|q| (q.point_in_obj_m - moved).norm() < 1e-9)
                );
            }
        }
        // 5 x 6 hexagonal: its half turn in the plane takes even positions to odd ones; only flips remain.
        assert_eq!(hex.ambiguity(), None);
        let odd = Target::circle_grid(&grid(5, 5, GridLayout::Hexagonal)).unwrap();
        assert!(
            matches!(odd.ambiguity(), Some(TargetAmbiguity::Symmetric { motions }) if motions.len() == 1)
        );
    }
}
