//! SSE2 kernels. SSE2 is part of the x86_64 baseline, so every x86_64 CPU runs them. Each is a
//! `#[target_feature(enable = "sse2")]` function, in which the intrinsics are safe to call (only the unaligned loads,
//! which take raw pointers, need `unsafe`); callers' `unsafe` blocks only assert the feature.

use std::arch::x86_64::*;

use crate::centroid::component::{dilate, single_run};
use crate::centroid::moments::Moments;

/// Pixels `k..k + 8` of `px`.
#[inline]
#[target_feature(enable = "sse2")]
fn load(px: &[u16], k: usize) -> __m128i {
    let chunk: &[u16; 8] = px[k..k + 8].try_into().expect("8 pixels");
    // SAFETY: `chunk` is 16 readable bytes, and `_mm_loadu_si128` reads 16 bytes at any alignment.
    unsafe { _mm_loadu_si128(chunk.as_ptr().cast()) }
}

/// Lane-wise unsigned maximum (SSE2 has only the signed one).
#[inline]
#[target_feature(enable = "sse2")]
fn max_epu16(a: __m128i, b: __m128i) -> __m128i {
    _mm_adds_epu16(_mm_subs_epu16(a, b), b)
}

/// The largest of the eight unsigned lanes.
#[inline]
#[target_feature(enable = "sse2")]
fn hmax(m: __m128i) -> u16 {
    let m = max_epu16(m, _mm_shuffle_epi32(m, 0b01_00_11_10));
    let m = max_epu16(m, _mm_shuffle_epi32(m, 0b10_11_00_01));
    let m = max_epu16(m, _mm_shufflelo_epi16(m, 0b10_11_00_01));
    _mm_extract_epi16(m, 0) as u16
}

/// Sum of the four 32-bit lanes (the callers' sums fit 32 bits).
#[inline]
#[target_feature(enable = "sse2")]
fn hsum32(v: __m128i) -> u32 {
    let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b01_00_11_10));
    let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b10_11_00_01));
    _mm_cvtsi128_si32(v) as u32
}

/// The eight unsigned 16-bit lanes summed pairwise into four 32-bit lanes.
#[inline]
#[target_feature(enable = "sse2")]
fn widen_sum(v: __m128i) -> __m128i {
    let z = _mm_setzero_si128();
    _mm_add_epi32(_mm_unpacklo_epi16(v, z), _mm_unpackhi_epi16(v, z))
}

/// The largest pixel and the index of its first occurrence (`px.len() >= 8`).
#[target_feature(enable = "sse2")]
pub(super) fn peak(px: &[u16]) -> (u16, usize) {
    let z = _mm_setzero_si128();
    let (mut m0, mut m1, mut m2, mut m3) = (z, z, z, z);
    let mut chunks = px.chunks_exact(32);
    for c in chunks.by_ref() {
        m0 = max_epu16(m0, load(c, 0));
        m1 = max_epu16(m1, load(c, 8));
        m2 = max_epu16(m2, load(c, 16));
        m3 = max_epu16(m3, load(c, 24));
    }
    let mut eights = chunks.remainder().chunks_exact(8);
    for c in eights.by_ref() {
        m0 = max_epu16(m0, load(c, 0));
    }
    if !eights.remainder().is_empty() {
        // The last eight pixels, overlapping pixels already seen: harmless for a maximum.
        m1 = max_epu16(m1, load(px, px.len() - 8));
    }
    let peak = hmax(max_epu16(max_epu16(m0, m1), max_epu16(m2, m3)));
    // The first 32 pixels holding it, then the pixel.
    let v = _mm_set1_epi16(peak as i16);
    let mut chunks = px.chunks_exact(32);
    for (c, chunk) in chunks.by_ref().enumerate() {
        let eq = _mm_or_si128(
            _mm_or_si128(
                _mm_cmpeq_epi16(load(chunk, 0), v),
                _mm_cmpeq_epi16(load(chunk, 8), v),
            ),
            _mm_or_si128(
                _mm_cmpeq_epi16(load(chunk, 16), v),
                _mm_cmpeq_epi16(load(chunk, 24), v),
            ),
        );
        if _mm_movemask_epi8(eq) != 0 {
            let low = _mm_packs_epi16(
                _mm_cmpeq_epi16(load(chunk, 0), v),
                _mm_cmpeq_epi16(load(chunk, 8), v),
            );
            let high = _mm_packs_epi16(
                _mm_cmpeq_epi16(load(chunk, 16), v),
                _mm_cmpeq_epi16(load(chunk, 24), v),
            );
            let bits = (_mm_movemask_epi8(low) as u32) | (_mm_movemask_epi8(high) as u32) << 16;
            return (peak, 32 * c + bits.trailing_zeros() as usize);
        }
    }
    let done = px.len() - chunks.remainder().len();
    let at = chunks.remainder().iter().position(|&p| p == peak);
    (peak, at.map_or(0, |k| done + k))
}

