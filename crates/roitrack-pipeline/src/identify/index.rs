//! A uniform grid over points in the image, for nearest-neighbour queries among a few hundred blobs.

use nalgebra::Vector2;

/// Points bucketed by square cells.
#[derive(Debug, Clone)]
pub(crate) struct PointIndex {
    origin: Vector2<f64>,
    cell: f64,
    cols: usize,
    rows: usize,
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

    /// The cells (columns and rows, inclusive) that a disk of `radius` around `p` touches; `None` if it misses the
    /// indexed area or is not finite.
    fn cells_around(
        &self,
        p: &Vector2<f64>,
        radius: f64,
    ) -> Option<(
        std::ops::RangeInclusive<usize>,
        std::ops::RangeInclusive<usize>,
    )> {
        if !(p.x.is_finite() && p.y.is_finite() && radius.is_finite()) {
            return None;
        }
        // Truncation is the floor of a non-negative value (and cheaper than `floor`, a library call here): the low
        // ends are clamped at 0 first, the high ends refused below it.
        let (hi_i, hi_j) = (
            (p.x + radius - self.origin.x) / self.cell,
            (p.y + radius - self.origin.y) / self.cell,
        );
        if hi_i < 0.0 || hi_j < 0.0 {
            return None;
        }
        let lo_i = ((p.x - radius - self.origin.x) / self.cell).max(0.0) as usize;
        let lo_j = ((p.y - radius - self.origin.y) / self.cell).max(0.0) as usize;
        let hi_i = (hi_i as usize).min(self.cols - 1);
        let hi_j = (hi_j as usize).min(self.rows - 1);
        (lo_i <= hi_i && lo_j <= hi_j).then_some((lo_i..=hi_i, lo_j..=hi_j))
    }

