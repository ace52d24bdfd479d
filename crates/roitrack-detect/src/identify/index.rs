//! A uniform grid over points in the image, for nearest-neighbour queries among a few hundred blobs.

use nalgebra::Vector2;

/// Points bucketed by square cells.
#[derive(Debug, Clone)]
pub(crate) struct PointIndex {
    origin: Vector2<f64>,
    cell: f64,
    cols: usize,
    rows: usize,
    /// `cols` and `rows` as floats, the bounds of a query's cells (converted once, not at every query).
    cols_f: f64,
    rows_f: f64,
    /// Start of each cell's entries in `entries` (`cols * rows + 1` offsets).
    starts: Vec<u32>,
    entries: Vec<u32>,
    points: Vec<Vector2<f64>>,
}

impl PointIndex {
    /// Indexes `points` with cells of `cell` (chosen near the typical spacing).
    pub fn new(points: &[Vector2<f64>], cell: f64) -> Self {
        let finite = points.iter().filter(|p| p.x.is_finite() && p.y.is_finite());
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for p in finite {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if !lo.x.is_finite() {
            lo = Vector2::zeros();
            hi = Vector2::zeros();
        }
        let cell = cell.max(1e-9);
        let cols = (((hi.x - lo.x) / cell) as usize + 1).min(4096);
        let rows = (((hi.y - lo.y) / cell) as usize + 1).min(4096);
        let cell = cell
            .max((hi.x - lo.x) / cols as f64)
            .max((hi.y - lo.y) / rows as f64);
        let mut index = Self {
            origin: lo,
            cell,
            cols,
            rows,
            cols_f: cols as f64,
            rows_f: rows as f64,
            starts: vec![0; cols * rows + 1],
            entries: Vec::with_capacity(points.len()),
            points: points.to_vec(),
        };
        let cells: Vec<Option<usize>> = points.iter().map(|p| index.cell_of(p)).collect();
        for c in cells.iter().flatten() {
            index.starts[c + 1] += 1;
        }
        for k in 1..index.starts.len() {
            index.starts[k] += index.starts[k - 1];
        }
        let mut fill = index.starts.clone();
        index.entries.resize(index.starts[cols * rows] as usize, 0);
        for (i, c) in cells.iter().enumerate() {
            if let Some(c) = c {
                index.entries[fill[*c] as usize] = i as u32;
                fill[*c] += 1;
            }
        }
        index
    }

    fn cell_of(&self, p: &Vector2<f64>) -> Option<usize> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        }
        let i = (p.x - self.origin.x) / self.cell;
        let j = (p.y - self.origin.y) / self.cell;
        // Truncation is the floor of a non-negative value.
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.cols && (j as usize) < self.rows)
            .then(|| j as usize * self.cols + i as usize)
    }

    /// The cells (columns and rows, as half-open ranges) that a disk of `radius` around `p` touches; `None` if it
    /// misses the indexed area or is not finite.
    #[inline]
    fn cells_around(
        &self,
        p: &Vector2<f64>,
        radius: f64,
    ) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
        if !(p.x.is_finite() && p.y.is_finite() && radius.is_finite()) {
            return None;
        }
        let (hi_i, hi_j) = (
            (p.x + radius - self.origin.x) / self.cell,
            (p.y + radius - self.origin.y) / self.cell,
        );
        if hi_i < 0.0 || hi_j < 0.0 {
            return None;
        }
        // Each end clamped to the grid, then truncated (the floor of a non-negative value): the cells the
        // saturating conversions to `usize` gave (a low end beyond the grid still refuses the disk), at a few
        // instructions where each of those took a dozen, for a query made tens of thousands of times a search.
        // The values are not NaN: the operands are finite and `cell` positive (an overflow is an infinity, which
        // the clamp bounds).
        let floor = |v: f64, top: f64| -> usize {
            let v = v.clamp(0.0, top);
            // SAFETY: `v` is in [0, 4096] (the grid has at most 4096 columns and rows), not NaN: it fits a `u32`.
            unsafe { v.to_int_unchecked::<u32>() as usize }
        };
        let lo_i = floor((p.x - radius - self.origin.x) / self.cell, self.cols_f);
        let lo_j = floor((p.y - radius - self.origin.y) / self.cell, self.rows_f);
        let hi_i = floor(hi_i, self.cols_f - 1.0);
        let hi_j = floor(hi_j, self.rows_f - 1.0);
        (lo_i <= hi_i && lo_j <= hi_j).then_some((lo_i..hi_i + 1, lo_j..hi_j + 1))
    }

    /// Calls `f(index, distance)` for every point within `radius` of `p`.
    pub fn within(&self, p: &Vector2<f64>, radius: f64, mut f: impl FnMut(usize, f64)) {
        let Some((cols, rows)) = self.cells_around(p, radius) else {
            return;
        };
        for j in rows {
            // The entries of a row's cells are contiguous, in the order of the cells.
            let row = j * self.cols;
            let entries = &self.entries
                [self.starts[row + cols.start] as usize..self.starts[row + cols.end] as usize];
            for &e in entries {
                let d = (self.points[e as usize] - p).norm();
                if d <= radius {
                    f(e as usize, d);
                }
            }
        }
    }

    /// Whether any point lies within `radius` of `p`.
    pub fn any_within(&self, p: &Vector2<f64>, radius: f64) -> bool {
        let Some((cols, rows)) = self.cells_around(p, radius) else {
            return false;
        };
        let radius2 = radius * radius;
        for j in rows {
            let row = j * self.cols;
            let entries = &self.entries
                [self.starts[row + cols.start] as usize..self.starts[row + cols.end] as usize];
            if entries
                .iter()
                .any(|&e| (self.points[e as usize] - p).norm_squared() <= radius2)
            {
                return true;
            }
        }
        false
    }

    /// The nearest point within `radius` of `p` that `accept` allows.
    pub fn nearest(
        &self,
        p: &Vector2<f64>,
        radius: f64,
        mut accept: impl FnMut(usize) -> bool,
    ) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        self.within(p, radius, |i, d| {
            if best.is_none_or(|(_, bd)| d < bd) && accept(i) {
                best = Some((i, d));
            }
        });
        best
    }

    /// Up to `k` nearest points to point `i` (itself excluded) within `radius`, nearest first.
    pub fn neighbours(&self, i: usize, k: usize, radius: f64) -> Vec<(usize, f64)> {
        let mut found = Vec::new();
        self.neighbours_into(i, k, radius, &mut found);
        found
    }

    /// The first `take` of [`Self::neighbours`] `(i, k, radius)` whose area is within a factor `ratio` of point `i`'s
    /// (strictly; `areas_px` by point): the blobs that may be circles of the same target as `i`'s seen from about as
    /// far, nearest first.
    pub fn similar_neighbours(
        &self,
        i: usize,
        k: usize,
        radius: f64,
        areas_px: &[f64],
        ratio: f64,
        take: usize,
    ) -> Vec<usize> {
        self.neighbours(i, k, radius)
            .into_iter()
            .map(|(b, _)| b)
            .filter(|&b| areas_px[b] < ratio * areas_px[i] && areas_px[b] > areas_px[i] / ratio)
            .take(take)
            .collect()
    }

    /// [`Self::neighbours`] into `found` (cleared first), for a caller that asks for many.
    pub fn neighbours_into(&self, i: usize, k: usize, radius: f64, found: &mut Vec<(usize, f64)>) {
        // Search a growing disk, not the whole `radius` (often "everything"): once it holds k others, the k nearest
        // of all are in it, and in the same order (the cells are visited in the same row-major order, and the k
        // nearest are kept as a stable sort would order them: a point goes after those as near), so this is the
        // full search's answer at the cost of a few cells.
        found.clear();
        if k == 0 {
            return;
        }
        // The first disk holds about twice k points where they are spread evenly. Any first disk gives the same
        // answer: points as near as the k-th nearest are all in the last disk searched, visited in the same order
        // (two cells' order is the same in any rectangle of cells that holds both).
        let area = (self.cols * self.rows) as f64 * self.cell * self.cell;
        let even = (2.0 * k as f64 * area
            / (std::f64::consts::PI * self.entries.len().max(1) as f64))
            .sqrt();
        let mut reach = (2.0 * self.cell).max(even).min(radius);
        loop {
            found.clear();
            self.within(&self.points[i], reach, |j, d| {
                if j == i || found.len() == k && d >= found[k - 1].1 {
                    return;
                }
                if found.len() == k {
                    found.pop();
                }
                // Moved down from the end past the farther ones only: after those as near, where a stable sort puts
                // it (a few steps for a few neighbours, where a search and an insertion cost a call to move memory).
                found.push((j, d));
                let mut at = found.len() - 1;
                while at > 0 && found[at - 1].1 > d {
                    found.swap(at - 1, at);
                    at -= 1;
                }
            });
            // Fewer than k only when the disk held fewer than k others.
            if reach >= radius || found.len() >= k || reach > self.extent() {
                break;
            }
            reach = (2.0 * reach).min(radius);
        }
    }

    /// The diagonal of the indexed area (px): a disk of this radius around any indexed point covers every cell.
    fn extent(&self) -> f64 {
        self.cell * ((self.cols * self.cols + self.rows * self.rows) as f64).sqrt()
    }
}

