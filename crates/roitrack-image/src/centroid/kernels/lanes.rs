//! The lane primitives the vectorised kernels are written with ([`Lanes`]), and the macro that instantiates the
//! kernels for an instruction set inside its `#[target_feature]` entry points ([`entry_points!`]).
//!
//! The kernels ([`super::scan`], [`super::walk`]) are written once, generic over [`Lanes`]; SSE2 ([`super::sse2`])
//! and AVX-512 ([`super::avx512`]) implement the trait. Most primitives are one or two instructions; a few are
//! whole idioms where the instruction sets differ most (how a vector past a slice's end is read, how a row's mask is
//! extracted, the border's running minimum, maximum and sum, the gather of the border's pixel pairs). A value of an
//! implementing type is a token: it exists only where the CPU runs the instructions, which is what makes its
//! methods safe to call. The methods and the kernels are `#[inline(always)]`, so that all of a kernel inlines into
//! its entry point, a `#[target_feature]` function, where the intrinsics then inline too (outside one, the
//! intrinsics would be calls).

/// A vector of [`Lanes::WIDTH`] unsigned 16-bit lanes (pixels) and the operations on it the kernels use. See the
/// module's documentation.
///
/// Lane `l` of a vector loaded from a slice at `k` holds pixel `k + l`; a mask's bit `l` is lane `l`'s.
pub(super) trait Lanes: Copy {
    /// Lanes (pixels) a vector.
    const WIDTH: usize;
    /// Shortest slice [`Lanes::span`] handles: a span of SSE2 is a whole vector, read back over the pixels before it.
    const MIN_PIXELS: usize;
    /// [`Lanes::WIDTH`] unsigned 16-bit lanes.
    type V: Copy;
    /// A set of lanes.
    type Keep: Copy;
    /// Where the last pixels of a slice, fewer than a vector, sit in a vector ([`Lanes::span`]).
    type Span: Copy;
    /// 32-bit lanes of sums ([`Lanes::sum_add`]).
    type Sum: Copy;
    /// The column of each lane of a vector, to weight sums by ([`Lanes::sum_weighted`]).
    type Cols: Copy;
    /// A running minimum, maximum and sum of pixels ([`Lanes::mms_add`]).
    type MinMaxSum;

    /// All lanes 0.
    fn zero(self) -> Self::V;
    /// All lanes `x`.
    fn splat(self, x: u16) -> Self::V;
    /// Pixels `k..k + WIDTH` of `px`.
    fn load(self, px: &[u16], k: usize) -> Self::V;
    /// The pixels `start..end` of a slice (`0 < end - start <= WIDTH`, `end >= MIN_PIXELS`).
    fn span(self, start: usize, end: usize) -> Self::Span;
    /// The index in the slice of the pixel in lane 0 of `span`'s vector.
    fn span_offset(self, span: Self::Span) -> usize;
    /// The lanes of `span`'s vector that hold its pixels.
    fn span_keep(self, span: Self::Span) -> Self::Keep;
    /// The vector of `span` of `px`: its pixels in the lanes of [`Lanes::span_keep`], the others either 0 or pixels
    /// of `px` before the span's (which the instruction set says, not the caller).
    fn load_span(self, px: &[u16], span: Self::Span) -> Self::V;
    /// `value -sat t` of the pixels of `span` of `px` in their lanes, 0 in the others.
    fn excess_span(self, px: &[u16], span: Self::Span, t: Self::V) -> Self::V;
    /// The lanes `0..n` (`n <= WIDTH`).
    fn first_lanes(self, n: usize) -> Self::Keep;
    /// Bit `l` set for the lanes `l` of `keep`.
    fn keep_bits(self, keep: Self::Keep) -> u64;

