//! AVX-512 kernels (F and BW, with BMI1, LZCNT and POPCNT), for the CPUs that have them (see [`super::Isa`]): 32 pixels
//! a register, loaded under a mask at any width, and comparisons that give each row's above-threshold mask directly.
//! Each is a `#[target_feature]` function, in which the intrinsics are safe to call (only the loads and gathers, which
//! take raw pointers, need `unsafe`); callers' `unsafe` blocks assert the CPU's features.

use std::arch::x86_64::*;

use crate::centroid::component::{dilate, single_run};
use crate::centroid::moments::Moments;

/// Whether the CPU runs these kernels (std caches the answer).
pub(super) fn available() -> bool {
    is_x86_feature_detected!("avx512f")
        && is_x86_feature_detected!("avx512bw")
        && is_x86_feature_detected!("bmi1")
        && is_x86_feature_detected!("lzcnt")
        && is_x86_feature_detected!("popcnt")
}

/// The lowest `n` bits (`n <= 32`).
#[inline]
fn low_bits(n: usize) -> u32 {
    ((1u64 << n) - 1) as u32
}

/// 32 pixels.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn load32(px: &[u16; 32]) -> __m512i {
    // SAFETY: `px` is 64 readable bytes, and `_mm512_loadu_si512` reads 64 bytes at any alignment.
    unsafe { _mm512_loadu_si512(px.as_ptr().cast()) }
}

/// The first `min(32, px.len())` pixels of `px`, the other lanes 0.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn load(px: &[u16]) -> __m512i {
    // SAFETY: only the lanes in bounds are read (the others, masked off, are neither read nor fault), at any
    // alignment.
    unsafe { _mm512_maskz_loadu_epi16(low_bits(px.len().min(32)), px.as_ptr().cast()) }
}

/// The largest of the 32 unsigned lanes.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn hmax(m: __m512i) -> u16 {
    let m = _mm256_max_epu16(_mm512_castsi512_si256(m), _mm512_extracti64x4_epi64(m, 1));
    let m = _mm_max_epu16(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
    // The complement's minimum.
    !(_mm_cvtsi128_si32(_mm_minpos_epu16(_mm_xor_si128(m, _mm_set1_epi16(-1)))) as u16)
}

/// The smallest of the 32 unsigned lanes.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn hmin(m: __m512i) -> u16 {
    let m = _mm256_min_epu16(_mm512_castsi512_si256(m), _mm512_extracti64x4_epi64(m, 1));
    let m = _mm_min_epu16(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
    _mm_cvtsi128_si32(_mm_minpos_epu16(m)) as u16
}

/// The 32 unsigned 16-bit lanes as two vectors of 16 32-bit lanes (lanes 0-15, 16-31).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn widen(v: __m512i) -> (__m512i, __m512i) {
    (
        _mm512_cvtepu16_epi32(_mm512_castsi512_si256(v)),
        _mm512_cvtepu16_epi32(_mm512_extracti64x4_epi64(v, 1)),
    )
}

/// Sum of the 32 unsigned 16-bit lanes (the callers' sums fit 31 bits).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn hsum(v: __m512i) -> u64 {
    let (lo, hi) = widen(v);
    _mm512_reduce_add_epi32(_mm512_add_epi32(lo, hi)) as u32 as u64
}

/// 0 to 15 (32-bit lanes).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn lane_index32() -> __m512i {
    _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
}