/// How far beyond the points the distance field's grid goes (px).
const FIELD_MARGIN_PX: f64 = 16.0;

/// How far a distance stored in the field may be from the exact one (px): distances in f32, from offsets in f32, are
/// within a few thousandths of a px of the exact ones for grids of thousands of px.
const ROUNDING_MARGIN_PX: f64 = 0.01;

/// The distance from the centre of each of a grid of fine cells to the nearest point (up to a cap): whether any point
/// lies within a radius of a position, answered from one cell for most positions, for searches that test far more
/// positions than there are points. Exact: where the cell cannot tell, the index is asked.
#[derive(Debug, Clone)]
pub(crate) struct NearestDistance {
    /// The corner of the first cell (px).
    origin: Vector2<f64>,
    /// The inverse of the cells' side (1/px).
    per_px: f64,
    cols: usize,
    /// `cols` and the rows' count as floats: the bounds a position's cell coordinates are tested against (a
    /// conversion from `usize` per test costs several instructions, and the test is made hundreds of thousands of
    /// times a search).
    cols_f: f64,
    rows_f: f64,
    /// The cells' side (px).
    cell_px: f64,
    /// Half a cell's diagonal (px), plus the margin for the rounding of the stored distances: how far a position in
    /// a cell may be nearer to or farther from a point than the cell's centre.
    half_diagonal_px: f64,
    /// Per cell (row-major), the distance (px) from its centre to the nearest point, at most `cap_px`.
    distance_px: Vec<f32>,
    /// Per cell, the index's point nearest its centre (`u32::MAX` where none is within the cap): where the distance
    /// alone cannot tell, the likeliest point within a radius is tried before the index is searched.
    nearest_point: Vec<u32>,
    /// Per cell, the distance (px) from its centre to the nearest point but that one (at most `cap_px`): where
    /// `p` is nearer the cell's nearest point than any other can be, that point is the nearest to `p`.
    second_px: Vec<f32>,
    cap_px: f64,
    /// How far every point is sure to be from a position outside the grid (px): the grid reaches a margin beyond
    /// the points' bounding box, less the rounding of a position's cells.
    outside_px: f64,
    /// The bounding box of the points (px).
    lo: Vector2<f64>,
    hi: Vector2<f64>,
}