    /// Lane-wise `a + b` (wrapping).
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    /// Lane-wise `a -sat b` (0 where `b >= a`).
    fn sub_sat(self, a: Self::V, b: Self::V) -> Self::V;
    /// Lane-wise maximum.
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// The largest lane.
    fn hmax(self, v: Self::V) -> u16;
    /// Bit `l` set where lanes `l` of `a` and `b` are equal.
    fn eq_bits(self, a: Self::V, b: Self::V) -> u64;
    /// Bit `l` set where lane `l` is not 0.
    fn nonzero_bits(self, v: Self::V) -> u64;
    /// [`Lanes::nonzero_bits`] of `a` and, above them, of `b` (`2 * WIDTH` bits: `WIDTH <= 32`).
    fn nonzero_bits2(self, a: Self::V, b: Self::V) -> u64;
    /// `v` in the lanes `l` whose bit `l` of `bits` is set, 0 in the others (bits from `WIDTH` on ignored).
    fn select(self, v: Self::V, bits: u64) -> Self::V;
    /// `zeros` plus 1 in the lanes where `v` is 0.
    fn count_zeros(self, zeros: Self::V, v: Self::V) -> Self::V;

    /// No sums.
    fn sum_zero(self) -> Self::Sum;
    /// `acc` plus the lanes of `v`, in 32-bit lanes (which lanes of `v` go into which of `acc` is the instruction
    /// set's: only [`Lanes::hsum`] of the result is defined).
    fn sum_add(self, acc: Self::Sum, v: Self::V) -> Self::Sum;
    /// The columns `offset..offset + WIDTH` of a vector's lanes.
    fn cols(self, offset: usize) -> Self::Cols;
    /// `acc` plus each lane of `v` times its column in `cols` (lanes up to 65535, columns below 64), in 32-bit lanes.
    fn sum_weighted(self, acc: Self::Sum, v: Self::V, cols: Self::Cols) -> Self::Sum;
    /// The sum of the lanes of `acc` (which the callers keep below 2^32).
    fn hsum(self, acc: Self::Sum) -> u64;

    /// Nothing added yet.
    fn min_max_sum(self) -> Self::MinMaxSum;
    /// Adds all the lanes of `v`.
    fn mms_add(self, acc: &mut Self::MinMaxSum, v: Self::V);
    /// Adds the `count` lanes `keep` of `v`, a vector of [`Lanes::load_span`] or [`Lanes::pairs`] (whose other lanes
    /// are the instruction set's: repeated pixels or 0).
    fn mms_add_kept(self, acc: &mut Self::MinMaxSum, v: Self::V, keep: Self::Keep, count: u64);
    /// (minimum, maximum, sum).
    fn mms_finish(self, acc: &Self::MinMaxSum) -> (u16, u16, u64);
    /// Pixel pairs `pairs[j * w..j * w + 2]` for `j` in `first..first + n` (`0 < n <= WIDTH / 2`, all in bounds),
    /// in lanes `0..2 * n`; the other lanes are the instruction set's (repeated pixels or 0).
    fn pairs(self, pairs: &[u16], w: usize, first: usize, n: usize) -> Self::V;
}