/// The largest pixel and the index of its first occurrence (`px` not empty).
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
pub(super) fn peak(px: &[u16]) -> (u16, usize) {
    let mut chunks = px.chunks_exact(32);
    let mut m = _mm512_setzero_si512();
    for c in chunks.by_ref() {
        m = _mm512_max_epu16(m, load32(c.try_into().expect("32 pixels")));
    }
    let rest = chunks.remainder();
    let peak = hmax(_mm512_max_epu16(m, load(rest)));
    let v = _mm512_set1_epi16(peak as i16);
    for (c, chunk) in px.chunks_exact(32).enumerate() {
        let eq = _mm512_cmpeq_epi16_mask(load32(chunk.try_into().expect("32 pixels")), v);
        if eq != 0 {
            return (peak, 32 * c + eq.trailing_zeros() as usize);
        }
    }
    let eq = _mm512_cmpeq_epi16_mask(load(rest), v) & low_bits(rest.len());
    let at = if eq == 0 {
        0
    } else {
        px.len() - rest.len() + eq.trailing_zeros() as usize
    };
    (peak, at)
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image (`w, h >= 2`): the top row but
/// its last pixel, the bottom row but its first, and the (last, first) pixel pairs of consecutive rows, which are
/// adjacent in memory (gathered 16 pairs at a time).
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
pub(super) fn border_min_max_sum(px: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
    let z = _mm512_setzero_si512();
    let (mut min, mut max, mut sum) = (_mm512_set1_epi16(-1), z, z);
    let mut add = |v: __m512i, lanes: u32| {
        min = _mm512_mask_min_epu16(min, lanes, min, v);
        max = _mm512_max_epu16(max, v);
        let (lo, hi) = widen(v);
        sum = _mm512_add_epi32(sum, _mm512_add_epi32(lo, hi));
    };
    for seg in [&px[..w - 1], &px[(h - 1) * w + 1..h * w]] {
        for part in seg.chunks(32) {
            add(load(part), low_bits(part.len()));
        }
    }
    // Pair j (rows j and j + 1) at `j * w` in `pairs`.
    let pairs = &px[w - 1..(h - 1) * w + 1];
    let step = _mm512_mullo_epi32(lane_index32(), _mm512_set1_epi32(w as i32));
    for first in (0..h - 1).step_by(16) {
        let n = (h - 1 - first).min(16);
        let offsets = _mm512_add_epi32(step, _mm512_set1_epi32((first * w) as i32));
        // SAFETY: pair j is `pairs[j * w..j * w + 2]`, in bounds for j < h - 1; the lanes past `n` pairs are
        // masked off (not read).
        let v = unsafe {
            _mm512_mask_i32gather_epi32(
                z,
                low_bits(n) as __mmask16,
                offsets,
                pairs.as_ptr().cast(),
                2,
            )
        };
        add(v, low_bits(2 * n));
    }
    (
        hmin(min),
        hmax(max),
        _mm512_reduce_add_epi32(sum) as u32 as u64,
    )
}

/// One pass over the rows of a simple component: see [`simple_component`]. Rows are `N` registers of 32 pixels
/// (`32 * (N - 1) < w <= 32 * N`).
struct Walk<'a, const N: usize> {
    px: &'a [u16],
    w: usize,
    h: usize,
    /// The threshold, broadcast.
    t: __m512i,
    /// Lanes of each register inside the row.
    lanes: [u32; N],
    /// Rows of 16-bit sums that cannot overflow (at least 1).
    block: usize,
    /// Integer sums: count, twice the sum of i, sum of j, and of `v = value - threshold` unweighted and weighted by
    /// i and by j.
    n: u64,
    sum_i2: u64,
    sum_j: u64,
    sum_v: u64,
    sum_iv: u64,
    sum_jv: u64,
}

