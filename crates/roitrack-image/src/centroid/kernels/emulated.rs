//! Test-only lane primitives in plain arrays ([`Emulated`]), 32 lanes wide and with AVX-512's semantics (a span's
//! other lanes 0, sets of lanes as bits, pairs gathered 16 at a time), so that the generic kernels' 32-lane
//! instantiation, the one AVX-512 CPUs run, is tested on any CPU. It also checks what the AVX-512 primitives assume
//! of their callers (the lanes outside a kept set are 0).

use super::lanes::Lanes;

/// The emulated instruction set.
#[derive(Debug, Clone, Copy)]
pub(super) struct Emulated;

/// 32 lanes.
type V = [u16; 32];

/// The last pixels `start..end` of a slice, in lanes `0..end - start`.
#[derive(Clone, Copy)]
pub(super) struct Span {
    start: usize,
    end: usize,
}

/// Running minimum, maximum and (32-bit, wrapping) sum per lane.
pub(super) struct MinMaxSum {
    min: V,
    max: V,
    sum: [u32; 32],
}

/// The lowest `n` bits (`n <= 32`).
fn low_bits(n: usize) -> u32 {
    ((1u64 << n) - 1) as u32
}

/// Bit l set where `f(l)`.
fn bits(f: impl Fn(usize) -> bool) -> u64 {
    (0..32).fold(0, |acc, l| acc | (u64::from(f(l)) << l))
}

impl Lanes for Emulated {
    const WIDTH: usize = 32;
    const MIN_PIXELS: usize = 1;
    type V = V;
    type Keep = u32;
    type Span = Span;
    type Sum = [u32; 32];
    type Cols = [u32; 32];
    type MinMaxSum = MinMaxSum;

    fn zero(self) -> V {
        [0; 32]
    }

    fn splat(self, x: u16) -> V {
        [x; 32]
    }

    fn load(self, px: &[u16], k: usize) -> V {
        px[k..k + 32].try_into().expect("32 pixels")
    }

    fn span(self, start: usize, end: usize) -> Span {
        assert!(start < end && end - start <= 32);
        Span { start, end }
    }

    fn span_offset(self, span: Span) -> usize {
        span.start
    }

    fn span_keep(self, span: Span) -> u32 {
        low_bits(span.end - span.start)
    }

    fn load_span(self, px: &[u16], span: Span) -> V {
        let part = &px[span.start..span.end];
        std::array::from_fn(|l| part.get(l).copied().unwrap_or(0))
    }

    fn excess_span(self, px: &[u16], span: Span, t: V) -> V {
        self.sub_sat(self.load_span(px, span), t)
    }

    fn first_lanes(self, n: usize) -> u32 {
        low_bits(n)
    }

    fn keep_bits(self, keep: u32) -> u64 {
        u64::from(keep)
    }

    fn add(self, a: V, b: V) -> V {
        std::array::from_fn(|l| a[l].wrapping_add(b[l]))
    }

    fn sub_sat(self, a: V, b: V) -> V {
        std::array::from_fn(|l| a[l].saturating_sub(b[l]))
    }

    fn max(self, a: V, b: V) -> V {
        std::array::from_fn(|l| a[l].max(b[l]))
    }

    fn hmax(self, v: V) -> u16 {
        v.into_iter().fold(0, u16::max)
    }

    fn eq_bits(self, a: V, b: V) -> u64 {
        bits(|l| a[l] == b[l])
    }

    fn nonzero_bits(self, v: V) -> u64 {
        bits(|l| v[l] != 0)
    }

    fn nonzero_bits2(self, a: V, b: V) -> u64 {
        self.nonzero_bits(a) | self.nonzero_bits(b) << 32
    }

    fn select(self, v: V, bits: u64) -> V {
        std::array::from_fn(|l| if (bits >> l) & 1 == 1 { v[l] } else { 0 })
    }

    fn count_zeros(self, zeros: V, v: V) -> V {
        std::array::from_fn(|l| zeros[l] + u16::from(v[l] == 0))
    }

    fn sum_zero(self) -> [u32; 32] {
        [0; 32]
    }

    fn sum_add(self, acc: [u32; 32], v: V) -> [u32; 32] {
        std::array::from_fn(|l| acc[l].wrapping_add(u32::from(v[l])))
    }

    fn cols(self, offset: usize) -> [u32; 32] {
        std::array::from_fn(|l| (offset + l) as u32)
    }

    fn sum_weighted(self, acc: [u32; 32], v: V, cols: [u32; 32]) -> [u32; 32] {
        assert!(cols.iter().all(|&c| c < 64), "{cols:?}");
        std::array::from_fn(|l| acc[l].wrapping_add(u32::from(v[l]) * cols[l]))
    }

    fn hsum(self, acc: [u32; 32]) -> u64 {
        u64::from(acc.into_iter().fold(0u32, u32::wrapping_add))
    }

    fn min_max_sum(self) -> MinMaxSum {
        MinMaxSum {
            min: [u16::MAX; 32],
            max: [0; 32],
            sum: [0; 32],
        }
    }

    fn mms_add(self, acc: &mut MinMaxSum, v: V) {
        self.mms_add_kept(acc, v, u32::MAX, 32);
    }

    /// As AVX-512's: the lanes outside `keep` must be 0 (checked), left out of the minimum only.
    fn mms_add_kept(self, acc: &mut MinMaxSum, v: V, keep: u32, count: u64) {
        assert_eq!(u64::from(keep.count_ones()), count);
        for (l, (min, &p)) in acc.min.iter_mut().zip(&v).enumerate() {
            if (keep >> l) & 1 == 1 {
                *min = (*min).min(p);
            } else {
                assert_eq!(p, 0, "lane {l} outside the kept ones");
            }
        }
        acc.max = self.max(acc.max, v);
        acc.sum = self.sum_add(acc.sum, v);
    }

    fn mms_finish(self, acc: &MinMaxSum) -> (u16, u16, u64) {
        (
            acc.min.into_iter().fold(u16::MAX, u16::min),
            self.hmax(acc.max),
            self.hsum(acc.sum),
        )
    }

    fn pairs(self, pairs: &[u16], w: usize, first: usize, n: usize) -> V {
        assert!(0 < n && n <= 16);
        std::array::from_fn(|l| {
            let j = first + l / 2;
            if l / 2 < n { pairs[j * w + l % 2] } else { 0 }
        })
    }
}