/// Safe methods of an instruction set's token `$lanes` (an implementation of [`Lanes`]) that run the generic kernels
/// named (of `peak`, `border_min_max_sum`, `row_masks`, `window_moments`, `simple_component`) inside
/// `#[target_feature(enable = $features)]` functions: the kernels and the lane primitives inline into them, and so do
/// the intrinsics.
#[cfg(target_arch = "x86_64")]
macro_rules! entry_points {
    ($lanes:ty, $features:literal, $($kernel:ident),+) => {
        impl $lanes {
            $(entry_points!(@$kernel $lanes, $features);)+
        }
    };
    (@peak $lanes:ty, $features:literal) => {
        /// The largest pixel and the index of its first occurrence (`px.len() >= MIN_PIXELS`).
        #[inline]
        pub(in crate::centroid::kernels) fn peak(self, px: &[u16]) -> (u16, usize) {
            #[target_feature(enable = $features)]
            fn peak(lanes: $lanes, px: &[u16]) -> (u16, usize) {
                crate::centroid::kernels::scan::peak(lanes, px)
            }
            // SAFETY: `self` exists only where the CPU has the features.
            unsafe { peak(self, px) }
        }
    };
    (@border_min_max_sum $lanes:ty, $features:literal) => {
        /// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image (`w - 1 >= MIN_PIXELS`,
        /// `h >= 2`).
        #[inline]
        pub(in crate::centroid::kernels) fn border_min_max_sum(
            self,
            px: &[u16],
            w: usize,
            h: usize,
        ) -> (u16, u16, u64) {
            #[target_feature(enable = $features)]
            fn border(lanes: $lanes, px: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
                crate::centroid::kernels::scan::border_min_max_sum(lanes, px, w, h)
            }
            // SAFETY: `self` exists only where the CPU has the features.
            unsafe { border(self, px, w, h) }
        }
    };
    (@row_masks $lanes:ty, $features:literal) => {
        /// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold`
        /// (`MIN_PIXELS <= w <= 64`).
        #[inline]
        pub(in crate::centroid::kernels) fn row_masks(
            self,
            pixels: &[u16],
            w: usize,
            threshold: u16,
            rows: &mut [u64],
        ) {
            #[target_feature(enable = $features)]
            fn row_masks(lanes: $lanes, pixels: &[u16], w: usize, threshold: u16, rows: &mut [u64]) {
                crate::centroid::kernels::scan::row_masks(lanes, pixels, w, threshold, rows)
            }
            // SAFETY: `self` exists only where the CPU has the features.
            unsafe { row_masks(self, pixels, w, threshold, rows) }
        }
    };
    (@window_moments $lanes:ty, $features:literal) => {
        /// The moments of a component over a window of `N` vectors of columns: see
        /// [`crate::centroid::kernels::walk::window_moments`].
        #[allow(clippy::too_many_arguments)]
        #[inline]
        pub(in crate::centroid::kernels) fn window_moments<const N: usize>(
            self,
            px: &[u16],
            w: usize,
            comp: &[u64],
            mask: &[u64],
            rows: (usize, usize),
            s: usize,
            levels: (u16, u16),
        ) -> crate::centroid::moments::Moments {
            #[allow(clippy::too_many_arguments)]
            #[target_feature(enable = $features)]
            fn window<const N: usize>(
                lanes: $lanes,
                px: &[u16],
                w: usize,
                comp: &[u64],
                mask: &[u64],
                rows: (usize, usize),
                s: usize,
                levels: (u16, u16),
            ) -> crate::centroid::moments::Moments {
                crate::centroid::kernels::walk::window_moments::<$lanes, N>(
                    lanes, px, w, comp, mask, rows, s, levels,
                )
            }
            // SAFETY: `self` exists only where the CPU has the features.
            unsafe { window::<N>(self, px, w, comp, mask, rows, s, levels) }
        }
    };
    (@simple_component $lanes:ty, $features:literal) => {
        /// The seed's component when it is simple, rows of `N` vectors: see
        /// [`crate::centroid::kernels::walk::simple_component`].
        #[inline]
        pub(in crate::centroid::kernels) fn simple_component<const N: usize>(
            self,
            px: &[u16],
            size: (usize, usize),
            seed_j: usize,
            levels: (u16, u16),
        ) -> Option<crate::centroid::kernels::Found> {
            #[target_feature(enable = $features)]
            fn walk<const N: usize>(
                lanes: $lanes,
                px: &[u16],
                size: (usize, usize),
                seed_j: usize,
                levels: (u16, u16),
            ) -> Option<crate::centroid::kernels::Found> {
                crate::centroid::kernels::walk::simple_component::<$lanes, N>(
                    lanes, px, size, seed_j, levels,
                )
            }
            // SAFETY: `self` exists only where the CPU has the features.
            unsafe { walk::<N>(self, px, size, seed_j, levels) }
        }
    };
}

#[cfg(target_arch = "x86_64")]
pub(super) use entry_points;