    /// Calls `f(index, distance)` for every point within `radius` of `p`.
    pub fn within(&self, p: &Vector2<f64>, radius: f64, mut f: impl FnMut(usize, f64)) {
        let Some((cols, rows)) = self.cells_around(p, radius) else {
            return;
        };
        for j in rows {
            for i in cols.clone() {
                let c = j * self.cols + i;
                for &e in &self.entries[self.starts[c] as usize..self.starts[c + 1] as usize] {
                    let d = (self.points[e as usize] - p).norm();
                    if d <= radius {
                        f(e as usize, d);
                    }
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
            let entries = &self.entries[self.starts[row + cols.start()] as usize
                ..self.starts[row + cols.end() + 1] as usize];
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
        // Search a growing disk, not the whole `radius` (often "everything"): once it holds k others, the k nearest
        // of all are in it, and in the same order (the cells are visited in the same row-major order, the sort is
        // stable), so this is the full search's answer at the cost of a few cells.
        let mut found = Vec::new();
        let mut reach = (2.0 * self.cell).min(radius);
        loop {
            found.clear();
            self.within(&self.points[i], reach, |j, d| {
                if j != i {
                    found.push((j, d));
                }
            });
            if reach >= radius || found.len() >= k.max(1) || reach > self.extent() {
                break;
            }
            reach = (2.0 * reach).min(radius);
        }
        found.sort_by(|a, b| a.1.total_cmp(&b.1));
        found.truncate(k);
        found
    }

    /// The diagonal of the indexed area (px): a disk of this radius around any indexed point covers every cell.
    fn extent(&self) -> f64 {
        self.cell * ((self.cols * self.cols + self.rows * self.rows) as f64).sqrt()
    }
}

/// How many points each rectangle of fine cells holds (a summed-area table): a constant-time test that no point lies
/// near a position, for searches that test far more positions than there are points.
#[derive(Debug, Clone)]
pub(crate) struct Occupancy {
    origin: Vector2<f64>,
    /// The inverse of the cells' side (1/px).
    per_px: f64,
    cols: usize,
    rows: usize,
    /// `counts[j * (cols + 1) + i]`: the points in the cells left of column `i` and above row `j`.
    counts: Vec<u32>,
}

impl Occupancy {
    /// The table of `points` (the non-finite ones left out) with cells of `cell` (px), at most 512 a side.
    pub fn new(points: &[Vector2<f64>], cell: f64) -> Self {
        let finite = || points.iter().filter(|p| p.x.is_finite() && p.y.is_finite());
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for p in finite() {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if !lo.x.is_finite() {
            lo = Vector2::zeros();
            hi = Vector2::zeros();
        }
        let cell = cell.max((hi.x - lo.x).max(hi.y - lo.y) / 511.0).max(1e-9);
        let cols = ((hi.x - lo.x) / cell) as usize + 1;
        let rows = ((hi.y - lo.y) / cell) as usize + 1;
        let stride = cols + 1;
        let mut counts = vec![0u32; stride * (rows + 1)];
        for p in finite() {
            let i = (((p.x - lo.x) / cell) as usize).min(cols - 1);
            let j = (((p.y - lo.y) / cell) as usize).min(rows - 1);
            counts[(j + 1) * stride + i + 1] += 1;
        }
        for j in 1..=rows {
            for i in 1..=cols {
                counts[j * stride + i] += counts[j * stride + i - 1] + counts[(j - 1) * stride + i]
                    - counts[(j - 1) * stride + i - 1];
            }
        }
        Self {
            origin: lo,
            per_px: 1.0 / cell,
            cols,
            rows,
            counts,
        }
    }

    /// False only if no point lies within `radius` of `p` (true may also mean one lies only near it: the cells
    /// that cover the disk's bounding square hold one).
    pub fn maybe_within(&self, p: &Vector2<f64>, radius: f64) -> bool {
        let (x0, y0) = (
            (p.x - radius - self.origin.x) * self.per_px,
            (p.y - radius - self.origin.y) * self.per_px,
        );
        let (x1, y1) = (
            (p.x + radius - self.origin.x) * self.per_px,
            (p.y + radius - self.origin.y) * self.per_px,
        );
        // Not finite, or wholly outside: the comparisons fail or the range is empty. Truncation is the floor of a
        // non-negative value.
        if !(x1 >= 0.0 && y1 >= 0.0 && x0 < self.cols as f64 && y0 < self.rows as f64) {
            return false;
        }
        let (i0, j0) = (x0.max(0.0) as usize, y0.max(0.0) as usize);
        let (i1, j1) = (
            (x1 as usize).min(self.cols - 1) + 1,
            (y1 as usize).min(self.rows - 1) + 1,
        );
        let stride = self.cols + 1;
        let c = &self.counts;
        c[j1 * stride + i1] + c[j0 * stride + i0] != c[j0 * stride + i1] + c[j1 * stride + i0]
    }
}

/// Hypotheses from predictions, collected once each.
#[derive(Debug, Default)]
pub(crate) struct Hypotheses {
    seen: std::collections::HashSet<Vec<(usize, usize)>>,
    pub list: Vec<Vec<(usize, usize)>>,
}

impl Hypotheses {
    /// Extends the seed correspondences `pairs` to every other of the `n` target points whose `predicted` position
    /// has an unused blob within `gate`, and keeps the result if it covers at least `min_matched` points and is new.
    /// Gives up as soon as too many points miss.
    pub fn extend_and_keep(
        &mut self,
        index: &PointIndex,
        mut pairs: Vec<(usize, usize)>,
        n: usize,
        gate: impl Fn(usize) -> f64,
        min_matched: usize,
        predicted: impl Fn(usize) -> Vector2<f64>,
    ) {
        let seeds = pairs.len();
        let mut misses = 0;
        for p in 0..n {
            if pairs[..seeds].iter().any(|&(q, _)| q == p) {
                continue;
            }
            match index.nearest(&predicted(p), gate(p), |b| {
                pairs.iter().all(|&(_, pb)| pb != b)
            }) {
                Some((b, _)) => pairs.push((p, b)),
                None => {
                    misses += 1;
                    if n - misses < min_matched {
                        return;
                    }
                }
            }
        }
        if pairs.len() >= min_matched {
            pairs.sort_unstable();
            if self.seen.insert(pairs.clone()) {
                self.list.push(pairs);
            }
        }
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
    fn occupancy_never_misses_a_point_and_any_within_agrees_with_brute_force() {
        let points: Vec<Vector2<f64>> = (0..300)
            .map(|k| {
                let x = ((k * 7919) % 613) as f64 * 1.03 + 0.37;
                let y = ((k * 104_729) % 457) as f64 * 0.97 + 0.11;
                Vector2::new(x, y)
            })
            .collect();
        let index = PointIndex::new(&points, 25.0);
        let occupancy = Occupancy::new(&points, 3.0);
        let (mut empty, mut told_empty) = (0, 0);
        for k in 0..5000 {
            let q = Vector2::new(
                ((k * 37) % 700) as f64 * 0.93 - 20.0,
                ((k * 53) % 520) as f64 * 0.91 - 15.0,
            );
            let radius = 0.5 + (k % 13) as f64;
            let brute = points.iter().any(|p| (p - q).norm() <= radius);
            assert_eq!(index.any_within(&q, radius), brute, "{q:?} {radius}");
            if !brute {
                empty += 1;
            }
            if !occupancy.maybe_within(&q, radius) {
                assert!(!brute, "{q:?} {radius}");
                told_empty += 1;
            }
        }
        // It tells most empty disks apart: it is worth its table.
        assert!(
            told_empty as f64 > 0.5 * empty as f64,
            "{told_empty} of {empty}"
        );
    }
}
