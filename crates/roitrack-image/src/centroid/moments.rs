//! The integer first-order moments of a component ([`Moments`]) and their measurement over a component given as row
//! masks: vectorised over a window of its columns where the CPU allows (in [`super::kernels`]), else a row at a time.
//!
//! The moments are integer sums, exact whatever the order they are added in: that is what lets every instruction set
//! give the same centroid to the bit.

use super::kernels::{self, Isa};

/// Integer first-order moments of a component: pixel count, sums of i, j, value, value * i, value * j.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Moments {
    pub(super) n: u64,
    pub(super) sum_i: u64,
    pub(super) sum_j: u64,
    pub(super) sum_p: u64,
    pub(super) sum_pi: u64,
    pub(super) sum_pj: u64,
}

/// The moments of the component `comp` (rows `lo..=hi`), a row at a time over its runs.
pub(super) fn scalar_moments(
    pixels: &[u16],
    w: usize,
    comp: &[u64],
    lo: usize,
    hi: usize,
) -> Moments {
    let mut m = Moments::default();
    for (j, &bits) in comp.iter().enumerate().take(hi + 1).skip(lo) {
        if bits == 0 {
            continue;
        }
        let first = bits.trailing_zeros() as usize;
        let last = 63 - bits.leading_zeros() as usize;
        let span = &pixels[j * w + first..=j * w + last];
        let single_run = bits >> first == u64::MAX >> (63 - (last - first));
        let (n, si, sp, spi) = if single_run {
            // One run (always, for a convex blob): plain sums over it (u32 cannot overflow: 64 x 65535 x 63).
            let n = (last - first + 1) as u64;
            let (sp, spk) = span
                .iter()
                .enumerate()
                .fold((0u32, 0u32), |(sp, spk), (k, &p)| {
                    (sp + u32::from(p), spk + u32::from(p) * k as u32)
                });
            let (sp, spk) = (u64::from(sp), u64::from(spk));
            (
                n,
                n * (first + last) as u64 / 2,
                sp,
                spk + first as u64 * sp,
            )
        } else {
            let (mut n, mut si, mut sp, mut spi) = (0u64, 0u64, 0u64, 0u64);
            for (k, &p) in span.iter().enumerate() {
                let i = (first + k) as u64;
                let m = (bits >> i) & 1;
                let pm = u64::from(p) * m;
                n += m;
                si += m * i;
                sp += pm;
                spi += pm * i;
            }
            (n, si, sp, spi)
        };
        m.n += n;
        m.sum_i += si;
        m.sum_j += n * j as u64;
        m.sum_p += sp;
        m.sum_pi += spi;
        m.sum_pj += sp * j as u64;
    }
    m
}

/// The moments of the component `comp` (rows `lo..=hi`, columns `cols` the union of its rows) of the above-threshold
/// pixels `mask`: with SSE2 over a window of 8-pixel vectors holding its columns where the ROI is wide enough, else a
/// row at a time.
#[allow(clippy::too_many_arguments)]
pub(super) fn moments(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    comp: &[u64],
    mask: &[u64],
    rows: (usize, usize),
    cols: u64,
    levels: (u16, u16),
) -> Moments {
    kernels::window_moments(isa, pixels, w, comp, mask, rows, cols, levels)
        .unwrap_or_else(|| scalar_moments(pixels, w, comp, rows.0, rows.1))
}

/// Sums over a component of its weights `v = value - threshold` times `x^p y^q` (p + q <= 3), (x, y) the pixel's
/// column and row relative to an origin: what the shape check ([`crate::symmetry`]) needs, exact integers (so that
/// every instruction set gives the same check to the bit).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct ShapeSums {
    /// In the order 00, 10, 01, 20, 11, 02, 30, 21, 12, 03 (`s[k]` for `x^p y^q`).
    pub(crate) s: [u64; 10],
}

impl ShapeSums {
    /// From sums that are non-negative (they are, over pixels right of and below the origin).
    pub(super) fn from_i64(s: [i64; 10]) -> Self {
        Self {
            s: s.map(|x| x as u64),
        }
    }
}

/// Calls `visit(i, j, v)` for every pixel of rows `lo..=hi` and columns `first..=last` with its weight in the shape
/// sums: `value - threshold`, at most `cap`, and 0 outside `comp` (bit i column i; `None`: every pixel counts, those
/// at or below the threshold weighing 0).
#[inline(always)]
pub(crate) fn visit_shape_weights(
    pixels: &[u16],
    w: usize,
    comp: Option<&[u64]>,
    (lo, hi): (usize, usize),
    (first, last): (usize, usize),
    (threshold, cap): (u16, u16),
    mut visit: impl FnMut(usize, usize, u64),
) {
    for j in lo..=hi {
        let bits = comp.map_or(u64::MAX, |c| c[j]);
        for i in first..=last {
            let v =
                u64::from(pixels[j * w + i].saturating_sub(threshold).min(cap)) * ((bits >> i) & 1);
            visit(i, j, v);
        }
    }
}

/// The [`ShapeSums`] of the component of rows `lo..=hi` and columns `first..=last`, x from column `origin`
/// (`<= first`), y from row `lo`, a pixel at a time: of the pixels of `comp` (bit i column i), or with `None` of every
/// above-threshold pixel of those rows and columns (a simple component's); each pixel weighs `value - threshold`, at
/// most `cap` (see [`visit_shape_weights`]).
pub(crate) fn scalar_shape_sums(
    pixels: &[u16],
    w: usize,
    comp: Option<&[u64]>,
    (lo, hi): (usize, usize),
    (first, last): (usize, usize),
    origin: usize,
    levels: (u16, u16),
) -> ShapeSums {
    let mut s = [0u64; 10];
    visit_shape_weights(
        pixels,
        w,
        comp,
        (lo, hi),
        (first, last),
        levels,
        |i, j, v| {
            let (x, y) = ((i - origin) as u64, (j - lo) as u64);
            let (vx, vy) = (v * x, v * y);
            s[0] += v;
            s[1] += vx;
            s[2] += vy;
            s[3] += vx * x;
            s[4] += vx * y;
            s[5] += vy * y;
            s[6] += vx * x * x;
            s[7] += vx * x * y;
            s[8] += vx * y * y;
            s[9] += vy * y * y;
        },
    );
    ShapeSums { s }
}