/// Bit i set where `px[i] <= threshold` (broadcast in `t`), for 16 pixels.
#[inline]
#[target_feature(enable = "sse2")]
fn at_most16(px: &[u16], t: __m128i) -> u64 {
    let z = _mm_setzero_si128();
    // `p <= t` where `p - t` saturates to 0.
    let a = _mm_cmpeq_epi16(_mm_subs_epu16(load(px, 0), t), z);
    let b = _mm_cmpeq_epi16(_mm_subs_epu16(load(px, 8), t), z);
    u64::from(_mm_movemask_epi8(_mm_packs_epi16(a, b)) as u32)
}

/// Bit i set where `px[i] <= threshold` (broadcast in `t`), for 8 pixels.
#[inline]
#[target_feature(enable = "sse2")]
fn at_most8(px: &[u16], t: __m128i) -> u64 {
    let z = _mm_setzero_si128();
    let a = _mm_cmpeq_epi16(_mm_subs_epu16(load(px, 0), t), z);
    u64::from(_mm_movemask_epi8(_mm_packs_epi16(a, z)) as u32)
}

/// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold` (`8 <= w <= 64`).
#[target_feature(enable = "sse2")]
pub(super) fn row_masks(pixels: &[u16], w: usize, threshold: u16, rows: &mut [u64]) {
    let t = _mm_set1_epi16(threshold as i16);
    let width = u64::MAX >> (64 - w);
    let tail = w % 8;
    for (m, row) in rows.iter_mut().zip(pixels.chunks_exact(w)) {
        let mut at_most = 0;
        let mut sixteens = row.chunks_exact(16);
        for (c, chunk) in sixteens.by_ref().enumerate() {
            at_most |= at_most16(chunk, t) << (16 * c);
        }
        let rest = sixteens.remainder();
        if rest.len() >= 8 {
            at_most |= at_most8(rest, t) << (w - rest.len());
        }
        if tail != 0 {
            // The row's last 8 pixels, overlapping pixels already classified.
            at_most |= at_most8(&row[w - 8..], t) >> (8 - tail) << (w - tail);
        }
        *m = !at_most & width;
    }
}

/// Running minimum, maximum and sum of vectors of pixels, in signed lanes: each pixel less 32768 (its top bit
/// flipped), so that SSE2's signed minimum and maximum and its multiply-add apply.
struct MinMaxSum {
    min: __m128i,
    max: __m128i,
    /// Sums of pairs of lanes (32-bit).
    sum: __m128i,
    /// Pixels added.
    count: u64,
}

impl MinMaxSum {
    /// Adds the `count` pixels of `v` whose lanes are set in `sum_lanes` to the sum and all its lanes to the
    /// minimum and maximum (the others repeat pixels added).
    #[inline]
    #[target_feature(enable = "sse2")]
    fn add(&mut self, v: __m128i, sum_lanes: __m128i, count: u64) {
        let v = _mm_xor_si128(v, _mm_set1_epi16(i16::MIN));
        self.min = _mm_min_epi16(self.min, v);
        self.max = _mm_max_epi16(self.max, v);
        let v = _mm_and_si128(v, sum_lanes);
        self.sum = _mm_add_epi32(self.sum, _mm_madd_epi16(v, _mm_set1_epi16(1)));
        self.count += count;
    }