impl NearestDistance {
    /// The field of the points of `index` with cells of `cell` (px; at most 2^20 cells), over their bounding box
    /// and `cap` (px) around it, the distances capped at `cap` (less where the points are so many that filling the
    /// cells near each would cost more than a few passes over the grid).
    pub fn new(index: &PointIndex, cell: f64, cap: f64) -> Self {
        let finite: Vec<Vector2<f64>> = index
            .entries
            .iter()
            .map(|&e| index.points[e as usize])
            .collect();
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for p in &finite {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if finite.is_empty() {
            lo = Vector2::zeros();
            hi = Vector2::zeros();
        }
        // The grid covers the points and a margin around them; farther out, the distance to their bounding box
        // tells most positions apart.
        let margin = cap.min(FIELD_MARGIN_PX);
        let span = (hi - lo).add_scalar(2.0 * margin);
        let cell = cell
            .max((span.x * span.y / f64::from(1u32 << 20)).sqrt())
            .max(1e-6);
        let cols = (span.x / cell) as usize + 1;
        let rows = (span.y / cell) as usize + 1;
        // Each point fills the cells within the cap around it: at most about four times the grid in all.
        let cap =
            cap.min(0.5 * cell * (4.0 * (cols * rows) as f64 / finite.len().max(1) as f64).sqrt());
        let origin = lo.add_scalar(-margin);
        // Squared distances first, their roots once per cell at the end.
        let mut distance_px = vec![(cap * cap) as f32; cols * rows];
        let mut nearest_point = vec![u32::MAX; cols * rows];
        let mut second_px = vec![(cap * cap) as f32; cols * rows];
        let reach = (cap / cell).ceil() as isize + 1;
        for (p, &point) in finite.iter().zip(&index.entries) {
            // The cell of the point, and those whose centres are within the cap.
            let (ci, cj) = (
                ((p.x - origin.x) / cell) as isize,
                ((p.y - origin.y) / cell) as isize,
            );
            let (i0, i1) = ((ci - reach).max(0), (ci + reach).min(cols as isize - 1));
            if i0 > i1 {
                continue;
            }
            let x0 = (origin.x + (i0 as f64 + 0.5) * cell - p.x) as f32;
            for j in (cj - reach).max(0)..=(cj + reach).min(rows as isize - 1) {
                let dy = (origin.y + (j as f64 + 0.5) * cell - p.y) as f32;
                let row = &mut distance_px[j as usize * cols..][i0 as usize..=i1 as usize];
                let nearest = &mut nearest_point[j as usize * cols..][i0 as usize..=i1 as usize];
                let second = &mut second_px[j as usize * cols..][i0 as usize..=i1 as usize];
                for (k, ((stored, nearest), second)) in
                    row.iter_mut().zip(nearest).zip(second).enumerate()
                {
                    let dx = x0 + k as f32 * cell as f32;
                    let d2 = dx * dx + dy * dy;
                    if d2 < *stored {
                        *second = *stored;
                        *stored = d2;
                        *nearest = point;
                    } else if d2 < *second {
                        *second = d2;
                    }
                }
            }
        }
        for d in distance_px.iter_mut().chain(&mut second_px) {
            *d = d.sqrt();
        }
        // The cap as stored: a cell that holds it may be farther from every point.
        let cap_stored = f64::from(((cap * cap) as f32).sqrt());
        Self {
            origin,
            per_px: 1.0 / cell,
            cols,
            cols_f: cols as f64,
            rows_f: rows as f64,
            cell_px: cell,
            half_diagonal_px: 0.5 * std::f64::consts::SQRT_2 * cell + ROUNDING_MARGIN_PX,
            distance_px,
            nearest_point,
            second_px,
            cap_px: cap_stored,
            outside_px: margin - ROUNDING_MARGIN_PX,
            lo,
            hi,
        }
    }

    /// How far from `p` the nearest point of the field is sure to be, if any lies within `radius`: `None` if none
    /// does, else a radius at most `radius` (`radius` itself where the field cannot tell), and the point nearest the
    /// centre of `p`'s cell (if the field has one there), the likeliest within `radius`.
    #[inline]
    fn reach(&self, p: &Vector2<f64>, radius: f64) -> Option<(f64, Option<usize>)> {
        let (x, y) = (
            (p.x - self.origin.x) * self.per_px,
            (p.y - self.origin.y) * self.per_px,
        );
        // Not finite, or outside the grid: the comparisons fail.
        if x >= 0.0 && y >= 0.0 && x < self.cols_f && y < self.rows_f {
            // Non-negative and below the grid's size (at most 2^20 cells): `u32`'s conversion is the floor, and
            // costs an instruction where `usize`'s costs several.
            let (i, j) = (x as u32, y as u32);
            let cell = j as usize * self.cols + i as usize;
            let d = f64::from(self.distance_px[cell]);
            // How far `p` is from its cell's centre, which bounds how much nearer to or farther from any point it is
            // than the centre; plus the margin for the stored distances' rounding.
            let (dx, dy) = (x - f64::from(i) - 0.5, y - f64::from(j) - 0.5);
            let off_centre_px = (dx * dx + dy * dy).sqrt() * self.cell_px + ROUNDING_MARGIN_PX;
            if d - off_centre_px > radius {
                return None;
            }
            if d < self.cap_px {
                let nearest = self.nearest_point[cell];
                return Some((
                    radius.min(d + off_centre_px),
                    (nearest != u32::MAX).then_some(nearest as usize),
                ));
            }
        } else if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        } else {
            // No point is nearer than the points' bounding box.
            let outside = (self.lo - p).sup(&(p - self.hi)).sup(&Vector2::zeros());
            if outside.norm() > radius + 1e-9 * (1.0 + radius) {
                return None;
            }
        }
        Some((radius, None))
    }

