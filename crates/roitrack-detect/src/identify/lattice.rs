//! Hypotheses for grid targets: the target's points on a lattice, the image's blobs grown into a lattice of their
//! own from a seed and its neighbours, and every way of laying the one on the other.
//!
//! A square or hexagonal grid of circles is a lattice: every point is `o + i a + j b` for integers i, j. In the image
//! the lattice is seen through a homography, which is locally affine: from a seed blob and two neighbours the
//! positions of the next lattice points are predicted by an affine map fitted to the blobs already labelled nearby,
//! and the blob found there (of a size like its neighbour's) gets the next label. Clutter is not where a lattice
//! point is predicted, so it stays out; a missing blob leaves a hole the growth goes around. The image labels
//! (m, n) relate to the target's (i, j) by an integer map of determinant ±1 and a shift; every map with entries in
//! -1..1 and every shift that lays most labelled blobs on target points is a hypothesis, to be verified by a pose.

use std::collections::VecDeque;

use nalgebra::{Matrix2, Vector2};

use super::index::PointIndex;

/// A target whose points lie on a lattice: `plane_m[p] = origin + i a + j b`.
#[derive(Debug, Clone)]
pub(crate) struct TargetLattice {
    lo: (i32, i32),
    hi: (i32, i32),
    /// `cell[(j - lo.1) * width + (i - lo.0)]`: the point at (i, j), if any.
    cell: Vec<Option<u32>>,
}

impl TargetLattice {
    /// The lattice of the target's in-plane points, if they are on one (to 2 % of the shortest spacing).
    pub fn of(plane_m: &[Vector2<f64>]) -> Option<Self> {
        let n = plane_m.len();
        if n < 4 {
            return None;
        }
        let mut a: Option<Vector2<f64>> = None;
        for (k, p) in plane_m.iter().enumerate() {
            for q in &plane_m[k + 1..] {
                let d = q - p;
                if a.is_none_or(|a| d.norm() < a.norm()) && d.norm() > 0.0 {
                    a = Some(d);
                }
            }
        }
        let a = a?;
        let mut b: Option<Vector2<f64>> = None;
        for (k, p) in plane_m.iter().enumerate() {
            for q in &plane_m[k + 1..] {
                let d = q - p;
                let sin = (a.x * d.y - a.y * d.x).abs() / (a.norm() * d.norm());
                if sin > 0.2 && b.is_none_or(|b| d.norm() < b.norm()) {
                    b = Some(d);
                }
            }
        }
        let b = b?;
        let basis = Matrix2::from_columns(&[a, b]);
        let inverse = basis.try_inverse()?;
        let origin = plane_m[0];
        let mut coords = Vec::with_capacity(n);
        for p in plane_m {
            let c = inverse * (p - origin);
            let (i, j) = (c.x.round(), c.y.round());
            if (c.x - i).abs() > 0.02 || (c.y - j).abs() > 0.02 {
                return None;
            }
            coords.push((i as i32, j as i32));
        }
        let lo = coords
            .iter()
            .fold((i32::MAX, i32::MAX), |l, c| (l.0.min(c.0), l.1.min(c.1)));
        let hi = coords
            .iter()
            .fold((i32::MIN, i32::MIN), |h, c| (h.0.max(c.0), h.1.max(c.1)));
        let width = (hi.0 - lo.0 + 1) as usize;
        let height = (hi.1 - lo.1 + 1) as usize;
        if width * height > 1 << 20 {
            return None;
        }
        let mut cell = vec![None; width * height];
        for (k, c) in coords.iter().enumerate() {
            let slot = &mut cell[(c.1 - lo.1) as usize * width + (c.0 - lo.0) as usize];
            if slot.is_some() {
                return None;
            }
            *slot = Some(k as u32);
        }
        Some(Self { lo, hi, cell })
    }

    /// The point at lattice coordinates (i, j).
    pub fn point_at(&self, i: i32, j: i32) -> Option<usize> {
        if i < self.lo.0 || j < self.lo.1 || i > self.hi.0 || j > self.hi.1 {
            return None;
        }
        let width = (self.hi.0 - self.lo.0 + 1) as usize;
        self.cell[(j - self.lo.1) as usize * width + (i - self.lo.0) as usize].map(|p| p as usize)
    }
}

