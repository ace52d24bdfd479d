//! Connected components (8-connectivity) of the pixels above one threshold, with their binary moments up to second
//! order and what the shape filters need, from horizontal runs joined by union-find.

/// Binary moments and outline figures of one component (integer sums: exact).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Component {
    pub n: u64,
    pub sum_i: u64,
    pub sum_j: u64,
    pub sum_ii: u64,
    pub sum_jj: u64,
    pub sum_ij: u64,
    /// Horizontal runs: a convex shape has one per row.
    pub runs: u32,
    pub row_min: u32,
    pub row_max: u32,
    pub touches_border: bool,
}

impl Component {
    fn add(&mut self, o: &Component) {
        self.n += o.n;
        self.sum_i += o.sum_i;
        self.sum_j += o.sum_j;
        self.sum_ii += o.sum_ii;
        self.sum_jj += o.sum_jj;
        self.sum_ij += o.sum_ij;
        self.runs += o.runs;
        self.row_min = self.row_min.min(o.row_min);
        self.row_max = self.row_max.max(o.row_max);
        self.touches_border |= o.touches_border;
    }

    /// Centre of the pixels (px).
    pub fn centre(&self) -> (f64, f64) {
        let n = self.n as f64;
        (self.sum_i as f64 / n, self.sum_j as f64 / n)
    }

    /// Central second moments (px²): (μ_uu, μ_vv, μ_uv), each pixel counted as a unit square (+1/12).
    pub fn covariance(&self) -> (f64, f64, f64) {
        let n = self.n as f64;
        let (cu, cv) = self.centre();
        (
            self.sum_ii as f64 / n - cu * cu + 1.0 / 12.0,
            self.sum_jj as f64 / n - cv * cv + 1.0 / 12.0,
            self.sum_ij as f64 / n - cu * cv,
        )
    }
}

/// A run of pixels in one row (inclusive ends).
#[derive(Debug, Clone, Copy)]
struct Run {
    start: u32,
    end: u32,
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let grand = parent[parent[x as usize] as usize];
        parent[x as usize] = grand;
        x = grand;
    }
    x
}

/// Buffers reused from one threshold to the next.
#[derive(Debug, Default)]
pub(crate) struct Labeller {
    runs: Vec<Run>,
    parts: Vec<Component>,
    parent: Vec<u32>,
    totals: Vec<Option<Component>>,
}

impl Labeller {
    /// The components of the pixels strictly above `threshold` in a row-major `width` x `height` image, each passed
    /// to `keep` (in the order of their first pixel).
    pub fn components(
        &mut self,
        pixels: &[u16],
        width: usize,
        height: usize,
        threshold: u16,
        mut keep: impl FnMut(&Component),
    ) {
        self.runs.clear();
        self.parts.clear();
        self.parent.clear();
        let mut previous_row = 0..0;
        for (j, row) in pixels.chunks_exact(width.max(1)).take(height).enumerate() {
            let row_start = self.runs.len();
            let mut i = 0;
            while i < width {
                // Skip the background quickly: most pixels of a photograph are below any one threshold.
                match row[i..].iter().position(|&p| p > threshold) {
                    Some(k) => i += k,
                    None => break,
                }
                let start = i;
                let end = row[i..]
                    .iter()
                    .position(|&p| p <= threshold)
                    .map_or(width, |k| i + k);
                i = end;
                let (s, e) = (start as u64, end as u64);
                let n = e - s;
                let jj = j as u64;
                // Sums of i and i² over s..e in closed form.
                let sum_i = (s + e - 1) * n / 2;
                let sq = |x: u64| x * (x + 1) * (2 * x + 1) / 6;
                let sum_ii = sq(e - 1) - if s > 0 { sq(s - 1) } else { 0 };
                let id = self.runs.len() as u32;
                self.runs.push(Run {
                    start: start as u32,
                    end: (end - 1) as u32,
                });
                self.parts.push(Component {
                    n,
                    sum_i,
                    sum_j: n * jj,
                    sum_ii,
                    sum_jj: n * jj * jj,
                    sum_ij: sum_i * jj,
                    runs: 1,
                    row_min: j as u32,
                    row_max: j as u32,
                    touches_border: j == 0 || j + 1 == height || start == 0 || end == width,
                });
                self.parent.push(id);
            }
            // Join with the runs of the row above that overlap or touch diagonally.
            let mut p = previous_row.start;
            for r in row_start..self.runs.len() {
                let run = self.runs[r];
                while p < previous_row.end && self.runs[p].end + 1 < run.start {
                    p += 1;
                }
                let mut q = p;
                while q < previous_row.end && self.runs[q].start <= run.end + 1 {
                    let (ra, rb) = (
                        find(&mut self.parent, q as u32),
                        find(&mut self.parent, r as u32),
                    );
                    if ra < rb {
                        self.parent[rb as usize] = ra;
                    } else if rb < ra {
                        self.parent[ra as usize] = rb;
                    }
                    q += 1;
                }
            }
            previous_row = row_start..self.runs.len();
        }
        self.totals.clear();
        self.totals.resize(self.runs.len(), None);
        for r in 0..self.parts.len() {
            let root = find(&mut self.parent, r as u32) as usize;
            let part = self.parts[r];
            match &mut self.totals[root] {
                Some(total) => total.add(&part),
                slot => *slot = Some(part),
            }
        }
        for c in self.totals.iter().flatten() {
            keep(c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_of_a_rectangle_and_a_ring() {
        let (w, h) = (20usize, 16usize);
        let mut img = vec![0u16; w * h];
        for j in 3..7 {
            for i in 2..8 {
                img[j * w + i] = 100;
            }
        }
        // A ring: a 7 x 7 square with a 3 x 3 hole.
        for j in 6..13 {
            for i in 11..18 {
                if !(8..11).contains(&j) || !(13..16).contains(&i) {
                    img[j * w + i] = 100;
                }
            }
        }
        let mut found = Vec::new();
        Labeller::default().components(&img, w, h, 50, |c| found.push(*c));
        assert_eq!(found.len(), 2);
        let rect = found[0];
        assert_eq!(rect.n, 24);
        let (cu, cv) = rect.centre();
        assert!((cu - 4.5).abs() < 1e-12 && (cv - 4.5).abs() < 1e-12);
        let (uu, vv, uv) = rect.covariance();
        // A uniform w x h rectangle: w²/12 and h²/12.
        assert!((uu - 36.0 / 12.0).abs() < 1e-12 && (vv - 16.0 / 12.0).abs() < 1e-12);
        assert!(uv.abs() < 1e-12);
        assert_eq!(rect.runs, 4);
        let ring = found[1];
        assert_eq!(ring.n, 40);
        assert_eq!(ring.runs, 7 + 3);
        assert_eq!((ring.row_min, ring.row_max), (6, 12));
        assert!(!ring.touches_border && !rect.touches_border);
    }
}