    /// `p` (px) in the field's cell coordinates (cells from the grid's corner), as [`Self::any_within_cells`] takes
    /// positions: a caller that tests many positions an affine map predicts can map them to cells directly.
    #[inline]
    pub fn cells_of(&self, p: &Vector2<f64>) -> Vector2<f64> {
        (p - self.origin) * self.per_px
    }

    /// Cells per px: a displacement (px) times this is the displacement in cells.
    #[inline]
    pub fn cells_per_px(&self) -> f64 {
        self.per_px
    }

    /// Whether any point of `index` (the field's) lies within `radius` of `p`: as
    /// [`PointIndex::any_within`] says, which is asked only where the field cannot tell (after the point nearest
    /// the cell's centre, which is most often the one within `radius` when there is one). (The search asks from
    /// cells, [`Self::any_within_cells`]; the tests, from positions.)
    #[cfg(test)]
    pub fn any_within(&self, index: &PointIndex, p: &Vector2<f64>, radius: f64) -> bool {
        self.any_within_at(index, &self.cells_of(p), || *p, radius)
    }

    /// [`Self::any_within`] at the position whose cell coordinates are `c` ([`Self::cells_of`]): `origin + c × cell`
    /// (px), to the rounding of that product (about 1e-13 px for grids of thousands of px), which the caller allows
    /// for. A test from cells spares the conversion of each position to cells.
    #[inline]
    pub fn any_within_cells(&self, index: &PointIndex, c: &Vector2<f64>, radius: f64) -> bool {
        self.any_within_at(index, c, || self.origin + c * self.cell_px, radius)
    }