    /// Adds `seg` (at least 8 pixels), 8 at a time, the last 8 overlapping those before them.
    #[inline]
    #[target_feature(enable = "sse2")]
    fn add_segment(&mut self, seg: &[u16]) {
        let all = _mm_set1_epi16(-1);
        let mut eights = seg.chunks_exact(8);
        for c in eights.by_ref() {
            self.add(load(c, 0), all, 8);
        }
        let rest = eights.remainder().len();
        if rest > 0 {
            let new = _mm_cmpgt_epi16(lane_index(), _mm_set1_epi16(7 - rest as i16));
            self.add(load(seg, seg.len() - 8), new, rest as u64);
        }
    }

    /// (minimum, maximum, sum).
    #[inline]
    #[target_feature(enable = "sse2")]
    fn finish(&self) -> (u16, u16, u64) {
        let min = _mm_min_epi16(self.min, _mm_shuffle_epi32(self.min, 0b01_00_11_10));
        let min = _mm_min_epi16(min, _mm_shuffle_epi32(min, 0b10_11_00_01));
        let min = _mm_min_epi16(min, _mm_shufflelo_epi16(min, 0b10_11_00_01));
        let max = _mm_max_epi16(self.max, _mm_shuffle_epi32(self.max, 0b01_00_11_10));
        let max = _mm_max_epi16(max, _mm_shuffle_epi32(max, 0b10_11_00_01));
        let max = _mm_max_epi16(max, _mm_shufflelo_epi16(max, 0b10_11_00_01));
        let sum = i64::from(hsum32(self.sum) as i32) + 32768 * self.count as i64;
        (
            _mm_extract_epi16(min, 0) as u16 ^ 0x8000,
            _mm_extract_epi16(max, 0) as u16 ^ 0x8000,
            sum as u64,
        )
    }
}

/// 0 to 7.
#[inline]
#[target_feature(enable = "sse2")]
fn lane_index() -> __m128i {
    _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7)
}

