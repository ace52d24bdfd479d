//! The kernels that sum a component's moments, written once over [`Lanes`]: the one-pass walk that finds and
//! measures a simple component ([`simple_component`], the usual case) and the moments of any component over a
//! window of its columns ([`window_moments`]).
//!
//! Both sum `v = value - threshold` per column in 16-bit lanes over blocks of rows short enough not to overflow
//! ([`block_rows`]), with the running sums of those sums, whence the row moment (a block's rows weighted by how many
//! running sums they are in), and fold them into 64-bit totals at the end of each block ([`fold`]). The pixel counts
//! and index sums are exact integers too, so the moments are the same to the bit whatever the instruction set and
//! the vector width. Each kernel is `#[inline(always)]`: it is instantiated inside an instruction set's
//! `#[target_feature]` entry point.

use super::Found;
use super::lanes::Lanes;
use crate::centroid::component::{dilate, single_run};
use crate::centroid::moments::Moments;

/// Rows of 16-bit sums of values up to `d` and of their running sums that cannot overflow: the largest
/// `m <= rows` with `d * m * (m + 1) / 2 <= 65535` (at least 1).
pub(super) fn block_rows(d: u64, rows: u64) -> u64 {
    let fits = |m: u64| d * m * (m + 1) / 2 <= u64::from(u16::MAX);
    if fits(rows) {
        return rows;
    }
    let mut m = ((2.0 * 65535.0 / d.max(1) as f64).sqrt() as u64).clamp(1, rows);
    while m > 1 && !fits(m) {
        m -= 1;
    }
    while m < rows && fits(m + 1) {
        m += 1;
    }
    m
}

/// Totals of `v = value - threshold` over a component: unweighted, and weighted by the column and by the row.
#[derive(Default)]
struct Sums {
    v: u64,
    iv: u64,
    jv: u64,
}

/// Folds the 16-bit sums `a` (of `v` per lane over a block of rows) and `b` (running sums of `a`) into `sums` and
/// clears them; `cols` the columns of the vectors' lanes, `last` the block's last row walked. Walking down, row j of
/// the block is in `last + 1 - j` of the running sums; walking up (`DOWN` false), in `j + 1 - last`.
#[inline(always)]
fn fold<L: Lanes, const N: usize, const DOWN: bool>(
    l: L,
    sums: &mut Sums,
    a: &mut [L::V; N],
    b: &mut [L::V; N],
    cols: &[L::Cols; N],
    last: usize,
) {
    let (mut sa, mut sb, mut sia) = (l.sum_zero(), l.sum_zero(), l.sum_zero());
    for k in 0..N {
        sa = l.sum_add(sa, a[k]);
        sb = l.sum_add(sb, b[k]);
        sia = l.sum_weighted(sia, a[k], cols[k]);
        a[k] = l.zero();
        b[k] = l.zero();
    }
    // Each 32-bit sum holds at most 64 lanes of at most 65535 (times a column below 64).
    let (sa, sb) = (l.hsum(sa), l.hsum(sb));
    sums.v += sa;
    sums.iv += l.hsum(sia);
    let last = last as u64;
    sums.jv += if DOWN {
        (last + 1) * sa - sb
    } else {
        sb + last * sa - sa
    };
}