    /// [`Self::any_within`] at the position `p()`, whose cell coordinates are `c`: the position is formed only
    /// where the field cannot tell from the cell alone.
    #[inline]
    fn any_within_at(
        &self,
        index: &PointIndex,
        c: &Vector2<f64>,
        p: impl Fn() -> Vector2<f64>,
        radius: f64,
    ) -> bool {
        // Most positions are told from their cell's distance and half its diagonal alone: far from the radius.
        let (x, y) = (c.x, c.y);
        if x >= 0.0 && y >= 0.0 && x < self.cols_f && y < self.rows_f {
            // SAFETY: `x` and `y` are finite, non-negative and below the grid's columns and rows (at most 2^20
            // cells), so they fit an `i32`, whose conversion then truncates: the floor, in one instruction. The
            // checked conversion costs several more, and so does `u32`'s, hundreds of thousands of times a search.
            let (i, j) = unsafe {
                (
                    x.to_int_unchecked::<i32>() as u32,
                    y.to_int_unchecked::<i32>() as u32,
                )
            };
            let cell = j as usize * self.cols + i as usize;
            let d = f64::from(self.distance_px[cell]);
            if d - self.half_diagonal_px > radius {
                return false;
            }
            if d + self.half_diagonal_px <= radius && d < self.cap_px {
                return true;
            }
            // Near the radius: the exact offset from the cell's centre, then the point nearest the centre (the
            // likeliest within the radius), then whether any other can be (no nearer than the cell's second
            // distance allows): most such positions are told without searching the index.
            let (dx, dy) = (x - f64::from(i) - 0.5, y - f64::from(j) - 0.5);
            let off_centre_px = (dx * dx + dy * dy).sqrt() * self.cell_px;
            if d - off_centre_px - ROUNDING_MARGIN_PX > radius {
                return false;
            }
            let p = p();
            if d < self.cap_px {
                let likeliest = self.nearest_point[cell] as usize;
                if (index.points[likeliest] - p).norm_squared() <= radius * radius {
                    return true;
                }
                // Twice the margin: the stored distance's rounding, and that of this bound's own arithmetic.
                if f64::from(self.second_px[cell]) - off_centre_px - 2.0 * ROUNDING_MARGIN_PX
                    > radius
                {
                    return false;
                }
            }
            return index.any_within(&p, radius);
        }
        // Outside the grid (or not finite): most such positions are farther from every point than the radius.
        if radius < self.outside_px {
            return false;
        }
        let p = p();
        match self.reach(&p, radius) {
            None => false,
            Some((reach, _)) if reach < radius => true,
            Some((_, Some(likeliest)))
                if (index.points[likeliest] - p).norm_squared() <= radius * radius =>
            {
                true
            }
            Some(_) => index.any_within(&p, radius),
        }
    }