/// Pixels `k` and `k + 1` of `px` as one 32-bit lane.
#[inline]
fn pair(px: &[u16], k: usize) -> i32 {
    let two: &[u16; 2] = px[k..k + 2].try_into().expect("2 pixels");
    // SAFETY: `two` is 4 readable bytes; `read_unaligned` reads them at any alignment.
    unsafe { two.as_ptr().cast::<i32>().read_unaligned() }
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image (`w > 8`, `h > 1`): the top row
/// but its last pixel, the bottom row but its first, and the (last, first) pixel pairs of consecutive rows, which
/// are adjacent in memory.
#[target_feature(enable = "sse2")]
pub(super) fn border_min_max_sum(px: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
    let mut acc = MinMaxSum {
        min: _mm_set1_epi16(i16::MAX),
        max: _mm_set1_epi16(i16::MIN),
        sum: _mm_setzero_si128(),
        count: 0,
    };
    acc.add_segment(&px[..w - 1]);
    acc.add_segment(&px[(h - 1) * w + 1..h * w]);
    // Pairs `(j + 1) * w - 1` for rows j = 0..h - 1, four a vector.
    let all = _mm_set1_epi16(-1);
    let pairs = &px[w - 1..(h - 1) * w + 1];
    let mut j = 0;
    while j + 4 < h {
        let v = _mm_setr_epi32(
            pair(pairs, j * w),
            pair(pairs, (j + 1) * w),
            pair(pairs, (j + 2) * w),
            pair(pairs, (j + 3) * w),
        );
        acc.add(v, all, 8);
        j += 4;
    }
    // The last 1 to 3 pairs, the last one repeated (and left out of the sum).
    let rest = h - 1 - j;
    if rest > 0 {
        let at = |k: usize| pair(pairs, (j + k.min(rest - 1)) * w);
        let v = _mm_setr_epi32(at(0), at(1), at(2), at(3));
        let new = _mm_cmpgt_epi16(_mm_set1_epi16(2 * rest as i16), lane_index());
        acc.add(v, new, 2 * rest as u64);
    }
    acc.finish()
}

/// One row's contribution: `v` (the component's `value - threshold`, 0 elsewhere) into the sum `a`, the running
/// sum of sums `b` (for the row moment), the count of zero lanes `zeros` and its running sum `zeros_cum`.
#[inline]
#[target_feature(enable = "sse2")]
fn accumulate(
    v: __m128i,
    a: &mut __m128i,
    b: &mut __m128i,
    zeros: &mut __m128i,
    zeros_cum: &mut __m128i,
) {
    *a = _mm_add_epi16(*a, v);
    *b = _mm_add_epi16(*b, *a);
    *zeros = _mm_sub_epi16(*zeros, _mm_cmpeq_epi16(v, _mm_setzero_si128()));
    *zeros_cum = _mm_add_epi16(*zeros_cum, *zeros);
}

/// The moments of the component `comp` (rows `lo..=hi`, within columns `s..s + 8 * N <= w`), `mask` the
/// above-threshold pixels, `peak` the ROI's maximum.
///
/// Per lane (column) it sums `v = value - threshold` (positive exactly on the component) in 16 bits over blocks of
/// rows short enough not to overflow, with the running sum of those sums (the sum over rows of `(last + 1 - j) v`,
/// whence the row moment), and counts the lanes where `v` is 0. Where the row's mask holds nothing but the
/// component in the window (nearly always), `v` is `value -sat threshold`; elsewhere the component's bits mask it.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "sse2")]
pub(super) fn window_moments<const N: usize>(
    px: &[u16],
    w: usize,
    comp: &[u64],
    mask: &[u64],
    (lo, hi): (usize, usize),
    s: usize,
    threshold: u16,
    peak: u16,
) -> Moments {
    let z = _mm_setzero_si128();
    let t = _mm_set1_epi16(threshold as i16);
    let lane_bit = _mm_setr_epi16(1, 2, 4, 8, 16, 32, 64, 128);
    let lane_index = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7);
    let window = u64::MAX >> (64 - 8 * N);
    let (mut a, mut b, mut zeros, mut zeros_cum) = ([z; N], [z; N], [z; N], [z; N]);
    let rows = (hi - lo + 1) as u64;
    let block = super::block_rows(u64::from(peak - threshold), rows);
    let (mut sum_v, mut sum_iv, mut sum_jv) = (0u64, 0u64, 0u64);
    let mut in_block = 0;
    let rows_px = px.chunks_exact(w).skip(lo);
    for (((j, row), &c), &m) in (lo..=hi)
        .zip(rows_px)
        .zip(&comp[lo..=hi])
        .zip(&mask[lo..=hi])
    {
        let row = &row[s..s + 8 * N];
        let bits = c >> s;
        if (m >> s) & window == bits {
            for k in 0..N {
                let v = _mm_subs_epu16(load(row, 8 * k), t);
                accumulate(v, &mut a[k], &mut b[k], &mut zeros[k], &mut zeros_cum[k]);
            }
        } else {
            for k in 0..N {
                let byte = _mm_set1_epi16(((bits >> (8 * k)) & 0xFF) as i16);
                let in_comp = _mm_cmpeq_epi16(_mm_and_si128(byte, lane_bit), lane_bit);
                let v = _mm_and_si128(_mm_subs_epu16(load(row, 8 * k), t), in_comp);
                accumulate(v, &mut a[k], &mut b[k], &mut zeros[k], &mut zeros_cum[k]);
            }
        }
        in_block += 1;
        if in_block == block || j == hi {
            // Into 64-bit totals (each 32-bit lane sum below holds at most 2N products of 16 and 6 bits).
            let (mut sa, mut sb, mut sia) = (z, z, z);
            for k in 0..N {
                sa = _mm_add_epi32(sa, widen_sum(a[k]));
                sb = _mm_add_epi32(sb, widen_sum(b[k]));
                let col = _mm_add_epi16(_mm_set1_epi16((s + 8 * k) as i16), lane_index);
                let (lo16, hi16) = (_mm_mullo_epi16(a[k], col), _mm_mulhi_epu16(a[k], col));
                sia = _mm_add_epi32(
                    sia,
                    _mm_add_epi32(
                        _mm_unpacklo_epi16(lo16, hi16),
                        _mm_unpackhi_epi16(lo16, hi16),
                    ),
                );
                a[k] = z;
                b[k] = z;
            }
            let (sa, sb) = (u64::from(hsum32(sa)), u64::from(hsum32(sb)));
            sum_v += sa;
            sum_iv += u64::from(hsum32(sia));
            sum_jv += (j as u64 + 1) * sa - sb;
            in_block = 0;
        }
    }
    // Counts from the zero lanes: `zeros <= 64`, `zeros_cum <= 2080`, columns < 64 (products fit 16-bit lanes'
    // signed multiply-adds).
    let ones = _mm_set1_epi16(1);
    let (mut z_sum, mut z_col, mut z_cum) = (z, z, z);
    for k in 0..N {
        let col = _mm_add_epi16(_mm_set1_epi16((s + 8 * k) as i16), lane_index);
        z_sum = _mm_add_epi32(z_sum, _mm_madd_epi16(zeros[k], ones));
        z_col = _mm_add_epi32(z_col, _mm_madd_epi16(zeros[k], col));
        z_cum = _mm_add_epi32(z_cum, _mm_madd_epi16(zeros_cum[k], ones));
    }
    let (z_sum, z_col, z_cum) = (
        u64::from(hsum32(z_sum)),
        u64::from(hsum32(z_col)),
        u64::from(hsum32(z_cum)),
    );
    let lanes = 8 * N as u64;
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
        sum_p: sum_v + t * n,
        sum_pi: sum_iv + t * sum_i,
        sum_pj: sum_jv + t * sum_j,
    }
}