impl<const N: usize> Walk<'_, N> {
    /// Row `j`'s above-threshold mask and its `value -sat threshold` (0 at or below the threshold and past the
    /// row's end).
    #[inline]
    #[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
    fn classify(&self, j: usize) -> (u64, [__m512i; N]) {
        let row = &self.px[j * self.w..(j + 1) * self.w];
        let mut v = [_mm512_setzero_si512(); N];
        let mut mask = 0;
        for (k, (v, &lanes)) in v.iter_mut().zip(&self.lanes).enumerate() {
            // SAFETY: the lanes of `lanes` are pixels `32 * k..w` of the row; the others, masked off, are neither
            // read nor fault.
            let p = unsafe {
                _mm512_maskz_loadu_epi16(lanes, row.as_ptr().wrapping_add(32 * k).cast())
            };
            *v = _mm512_subs_epu16(p, self.t);
            mask |= u64::from(_mm512_test_epi16_mask(*v, *v)) << (32 * k);
        }
        (mask, v)
    }

    /// Folds the 16-bit sums `a` (of `v` per lane over a block of rows, `last` the block's last row walked) and
    /// `b` (running sums of `a`) into the totals and clears them. Walking down, row j counts `last + 1 - j`
    /// times in `b`; walking up, `j + 1 - last` times.
    #[inline]
    #[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
    fn fold<const DOWN: bool>(&mut self, a: &mut [__m512i; N], b: &mut [__m512i; N], last: usize) {
        let (mut sa, mut sb, mut sia) = (0, 0, 0);
        for k in 0..N {
            let (lo, hi) = widen(a[k]);
            let col = _mm512_add_epi32(lane_index32(), _mm512_set1_epi32(32 * k as i32));
            let col_hi = _mm512_add_epi32(col, _mm512_set1_epi32(16));
            sa += _mm512_reduce_add_epi32(_mm512_add_epi32(lo, hi)) as u32 as u64;
            sia += _mm512_reduce_add_epi32(_mm512_add_epi32(
                _mm512_mullo_epi32(lo, col),
                _mm512_mullo_epi32(hi, col_hi),
            )) as u32 as u64;
            sb += hsum(b[k]);
            a[k] = _mm512_setzero_si512();
            b[k] = _mm512_setzero_si512();
        }
        let last = last as u64;
        self.sum_v += sa;
        self.sum_iv += sia;
        self.sum_jv += if DOWN {
            (last + 1) * sa - sb
        } else {
            sb + last * sa - sa
        };
    }

    /// Takes the rows from `start` on, downwards (`DOWN`, to the last row at most) or upwards (to row 0), while
    /// they continue the simple component, `prev` being the mask of the row before `start` (or of `start`
    /// itself), `union` the union of their masks. Returns the number of rows taken, or `None` if the component
    /// is not simple.
    #[inline]
    #[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
    fn rows<const DOWN: bool>(
        &mut self,
        start: usize,
        mut prev: u64,
        union: &mut u64,
    ) -> Option<usize> {
        let z = _mm512_setzero_si512();
        let (mut a, mut b) = ([z; N], [z; N]);
        let (mut n, mut sum_i2, mut sum_j) = (0u64, 0u64, 0u64);
        let mut left = self.block;
        // Rows `start..end` (down) or `end + 1..=start` (up, `end` wrapping below 0) are taken.
        let mut end = start;
        loop {
            let (mask, v) = self.classify(end);
            if mask == 0 {
                break;
            }
            if !single_run(mask) || dilate(prev) & mask == 0 {
                return None;
            }
            let count = u64::from(mask.count_ones());
            let ends = u64::from(mask.trailing_zeros()) + u64::from(63 - mask.leading_zeros());
            n += count;
            sum_i2 += count * ends;
            sum_j += count * end as u64;
            *union |= mask;
            for k in 0..N {
                a[k] = _mm512_add_epi16(a[k], v[k]);
                b[k] = _mm512_add_epi16(b[k], a[k]);
            }
            prev = mask;
            left -= 1;
            if left == 0 {
                self.fold::<DOWN>(&mut a, &mut b, end);
                left = self.block;
            }
            if DOWN {
                end += 1;
                if end == self.h {
                    break;
                }
            } else {
                end = end.wrapping_sub(1);
                if end == usize::MAX {
                    break;
                }
            }
        }
        let taken = if DOWN {
            end - start
        } else {
            start.wrapping_sub(end)
        };
        if left != self.block {
            let last = if DOWN { end - 1 } else { end.wrapping_add(1) };
            self.fold::<DOWN>(&mut a, &mut b, last);
        }
        self.n += n;
        self.sum_i2 += sum_i2;
        self.sum_j += sum_j;
        Some(taken)
    }
}

/// As `sse2::simple_component`, for `32 * (N - 1) < w <= 32 * N`.
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
pub(super) fn simple_component<const N: usize>(
    px: &[u16],
    (w, h): (usize, usize),
    seed_j: usize,
    threshold: u16,
    peak: u16,
) -> Option<(Moments, (usize, usize), u64)> {
    assert!(32 * (N - 1) < w && w <= 32 * N && px.len() == w * h);
    let mut lanes = [0; N];
    for (k, l) in lanes.iter_mut().enumerate() {
        *l = low_bits((w - 32 * k).min(32));
    }
    let mut walk = Walk {
        px,
        w,
        h,
        t: _mm512_set1_epi16(threshold as i16),
        lanes,
        block: super::block_rows(u64::from(peak - threshold), h as u64) as usize,
        n: 0,
        sum_i2: 0,
        sum_j: 0,
        sum_v: 0,
        sum_iv: 0,
        sum_jv: 0,
    };
    let seed_mask = walk.classify(seed_j).0;
    let mut union = 0;
    let down = walk.rows::<true>(seed_j, seed_mask, &mut union)?;
    let up = if seed_j > 0 {
        walk.rows::<false>(seed_j - 1, seed_mask, &mut union)?
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
    Some((moments, (seed_j - up, seed_j + down - 1), union))
}