    /// The point of `index` (the field's) nearest to `p` and its distance, as [`PointIndex::within`] measures it,
    /// where the field can tell it without a search: the point nearest the centre of `p`'s cell, when `p` is nearer
    /// to it than any other point can be (every other is at least the cell's second distance from the centre,
    /// less `p`'s offset from it, less the stored distances' rounding). Strictly nearer: no other point ties it.
    #[inline]
    fn sure_nearest(&self, index: &PointIndex, p: &Vector2<f64>) -> Option<(usize, f64)> {
        let (x, y) = (
            (p.x - self.origin.x) * self.per_px,
            (p.y - self.origin.y) * self.per_px,
        );
        if !(x >= 0.0 && y >= 0.0 && x < self.cols_f && y < self.rows_f) {
            return None;
        }
        // SAFETY: as in `any_within`: finite, non-negative and within the grid's at most 2^20 cells.
        let (i, j) = unsafe { (x.to_int_unchecked::<u32>(), y.to_int_unchecked::<u32>()) };
        let cell = j as usize * self.cols + i as usize;
        let nearest = self.nearest_point[cell];
        if nearest == u32::MAX {
            return None;
        }
        let d = (index.points[nearest as usize] - p).norm();
        let (dx, dy) = (x - f64::from(i) - 0.5, y - f64::from(j) - 0.5);
        let off_centre_px = (dx * dx + dy * dy).sqrt() * self.cell_px;
        // Twice the margin: the stored distance's rounding, and that of this bound's own arithmetic.
        let others_beyond_px =
            f64::from(self.second_px[cell]) - off_centre_px - 2.0 * ROUNDING_MARGIN_PX;
        (d < others_beyond_px).then_some((nearest as usize, d))
    }

    /// [`PointIndex::nearest`] of `index` (the field's points), searched first within the field's [`Self::reach`]
    /// (the same point: the nearest accepted one is there if the nearest of all is accepted), then, if the point
    /// there is not accepted, within `radius`.
    pub fn nearest(
        &self,
        index: &PointIndex,
        p: &Vector2<f64>,
        radius: f64,
        mut accept: impl FnMut(usize) -> bool,
    ) -> Option<(usize, f64)> {
        if let Some((nearest, d)) = self.sure_nearest(index, p)
            && d <= radius
            && accept(nearest)
        {
            return Some((nearest, d));
        }
        let (reach, _) = self.reach(p, radius)?;
        if reach < radius
            && let Some(found) = index.nearest(p, reach, &mut accept)
        {
            return Some(found);
        }
        index.nearest(p, radius, accept)
    }
}

