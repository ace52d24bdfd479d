//! The lane primitives with SSE2 ([`Sse2`]), part of the x86_64 baseline, so every x86_64 CPU runs them: 8 pixels a
//! vector, and the kernels' entry points for SSE2.
//!
//! SSE2 has no masked loads: the last pixels of a slice, fewer than 8, are read as the slice's last 8 pixels (so the
//! slice must hold 8), overlapping pixels already taken, and a lane mask keeps the new ones. It has no unsigned
//! 16-bit minimum or maximum either: saturating arithmetic makes the maximum, and the border's running minimum and
//! maximum work in signed lanes, each pixel less 32768. Masks are extracted from comparisons a byte per lane, two
//! vectors at a time.

use std::arch::x86_64::*;

use super::lanes::{Lanes, entry_points};

/// The SSE2 token (every x86_64 CPU runs SSE2).
#[derive(Debug, Clone, Copy)]
pub(super) struct Sse2(());

impl Sse2 {
    /// The token: SSE2 is part of the x86_64 baseline.
    pub(super) fn new() -> Self {
        Self(())
    }
}

entry_points!(
    Sse2,
    "sse2",
    peak,
    border_min_max_sum,
    row_masks,
    window_moments,
    simple_component
);

/// The last pixels `start..end` of a slice: its pixels `end - 8..end`, of which the lanes `keep` are the span's.
#[derive(Clone, Copy)]
pub(super) struct Span {
    offset: usize,
    keep: __m128i,
}

/// Running minimum, maximum and sum of vectors of pixels, in signed lanes: each pixel less 32768 (its top bit
/// flipped), so that SSE2's signed minimum and maximum and its multiply-add apply.
pub(super) struct MinMaxSum {
    min: __m128i,
    max: __m128i,
    /// Sums of pairs of lanes (32-bit).
    sum: __m128i,
    /// Pixels added.
    count: u64,
}

/// Pixels `k` and `k + 1` of `px` as one 32-bit lane.
#[inline(always)]
fn pair(px: &[u16], k: usize) -> i32 {
    let two: &[u16; 2] = px[k..k + 2].try_into().expect("2 pixels");
    // SAFETY: `two` is 4 readable bytes; `read_unaligned` reads them at any alignment.
    unsafe { two.as_ptr().cast::<i32>().read_unaligned() }
}

impl Sse2 {
    /// 0 to 7.
    #[inline(always)]
    fn lane_index(self) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7) }
    }

    /// Adds `v` to `acc`: all its lanes to the minimum and maximum, the lanes `sum_lanes` (`count` of them) to the sum
    /// (the others repeat pixels added).
    #[inline(always)]
    fn mms_add_lanes(
        self,
        acc: &mut MinMaxSum,
        v: __m128i,
        sum_lanes: Option<__m128i>,
        count: u64,
    ) {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let v = _mm_xor_si128(v, _mm_set1_epi16(i16::MIN));
            acc.min = _mm_min_epi16(acc.min, v);
            acc.max = _mm_max_epi16(acc.max, v);
            let v = sum_lanes.map_or(v, |lanes| _mm_and_si128(v, lanes));
            acc.sum = _mm_add_epi32(acc.sum, _mm_madd_epi16(v, _mm_set1_epi16(1)));
        }
        acc.count += count;
    }
}

impl Lanes for Sse2 {
    const WIDTH: usize = 8;
    const MIN_PIXELS: usize = 8;
    type V = __m128i;
    type Keep = __m128i;
    type Span = Span;
    /// Four 32-bit lanes.
    type Sum = __m128i;
    /// The columns, in 16-bit lanes.
    type Cols = __m128i;
    type MinMaxSum = MinMaxSum;