/// The eight 16-bit lanes of `a` (each at most 65535) times those of `col` (each below 64), summed pairwise into
/// four 32-bit lanes.
#[inline]
#[target_feature(enable = "sse2")]
fn weighted_sum(a: __m128i, col: __m128i) -> __m128i {
    let (lo16, hi16) = (_mm_mullo_epi16(a, col), _mm_mulhi_epu16(a, col));
    _mm_add_epi32(
        _mm_unpacklo_epi16(lo16, hi16),
        _mm_unpackhi_epi16(lo16, hi16),
    )
}

/// One pass over the rows of a simple component: see [`simple_component`].
struct Walk<'a, const N: usize> {
    px: &'a [u16],
    w: usize,
    h: usize,
    /// The threshold, broadcast.
    t: __m128i,
    /// Lanes of the row's last vector not already in the one before it.
    keep: __m128i,
    /// Column of each lane of the row's vectors.
    cols: [__m128i; N],
    width: u64,
    /// Rows of 16-bit sums that cannot overflow (at least 1).
    block: usize,
    /// Integer sums: count, twice the sum of i, j, `v = value - threshold`, `v * i`, `v * j`.
    n: u64,
    sum_i2: u64,
    sum_j: u64,
    sum_v: u64,
    sum_iv: u64,
    sum_jv: u64,
    /// Union of the rows' masks.
    union: u64,
}