/// Hypotheses from predictions, collected once each.
#[derive(Debug, Default)]
pub(crate) struct Hypotheses {
    seen: std::collections::HashSet<Vec<(usize, usize)>, super::lattice::NodeHasher>,
    pub list: Vec<Vec<(usize, usize)>>,
    /// Per blob, whether the extension under way has used it (all false between extensions).
    used: Vec<bool>,
}

impl Hypotheses {
    /// Appends the hypotheses of `later` (a search continued from where this one stopped) that this one has not
    /// made: the list one search through both would have made.
    pub fn append(&mut self, later: Hypotheses) {
        for pairs in later.list {
            if self.seen.insert(pairs.clone()) {
                self.list.push(pairs);
            }
        }
    }

    /// Extends the seed correspondences `pairs` to every other of the `n` target points whose `predicted` position
    /// has an unused blob within `gate` (the nearest: found sooner with the `field` of the index's points), and keeps
    /// the result if it covers at least `min_matched` points and is new. Gives up as soon as too many points miss.
    /// Whether the result covers `min_matched` points (new or not).
    #[allow(clippy::too_many_arguments)]
    pub fn extend_and_keep(
        &mut self,
        index: &PointIndex,
        field: Option<&NearestDistance>,
        mut pairs: Vec<(usize, usize)>,
        n: usize,
        gate: impl Fn(usize) -> f64,
        min_matched: usize,
        predicted: impl Fn(usize) -> Vector2<f64>,
    ) -> bool {
        let seeds = pairs.len();
        let mut misses = 0;
        let used = &mut self.used;
        used.resize(index.points.len(), false);
        for &(_, b) in &pairs {
            used[b] = true;
        }
        let mut complete = true;
        for p in 0..n {
            if pairs[..seeds].iter().any(|&(q, _)| q == p) {
                continue;
            }
            let unused = |b: usize| !used[b];
            let found = match field {
                Some(field) => field.nearest(index, &predicted(p), gate(p), unused),
                None => index.nearest(&predicted(p), gate(p), unused),
            };
            match found {
                Some((b, _)) => {
                    used[b] = true;
                    pairs.push((p, b));
                }
                None => {
                    misses += 1;
                    if n - misses < min_matched {
                        complete = false;
                        break;
                    }
                }
            }
        }
        for &(_, b) in &pairs {
            used[b] = false;
        }
        let covered = complete && pairs.len() >= min_matched;
        if covered {
            pairs.sort_unstable();
            if self.seen.insert(pairs.clone()) {
                self.list.push(pairs);
            }
        }
        covered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_and_neighbours_agree_with_brute_force() {
        let points: Vec<Vector2<f64>> = (0..200)
            .map(|k| {
                let x = ((k * 7919) % 613) as f64 * 1.03;
                let y = ((k * 104_729) % 457) as f64 * 0.97;
                Vector2::new(x, y)
            })
            .collect();
        let index = PointIndex::new(&points, 25.0);
        for q in [
            Vector2::new(100.0, 200.0),
            Vector2::new(-5.0, 3.0),
            Vector2::new(600.0, 440.0),
        ] {
            let brute = points
                .iter()
                .enumerate()
                .map(|(i, p)| (i, (p - q).norm()))
                .filter(|&(_, d)| d <= 60.0)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            assert_eq!(index.nearest(&q, 60.0, |_| true), brute);
        }
        // The k nearest as a stable sort of every point found orders them (the search as first written), ties
        // (points repeated) included.
        let mut repeated = points.clone();
        repeated.extend_from_slice(&points[..40]);
        let twice = PointIndex::new(&repeated, 25.0);
        for i in (0..repeated.len()).step_by(7) {
            for k in [0, 1, 4, 12] {
                for radius in [30.0, 1e9] {
                    let mut reach = (2.0 * twice.cell).min(radius);
                    let reference = loop {
                        let mut found = Vec::new();
                        twice.within(&twice.points[i], reach, |j, d| {
                            if j != i {
                                found.push((j, d));
                            }
                        });
                        if reach >= radius || found.len() >= k.max(1) || reach > twice.extent() {
                            found.sort_by(|a, b| a.1.total_cmp(&b.1));
                            found.truncate(k);
                            break found;
                        }
                        reach = (2.0 * reach).min(radius);
                    };
                    assert_eq!(
                        twice.neighbours(i, k, radius),
                        reference,
                        "{i} {k} {radius}"
                    );
                }
            }
        }
        let n = index.neighbours(5, 4, 1e9);
        let mut brute: Vec<(usize, f64)> = points
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != 5)
            .map(|(i, p)| (i, (p - points[5]).norm()))
            .collect();
        brute.sort_by(|a, b| a.1.total_cmp(&b.1));
        assert_eq!(n, brute[..4].to_vec());
    }

