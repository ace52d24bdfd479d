//! The passes over the pixels, vectorised, and the choice of instructions ([`Isa`]): the ROI's peak, its border's
//! minimum, maximum and sum, the rows' above-threshold masks, the moments over a window of columns, and the one-pass
//! walk that finds and measures a simple (convex) component.
//!
//! The vectorised kernels are written once, generic over the lane primitives of [`lanes::Lanes`]: those that scan
//! pixels in `scan.rs`, those that sum moments in `walk.rs`. Each instruction set implements the primitives and
//! instantiates the kernels inside its own `#[target_feature]` entry points: SSE2 (`sse2.rs`, every x86_64 CPU, 8
//! pixels a vector) and AVX-512 (`avx512.rs`, where the CPU has it, 32). `portable.rs` takes a pixel at a time, on
//! other CPUs and for ROIs too narrow for a vector; it is also the reference the others are tested against.
//! `emulated.rs` (tests only) implements the primitives in plain arrays, with AVX-512's width and semantics, so that
//! the generic kernels' 32-lane instantiation is tested on any CPU.
//!
//! Each function here takes the [`Isa`] found once per call of [`super::measure_blob`] and runs the kernel of that
//! instruction set. All give the same results, to the bit. AVX-512 CPUs make the row masks and the window moments
//! with SSE2 (as they did before the kernels were generic).

#[cfg(target_arch = "x86_64")]
mod avx512;
#[cfg(test)]
mod emulated;
#[cfg(any(target_arch = "x86_64", test))]
mod lanes;
mod portable;
#[cfg(any(target_arch = "x86_64", test))]
mod scan;
#[cfg(target_arch = "x86_64")]
mod shape;
#[cfg(target_arch = "x86_64")]
mod sse2;
#[cfg(any(target_arch = "x86_64", test))]
mod walk;

#[cfg(target_arch = "x86_64")]
use self::{avx512::Avx512, lanes::Lanes, sse2::Sse2};
use super::moments::{Moments, ShapeSums, scalar_shape_sums};

/// A component found in one pass: its moments, first and last rows, and union of columns.
pub(super) type Found = (Moments, (usize, usize), u64);

/// The instructions the kernels use. All give the same results, to the bit (integer sums).
///
/// `Isa::Avx512` only where the CPU has the features ([`Isa::detect`]): the AVX-512 kernels rely on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(super) enum Isa {
    /// AVX-512 (F, BW) with BMI1, LZCNT and POPCNT, where the CPU has them.
    Avx512,
    /// SSE2: every x86_64 CPU.
    Sse2,
    /// A pixel at a time.
    Portable,
}

impl Isa {
    /// The best the CPU runs.
    #[cfg(target_arch = "x86_64")]
    pub(super) fn detect() -> Self {
        if Avx512::available() {
            Self::Avx512
        } else {
            Self::Sse2
        }
    }

    /// The best the CPU runs.
    #[cfg(not(target_arch = "x86_64"))]
    pub(super) fn detect() -> Self {
        Self::Portable
    }
}

/// The AVX-512 token of `Isa::Avx512`.
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx512_token() -> Avx512 {
    // SAFETY: called only for `Isa::Avx512`, which is only where the CPU has the features.
    unsafe { Avx512::new_unchecked() }
}

/// The largest pixel and the index of its first occurrence (row-major).
#[inline]
pub(super) fn peak(isa: Isa, pixels: &[u16]) -> (u16, usize) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 if pixels.len() >= Avx512::MIN_PIXELS => avx512_token().peak(pixels),
        #[cfg(target_arch = "x86_64")]
        Isa::Sse2 if pixels.len() >= Sse2::MIN_PIXELS => Sse2::new().peak(pixels),
        _ => portable::peak(pixels),
    }
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image (vectorised where the top and bottom
/// rows but a pixel, `w - 1`, fill a span).
#[inline]
pub(super) fn border_min_max_sum(isa: Isa, pixels: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 if w > Avx512::MIN_PIXELS && h > 1 => {
            avx512_token().border_min_max_sum(pixels, w, h)
        }
        #[cfg(target_arch = "x86_64")]
        Isa::Sse2 if w > Sse2::MIN_PIXELS && h > 1 => Sse2::new().border_min_max_sum(pixels, w, h),
        _ => portable::border_min_max_sum(pixels, w, h),
    }
}

/// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold`.
#[inline]
pub(in crate::centroid) fn row_masks(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    threshold: u16,
    rows: &mut [u64],
) {
    #[cfg(target_arch = "x86_64")]
    if isa != Isa::Portable && w >= Sse2::MIN_PIXELS {
        return Sse2::new().row_masks(pixels, w, threshold, rows);
    }
    let _ = isa;
    portable::row_masks(pixels, w, threshold, rows);
}

/// The moments of the component `comp` (rows `lo..=hi`, columns `cols` the union of its rows) of the above-threshold
/// pixels `mask`, with SSE2 over a window of 8-pixel vectors holding its columns; `None` where the ROI is too narrow
/// for the window (or without vectors).
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn window_moments(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    comp: &[u64],
    mask: &[u64],
    rows: (usize, usize),
    cols: u64,
    levels: (u16, u16),
) -> Option<Moments> {
    #[cfg(target_arch = "x86_64")]
    if isa != Isa::Portable {
        let first = cols.trailing_zeros() as usize;
        let last = 63 - cols.leading_zeros() as usize;
        let vectors = (last - first) / Sse2::WIDTH + 1;
        if Sse2::WIDTH * vectors <= w {
            let s = first.min(w - Sse2::WIDTH * vectors);
            let sse2 = Sse2::new();
            macro_rules! window {
                ($n:literal) => {
                    sse2.window_moments::<$n>(pixels, w, comp, mask, rows, s, levels)
                };
            }
            return Some(match vectors {
                1 => window!(1),
                2 => window!(2),
                3 => window!(3),
                4 => window!(4),
                5 => window!(5),
                6 => window!(6),
                7 => window!(7),
                _ => window!(8),
            });
        }
    }
    let _ = (isa, pixels, w, comp, mask, rows, cols, levels);
    None
}

/// The [`ShapeSums`] of the component of rows `rows` and columns `cols` (their union), y from its first row, x from
/// the first column of the window of 8-pixel vectors that holds its columns (from its first column where the ROI is
/// too narrow for the window): of the pixels of `comp`, or with `None` of every above-threshold pixel of those rows (a
/// simple component's). With SSE2, or AVX2 where the CPU has it, over that window (see `shape.rs`) where the
/// component's values allow, else a pixel at a time; the same integers either way. (AVX2 is used whatever `isa` but
/// the portable: the AVX-512 token is not needed for 16-pixel vectors.)
#[inline]
pub(super) fn shape_sums(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    comp: Option<&[u64]>,
    rows: (usize, usize),
    cols: u64,
    (threshold, peak): (u16, u16),
) -> ShapeSums {
    let first = cols.trailing_zeros() as usize;
    let last = 63 - cols.leading_zeros() as usize;
    let vectors = (last - first) / 8 + 1;
    let origin = if 8 * vectors <= w {
        first.min(w - 8 * vectors)
    } else {
        first
    };
    #[cfg(target_arch = "x86_64")]
    if isa != Isa::Portable && 8 * vectors <= w {
        let vmax = peak - threshold;
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        if let Some(sums) = shape::shape_sums(
            pixels, w, comp, rows, origin, vectors, threshold, vmax, avx2,
        ) {
            return sums;
        }
    }
    let _ = (isa, peak);
    scalar_shape_sums(
        pixels,
        w,
        comp,
        rows,
        (first, last),
        origin,
        (threshold, u16::MAX),
    )
}

/// The seed's component (its moments, first and last rows and union of columns) when it is simple, found and
/// measured in one pass over its rows (see `walk::simple_component`); `None` when it is not (or without vectors, or
/// the ROI is narrower than a vector where that matters: SSE2).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(super) fn walk_simple(
    isa: Isa,
    pixels: &[u16],
    (w, h): (usize, usize),
    seed_j: usize,
    levels: (u16, u16),
) -> Option<Found> {
    macro_rules! walk {
        ($lanes:expr, $n:literal) => {
            $lanes.simple_component::<$n>(pixels, (w, h), seed_j, levels)
        };
    }
    match isa {
        Isa::Avx512 if w >= Avx512::MIN_PIXELS => {
            let avx512 = avx512_token();
            match w.div_ceil(Avx512::WIDTH) {
                1 => walk!(avx512, 1),
                _ => walk!(avx512, 2),
            }
        }
        Isa::Sse2 if w >= Sse2::MIN_PIXELS => {
            let sse2 = Sse2::new();
            match w.div_ceil(Sse2::WIDTH) {
                1 => walk!(sse2, 1),
                2 => walk!(sse2, 2),
                3 => walk!(sse2, 3),
                4 => walk!(sse2, 4),
                5 => walk!(sse2, 5),
                6 => walk!(sse2, 6),
                7 => walk!(sse2, 7),
                _ => walk!(sse2, 8),
            }
        }
        _ => None,
    }
}