impl<const N: usize> Walk<'_, N> {
    /// Row `j`'s above-threshold mask and its `value -sat threshold` as vectors (0 below the threshold and in the
    /// lanes of the last vector that repeat columns of the one before).
    #[inline]
    #[target_feature(enable = "sse2")]
    fn classify(&self, j: usize) -> (u64, [__m128i; N]) {
        let (w, z) = (self.w, _mm_setzero_si128());
        let row = &self.px[j * w..j * w + w];
        let mut v = [z; N];
        let mut at_most = [z; N];
        for k in 0..N {
            let offset = if k + 1 == N { w - 8 } else { 8 * k };
            v[k] = _mm_subs_epu16(load(row, offset), self.t);
            at_most[k] = _mm_cmpeq_epi16(v[k], z);
        }
        v[N - 1] = _mm_and_si128(v[N - 1], self.keep);
        let mut bits = 0u64;
        for k in (0..N - 1).step_by(2) {
            let next = if k + 2 < N { at_most[k + 1] } else { z };
            let pair = _mm_movemask_epi8(_mm_packs_epi16(at_most[k], next)) as u32;
            bits |= u64::from(pair) << (8 * k);
        }
        let last = _mm_movemask_epi8(_mm_packs_epi16(at_most[N - 1], z)) as u32;
        bits |= u64::from(last) >> (8 * N - w) << (8 * (N - 1));
        (!bits & self.width, v)
    }

    /// Folds the 16-bit sums `a` (of `v` per lane) and `b` (running sums of `a`) of a block of rows into the
    /// totals and clears them; `last` the block's last row walked.
    #[inline]
    #[target_feature(enable = "sse2")]
    fn flush<const DOWN: bool>(&mut self, a: &mut [__m128i; N], b: &mut [__m128i; N], last: usize) {
        let z = _mm_setzero_si128();
        let (mut sa, mut sb, mut sia) = (z, z, z);
        for k in 0..N {
            sa = _mm_add_epi32(sa, widen_sum(a[k]));
            sb = _mm_add_epi32(sb, widen_sum(b[k]));
            sia = _mm_add_epi32(sia, weighted_sum(a[k], self.cols[k]));
            a[k] = z;
            b[k] = z;
        }
        let (sa, sb) = (u64::from(hsum32(sa)), u64::from(hsum32(sb)));
        self.sum_v += sa;
        self.sum_iv += u64::from(hsum32(sia));
        let last = last as u64;
        // Walking down, a row j of the block (rows up to `last`) is in `last + 1 - j` of the running sums;
        // walking up (rows down to `last`), in `j + 1 - last`.
        self.sum_jv += if DOWN {
            (last + 1) * sa - sb
        } else {
            sb + last * sa - sa
        };
    }

    /// Takes the rows from `start` on, downwards (`DOWN`, to the last row at most) or upwards (to row 0), while
    /// they continue the simple component, `prev` being the mask of the row before `start` (or of `start`
    /// itself). Returns the number of rows taken, or `None` if the component is not simple.
    #[inline]
    #[target_feature(enable = "sse2")]
    fn rows<const DOWN: bool>(&mut self, start: usize, mut prev: u64) -> Option<usize> {
        let z = _mm_setzero_si128();
        let (mut a, mut b) = ([z; N], [z; N]);
        let (mut n, mut sum_i2, mut sum_j, mut union) = (0u64, 0u64, 0u64, 0u64);
        let mut left = self.block;
        // Rows `start..end` (down) or `end..=start` (up), `end` the first not taken.
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
                a[k] = _mm_add_epi16(a[k], v[k]);
                b[k] = _mm_add_epi16(b[k], a[k]);
            }
            prev = mask;
            left -= 1;
            if left == 0 {
                self.flush::<DOWN>(&mut a, &mut b, end);
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
            self.flush::<DOWN>(&mut a, &mut b, last);
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
/// `8 * (N - 1) < w <= 8 * N`; `peak` the ROI's maximum, above `threshold`.
#[target_feature(enable = "sse2")]
pub(super) fn simple_component<const N: usize>(
    px: &[u16],
    (w, h): (usize, usize),
    seed_j: usize,
    threshold: u16,
    peak: u16,
) -> Option<(Moments, (usize, usize), u64)> {
    let lane_index = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7);
    let overlap = 8 * N - w;
    let mut cols = [lane_index; N];
    for (k, col) in cols.iter_mut().enumerate() {
        let offset = if k + 1 == N { w - 8 } else { 8 * k };
        *col = _mm_add_epi16(*col, _mm_set1_epi16(offset as i16));
    }
    let mut walk = Walk {
        px,
        w,
        h,
        t: _mm_set1_epi16(threshold as i16),
        keep: _mm_cmpgt_epi16(lane_index, _mm_set1_epi16(overlap as i16 - 1)),
        cols,
        width: u64::MAX >> (64 - w),
        block: super::block_rows(u64::from(peak - threshold), h as u64) as usize,
        n: 0,
        sum_i2: 0,
        sum_j: 0,
        sum_v: 0,
        sum_iv: 0,
        sum_jv: 0,
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
        sum_p: walk.sum_v + t * walk.n,
        sum_pi: walk.sum_iv + t * sum_i,
        sum_pj: walk.sum_jv + t * walk.sum_j,
    };
    Some((moments, (seed_j - up, seed_j + down - 1), walk.union))
}