    #[test]
    fn nearest_distance_and_any_within_agree_with_brute_force() {
        let points: Vec<Vector2<f64>> = (0..300)
            .map(|k| {
                let x = ((k * 7919) % 613) as f64 * 1.03 + 0.37;
                let y = ((k * 104_729) % 457) as f64 * 0.97 + 0.11;
                Vector2::new(x, y)
            })
            .collect();
        let index = PointIndex::new(&points, 25.0);
        // A dense set (the cap shrinks) and a sparse one, fine and coarse cells.
        for (count, cell, cap) in [(300, 3.0, 64.0), (12, 3.0, 64.0), (300, 7.5, 20.0)] {
            let points = &points[..count];
            let index = if count == 300 {
                index.clone()
            } else {
                PointIndex::new(points, 25.0)
            };
            let field = NearestDistance::new(&index, cell, cap);
            for k in 0..20_000 {
                let q = Vector2::new(
                    ((k * 37) % 800) as f64 * 0.93 - 60.0,
                    ((k * 53) % 640) as f64 * 0.91 - 50.0,
                );
                let radius = 0.5 + (k % 61) as f64;
                let brute = points.iter().any(|p| (p - q).norm() <= radius);
                assert_eq!(index.any_within(&q, radius), brute, "{q:?} {radius}");
                assert_eq!(
                    field.any_within(&index, &q, radius),
                    brute,
                    "{q:?} {radius}"
                );
                // From cell coordinates: the answer at the position they stand for.
                let cells = field.cells_of(&q) + Vector2::new(0.37, -0.21);
                let at = field.origin + cells * field.cell_px;
                assert_eq!(
                    field.any_within_cells(&index, &cells, radius),
                    points.iter().any(|p| (p - at).norm() <= radius),
                    "{at:?} {radius}"
                );
                // The nearest point accepted, every other one refused.
                for parity in [0, 1] {
                    let accept = |b: usize| b % 2 == parity;
                    assert_eq!(
                        field.nearest(&index, &q, radius, accept),
                        index.nearest(&q, radius, accept),
                        "{q:?} {radius}"
                    );
                }
            }
            // Positions where the distance to the nearest point is the radius to rounding.
            for (k, p) in points.iter().enumerate().take(50) {
                let q = p + Vector2::new(3.0, 4.0);
                let nearest = points
                    .iter()
                    .map(|o| (o - q).norm())
                    .fold(f64::INFINITY, f64::min);
                for radius in [nearest, nearest - 1e-12, nearest + 1e-12] {
                    let brute = points.iter().any(|o| (o - q).norm() <= radius);
                    assert_eq!(field.any_within(&index, &q, radius), brute, "{k} {radius}");
                }
            }
            let nowhere = Vector2::new(f64::NAN, 3.0);
            assert!(!field.any_within(&index, &nowhere, 10.0));
        }
    }
}