/// The moments of the component `comp` (rows `lo..=hi`, within columns `s..s + N * WIDTH <= w`), `mask` the
/// above-threshold pixels, `levels` the threshold and the ROI's maximum.
///
/// Per lane (column) it sums `v = value - threshold` (positive exactly on the component) and its running sums (see
/// the module's documentation), and counts the lanes where `v` is 0, whence the pixel count and index sums. Where
/// the row's mask holds nothing but the component in the window (nearly always), `v` is `value -sat threshold`;
/// elsewhere the component's bits mask it.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn window_moments<L: Lanes, const N: usize>(
    l: L,
    px: &[u16],
    w: usize,
    comp: &[u64],
    mask: &[u64],
    (lo, hi): (usize, usize),
    s: usize,
    (threshold, peak): (u16, u16),
) -> Moments {
    let width = L::WIDTH;
    let z = l.zero();
    let t = l.splat(threshold);
    let cols: [L::Cols; N] = std::array::from_fn(|k| l.cols(s + k * width));
    let window = u64::MAX >> (64 - N * width);
    let (mut a, mut b, mut zeros, mut zeros_cum) = ([z; N], [z; N], [z; N], [z; N]);
    let rows = (hi - lo + 1) as u64;
    let block = block_rows(u64::from(peak - threshold), rows);
    let mut sums = Sums::default();
    let mut in_block = 0;
    let rows_px = px.chunks_exact(w).skip(lo);
    for (((j, row), &c), &m) in (lo..=hi)
        .zip(rows_px)
        .zip(&comp[lo..=hi])
        .zip(&mask[lo..=hi])
    {
        let row = &row[s..s + N * width];
        let bits = c >> s;
        let whole = (m >> s) & window == bits;
        for k in 0..N {
            let mut v = l.sub_sat(l.load(row, k * width), t);
            if !whole {
                v = l.select(v, bits >> (k * width));
            }
            a[k] = l.add(a[k], v);
            b[k] = l.add(b[k], a[k]);
            zeros[k] = l.count_zeros(zeros[k], v);
            zeros_cum[k] = l.add(zeros_cum[k], zeros[k]);
        }
        in_block += 1;
        if in_block == block || j == hi {
            fold::<L, N, true>(l, &mut sums, &mut a, &mut b, &cols, j);
            in_block = 0;
        }
    }
    // Counts from the zero lanes: `zeros <= 64`, `zeros_cum <= 2080`, columns below 64.
    let (mut z_sum, mut z_col, mut z_cum) = (l.sum_zero(), l.sum_zero(), l.sum_zero());
    for k in 0..N {
        z_sum = l.sum_add(z_sum, zeros[k]);
        z_col = l.sum_weighted(z_col, zeros[k], cols[k]);
        z_cum = l.sum_add(z_cum, zeros_cum[k]);
    }
    let (z_sum, z_col, z_cum) = (l.hsum(z_sum), l.hsum(z_col), l.hsum(z_cum));
    let lanes = (N * width) as u64;
    let sum_cols = lanes * s as u64 + lanes * (lanes - 1) / 2;
    let sum_rows = (lo + hi) as u64 * rows / 2;
    let n = lanes * rows - z_sum;
    let sum_i = rows * sum_cols - z_col;
    // Over the rows, j times "non-zero" is the sum of the rows less j times "zero", which is
    // `(hi + 1) zeros - zeros_cum`.
    let sum_j = lanes * sum_rows - ((hi as u64 + 1) * z_sum - z_cum);
    let t = u64::from(threshold);
    Moments {
        n,
        sum_i,
        sum_j,
        sum_p: sums.v + t * n,
        sum_pi: sums.iv + t * sum_i,
        sum_pj: sums.jv + t * sum_j,
    }
}

/// One pass over the rows of a simple component: see [`simple_component`]. A row is `N` vectors: the first `N - 1`
/// whole, the last the row's remaining pixels as a span.
struct Walk<'a, L: Lanes, const N: usize> {
    l: L,
    px: &'a [u16],
    w: usize,
    h: usize,
    /// The threshold, broadcast.
    t: L::V,
    /// The row's last vector.
    last: L::Span,
    /// Column of each lane of the row's vectors.
    cols: [L::Cols; N],
    /// Rows of 16-bit sums that cannot overflow (at least 1).
    block: usize,
    /// Count, twice the sum of i, sum of j.
    n: u64,
    sum_i2: u64,
    sum_j: u64,
    sums: Sums,
    /// Union of the rows' masks.
    union: u64,
}