/// The hash of a lattice node's two small integer coordinates (or of a hypothesis' pairs of indices): a
/// multiplication (the keys are not chosen by anyone who could make them collide on purpose, so a keyed hash buys
/// nothing).
pub(crate) type NodeHasher = std::hash::BuildHasherDefault<NodeHash>;

#[derive(Debug, Default)]
pub(crate) struct NodeHash(u64);

impl std::hash::Hasher for NodeHash {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_i32(&mut self, x: i32) {
        self.write_u64(u64::from(x as u32));
    }

    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }

    fn write_u64(&mut self, x: u64) {
        // Fibonacci hashing: the golden ratio's odd multiplier spreads consecutive keys over the high bits, which
        // the standard map's table reads.
        self.0 = (self.0.rotate_left(29) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// Blobs labelled with integer coordinates by growing from a seed.
#[derive(Debug, Clone)]
pub(crate) struct GrownLattice {
    /// (m, n, blob index)
    pub nodes: Vec<(i32, i32, usize)>,
}

/// The blob at each node of a grown lattice: a table over the box of the nodes so far, grown as they spread.
#[derive(Debug, Default)]
struct NodeMap {
    /// The node of the table's first cell.
    lo: (i32, i32),
    cols: i32,
    rows: i32,
    /// Row-major over the box; `u32::MAX` where no blob is.
    blobs: Vec<u32>,
}

impl NodeMap {
    /// Calls `f(n, blob)` for the nodes `(m, n)` with a blob, `n` in `n_lo..=n_hi` increasing: a column of the
    /// table bounded once, not each node looked up.
    fn for_each_in_column(&self, m: i32, n_lo: i32, n_hi: i32, mut f: impl FnMut(i32, usize)) {
        let i = m - self.lo.0;
        if i < 0 || i >= self.cols {
            return;
        }
        for j in (n_lo - self.lo.1).max(0)..=(n_hi - self.lo.1).min(self.rows - 1) {
            let b = self.blobs[(j * self.cols + i) as usize];
            if b != u32::MAX {
                f(j + self.lo.1, b as usize);
            }
        }
    }

    fn get(&self, m: i32, n: i32) -> Option<usize> {
        let (i, j) = (m - self.lo.0, n - self.lo.1);
        if i < 0 || j < 0 || i >= self.cols || j >= self.rows {
            return None;
        }
        let b = self.blobs[(j * self.cols + i) as usize];
        (b != u32::MAX).then_some(b as usize)
    }

    fn insert(&mut self, (m, n): (i32, i32), b: usize) {
        let (i, j) = (m - self.lo.0, n - self.lo.1);
        if i < 0 || j < 0 || i >= self.cols || j >= self.rows {
            // A box twice as large (at least 8 nodes more each way) around the old one and the new node.
            let margin = 8.max(self.cols.max(self.rows) / 2);
            let lo = ((m - margin).min(self.lo.0), (n - margin).min(self.lo.1));
            let hi = if self.blobs.is_empty() {
                (m + margin, n + margin)
            } else {
                (
                    (m + margin).max(self.lo.0 + self.cols - 1),
                    (n + margin).max(self.lo.1 + self.rows - 1),
                )
            };
            let (cols, rows) = (hi.0 - lo.0 + 1, hi.1 - lo.1 + 1);
            let mut blobs = vec![u32::MAX; (cols * rows) as usize];
            for jj in 0..self.rows {
                for ii in 0..self.cols {
                    let (tm, tn) = (self.lo.0 + ii - lo.0, self.lo.1 + jj - lo.1);
                    blobs[(tn * cols + tm) as usize] = self.blobs[(jj * self.cols + ii) as usize];
                }
            }
            *self = Self {
                lo,
                cols,
                rows,
                blobs,
            };
        }
        let (i, j) = (m - self.lo.0, n - self.lo.1);
        self.blobs[(j * self.cols + i) as usize] = b as u32;
    }
}

/// Grows an image lattice from `seed` with first steps towards blobs `first` and `second` (positions `ideal`, areas
/// `areas`). Blobs marked in `taken` are not used. The growth stops once it holds `max_nodes` nodes (it holds the
/// three it starts from whatever `max_nodes`): they are then the first `max_nodes` nodes of the whole growth, which
/// adds them in the same order, so a caller asking only whether a lattice reaches that size is spared the rest.
#[allow(clippy::too_many_arguments)]
pub(crate) fn grow(
    ideal: &[Vector2<f64>],
    areas: &[f64],
    index: &PointIndex,
    taken: &[bool],
    seed: usize,
    first: usize,
    second: usize,
    max_nodes: usize,
) -> GrownLattice {
    // About 200 look-ups a grown node (the 5 x 5 support of each of its 8 neighbours): a dense table of the nodes'
    // box, not a hash map.
    let mut at = NodeMap::default();
    let mut used = taken.to_vec();
    let mut nodes = vec![(0, 0, seed), (1, 0, first), (0, 1, second)];
    for &(m, n, b) in &nodes {
        at.insert((m, n), b);
        used[b] = true;
    }
    let mut queue: VecDeque<(i32, i32)> = nodes.iter().map(|&(m, n, _)| (m, n)).collect();
    'growth: while nodes.len() < max_nodes {
        let Some((m, n)) = queue.pop_front() else {
            break;
        };
        let Some(from) = at.get(m, n) else {
            continue;
        };
        for (dm, dn) in [
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (-1, -1),
            (1, -1),
            (-1, 1),
        ] {
            let (tm, tn) = (m + dm, n + dn);
            if at.get(tm, tn).is_some() {
                continue;
            }
            // A local affine map from the labelled blobs around the target node.
            let mut support = AffineSums::default();
            for sm in tm - 2..=tm + 2 {
                at.for_each_in_column(sm, tn - 2, tn + 2, |sn, b| {
                    support.add(sm - tm, sn - tn, ideal[b]);
                });
            }
            let Some((predicted, step)) = support.prediction() else {
                continue;
            };
            let gate = 0.3 * step;
            let area = areas[from];
            let found = index.nearest(&predicted, gate, |b| {
                !used[b] && areas[b] < 2.5 * area && areas[b] > area / 2.5
            });
            if let Some((b, _)) = found {
                used[b] = true;
                at.insert((tm, tn), b);
                nodes.push((tm, tn, b));
                queue.push_back((tm, tn));
                if nodes.len() >= max_nodes {
                    break 'growth;
                }
            }
        }
    }
    GrownLattice { nodes }
}

/// The normal equations of the least squares of an affine map `x = c + A (m, n)` (lattice offset -> image) through
/// supports at offsets `(m, n)` of at most 2 from a node, summed as the supports come: what the products of the
/// design rows `(1, m, n)` with themselves and with `x` add up to, at a fraction of the cost of forming each
/// product as a matrix (most of a growth's time). The offsets' sums (the normal matrix) are small integers, exact
/// in any order; the sums of `x` are added in the supports' order, each term exact (`x` times 0, ±1 or ±2), so both
/// are bit for bit those of the matrix products.
#[derive(Debug, Clone, Copy, Default)]
struct AffineSums {
    count: i32,
    /// Σm, Σn, Σm², Σmn, Σn².
    m: i32,
    n: i32,
    mm: i32,
    mn: i32,
    nn: i32,
    /// Σx, Σm x, Σn x (image coordinates u, v).
    x: [[f64; 2]; 3],
}

impl AffineSums {
    fn add(&mut self, m: i32, n: i32, x: Vector2<f64>) {
        self.count += 1;
        self.m += m;
        self.n += n;
        self.mm += m * m;
        self.mn += m * n;
        self.nn += n * n;
        let (fm, fn_) = (f64::from(m), f64::from(n));
        self.x[0][0] += x.x;
        self.x[0][1] += x.y;
        self.x[1][0] += fm * x.x;
        self.x[1][1] += fm * x.y;
        self.x[2][0] += fn_ * x.x;
        self.x[2][1] += fn_ * x.y;
    }

    /// The position at the origin of the fitted map, and the map's shorter step; `None` without three
    /// non-collinear supports.
    fn prediction(&self) -> Option<(Vector2<f64>, f64)> {
        if self.count < 3 {
            return None;
        }
        let [count, m, n, mm, mn, nn] =
            [self.count, self.m, self.n, self.mm, self.mn, self.nn].map(f64::from);
        let ata = nalgebra::Matrix3::new(count, m, n, m, mm, mn, n, mn, nn);
        let [[x0, y0], [x1, y1], [x2, y2]] = self.x;
        let atx = nalgebra::Matrix3x2::new(x0, y0, x1, y1, x2, y2);
        affine_fit(ata, atx)
    }
}

/// The affine map's fit from its normal equations (AᵀA, Aᵀx; A's rows (1, m, n)): the position at the origin, and
/// the map's shorter step; `None` where the supports are (nearly) collinear.
fn affine_fit(
    ata: nalgebra::Matrix3<f64>,
    atx: nalgebra::Matrix3x2<f64>,
) -> Option<(Vector2<f64>, f64)> {
    let decomposition = ata.cholesky()?;
    // Collinear supports make the normal matrix nearly singular.
    let diagonal_min = decomposition.l().diagonal().min();
    if diagonal_min < 0.3 {
        return None;
    }
    let solution = decomposition.solve(&atx);
    let c = Vector2::new(solution[(0, 0)], solution[(0, 1)]);
    let a1 = Vector2::new(solution[(1, 0)], solution[(1, 1)]);
    let a2 = Vector2::new(solution[(2, 0)], solution[(2, 1)]);
    Some((c, a1.norm().min(a2.norm())))
}

/// Integer 2 x 2 maps with entries in -1..=1 and determinant ±1.
fn unimodular_maps() -> Vec<[i32; 4]> {
    let mut maps = Vec::new();
    for a in -1i32..=1 {
        for b in -1..=1 {
            for c in -1..=1 {
                for d in -1..=1 {
                    if (a * d - b * c).abs() == 1 {
                        maps.push([a, b, c, d]);
                    }
                }
            }
        }
    }
    maps
}

/// Every (map, shift) that lays at least `min_fraction` of the grown nodes on target points, the nodes' box sticking
/// out of the target's by at most `slack` lattice steps: the correspondences (target point, blob) of each.
pub(crate) fn placements(
    lattice: &TargetLattice,
    grown: &GrownLattice,
    min_fraction: f64,
    slack: i32,
) -> Vec<Vec<(usize, usize)>> {
    let nodes = &grown.nodes;
    let allowed_misses = ((1.0 - min_fraction) * nodes.len() as f64).floor() as usize;
    let mut out = Vec::new();
    for map in unimodular_maps() {
        let mapped: Vec<(i32, i32)> = nodes
            .iter()
            .map(|&(m, n, _)| (map[0] * m + map[1] * n, map[2] * m + map[3] * n))
            .collect();
        let lo = mapped
            .iter()
            .fold((i32::MAX, i32::MAX), |l, c| (l.0.min(c.0), l.1.min(c.1)));
        let hi = mapped
            .iter()
            .fold((i32::MIN, i32::MIN), |h, c| (h.0.max(c.0), h.1.max(c.1)));
        // Shifts that keep the nodes' box within the target's, give or take the slack.
        for ti in (lattice.lo.0 - lo.0 - slack)..=(lattice.hi.0 - hi.0 + slack) {
            'shift: for tj in (lattice.lo.1 - lo.1 - slack)..=(lattice.hi.1 - hi.1 + slack) {
                let mut pairs = Vec::with_capacity(nodes.len());
                let mut misses = 0;
                for (k, &(i, j)) in mapped.iter().enumerate() {
                    match lattice.point_at(i + ti, j + tj) {
                        Some(p) => pairs.push((p, nodes[k].2)),
                        None => {
                            misses += 1;
                            if misses > allowed_misses {
                                continue 'shift;
                            }
                        }
                    }
                }
                if pairs.len() >= 4 {
                    out.push(pairs);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fit the growth used before [`AffineSums`]: the normal equations summed as matrix products.
    fn fit_by_products(support: &[(i32, i32, Vector2<f64>)]) -> Option<(Vector2<f64>, f64)> {
        if support.len() < 3 {
            return None;
        }
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atx = nalgebra::Matrix3x2::<f64>::zeros();
        for &(m, n, x) in support {
            let a = nalgebra::Vector3::new(1.0, f64::from(m), f64::from(n));
            ata += a * a.transpose();
            atx += a * x.transpose();
        }
        affine_fit(ata, atx)
    }

    /// The sums give the matrix products' fit bit for bit: random subsets of the 5 x 5 offsets (collinear and
    /// too small ones included) at random positions, negative and fractional.
    #[test]
    fn affine_sums_fit_as_the_matrix_products_did() {
        let mut state = 3u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            state >> 11
        };
        let (mut fitted, mut refused) = (0, 0);
        for _ in 0..5000 {
            let keep = next();
            // From every offset kept to about one in five.
            let sparse = 1 + next() % 5;
            let mut support = Vec::new();
            let mut sums = AffineSums::default();
            for sm in -2..=2 {
                for sn in -2..=2 {
                    if keep >> (5 * (sm + 2) + sn + 2) & 1 == 1 && next() % sparse == 0 {
                        let x = Vector2::new(
                            (next() % 200_000) as f64 / 97.0 - 900.0,
                            (next() % 200_000) as f64 / 89.0 - 700.0,
                        );
                        support.push((sm, sn, x));
                        sums.add(sm, sn, x);
                    }
                }
            }
            let expected = fit_by_products(&support);
            let found = sums.prediction();
            match (expected, found) {
                (Some((c, step)), Some((c2, step2))) => {
                    assert_eq!(c.x.to_bits(), c2.x.to_bits());
                    assert_eq!(c.y.to_bits(), c2.y.to_bits());
                    assert_eq!(step.to_bits(), step2.to_bits());
                    fitted += 1;
                }
                (None, None) => refused += 1,
                other => panic!("{support:?}: {other:?}"),
            }
        }
        assert!(
            fitted > 1000 && refused > 100,
            "{fitted} fitted, {refused} refused"
        );
    }

    fn hexagonal(rows: i32, cols: i32, s: f64) -> Vec<Vector2<f64>> {
        let mut p = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                if (r + c) % 2 == 0 {
                    p.push(Vector2::new(
                        f64::from(c) * s / 2.0,
                        f64::from(r) * s * 60f64.to_radians().sin(),
                    ));
                }
            }
        }
        p
    }

    #[test]
    fn square_and_hexagonal_grids_are_lattices_and_random_points_are_not() {
        let square: Vec<Vector2<f64>> = (0..12)
            .map(|k| Vector2::new(f64::from(k % 4) * 0.02, f64::from(k / 4) * 0.02))
            .collect();
        let l = TargetLattice::of(&square).unwrap();
        let found: Vec<usize> = (-8..8)
            .flat_map(|i| (-8..8).map(move |j| (i, j)))
            .filter_map(|(i, j)| l.point_at(i, j))
            .collect();
        assert_eq!(found.len(), 12);
        let hex = hexagonal(6, 8, 0.012);
        assert!(TargetLattice::of(&hex).is_some());
        let random = vec![
            Vector2::new(0.0, 0.0),
            Vector2::new(0.031, 0.0),
            Vector2::new(0.0, 0.017),
            Vector2::new(0.043, 0.029),
        ];
        assert!(TargetLattice::of(&random).is_none());
    }

    #[test]
    fn growth_labels_a_sheared_grid_with_clutter_and_a_hole() {
        // A 7 x 5 grid seen through an affine map, a missing blob, clutter between and around.
        let map = Matrix2::new(21.0, 6.0, -4.0, 18.0);
        let mut ideal = Vec::new();
        for j in 0..5 {
            for i in 0..7 {
                if (i, j) != (3, 2) {
                    ideal.push(
                        map * Vector2::new(f64::from(i), f64::from(j)) + Vector2::new(100.0, 80.0),
                    );
                }
            }
        }
        let grid_blobs = ideal.len();
        ideal.push(Vector2::new(100.0 + 10.5, 80.0 - 2.0));
        ideal.push(Vector2::new(30.0, 30.0));
        ideal.push(Vector2::new(100.0 + 21.0 * 8.0, 80.0 - 4.0 * 8.0));
        let areas = vec![50.0; ideal.len()];
        let index = PointIndex::new(&ideal, 20.0);
        let grown = grow(
            &ideal,
            &areas,
            &index,
            &vec![false; ideal.len()],
            0,
            1,
            7,
            usize::MAX,
        );
        assert_eq!(grown.nodes.len(), grid_blobs);
        assert!(grown.nodes.iter().all(|&(_, _, b)| b < grid_blobs));
        let target: Vec<Vector2<f64>> = (0..35)
            .map(|k| Vector2::new(f64::from(k % 7), f64::from(k / 7)))
            .collect();
        let lattice = TargetLattice::of(&target).unwrap();
        let placed = placements(&lattice, &grown, 0.95, 1);
        // The identity and the half turn lay every node on the target.
        assert!(placed.iter().any(|pairs| pairs.iter().all(|&(p, b)| {
            let k = if p >= 17 { p - 1 } else { p };
            k == b
        })));
        assert!(placed.iter().all(|pairs| pairs.len() == grid_blobs));
    }
}
