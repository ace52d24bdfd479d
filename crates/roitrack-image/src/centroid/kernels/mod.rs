//! The passes over the pixels, vectorised, and the choice of instructions ([`Isa`]): the ROI's peak, its border's
//! minimum, maximum and sum, the rows' above-threshold masks, the moments over a window of columns, and the one-pass
//! walk that finds and measures a simple (convex) component.
//!
//! Each function here takes the [`Isa`] found once per call of [`super::measure_blob`] and runs the SSE2 kernels
//! ([`sse2`]: every x86_64 CPU), the AVX-512 ones ([`avx512`]: where the CPU has them) or the portable ones
//! ([`portable`]: elsewhere, and for ROIs too narrow for a vector). All give the same results, to the bit.

#[cfg(target_arch = "x86_64")]
mod avx512;
mod portable;
#[cfg(target_arch = "x86_64")]
mod sse2;

use super::moments::Moments;

/// Rows of 16-bit sums of values up to `d` and of their running sums that cannot overflow: the largest
/// `m <= rows` with `d * m * (m + 1) / 2 <= 65535` (at least 1).
#[cfg(target_arch = "x86_64")]
fn block_rows(d: u64, rows: u64) -> u64 {
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

/// The instructions the kernels use. All give the same results, to the bit (integer sums).
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
        if avx512::available() {
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

/// The largest pixel and the index of its first occurrence (row-major).
pub(super) fn peak(isa: Isa, pixels: &[u16]) -> (u16, usize) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx512` only where the CPU has the features.
        Isa::Avx512 => unsafe { avx512::peak(pixels) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE2 is part of the x86_64 baseline.
        Isa::Sse2 if pixels.len() >= 8 => unsafe { sse2::peak(pixels) },
        _ => portable::peak(pixels),
    }
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image.
pub(super) fn border_min_max_sum(isa: Isa, pixels: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx512` only where the CPU has the features.
        Isa::Avx512 if w > 1 && h > 1 => unsafe { avx512::border_min_max_sum(pixels, w, h) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE2 is part of the x86_64 baseline.
        Isa::Sse2 if w > 8 && h > 1 => unsafe { sse2::border_min_max_sum(pixels, w, h) },
        _ => portable::border_min_max_sum(pixels, w, h),
    }
}

/// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold`.
pub(in crate::centroid) fn row_masks(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    threshold: u16,
    rows: &mut [u64],
) {
    #[cfg(target_arch = "x86_64")]
    if isa != Isa::Portable && w >= 8 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        return unsafe { sse2::row_masks(pixels, w, threshold, rows) };
    }
    let _ = isa;
    portable::row_masks(pixels, w, threshold, rows);
}

/// The moments of the component `comp` (rows `lo..=hi`, columns `cols` the union of its rows) of the above-threshold
/// pixels `mask`, with SSE2 over a window of 8-pixel vectors holding its columns; `None` where the ROI is too narrow
/// for the window (or without vectors).
#[allow(clippy::too_many_arguments)]
pub(super) fn window_moments(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    comp: &[u64],
    mask: &[u64],
    rows: (usize, usize),
    cols: u64,
    (threshold, peak): (u16, u16),
) -> Option<Moments> {
    #[cfg(target_arch = "x86_64")]
    if isa != Isa::Portable {
        let first = cols.trailing_zeros() as usize;
        let last = 63 - cols.leading_zeros() as usize;
        let vectors = (last - first) / 8 + 1;
        if 8 * vectors <= w {
            let s = first.min(w - 8 * vectors);
            macro_rules! window {
                ($n:literal) => {
                    sse2::window_moments::<$n>(pixels, w, comp, mask, rows, s, threshold, peak)
                };
            }
            // SAFETY: SSE2 is part of the x86_64 baseline.
            return Some(unsafe {
                match vectors {
                    1 => window!(1),
                    2 => window!(2),
                    3 => window!(3),
                    4 => window!(4),
                    5 => window!(5),
                    6 => window!(6),
                    7 => window!(7),
                    _ => window!(8),
                }
            });
        }
    }
    let _ = (isa, pixels, w, comp, mask, rows, cols, threshold, peak);
    None
}

/// The seed's component (its moments, first and last rows and union of columns) when it is simple, found and
/// measured in one pass over its rows (see `sse2::simple_component`); `None` when it is not (or without
/// vectors, or the ROI is narrower than 8 pixels).
#[cfg(target_arch = "x86_64")]
pub(super) fn walk_simple(
    isa: Isa,
    pixels: &[u16],
    (w, h): (usize, usize),
    seed_j: usize,
    (threshold, peak): (u16, u16),
) -> Option<(Moments, (usize, usize), u64)> {
    macro_rules! walk {
        ($isa:ident, $n:literal) => {
            $isa::simple_component::<$n>(pixels, (w, h), seed_j, threshold, peak)
        };
    }
    match isa {
        // SAFETY: `Isa::Avx512` only where the CPU has the features.
        Isa::Avx512 => unsafe {
            if w <= 32 {
                walk!(avx512, 1)
            } else {
                walk!(avx512, 2)
            }
        },
        // SAFETY: SSE2 is part of the x86_64 baseline.
        Isa::Sse2 if w >= 8 => unsafe {
            match w.div_ceil(8) {
                1 => walk!(sse2, 1),
                2 => walk!(sse2, 2),
                3 => walk!(sse2, 3),
                4 => walk!(sse2, 4),
                5 => walk!(sse2, 5),
                6 => walk!(sse2, 6),
                7 => walk!(sse2, 7),
                _ => walk!(sse2, 8),
            }
        },
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
) -> Option<(Moments, (usize, usize), u64)> {
    None
}
