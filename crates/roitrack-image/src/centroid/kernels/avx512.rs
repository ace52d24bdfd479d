//! The lane primitives with AVX-512 ([`Avx512`]: F and BW, with BMI1, LZCNT and POPCNT), for the CPUs that have them
//! (see [`super::Isa`]): 32 pixels a register, and the kernels' entry points for AVX-512.
//!
//! Loads under a mask read the last pixels of a slice at any width, the other lanes 0; comparisons give masks
//! directly; the border's pixel pairs are gathered 16 at a time. The primitives are `#[target_feature]` functions, in
//! which the intrinsics are safe to call (only the loads and gathers, which take raw pointers, need `unsafe`); the
//! trait's methods call them, asserting the CPU's features by the token.

use std::arch::x86_64::*;

use super::lanes::{Lanes, entry_points};

/// The AVX-512 token: exists only where the CPU has AVX-512 F and BW, BMI1, LZCNT and POPCNT.
#[derive(Debug, Clone, Copy)]
pub(super) struct Avx512(());

impl Avx512 {
    /// Whether the CPU runs these kernels (std caches the answer).
    pub(super) fn available() -> bool {
        is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx512bw")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt")
    }

    /// The token.
    ///
    /// # Safety
    /// Only where [`Avx512::available`].
    pub(super) unsafe fn new_unchecked() -> Self {
        debug_assert!(Self::available());
        Self(())
    }
}

entry_points!(
    Avx512,
    "avx512f,avx512bw,bmi1,lzcnt,popcnt",
    peak,
    border_min_max_sum,
    simple_component
);

/// The last pixels `start..end` of a slice, in lanes `0..end - start` (`keep`).
#[derive(Clone, Copy)]
pub(super) struct Span {
    start: usize,
    end: usize,
    keep: u32,
}

/// Running minimum, maximum and sum (in 32-bit lanes) of vectors of pixels.
pub(super) struct MinMaxSum {
    min: __m512i,
    max: __m512i,
    sum: __m512i,
}

/// The lowest `n` bits (`n <= 32`).
#[inline(always)]
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
fn load_part(px: &[u16]) -> __m512i {
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

/// `acc` plus the 32 lanes of `v`, widened: lanes `l` and `l + 16` into 32-bit lane `l`.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn sum_add(acc: __m512i, v: __m512i) -> __m512i {
    let (lo, hi) = widen(v);
    _mm512_add_epi32(acc, _mm512_add_epi32(lo, hi))
}

/// `acc` plus the 32 lanes of `v` times their columns (`cols.0` for lanes 0-15, `cols.1` for 16-31), in 32 bits.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn sum_weighted(acc: __m512i, v: __m512i, (col_lo, col_hi): (__m512i, __m512i)) -> __m512i {
    let (lo, hi) = widen(v);
    _mm512_add_epi32(
        acc,
        _mm512_add_epi32(
            _mm512_mullo_epi32(lo, col_lo),
            _mm512_mullo_epi32(hi, col_hi),
        ),
    )
}

/// The columns `offset..offset + 32` in two vectors of 16 32-bit lanes.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn cols(offset: usize) -> (__m512i, __m512i) {
    let col = _mm512_add_epi32(lane_index32(), _mm512_set1_epi32(offset as i32));
    (col, _mm512_add_epi32(col, _mm512_set1_epi32(16)))
}

/// 0 to 15 (32-bit lanes).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn lane_index32() -> __m512i {
    _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
}

/// Adds the lanes `lanes` of `v` to the minimum, and all to the maximum and sum (the others are 0).
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn mms_add(acc: &mut MinMaxSum, v: __m512i, lanes: u32) {
    acc.min = _mm512_mask_min_epu16(acc.min, lanes, acc.min, v);
    acc.max = _mm512_max_epu16(acc.max, v);
    acc.sum = sum_add(acc.sum, v);
}

/// Pixel pairs `pairs[j * w..j * w + 2]` for `j` in `first..first + n` (`0 < n <= 16`), gathered into lanes
/// `0..2 * n`, the others 0.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,bmi1,lzcnt,popcnt")]
fn pairs(pairs: &[u16], w: usize, first: usize, n: usize) -> __m512i {
    assert!(0 < n && n <= 16 && (first + n - 1) * w + 2 <= pairs.len());
    let step = _mm512_mullo_epi32(lane_index32(), _mm512_set1_epi32(w as i32));
    let offsets = _mm512_add_epi32(step, _mm512_set1_epi32((first * w) as i32));
    // SAFETY: pair j is `pairs[j * w..j * w + 2]`, in bounds for j < first + n (asserted); the lanes past `n` pairs
    // are masked off (not read).
    unsafe {
        _mm512_mask_i32gather_epi32(
            _mm512_setzero_si512(),
            low_bits(n) as __mmask16,
            offsets,
            pairs.as_ptr().cast(),
            2,
        )
    }
}

impl Lanes for Avx512 {
    const WIDTH: usize = 32;
    const MIN_PIXELS: usize = 1;
    type V = __m512i;
    type Keep = u32;
    type Span = Span;
    /// Sixteen 32-bit lanes.
    type Sum = __m512i;
    /// The columns of lanes 0-15 and 16-31, in 32-bit lanes.
    type Cols = (__m512i, __m512i);
    type MinMaxSum = MinMaxSum;