    #[inline(always)]
    fn zero(self) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_setzero_si128() }
    }

    #[inline(always)]
    fn splat(self, x: u16) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_set1_epi16(x as i16) }
    }

    #[inline(always)]
    fn load(self, px: &[u16], k: usize) -> __m128i {
        let chunk: &[u16; 8] = px[k..k + 8].try_into().expect("8 pixels");
        // SAFETY: SSE2 is part of the x86_64 baseline; `chunk` is 16 readable bytes, and `_mm_loadu_si128` reads 16
        // bytes at any alignment.
        unsafe { _mm_loadu_si128(chunk.as_ptr().cast()) }
    }

    #[inline(always)]
    fn span(self, start: usize, end: usize) -> Span {
        let offset = end - 8;
        // SAFETY: SSE2 is part of the x86_64 baseline.
        let keep = unsafe {
            _mm_cmpgt_epi16(
                self.lane_index(),
                _mm_set1_epi16((start - offset) as i16 - 1),
            )
        };
        Span { offset, keep }
    }

    #[inline(always)]
    fn span_offset(self, span: Span) -> usize {
        span.offset
    }

    #[inline(always)]
    fn span_keep(self, span: Span) -> __m128i {
        span.keep
    }

    /// The lanes outside the span hold the pixels before it.
    #[inline(always)]
    fn load_span(self, px: &[u16], span: Span) -> __m128i {
        self.load(px, span.offset)
    }

    #[inline(always)]
    fn excess_span(self, px: &[u16], span: Span, t: __m128i) -> __m128i {
        let v = self.sub_sat(self.load_span(px, span), t);
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_and_si128(v, span.keep) }
    }

    #[inline(always)]
    fn first_lanes(self, n: usize) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_cmpgt_epi16(_mm_set1_epi16(n as i16), self.lane_index()) }
    }

    #[inline(always)]
    fn keep_bits(self, keep: __m128i) -> u64 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { u64::from(_mm_movemask_epi8(_mm_packs_epi16(keep, _mm_setzero_si128())) as u32) }
    }

    #[inline(always)]
    fn add(self, a: __m128i, b: __m128i) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_add_epi16(a, b) }
    }

    #[inline(always)]
    fn sub_sat(self, a: __m128i, b: __m128i) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_subs_epu16(a, b) }
    }

    /// `(a -sat b) +sat b` (SSE2 has only the signed maximum).
    #[inline(always)]
    fn max(self, a: __m128i, b: __m128i) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_adds_epu16(_mm_subs_epu16(a, b), b) }
    }

    #[inline(always)]
    fn hmax(self, m: __m128i) -> u16 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let m = self.max(m, _mm_shuffle_epi32(m, 0b01_00_11_10));
            let m = self.max(m, _mm_shuffle_epi32(m, 0b10_11_00_01));
            let m = self.max(m, _mm_shufflelo_epi16(m, 0b10_11_00_01));
            _mm_extract_epi16(m, 0) as u16
        }
    }

    #[inline(always)]
    fn eq_bits(self, a: __m128i, b: __m128i) -> u64 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let eq = _mm_packs_epi16(_mm_cmpeq_epi16(a, b), _mm_setzero_si128());
            u64::from(_mm_movemask_epi8(eq) as u32)
        }
    }

    #[inline(always)]
    fn nonzero_bits(self, v: __m128i) -> u64 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let z = _mm_setzero_si128();
            let zero = _mm_packs_epi16(_mm_cmpeq_epi16(v, z), z);
            u64::from(_mm_movemask_epi8(zero) as u32 ^ 0xFF)
        }
    }

    #[inline(always)]
    fn nonzero_bits2(self, a: __m128i, b: __m128i) -> u64 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let z = _mm_setzero_si128();
            let zero = _mm_packs_epi16(_mm_cmpeq_epi16(a, z), _mm_cmpeq_epi16(b, z));
            u64::from(_mm_movemask_epi8(zero) as u32 ^ 0xFFFF)
        }
    }

    /// Broadcasts the low byte of `bits` and tests each lane's bit.
    #[inline(always)]
    fn select(self, v: __m128i, bits: u64) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let lane_bit = _mm_setr_epi16(1, 2, 4, 8, 16, 32, 64, 128);
            let byte = _mm_set1_epi16((bits & 0xFF) as i16);
            let keep = _mm_cmpeq_epi16(_mm_and_si128(byte, lane_bit), lane_bit);
            _mm_and_si128(v, keep)
        }
    }

    #[inline(always)]
    fn count_zeros(self, zeros: __m128i, v: __m128i) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_sub_epi16(zeros, _mm_cmpeq_epi16(v, _mm_setzero_si128())) }
    }

    #[inline(always)]
    fn sum_zero(self) -> __m128i {
        self.zero()
    }

    /// The eight lanes summed pairwise into the four 32-bit lanes.
    #[inline(always)]
    fn sum_add(self, acc: __m128i, v: __m128i) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let z = _mm_setzero_si128();
            let pairs = _mm_add_epi32(_mm_unpacklo_epi16(v, z), _mm_unpackhi_epi16(v, z));
            _mm_add_epi32(acc, pairs)
        }
    }

    #[inline(always)]
    fn cols(self, offset: usize) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_add_epi16(self.lane_index(), _mm_set1_epi16(offset as i16)) }
    }

    /// The products' low and high halves (16 bits each) interleaved into 32-bit lanes, summed pairwise.
    #[inline(always)]
    fn sum_weighted(self, acc: __m128i, v: __m128i, cols: __m128i) -> __m128i {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let (lo16, hi16) = (_mm_mullo_epi16(v, cols), _mm_mulhi_epu16(v, cols));
            let products = _mm_add_epi32(
                _mm_unpacklo_epi16(lo16, hi16),
                _mm_unpackhi_epi16(lo16, hi16),
            );
            _mm_add_epi32(acc, products)
        }
    }

    #[inline(always)]
    fn hsum(self, v: __m128i) -> u64 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b01_00_11_10));
            let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b10_11_00_01));
            u64::from(_mm_cvtsi128_si32(v) as u32)
        }
    }

    #[inline(always)]
    fn min_max_sum(self) -> MinMaxSum {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            MinMaxSum {
                min: _mm_set1_epi16(i16::MAX),
                max: _mm_set1_epi16(i16::MIN),
                sum: _mm_setzero_si128(),
                count: 0,
            }
        }
    }

    #[inline(always)]
    fn mms_add(self, acc: &mut MinMaxSum, v: __m128i) {
        self.mms_add_lanes(acc, v, None, 8);
    }

    /// The lanes outside `keep` repeat pixels added: harmless for the minimum and maximum, left out of the sum.
    #[inline(always)]
    fn mms_add_kept(self, acc: &mut MinMaxSum, v: __m128i, keep: __m128i, count: u64) {
        self.mms_add_lanes(acc, v, Some(keep), count);
    }

    #[inline(always)]
    fn mms_finish(self, acc: &MinMaxSum) -> (u16, u16, u64) {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let min = _mm_min_epi16(acc.min, _mm_shuffle_epi32(acc.min, 0b01_00_11_10));
            let min = _mm_min_epi16(min, _mm_shuffle_epi32(min, 0b10_11_00_01));
            let min = _mm_min_epi16(min, _mm_shufflelo_epi16(min, 0b10_11_00_01));
            let max = _mm_max_epi16(acc.max, _mm_shuffle_epi32(acc.max, 0b01_00_11_10));
            let max = _mm_max_epi16(max, _mm_shuffle_epi32(max, 0b10_11_00_01));
            let max = _mm_max_epi16(max, _mm_shufflelo_epi16(max, 0b10_11_00_01));
            let sum = i64::from(self.hsum(acc.sum) as i32) + 32768 * acc.count as i64;
            (
                _mm_extract_epi16(min, 0) as u16 ^ 0x8000,
                _mm_extract_epi16(max, 0) as u16 ^ 0x8000,
                sum as u64,
            )
        }
    }

    /// Four pairs read as 32-bit lanes; fewer repeat the last.
    #[inline(always)]
    fn pairs(self, pairs: &[u16], w: usize, first: usize, n: usize) -> __m128i {
        let at = |k: usize| pair(pairs, (first + k.min(n - 1)) * w);
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { _mm_setr_epi32(at(0), at(1), at(2), at(3)) }
    }
}
