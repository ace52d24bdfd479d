//! The board in the target's plane (the paper and the shapes printed on it) and its coverage of each pixel: corners
//! classified on a grid of the plane, pixels crossed by an edge supersampled.

use nalgebra::{Matrix3, Vector2, Vector3};
use roitrack_core::Target;

use super::PhotoError;
use super::clutter::board_marks;
use super::rays::Area;
use super::scene::PhotoScene;

/// A pixel whose footprint spans more plane-grid cells than this is supersampled rather than classified.
const MAX_CLASSIFY_CELLS: usize = 16;

/// Target number of plane-grid cells over the board.
const GRID_CELLS: f64 = 4096.0;

/// A shape printed on the board, in plane coordinates (m).
#[derive(Debug, Clone, Copy)]
pub(super) enum PlaneShape {
    Disk {
        centre: Vector2<f64>,
        radius: f64,
        level: f64,
    },
    Rect {
        lo: Vector2<f64>,
        hi: Vector2<f64>,
        level: f64,
    },
}

impl PlaneShape {
    pub(super) fn level(&self) -> f64 {
        match *self {
            Self::Disk { level, .. } | Self::Rect { level, .. } => level,
        }
    }

    pub(super) fn bounds(&self) -> (Vector2<f64>, Vector2<f64>) {
        match *self {
            Self::Disk { centre, radius, .. } => {
                let r = Vector2::repeat(radius);
                (centre - r, centre + r)
            }
            Self::Rect { lo, hi, .. } => (lo, hi),
        }
    }

    #[inline]
    pub(super) fn contains(&self, p: Vector2<f64>) -> bool {
        match *self {
            Self::Disk { centre, radius, .. } => (p - centre).norm_squared() <= radius * radius,
            Self::Rect { lo, hi, .. } => p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y,
        }
    }

    /// Whether the shape meets the box `lo..hi`.
    fn meets_box(&self, lo: Vector2<f64>, hi: Vector2<f64>) -> bool {
        match *self {
            Self::Disk { centre, radius, .. } => {
                let nearest = Vector2::new(centre.x.clamp(lo.x, hi.x), centre.y.clamp(lo.y, hi.y));
                (nearest - centre).norm_squared() < radius * radius
            }
            Self::Rect { lo: a, hi: b, .. } => a.x < hi.x && b.x > lo.x && a.y < hi.y && b.y > lo.y,
        }
    }
}