    #[inline(always)]
    fn zero(self) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { _mm512_setzero_si512() }
    }

    #[inline(always)]
    fn splat(self, x: u16) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { _mm512_set1_epi16(x as i16) }
    }

    #[inline(always)]
    fn load(self, px: &[u16], k: usize) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { load32(px[k..k + 32].try_into().expect("32 pixels")) }
    }

    #[inline(always)]
    fn span(self, start: usize, end: usize) -> Span {
        Span {
            start,
            end,
            keep: low_bits(end - start),
        }
    }

    #[inline(always)]
    fn span_offset(self, span: Span) -> usize {
        span.start
    }

    #[inline(always)]
    fn span_keep(self, span: Span) -> u32 {
        span.keep
    }

    /// The lanes outside the span are 0.
    #[inline(always)]
    fn load_span(self, px: &[u16], span: Span) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { load_part(&px[span.start..span.end]) }
    }

    #[inline(always)]
    fn excess_span(self, px: &[u16], span: Span, t: __m512i) -> __m512i {
        // 0 -sat t is 0 outside the span.
        self.sub_sat(self.load_span(px, span), t)
    }

    #[inline(always)]
    fn first_lanes(self, n: usize) -> u32 {
        low_bits(n)
    }

    #[inline(always)]
    fn keep_bits(self, keep: u32) -> u64 {
        u64::from(keep)
    }

    #[inline(always)]
    fn add(self, a: __m512i, b: __m512i) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { _mm512_add_epi16(a, b) }
    }

    #[inline(always)]
    fn sub_sat(self, a: __m512i, b: __m512i) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { _mm512_subs_epu16(a, b) }
    }

    #[inline(always)]
    fn max(self, a: __m512i, b: __m512i) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { _mm512_max_epu16(a, b) }
    }

    #[inline(always)]
    fn hmax(self, v: __m512i) -> u16 {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { hmax(v) }
    }

    #[inline(always)]
    fn eq_bits(self, a: __m512i, b: __m512i) -> u64 {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { u64::from(_mm512_cmpeq_epi16_mask(a, b)) }
    }

    #[inline(always)]
    fn nonzero_bits(self, v: __m512i) -> u64 {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { u64::from(_mm512_test_epi16_mask(v, v)) }
    }

    #[inline(always)]
    fn nonzero_bits2(self, a: __m512i, b: __m512i) -> u64 {
        self.nonzero_bits(a) | self.nonzero_bits(b) << 32
    }

    #[inline(always)]
    fn select(self, v: __m512i, bits: u64) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { _mm512_maskz_mov_epi16(bits as u32, v) }
    }

    #[inline(always)]
    fn count_zeros(self, zeros: __m512i, v: __m512i) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe {
            let zero = _mm512_cmpeq_epi16_mask(v, _mm512_setzero_si512());
            _mm512_mask_add_epi16(zeros, zero, zeros, _mm512_set1_epi16(1))
        }
    }

    #[inline(always)]
    fn sum_zero(self) -> __m512i {
        self.zero()
    }

    #[inline(always)]
    fn sum_add(self, acc: __m512i, v: __m512i) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { sum_add(acc, v) }
    }

    #[inline(always)]
    fn cols(self, offset: usize) -> (__m512i, __m512i) {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { cols(offset) }
    }

    #[inline(always)]
    fn sum_weighted(self, acc: __m512i, v: __m512i, cols: (__m512i, __m512i)) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { sum_weighted(acc, v, cols) }
    }

    #[inline(always)]
    fn hsum(self, acc: __m512i) -> u64 {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { u64::from(_mm512_reduce_add_epi32(acc) as u32) }
    }

    #[inline(always)]
    fn min_max_sum(self) -> MinMaxSum {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe {
            MinMaxSum {
                min: _mm512_set1_epi16(-1),
                max: _mm512_setzero_si512(),
                sum: _mm512_setzero_si512(),
            }
        }
    }

    #[inline(always)]
    fn mms_add(self, acc: &mut MinMaxSum, v: __m512i) {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { mms_add(acc, v, u32::MAX) }
    }

    /// The lanes outside `keep` are 0 (masked loads and gathers): left out of the minimum, harmless for the maximum
    /// and the sum.
    #[inline(always)]
    fn mms_add_kept(self, acc: &mut MinMaxSum, v: __m512i, keep: u32, _count: u64) {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { mms_add(acc, v, keep) }
    }

    #[inline(always)]
    fn mms_finish(self, acc: &MinMaxSum) -> (u16, u16, u64) {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { (hmin(acc.min), hmax(acc.max), self.hsum(acc.sum)) }
    }

    #[inline(always)]
    fn pairs(self, px: &[u16], w: usize, first: usize, n: usize) -> __m512i {
        // SAFETY: `self` exists only where the CPU has the features.
        unsafe { pairs(px, w, first, n) }
    }
}