/// The one-pass measurement of simple components is vectorised only.
#[cfg(not(target_arch = "x86_64"))]
pub(super) fn walk_simple(
    _isa: Isa,
    _pixels: &[u16],
    _size: (usize, usize),
    _seed_j: usize,
    _levels: (u16, u16),
) -> Option<Found> {
    None
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::emulated::Emulated;
    use super::*;
    use crate::centroid::component::{grow_component, simple_rows};
    use crate::centroid::moments::scalar_moments;
    use crate::centroid::test_rois::{blob, synthetic};

    /// The origin of [`shape_sums`]'s x for a component of columns `first..=last`.
    fn shape_origin(first: usize, last: usize, w: usize) -> usize {
        let vectors = (last - first) / 8 + 1;
        if 8 * vectors <= w {
            first.min(w - 8 * vectors)
        } else {
            first
        }
    }

    /// The instruction sets the CPU runs, but the portable one.
    fn vector_isas() -> Vec<Isa> {
        [Isa::Avx512, Isa::Sse2]
            .into_iter()
            .filter(|&isa| isa != Isa::Avx512 || Isa::detect() == Isa::Avx512)
            .filter(|_| Isa::detect() != Isa::Portable)
            .collect()
    }

    /// Checks every kernel on the `w` x `h` `pixels`, for each instruction set of `isas` and the emulated 32-lane
    /// one, against the portable kernels (the walk and the window moments at a few thresholds, from the peak).
    /// Returns the number of simple components the walks measured.
    fn check(isas: &[Isa], pixels: &[u16], (w, h): (usize, usize), rng: &mut impl Rng) -> usize {
        let case = format!("{w}x{h} {pixels:?}");
        let (peak, seed) = portable::peak(pixels);
        for &isa in isas {
            assert_eq!(super::peak(isa, pixels), (peak, seed), "{isa:?} {case}");
        }
        assert_eq!(scan::peak(Emulated, pixels), (peak, seed), "{case}");

        let border = portable::border_min_max_sum(pixels, w, h);
        for &isa in isas {
            let found = super::border_min_max_sum(isa, pixels, w, h);
            assert_eq!(found, border, "{isa:?} {case}");
        }
        if w > 1 && h > 1 {
            let found = scan::border_min_max_sum(Emulated, pixels, w, h);
            assert_eq!(found, border, "{case}");
        }

        if peak == 0 {
            return 0;
        }
        let (seed_i, seed_j) = (seed % w, seed / w);
        let mut simple = 0;
        for threshold in [
            0,
            border.0.min(peak - 1),
            peak / 2,
            rng.random_range(0..peak),
            peak - 1,
        ] {
            let levels = (threshold, peak);
            let case = format!("threshold {threshold}, {case}");
            let mut mask = vec![0u64; h];
            portable::row_masks(pixels, w, threshold, &mut mask);
            for &isa in isas {
                let mut found = vec![u64::MAX; h];
                super::row_masks(isa, pixels, w, threshold, &mut found);
                assert_eq!(found, mask, "{isa:?} {case}");
            }
            let mut found = vec![u64::MAX; h];
            scan::row_masks(Emulated, pixels, w, threshold, &mut found);
            assert_eq!(found, mask, "{case}");

            // The walk finds the simple component, or none.
            let walked = simple_rows(&mask, seed_j).map(|(lo, hi)| {
                let union = mask[lo..=hi].iter().fold(0, |acc, &m| acc | m);
                (scalar_moments(pixels, w, &mask, lo, hi), (lo, hi), union)
            });
            simple += usize::from(walked.is_some());
            for &isa in isas {
                if isa == Isa::Sse2 && w < 8 {
                    continue;
                }
                let found = walk_simple(isa, pixels, (w, h), seed_j, levels);
                assert_eq!(found, walked, "{isa:?} {case}");
            }
            let found = match w.div_ceil(32) {
                1 => {
                    walk::simple_component::<Emulated, 1>(Emulated, pixels, (w, h), seed_j, levels)
                }
                _ => {
                    walk::simple_component::<Emulated, 2>(Emulated, pixels, (w, h), seed_j, levels)
                }
            };
            assert_eq!(found, walked, "{case}");

            // The shape sums of the simple component, the whole rows' above-threshold pixels.
            if let Some((_, (lo, hi), union)) = walked {
                let first = union.trailing_zeros() as usize;
                let last = 63 - union.leading_zeros() as usize;
                let origin = shape_origin(first, last, w);
                let expected = scalar_shape_sums(
                    pixels,
                    w,
                    None,
                    (lo, hi),
                    (first, last),
                    origin,
                    (threshold, u16::MAX),
                );
                for &isa in isas {
                    let found = shape_sums(isa, pixels, w, None, (lo, hi), union, levels);
                    assert_eq!(found, expected, "{isa:?} {case}");
                }
            }

            // The window moments of the seed's component, grown.
            let mut comp = vec![0u64; h];
            let (lo, hi) = grow_component(&mask, seed_i, seed_j, &mut comp);
            let cols = comp.iter().fold(0, |acc, &c| acc | c);
            let moments = scalar_moments(pixels, w, &comp, lo, hi);
            // Its shape sums.
            let (first, last) = (
                cols.trailing_zeros() as usize,
                63 - cols.leading_zeros() as usize,
            );
            let origin = shape_origin(first, last, w);
            let expected = scalar_shape_sums(
                pixels,
                w,
                Some(&comp),
                (lo, hi),
                (first, last),
                origin,
                (threshold, u16::MAX),
            );
            for &isa in isas {
                let found = shape_sums(isa, pixels, w, Some(&comp), (lo, hi), cols, levels);
                assert_eq!(found, expected, "{isa:?} {case}");
            }
            for &isa in isas {
                let found = window_moments(isa, pixels, w, &comp, &mask, (lo, hi), cols, levels);
                assert!(found.is_none_or(|m| m == moments), "{isa:?} {case}");
            }
            let (first, last) = (
                cols.trailing_zeros() as usize,
                63 - cols.leading_zeros() as usize,
            );
            let vectors = (last - first) / 32 + 1;
            if 32 * vectors <= w {
                let s = first.min(w - 32 * vectors);
                let args = (
                    pixels,
                    w,
                    comp.as_slice(),
                    mask.as_slice(),
                    (lo, hi),
                    s,
                    levels,
                );
                let found = match vectors {
                    1 => walk::window_moments::<Emulated, 1>(
                        Emulated, args.0, args.1, args.2, args.3, args.4, args.5, args.6,
                    ),
                    _ => walk::window_moments::<Emulated, 2>(
                        Emulated, args.0, args.1, args.2, args.3, args.4, args.5, args.6,
                    ),
                };
                assert_eq!(found, moments, "{case}");
            }
        }
        simple
    }

    /// Every kernel of every instruction set the CPU runs (and of the emulated 32-lane one, AVX-512's semantics)
    /// gives the portable kernel's results, to the bit, on synthetic ROIs and ROIs of camera-like blobs of every size
    /// from 1 x 1 to 64 x 64.
    #[test]
    fn kernels_agree_with_the_portable_ones_at_every_size() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let isas = vector_isas();
        let mut simple = 0;
        for w in 1..=64 {
            for h in 1..=64 {
                let kind = w * 64 + h;
                let pixels = synthetic(&mut rng, w, h, kind);
                simple += check(&isas, &pixels, (w, h), &mut rng);
                let (pixels, _) = blob(&mut rng, w as u32, h as u32, kind);
                simple += check(&isas, &pixels, (w, h), &mut rng);
            }
        }
        assert!(simple > 10_000, "{simple}");
    }

    #[test]
    fn block_rows_is_the_longest_block_that_fits() {
        for d in [0, 1, 2, 7, 100, 1000, 30_000, 65_535] {
            for rows in 1..=64 {
                let m = walk::block_rows(d, rows);
                let fits = |m: u64| d * m * (m + 1) / 2 <= 65_535;
                assert!((1..=rows).contains(&m), "{d} {rows}: {m}");
                assert!(m == 1 || fits(m), "{d} {rows}: {m}");
                assert!(m == rows || !fits(m + 1), "{d} {rows}: {m}");
            }
        }
    }
}