/// A uniform grid over the board listing the shapes whose bounds meet each cell (compressed rows).
struct PlaneGrid {
    origin: Vector2<f64>,
    inv_cell_m: f64,
    pub(super) nx: usize,
    pub(super) ny: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl PlaneGrid {
    pub(super) fn new(lo: Vector2<f64>, hi: Vector2<f64>, shapes: &[PlaneShape]) -> Self {
        let size = hi - lo;
        let largest = shapes
            .iter()
            .map(|s| {
                let (a, b) = s.bounds();
                (b - a).max()
            })
            .fold(0.0, f64::max);
        let cell_m = largest.max((size.x * size.y / GRID_CELLS).sqrt()).max(1e-9);
        let nx = ((size.x / cell_m).ceil() as usize).max(1);
        let ny = ((size.y / cell_m).ceil() as usize).max(1);
        let mut grid = Self {
            origin: lo,
            inv_cell_m: 1.0 / cell_m,
            nx,
            ny,
            start: Vec::new(),
            items: Vec::new(),
        };
        let mut lists = vec![Vec::new(); nx * ny];
        for (k, shape) in shapes.iter().enumerate() {
            let (a, b) = shape.bounds();
            let (x0, x1, y0, y1) = grid.cells(a, b);
            for y in y0..=y1 {
                for list in &mut lists[y * nx + x0..=y * nx + x1] {
                    list.push(k as u32);
                }
            }
        }
        grid.start.push(0);
        for list in lists {
            grid.items.extend(list);
            grid.start.push(grid.items.len() as u32);
        }
        grid
    }

    /// Inclusive cell ranges (x0, x1, y0, y1) meeting the box `lo..hi`, clamped to the grid.
    #[inline]
    fn cells(&self, lo: Vector2<f64>, hi: Vector2<f64>) -> (usize, usize, usize, usize) {
        // Truncation is the floor for x >= 0 (and NaN gives 0): no call to floor.
        let index = |x: f64, n: usize| ((x * self.inv_cell_m).max(0.0) as usize).min(n - 1);
        (
            index(lo.x - self.origin.x, self.nx),
            index(hi.x - self.origin.x, self.nx),
            index(lo.y - self.origin.y, self.ny),
            index(hi.y - self.origin.y, self.ny),
        )
    }

    #[inline]
    fn cell(&self, x: usize, y: usize) -> &[u32] {
        let c = y * self.nx + x;
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }
}

/// How much of a pixel the board covers, from its corners.
enum Coverage {
    Background,
    Board(f64),
    Mixed,
}

/// The board's frame (object frame) of a planar target: origin at the points' centroid, in-plane axes `e1` (the object
/// x axis projected on the plane, or y if x is normal to it) and `e2`, with `e1 x e2` the plane's normal on the side
/// of +z (then +y, +x; +z for a target in its z = 0 plane). `None` if the target is not planar.
pub(super) fn board_frame(target: &Target) -> Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> {
    let plane = target.plane()?;
    let mut normal = plane.obj_r_plane.column(2).into_owned();
    let side = [normal.z, normal.y, normal.x]
        .into_iter()
        .find(|c| c.abs() > 1e-9)
        .unwrap_or(1.0);
    if side < 0.0 {
        normal = -normal;
    }
    let along = |axis: Vector3<f64>| axis - axis.dot(&normal) * normal;
    let x = along(Vector3::x());
    let e1 = if x.norm() > 0.5 {
        x.normalize()
    } else {
        along(Vector3::y()).normalize()
    };
    Some((plane.centre_m, e1, normal.cross(&e1)))
}

/// The board in its plane: the frame, the paper rectangle, the printed shapes (circles first, then marks).
pub(super) struct Board {
    /// In-plane axes, object frame.
    pub(super) e1_obj: Vector3<f64>,
    pub(super) e2_obj: Vector3<f64>,
    /// Ray (x, y, 1) to homogeneous plane point; `None` when the camera sees the plane edge-on.
    h_inv: Option<Matrix3<f64>>,
    lo: Vector2<f64>,
    hi: Vector2<f64>,
    pub(super) paper_level: f64,
    shapes: Vec<PlaneShape>,
    grid: PlaneGrid,
}

impl Board {
    pub(super) fn new(scene: &PhotoScene) -> Result<Self, PhotoError> {
        let (origin_obj, e1_obj, e2_obj) =
            board_frame(&scene.target).ok_or(PhotoError::NotPlanar)?;
        let mut shapes = Vec::with_capacity(scene.target.len() + scene.clutter.board_marks);
        let (mut lo, mut hi) = (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN));
        for p in scene.target.points() {
            let d = p.point_in_obj_m - origin_obj;
            let centre = Vector2::new(d.dot(&e1_obj), d.dot(&e2_obj));
            let radius = scene.circle_diameter_m(p) / 2.0;
            lo = lo.inf(&(centre - Vector2::repeat(radius)));
            hi = hi.sup(&(centre + Vector2::repeat(radius)));
            shapes.push(PlaneShape::Disk {
                centre,
                radius,
                level: scene.circle_level,
            });
        }
        let margin = Vector2::repeat(scene.paper_margin_m);
        let (board_lo, board_hi) = (lo - margin, hi + margin);
        board_marks(scene, (lo, hi), (board_lo, board_hi), &mut shapes);

        let r = scene.cam_r_obj;
        let origin_cam = r * origin_obj + scene.cam_t_obj_m;
        let (e1, e2) = (r * e1_obj, r * e2_obj);
        let corners = [
            (board_lo.x, board_lo.y),
            (board_hi.x, board_lo.y),
            (board_lo.x, board_hi.y),
            (board_hi.x, board_hi.y),
        ];
        if corners
            .iter()
            .all(|&(a, b)| (origin_cam + a * e1 + b * e2).z <= 0.0)
        {
            return Err(PhotoError::BoardBehindCamera);
        }
        // Edge-on (the plane through the camera centre): the board is a line, invisible.
        let edge_on = e1.cross(&e2).dot(&origin_cam).abs() < 1e-12;
        let h_inv = if edge_on {
            None
        } else {
            Matrix3::from_columns(&[e1, e2, origin_cam]).try_inverse()
        };
        let grid = PlaneGrid::new(board_lo, board_hi, &shapes);
        Ok(Self {
            e1_obj,
            e2_obj,
            h_inv,
            lo: board_lo,
            hi: board_hi,
            paper_level: scene.paper_level,
            shapes,
            grid,
        })
    }

    /// Level at the in-plane point `p` of the board: the last shape containing it, or the paper.
    #[inline]
    fn level_at(&self, p: Vector2<f64>) -> f64 {
        let (x, _, y, _) = self.grid.cells(p, p);
        let mut level = self.paper_level;
        for &k in self.grid.cell(x, y) {
            let shape = &self.shapes[k as usize];
            if shape.contains(p) {
                level = shape.level();
            }
        }
        level
    }