impl<L: Lanes, const N: usize> Walk<'_, L, N> {
    /// Row `j`'s above-threshold mask and its `value -sat threshold` as vectors (0 at or below the threshold and in
    /// the lanes of the last vector outside the row's last pixels).
    #[inline(always)]
    fn classify(&self, j: usize) -> (u64, [L::V; N]) {
        let (l, w, width) = (self.l, self.w, L::WIDTH);
        let row = &self.px[j * w..j * w + w];
        let mut v = [l.zero(); N];
        for (k, v) in v.iter_mut().enumerate().take(N - 1) {
            *v = l.sub_sat(l.load(row, k * width), self.t);
        }
        v[N - 1] = l.excess_span(row, self.last, self.t);
        let mut bits = 0u64;
        let mut k = 0;
        while k + 2 < N {
            bits |= l.nonzero_bits2(v[k], v[k + 1]) << (k * width);
            k += 2;
        }
        if k + 1 < N {
            bits |= l.nonzero_bits(v[k]) << (k * width);
        }
        bits |= l.nonzero_bits(v[N - 1]) << l.span_offset(self.last);
        (bits, v)
    }

    /// Takes the rows from `start` on, downwards (`DOWN`, to the last row at most) or upwards (to row 0), while
    /// they continue the simple component, `prev` being the mask of the row before `start` (or of `start`
    /// itself). Returns the number of rows taken, or `None` if the component is not simple.
    #[inline(always)]
    fn rows<const DOWN: bool>(&mut self, start: usize, mut prev: u64) -> Option<usize> {
        let l = self.l;
        let (mut a, mut b) = ([l.zero(); N], [l.zero(); N]);
        let (mut n, mut sum_i2, mut sum_j, mut union) = (0u64, 0u64, 0u64, 0u64);
        let mut left = self.block;
        // Rows `start..end` (down) or `end + 1..=start` (up, `end` wrapping below 0) are taken.
        let mut end = start;
        loop {
            if DOWN && end == self.h {
                break;
            }
            let (mask, v) = self.classify(end);
            if mask == 0 {
                break;
            }
            if !single_run(mask) || dilate(prev) & mask == 0 {
                return None;
            }
            let lowest = u64::from(mask.trailing_zeros());
            let highest = u64::from(63 - mask.leading_zeros());
            let count = highest - lowest + 1;
            n += count;
            sum_i2 += count * (lowest + highest);
            sum_j += count * end as u64;
            union |= mask;
            for k in 0..N {
                a[k] = l.add(a[k], v[k]);
                b[k] = l.add(b[k], a[k]);
            }
            prev = mask;
            left -= 1;
            if left == 0 {
                fold::<L, N, DOWN>(l, &mut self.sums, &mut a, &mut b, &self.cols, end);
                left = self.block;
            }
            if DOWN {
                end += 1;
            } else if end == 0 {
                end = usize::MAX;
                break;
            } else {
                end -= 1;
            }
        }
        let taken = if DOWN {
            end - start
        } else {
            start.wrapping_sub(end)
        };
        if left != self.block {
            let last = if DOWN { end - 1 } else { end.wrapping_add(1) };
            fold::<L, N, DOWN>(l, &mut self.sums, &mut a, &mut b, &self.cols, last);
        }
        self.n += n;
        self.sum_i2 += sum_i2;
        self.sum_j += sum_j;
        self.union |= union;
        Some(taken)
    }
}

/// The seed's component when it is simple: the non-empty rows of the threshold mask around the seed's (row
/// `seed_j`) are single runs each touching the next (a convex blob's, nearly always), so that the component is
/// these rows' masks whole. Then found and measured in one pass over its rows (and the empty row past each end, if
/// any): its moments, first and last rows, and union of columns. `None` when it is not simple. For
/// `WIDTH * (N - 1) < w <= WIDTH * N` and `w >= L::MIN_PIXELS`; `levels` the threshold and the ROI's maximum, above
/// it.
#[inline(always)]
pub(super) fn simple_component<L: Lanes, const N: usize>(
    l: L,
    px: &[u16],
    (w, h): (usize, usize),
    seed_j: usize,
    (threshold, peak): (u16, u16),
) -> Option<Found> {
    let width = L::WIDTH;
    assert!(width * (N - 1) < w && w <= width * N && px.len() == w * h);
    let last = l.span(width * (N - 1), w);
    let mut cols: [L::Cols; N] = std::array::from_fn(|k| l.cols(k * width));
    cols[N - 1] = l.cols(l.span_offset(last));
    let mut walk = Walk {
        l,
        px,
        w,
        h,
        t: l.splat(threshold),
        last,
        cols,
        block: block_rows(u64::from(peak - threshold), h as u64) as usize,
        n: 0,
        sum_i2: 0,
        sum_j: 0,
        sums: Sums::default(),
        union: 0,
    };
    let seed_mask = walk.classify(seed_j).0;
    let down = walk.rows::<true>(seed_j, seed_mask)?;
    let up = if seed_j > 0 {
        walk.rows::<false>(seed_j - 1, seed_mask)?
    } else {
        0
    };
    let t = u64::from(threshold);
    let sum_i = walk.sum_i2 / 2;
    let moments = Moments {
        n: walk.n,
        sum_i,
        sum_j: walk.sum_j,
        sum_p: walk.sums.v + t * walk.n,
        sum_pi: walk.sums.iv + t * sum_i,
        sum_pj: walk.sums.jv + t * walk.sum_j,
    };
    Some((moments, (seed_j - up, seed_j + down - 1), walk.union))
}