    #[inline]
    fn on_board(&self, p: Vector2<f64>) -> bool {
        p.x >= self.lo.x && p.x <= self.hi.x && p.y >= self.lo.y && p.y <= self.hi.y
    }

    /// Classifies a pixel by its corners' plane points (its samples lie in their convex hull).
    fn classify(&self, corners: &[Vector2<f64>; 4]) -> Coverage {
        let lo = corners[1..].iter().fold(corners[0], |a, b| a.inf(b));
        let hi = corners[1..].iter().fold(corners[0], |a, b| a.sup(b));
        if hi.x < self.lo.x || lo.x > self.hi.x || hi.y < self.lo.y || lo.y > self.hi.y {
            return Coverage::Background;
        }
        if !(self.on_board(lo) && self.on_board(hi)) {
            return Coverage::Mixed;
        }
        let (x0, x1, y0, y1) = self.grid.cells(lo, hi);
        if (x1.saturating_sub(x0) + 1) * (y1.saturating_sub(y0) + 1) > MAX_CLASSIFY_CELLS {
            return Coverage::Mixed;
        }
        let mut inside: Option<u32> = None;
        for y in y0..=y1 {
            for x in x0..=x1 {
                for &k in self.grid.cell(x, y) {
                    let shape = &self.shapes[k as usize];
                    if corners.iter().all(|&c| shape.contains(c)) {
                        inside = inside.max(Some(k));
                    } else if shape.meets_box(lo, hi) {
                        return Coverage::Mixed;
                    }
                }
            }
        }
        Coverage::Board(inside.map_or(self.paper_level, |k| self.shapes[k as usize].level()))
    }

    /// Board level (summed over the board's share of each pixel) and background share of every pixel of the area.
    pub(super) fn rasterise(
        &self,
        rays: &[[f64; 2]],
        area: &Area,
        supersampling: usize,
        board_level: &mut [f64],
        background_fraction: &mut [f64],
    ) {
        let Some(h_inv) = self.h_inv else {
            return;
        };
        let plane: Vec<[f64; 3]> = rays
            .iter()
            .map(|r| {
                let q = h_inv * Vector3::new(r[0], r[1], 1.0);
                [q.x, q.y, q.z]
            })
            .collect();
        // Dehomogenised, where in front of the camera.
        let points: Vec<Vector2<f64>> = plane
            .iter()
            .map(|q| Vector2::new(q[0] / q[2], q[1] / q[2]))
            .collect();
        let cw = area.width + 1;
        for j in 0..area.height {
            for i in 0..area.width {
                let c = [
                    j * cw + i,
                    j * cw + i + 1,
                    (j + 1) * cw + i,
                    (j + 1) * cw + i + 1,
                ];
                let in_front = c.iter().filter(|&&c| plane[c][2] > 0.0).count();
                if in_front == 0 {
                    continue;
                }
                let coverage = if in_front == 4 {
                    self.classify(&c.map(|c| points[c]))
                } else {
                    Coverage::Mixed
                };
                let k = j * area.width + i;
                match coverage {
                    Coverage::Background => {}
                    Coverage::Board(level) => {
                        board_level[k] = level;
                        background_fraction[k] = 0.0;
                    }
                    Coverage::Mixed => {
                        let (level, background) =
                            self.supersample(&c.map(|c| plane[c]), supersampling);
                        board_level[k] = level;
                        background_fraction[k] = background;
                    }
                }
            }
        }
    }

    /// Samples a pixel on an `s` x `s` grid: (summed board level, background share) per sample. `q`: the corners'
    /// homogeneous plane points (top-left, top-right, bottom-left, bottom-right); a sample's is their bilinear
    /// interpolation (the ray's, mapped linearly).
    fn supersample(&self, q: &[[f64; 3]; 4], s: usize) -> (f64, f64) {
        let lerp = |a: &[f64; 3], b: &[f64; 3], t: f64| {
            [
                a[0] + (b[0] - a[0]) * t,
                a[1] + (b[1] - a[1]) * t,
                a[2] + (b[2] - a[2]) * t,
            ]
        };
        let (mut level, mut background) = (0.0, 0usize);
        let step = 1.0 / s as f64;
        for sy in 0..s {
            let ty = (sy as f64 + 0.5) * step;
            let left = lerp(&q[0], &q[2], ty);
            let right = lerp(&q[1], &q[3], ty);
            for sx in 0..s {
                let p = lerp(&left, &right, (sx as f64 + 0.5) * step);
                if p[2] <= 0.0 {
                    background += 1;
                    continue;
                }
                let p = Vector2::new(p[0] / p[2], p[1] / p[2]);
                if self.on_board(p) {
                    level += self.level_at(p);
                } else {
                    background += 1;
                }
            }
        }
        let n = (s * s) as f64;
        (level / n, background as f64 / n)
    }
}
