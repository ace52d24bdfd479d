//! Blob centroid in an ROI: threshold, keep the connected component of the brightest pixel, first-order moments.
//!
//! [`measure_blob`] allocates nothing and reads the pixels about twice: pass 1 finds the maximum and the border's
//! statistics (whence the threshold); pass 2 walks the rows from the brightest pixel's, up and down, making each
//! row's above-threshold mask (one `u64`: ROIs up to [`MAX_ROI_WIDTH`] x [`MAX_ROI_HEIGHT`] pixels) and summing
//! `value - threshold` per column in 16-bit lanes (the row moment from running sums of the sums). When every row
//! met is a single run touching the previous one (a convex blob: the usual case), the component is these runs and the
//! walk has measured it. Otherwise every row's mask is made, the component is grown a whole row at a time with bit
//! operations (the run of set bits of `m` from a seed bit `s` towards the high bits is `((m + s) ^ m) & m`), and its
//! moments are summed over the window of its rows and columns.
//!
//! With the default options the blob must then pass a symmetry check ([`SymmetryCheck`], in [`crate::symmetry`]): a
//! reflection merged with a blob pulls its moments by up to half a pixel, and is caught by the outline's asymmetry.
//!
//! The kernels take 8 pixels a vector with SSE2 (every x86_64 CPU) or 32 with AVX-512 where the CPU has it, a pixel
//! at a time elsewhere. The moments are integer sums (exact), so every path gives the same centroid to the bit.

use thiserror::Error;

use crate::roi::Roi;
use crate::symmetry::outline_centre;

/// Widest ROI [`measure_blob`] accepts (pixels): a row's mask is one `u64`.
pub const MAX_ROI_WIDTH: u32 = 64;
/// Tallest ROI [`measure_blob`] accepts (pixels).
pub const MAX_ROI_HEIGHT: u32 = 64;

/// With [`Threshold::Auto`], the threshold is the background plus this fraction of the peak's contrast. Low, so that
/// the weighted centroid sees nearly the whole blurred edge (at 0.5, pixels entering and leaving the component as the
/// blob moves sub-pixel lock the centroid by up to 0.04 px; at 0.15, 0.008 px), yet about 50 noise sigmas above the
/// background for the default sensor (33 DN over a 0.6 DN noise).
pub const AUTO_THRESHOLD_FRACTION: f64 = 0.15;

/// With [`Threshold::Auto`], a blob is absent when its peak stands less than this many background standard deviations
/// above the background (a noise-only 64 x 64 ROI peaks at about 4 sigma).
pub const AUTO_MIN_CONTRAST_SIGMAS: f64 = 8.0;
/// With [`Threshold::Auto`], a blob is absent when its peak stands less than this above the background (DN), whatever
/// the noise (a noiseless image).
pub const AUTO_MIN_CONTRAST_DN: f64 = 4.0;

/// How pixels are classified as blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Threshold {
    /// Pixels strictly above this value (DN) are blob; weights are measured from it.
    Fixed(u16),
    /// From the ROI itself: the background is the mean of the ROI's border pixels below the midpoint of the border's
    /// minimum and the ROI's maximum (robust to another blob crossing the border); the threshold is the background
    /// plus [`AUTO_THRESHOLD_FRACTION`] (0.15) of the peak's contrast. A blob whose peak stands less than
    /// max([`AUTO_MIN_CONTRAST_SIGMAS`] * border noise, [`AUTO_MIN_CONTRAST_DN`]) above the background is absent.
    /// In a full frame ([`crate::detect_blobs`]) the background is the image's median and the noise its
    /// 50 - 15.9 percentile spread.
    #[default]
    Auto,
}

/// How a blob's centroid is measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CentroidOptions {
    pub threshold: Threshold,
    /// `true` (the default, the more accurate): first-order moments weighted by `value - threshold` over the
    /// component's pixels. Measuring from the threshold rather than from the background makes the weights vanish
    /// where pixels enter or leave the component as the blob moves, so the centroid does not lock to the pixel grid
    /// (noiseless 6 mm blob swept over sub-pixel positions: RMS error 0.004 px, against 0.014 px weighting by
    /// `value - background` at the same threshold). `false`: the paper's binary first-order moments of the
    /// thresholded pixels (RMS error 0.06-0.08 px: every pixel counts fully or not at all).
    pub intensity_weighted: bool,
    /// Smallest accepted component (pixels). Default 4.
    pub min_area_px: u32,
    /// Largest accepted component (pixels). Default 4096 (a full 64 x 64 ROI).
    pub max_area_px: u32,
    /// Reject blobs that are not centrally symmetric (see [`SymmetryCheck`]). Default on.
    pub symmetry: Option<SymmetryCheck>,
}

/// A test that the blob is the image of a disk, and nothing merged with it: a reflection or a glint touching the blob,
/// or an occluder cutting it, pulls the first-order moments by up to about half a pixel while the blob still looks like
/// one blob. A disk's image (an ellipse, blurred, and motion-blurred along a line) is centrally symmetric, so the
/// midpoints of its chords (rows, then columns) at half contrast lie on two lines through its centre (see
/// [`crate::symmetry`]); robust line fits find them despite the chords a spot moves. The blob is rejected as
/// [`BlobRejection::Asymmetric`] when that centre is off the centroid, or a chord midpoint off its line.
///
/// Measured with `cargo run --release -p roitrack-image --example image_bench reflections` (the default sensor, 4,000
/// ROIs a case, a spot of sigma 1.2 px, 0.5 to 1.5 times the blob's peak, 6 to 10 px from the ROI's centre, in every
/// ROI): no clean blob was rejected in any case, and the centroids the spots moved by more than 0.1 px fell from
/// 3,458 to 3 (worst 0.18 px) for 6 mm blobs (15 px), from 1,935 to 7 (worst 0.11 px) for 9 mm blobs (22 px), from
/// 3,453 to 5 with the wide-angle lens, and from 1,457 to 28 for 3 mm blobs (7 px), whose few chords leave a spot as
/// large as the blob harder to see. A spot apart from the blob and brighter takes the centroid whatever the check
/// (a gross outlier, for the estimator's gate). Costs about 1.3 µs a blob (the moments alone: 0.14 µs). Blobs with
/// fewer than 3 usable chords a direction (under about 5 px across) are not tested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetryCheck {
    /// Largest distance between the centroid and the outline's centre (px). Default 0.06.
    pub max_centre_offset_px: f64,
    /// Largest distance of a chord's midpoint from the fitted line of midpoints (px). Default 0.2.
    pub max_outline_residual_px: f64,
}

impl Default for SymmetryCheck {
    fn default() -> Self {
        Self {
            max_centre_offset_px: 0.06,
            max_outline_residual_px: 0.2,
        }
    }
}

impl Default for CentroidOptions {
    fn default() -> Self {
        Self {
            threshold: Threshold::Auto,
            intensity_weighted: true,
            min_area_px: 4,
            max_area_px: 4096,
            symmetry: Some(SymmetryCheck::default()),
        }
    }
}

impl CentroidOptions {
    /// The paper's measurement: binary first-order moments of the thresholded pixels (automatic threshold).
    pub fn binary() -> Self {
        Self {
            intensity_weighted: false,
            ..Self::default()
        }
    }
}

/// A measured blob.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Centroid {
    /// Centroid, full-sensor raw (distorted) pixel coordinates (pixel (i, j) is centred on (i, j)).
    pub u_px: f64,
    pub v_px: f64,
    /// Pixels in the component.
    pub area_px: u32,
    /// Sum over the component of `value - background` (DN): the blob's brightness.
    pub sum: f64,
    /// Brightest value (DN).
    pub peak: u16,
}

/// Why an ROI gave no centroid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum BlobRejection {
    #[error("no blob in the ROI (nothing stands out of the background)")]
    Absent,
    #[error("the blob touches the ROI's border (the ROI cuts it)")]
    TouchesBorder,
    #[error("the blob is too small ({area_px} px)")]
    TooSmall { area_px: u32 },
    #[error("the blob is too large ({area_px} px)")]
    TooLarge { area_px: u32 },
    #[error(
        "the blob is not centrally symmetric (a reflection or an occluder merged with it would bias its centroid)"
    )]
    Asymmetric,
}

/// Background level (DN), the integer threshold (pixels `> threshold` are blob) and the level weights are measured
/// from (DN) of an ROI.
struct Levels {
    background: f64,
    threshold: u16,
    weight_origin: f64,
}

/// Statistics of the border pixels at or below a cut.
#[derive(Debug, Clone, Copy)]
struct BorderStats {
    min: u16,
    max: u16,
    count: u32,
    sum: u64,
    sum_sq: u64,
}

impl BorderStats {
    /// Of the border pixels of a row-major `w` x `h` image at or below `cut` (all of them with `u16::MAX`).
    fn at_most(pixels: &[u16], w: usize, h: usize, cut: u16) -> Self {
        let mut st = Self {
            min: u16::MAX,
            max: 0,
            count: 0,
            sum: 0,
            sum_sq: 0,
        };
        let mut add = |p: u16| {
            if p <= cut {
                st.min = st.min.min(p);
                st.max = st.max.max(p);
                st.count += 1;
                st.sum += u64::from(p);
                st.sum_sq += u64::from(p) * u64::from(p);
            }
        };
        pixels[..w].iter().for_each(|&p| add(p));
        if h > 1 {
            pixels[(h - 1) * w..].iter().for_each(|&p| add(p));
        }
        for j in 1..h.saturating_sub(1) {
            add(pixels[j * w]);
            if w > 1 {
                add(pixels[j * w + w - 1]);
            }
        }
        st
    }

    /// Mean and standard deviation, if any pixel counted.
    fn mean_sigma(&self) -> Option<(f64, f64)> {
        (self.count > 0).then(|| {
            let n = f64::from(self.count);
            let mean = self.sum as f64 / n;
            (mean, (self.sum_sq as f64 / n - mean * mean).max(0.0).sqrt())
        })
    }
}

/// Number of border pixels of a `w` x `h` image.
fn border_len(w: usize, h: usize) -> u32 {
    let n = if h == 1 {
        w
    } else {
        2 * w + (h - 2) * w.min(2)
    };
    n as u32
}

/// The levels of an ROI given its peak and the minimum, maximum and sum of its border pixels (from one vectorised
/// pass: the rarer cases, a bright pixel on the border or a contrast that needs the border's noise, go through
/// `BorderStats::at_most`).
fn levels(
    pixels: &[u16],
    w: usize,
    h: usize,
    peak: u16,
    (min, max, sum): (u16, u16, u64),
    threshold: Threshold,
) -> Result<Levels, BlobRejection> {
    let all = BorderStats {
        min,
        max,
        count: border_len(w, h),
        sum,
        sum_sq: 0, // not computed
    };
    match threshold {
        Threshold::Fixed(t) => {
            if peak <= t {
                return Err(BlobRejection::Absent);
            }
            let below = if all.max <= t {
                all
            } else {
                BorderStats::at_most(pixels, w, h, t)
            };
            Ok(Levels {
                background: below.mean_sigma().map_or(f64::from(t), |(mean, _)| mean),
                threshold: t,
                weight_origin: f64::from(t),
            })
        }
        Threshold::Auto => {
            let cut = ((u32::from(all.min) + u32::from(peak)) / 2) as u16;
            let below = if all.max <= cut {
                all
            } else {
                BorderStats::at_most(pixels, w, h, cut)
            };
            let background = if below.count > 0 {
                below.sum as f64 / f64::from(below.count)
            } else {
                f64::from(all.min)
            };
            let contrast = f64::from(peak) - background;
            // A standard deviation is at most half the range, so a contrast of AUTO_MIN_CONTRAST_SIGMAS / 2 ranges
            // (plus 1 DN, far above the rounding of the sigma below) passes the test without the sum of squares.
            let range = f64::from(below.max.saturating_sub(below.min));
            let clear = contrast >= AUTO_MIN_CONTRAST_DN
                && contrast >= 0.5 * AUTO_MIN_CONTRAST_SIGMAS * range + 1.0;
            if !clear {
                let cut = if all.max <= cut { u16::MAX } else { cut };
                let sigma = BorderStats::at_most(pixels, w, h, cut)
                    .mean_sigma()
                    .map_or(0.0, |(_, sigma)| sigma);
                if contrast < (AUTO_MIN_CONTRAST_SIGMAS * sigma).max(AUTO_MIN_CONTRAST_DN) {
                    return Err(BlobRejection::Absent);
                }
            }
            let level = background + AUTO_THRESHOLD_FRACTION * contrast;
            Ok(Levels {
                background,
                // `as` truncates, which for the positive level is the floor (and saves a libm call).
                threshold: level as u16,
                weight_origin: level,
            })
        }
    }
}

/// Integer first-order moments of a component: pixel count, sums of i, j, value, value * i, value * j.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Moments {
    n: u64,
    sum_i: u64,
    sum_j: u64,
    sum_p: u64,
    sum_pi: u64,
    sum_pj: u64,
}

/// SSE2 kernels. SSE2 is part of the x86_64 baseline, so every x86_64 CPU runs them. Each is a
/// `#[target_feature(enable = "sse2")]` function, in which the intrinsics are safe to call (only the unaligned loads,
/// which take raw pointers, need `unsafe`); callers' `unsafe` blocks only assert the feature.
#[cfg(target_arch = "x86_64")]
mod sse2 {
    use std::arch::x86_64::*;

    use super::Moments;

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
        fn flush<const DOWN: bool>(
            &mut self,
            a: &mut [__m128i; N],
            b: &mut [__m128i; N],
            last: usize,
        ) {
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
                if !super::single_run(mask) || super::dilate(prev) & mask == 0 {
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
}

/// AVX-512 kernels (F and BW, with BMI1, LZCNT and POPCNT), for the CPUs that have them (see [`Isa`]): 32 pixels a
/// register, loaded under a mask at any width, and comparisons that give each row's above-threshold mask directly.
/// Each is a `#[target_feature]` function, in which the intrinsics are safe to call (only the loads and gathers, which
/// take raw pointers, need `unsafe`); callers' `unsafe` blocks assert the CPU's features.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use std::arch::x86_64::*;

    use super::Moments;

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
        fn fold<const DOWN: bool>(
            &mut self,
            a: &mut [__m512i; N],
            b: &mut [__m512i; N],
            last: usize,
        ) {
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
                if !super::single_run(mask) || super::dilate(prev) & mask == 0 {
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
}

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
enum Isa {
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
    fn detect() -> Self {
        if avx512::available() {
            Self::Avx512
        } else {
            Self::Sse2
        }
    }

    /// The best the CPU runs.
    #[cfg(not(target_arch = "x86_64"))]
    fn detect() -> Self {
        Self::Portable
    }
}

/// The largest pixel and the index of its first occurrence (row-major).
fn peak(isa: Isa, pixels: &[u16]) -> (u16, usize) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx512` only where the CPU has the features.
        Isa::Avx512 => unsafe { avx512::peak(pixels) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE2 is part of the x86_64 baseline.
        Isa::Sse2 if pixels.len() >= 8 => unsafe { sse2::peak(pixels) },
        _ => {
            let peak = pixels.iter().copied().fold(0, u16::max);
            (peak, first_equal(pixels, peak))
        }
    }
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image.
fn border_min_max_sum(isa: Isa, pixels: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx512` only where the CPU has the features.
        Isa::Avx512 if w > 1 && h > 1 => unsafe { avx512::border_min_max_sum(pixels, w, h) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE2 is part of the x86_64 baseline.
        Isa::Sse2 if w > 8 && h > 1 => unsafe { sse2::border_min_max_sum(pixels, w, h) },
        _ => {
            let (mut min, mut max, mut sum) = (u16::MAX, 0u16, 0u64);
            let mut add_row = |row: &[u16]| {
                min = row.iter().copied().fold(min, u16::min);
                max = row.iter().copied().fold(max, u16::max);
                sum += row.iter().map(|&p| u64::from(p)).sum::<u64>();
            };
            add_row(&pixels[..w]);
            if h > 1 {
                add_row(&pixels[(h - 1) * w..]);
            }
            for j in 1..h.saturating_sub(1) {
                add_row(&pixels[j * w..j * w + 1]);
                if w > 1 {
                    add_row(&pixels[j * w + w - 1..j * w + w]);
                }
            }
            (min, max, sum)
        }
    }
}

/// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold`.
fn row_masks(isa: Isa, pixels: &[u16], w: usize, threshold: u16, rows: &mut [u64]) {
    #[cfg(target_arch = "x86_64")]
    if isa != Isa::Portable && w >= 8 {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        return unsafe { sse2::row_masks(pixels, w, threshold, rows) };
    }
    let _ = isa;
    let mut flat = [0u64; (MAX_ROI_WIDTH * MAX_ROI_HEIGHT / 64) as usize];
    flat_above(pixels, threshold, &mut flat);
    for (j, m) in rows.iter_mut().enumerate() {
        *m = bits_at(&flat, j * w, w);
    }
}

/// Bit i set where `pred(chunk[i])`: the comparisons vectorise into a byte per pixel, and a multiplication gathers
/// each 8 bytes' low bits into one byte (b_k * 2^(8k) times 0x0102040810204080 puts b_k at bit 56 + k, carry-free).
#[inline]
fn mask16(chunk: &[u16; 16], pred: impl Fn(u16) -> bool) -> u64 {
    const GATHER: u64 = 0x0102_0408_1020_4080;
    let bytes: [u8; 16] = std::array::from_fn(|i| u8::from(pred(chunk[i])));
    let lo = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
    let hi = u64::from_le_bytes(bytes[8..].try_into().expect("8 bytes"));
    (lo.wrapping_mul(GATHER) >> 56) | ((hi.wrapping_mul(GATHER) >> 56) << 8)
}

/// Index of the first pixel equal to `value` (0 if none), comparing 16 pixels at a time.
#[inline]
fn first_equal(pixels: &[u16], value: u16) -> usize {
    let mut chunks = pixels.chunks_exact(16);
    for (c, chunk) in chunks.by_ref().enumerate() {
        let bits = mask16(chunk.try_into().expect("16 pixels"), |p| p == value);
        if bits != 0 {
            return 16 * c + bits.trailing_zeros() as usize;
        }
    }
    let done = pixels.len() - chunks.remainder().len();
    chunks
        .remainder()
        .iter()
        .position(|&p| p == value)
        .map_or(0, |k| done + k)
}

/// Bit k of `flat` (word k / 64, bit k % 64) set where `pixels[k] > threshold`, 16 pixels at a time.
#[inline]
fn flat_above(pixels: &[u16], threshold: u16, flat: &mut [u64]) {
    let mut words = pixels.chunks_exact(64);
    for (word, chunk) in flat.iter_mut().zip(words.by_ref()) {
        *word = chunk
            .chunks_exact(16)
            .enumerate()
            .fold(0, |bits, (c, sixteen)| {
                bits | mask16(sixteen.try_into().expect("16 pixels"), |p| p > threshold) << (16 * c)
            });
    }
    let rest = words.remainder();
    if !rest.is_empty() {
        flat[pixels.len() / 64] = rest
            .iter()
            .enumerate()
            .fold(0, |acc, (i, &p)| acc | (u64::from(p > threshold) << i));
    }
}

/// The `w` bits (`w <= 64`) of `flat` from bit `start` on.
#[inline]
fn bits_at(flat: &[u64], start: usize, w: usize) -> u64 {
    let (word, shift) = (start / 64, start % 64);
    let mut bits = flat[word] >> shift;
    if shift + w > 64 {
        bits |= flat[word + 1] << (64 - shift);
    }
    bits & (u64::MAX >> (64 - w))
}

/// The runs of `mask` containing a bit of `seeds` (one iteration per run: usually one).
#[inline]
fn run_fill(mask: u64, seeds: u64) -> u64 {
    let mut s = seeds & mask;
    let mut runs = 0;
    while s != 0 {
        let low = s & s.wrapping_neg();
        // From the lowest seed up to the run's end: the carry of `mask + low` runs through the run.
        let up = (mask.wrapping_add(low) ^ mask) & mask;
        // Below it, down to the mask's highest gap under it.
        let below = low - 1;
        let gaps = !mask & below;
        let down = below & !u64::MAX.checked_shr(gaps.leading_zeros()).unwrap_or(0);
        runs |= up | down;
        s &= !runs;
    }
    runs
}

/// The bits of `x` and their left and right neighbours.
#[inline]
fn dilate(x: u64) -> u64 {
    x | (x << 1) | (x >> 1)
}

/// Whether `m` (non-zero) is a single run of set bits (adding its lowest bit carries through the run).
#[inline]
fn single_run(m: u64) -> bool {
    m & m.wrapping_add(m & m.wrapping_neg()) == 0
}

/// The first and last rows of the seed's component when the non-empty rows of `mask` around the seed's (row
/// `seed_j`) are single runs each touching the next (a convex blob's, nearly always): that component is then these
/// rows' masks whole. `None` otherwise (then see [`grow_component`]).
fn simple_rows(mask: &[u64], seed_j: usize) -> Option<(usize, usize)> {
    if !single_run(mask[seed_j]) {
        return None;
    }
    let mut hi = seed_j;
    for pair in mask[seed_j..].windows(2) {
        let (above, m) = (pair[0], pair[1]);
        if m == 0 {
            break;
        }
        if !single_run(m) || dilate(above) & m == 0 {
            return None;
        }
        hi += 1;
    }
    let mut lo = seed_j;
    for pair in mask[..=seed_j].windows(2).rev() {
        let (m, below) = (pair[0], pair[1]);
        if m == 0 {
            break;
        }
        if !single_run(m) || dilate(below) & m == 0 {
            return None;
        }
        lo -= 1;
    }
    Some((lo, hi))
}

/// The 8-connected component of `mask` (one `u64` per row) containing bit `seed_i` of row `seed_j`, into `comp`
/// (zeroed on entry). Returns its first and last rows.
fn grow_component(mask: &[u64], seed_i: usize, seed_j: usize, comp: &mut [u64]) -> (usize, usize) {
    let h = mask.len();
    comp[seed_j] = run_fill(mask[seed_j], 1u64 << seed_i);
    let (mut lo, mut hi) = (seed_j, seed_j);
    let (mut need_down, mut need_up) = (true, true);
    // The first upward sweep starts above the seed's row unless the first downward one found pixels below it
    // touching runs of their upper rows outside the component; later ones start at `hi`.
    let mut up_from = seed_j;
    while need_down || need_up {
        if need_down {
            need_down = false;
            for j in lo + 1..h {
                let new = run_fill(mask[j], comp[j] | dilate(comp[j - 1]));
                if new != comp[j] {
                    comp[j] = new;
                    // New pixels may reach runs of the row above that the last upward sweep missed.
                    if dilate(new) & mask[j - 1] & !comp[j - 1] != 0 {
                        need_up = true;
                        up_from = h;
                    }
                }
                if new != 0 {
                    hi = hi.max(j);
                } else if j > hi {
                    break;
                }
            }
        }
        if need_up {
            need_up = false;
            for j in (0..hi.min(up_from)).rev() {
                let new = run_fill(mask[j], comp[j] | dilate(comp[j + 1]));
                if new != comp[j] {
                    comp[j] = new;
                    need_down |= dilate(new) & mask[j + 1] & !comp[j + 1] != 0;
                }
                if new != 0 {
                    lo = lo.min(j);
                } else if j < lo {
                    break;
                }
            }
            up_from = h;
        }
    }
    (lo, hi)
}

/// The moments of the component `comp` (rows `lo..=hi`), a row at a time over its runs.
fn scalar_moments(pixels: &[u16], w: usize, comp: &[u64], lo: usize, hi: usize) -> Moments {
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
fn moments(
    isa: Isa,
    pixels: &[u16],
    w: usize,
    comp: &[u64],
    mask: &[u64],
    rows: (usize, usize),
    cols: u64,
    (threshold, peak): (u16, u16),
) -> Moments {
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
            return unsafe {
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
            };
        }
    }
    let _ = (isa, mask, cols, threshold, peak);
    scalar_moments(pixels, w, comp, rows.0, rows.1)
}

/// The seed's component (its moments, first and last rows and union of columns) when it is simple, found and
/// measured in one pass over its rows (see `sse2::simple_component`); `None` when it is not (or without
/// vectors, or the ROI is narrower than 8 pixels).
#[cfg(target_arch = "x86_64")]
fn walk_simple(
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
fn walk_simple(
    _isa: Isa,
    _pixels: &[u16],
    _size: (usize, usize),
    _seed_j: usize,
    _levels: (u16, u16),
) -> Option<(Moments, (usize, usize), u64)> {
    None
}

/// The component of the seed pixel `(seed_i, seed_j)` (its moments, first and last rows and union of columns) from
/// the threshold mask of every row.
fn component_moments(
    isa: Isa,
    pixels: &[u16],
    (w, h): (usize, usize),
    (seed_i, seed_j): (usize, usize),
    levels: (u16, u16),
) -> (Moments, (usize, usize), u64) {
    let mut mask_rows = [0u64; MAX_ROI_HEIGHT as usize];
    row_masks(isa, pixels, w, levels.0, &mut mask_rows[..h]);
    let mask = &mask_rows[..h];
    let mut comp_rows = [0u64; MAX_ROI_HEIGHT as usize];
    let (comp, lo, hi) = match simple_rows(mask, seed_j) {
        Some((lo, hi)) => (mask, lo, hi),
        None => {
            let (lo, hi) = grow_component(mask, seed_i, seed_j, &mut comp_rows[..h]);
            (&comp_rows[..h], lo, hi)
        }
    };
    let cols = comp[lo..=hi].iter().fold(0, |acc, &c| acc | c);
    (
        moments(isa, pixels, w, comp, mask, (lo, hi), cols, levels),
        (lo, hi),
        cols,
    )
}

/// Measures the blob of an ROI: the connected component (8-connectivity) of above-threshold pixels that contains the
/// brightest pixel (the first in row-major order if several), so another blob or a reflection elsewhere in the ROI
/// does not bias it (a blob of equal brightness elsewhere in the ROI may win the tie: size the ROI to hold one blob).
/// The centroid is the component's first-order moments, weighted by `value - threshold` or binary (see
/// [`CentroidOptions`]), in full-sensor pixel coordinates.
///
/// Rejections, in this order: [`BlobRejection::Absent`] (nothing above the threshold or too little contrast),
/// [`BlobRejection::TouchesBorder`] (the component reaches the ROI's outer rows or columns), the area limits, then
/// [`BlobRejection::Asymmetric`] (with [`CentroidOptions::symmetry`], the default: something merged with the blob).
///
/// # Panics
/// If `pixels.len() != roi.len()`, or the ROI is empty or larger than [`MAX_ROI_WIDTH`] x [`MAX_ROI_HEIGHT`].
pub fn measure_blob(
    pixels: &[u16],
    roi: &Roi,
    opts: &CentroidOptions,
) -> Result<Centroid, BlobRejection> {
    measure_blob_with(Isa::detect(), pixels, roi, opts)
}

/// [`measure_blob`] with the given instructions.
fn measure_blob_with(
    isa: Isa,
    pixels: &[u16],
    roi: &Roi,
    opts: &CentroidOptions,
) -> Result<Centroid, BlobRejection> {
    let (w, h) = (roi.width as usize, roi.height as usize);
    assert!(
        (1..=MAX_ROI_WIDTH).contains(&roi.width) && (1..=MAX_ROI_HEIGHT).contains(&roi.height),
        "measure_blob handles ROIs of 1x1 to {MAX_ROI_WIDTH}x{MAX_ROI_HEIGHT} pixels, got {w}x{h}"
    );
    assert_eq!(pixels.len(), w * h, "pixel buffer length");
    // Pass 1: the peak and its first position; the border's statistics.
    let (peak, seed) = peak(isa, pixels);
    let border = border_min_max_sum(isa, pixels, w, h);
    let Levels {
        background,
        threshold,
        weight_origin,
    } = levels(pixels, w, h, peak, border, opts.threshold)?;

    // Pass 2: the seed's component and its integer moments.
    let seed = (seed % w, seed / w);
    let (
        Moments {
            n: area,
            sum_i,
            sum_j,
            sum_p,
            sum_pi,
            sum_pj,
        },
        (lo, hi),
        cols,
    ) = match walk_simple(isa, pixels, (w, h), seed.1, (threshold, peak)) {
        Some(found) => found,
        None => component_moments(isa, pixels, (w, h), seed, (threshold, peak)),
    };
    let edge_columns = 1u64 | (1u64 << (w - 1));
    if lo == 0 || hi == h - 1 || cols & edge_columns != 0 {
        return Err(BlobRejection::TouchesBorder);
    }
    let area_px = area as u32;
    if area_px < opts.min_area_px {
        return Err(BlobRejection::TooSmall { area_px });
    }
    if area_px > opts.max_area_px {
        return Err(BlobRejection::TooLarge { area_px });
    }
    let n = f64::from(area_px);
    let weight_sum = sum_p as f64 - weight_origin * n;
    let binary = (sum_i as f64 / n, sum_j as f64 / n);
    let weighted = if weight_sum > 0.0 {
        (
            (sum_pi as f64 - weight_origin * sum_i as f64) / weight_sum,
            (sum_pj as f64 - weight_origin * sum_j as f64) / weight_sum,
        )
    } else {
        binary
    };
    let (ci, cj) = if opts.intensity_weighted {
        weighted
    } else {
        binary
    };
    if let Some(check) = &opts.symmetry {
        // The outline at half the peak's contrast: the steepest part of a blurred edge.
        let level = background + 0.5 * (f64::from(peak) - background);
        let mut above = [0u64; MAX_ROI_HEIGHT as usize];
        row_masks(
            isa,
            &pixels[lo * w..(hi + 1) * w],
            w,
            level as u16,
            &mut above[lo..=hi],
        );
        above[lo..=hi].iter_mut().for_each(|m| *m &= cols);
        if let Some(outline) = outline_centre(pixels, w, &above[..h], (lo, hi), level) {
            // Against the weighted centroid whatever is output: binary moments lock to the pixel grid by up to
            // 0.1 px.
            let (du, dv) = (
                outline.centre_px.0 - weighted.0,
                outline.centre_px.1 - weighted.1,
            );
            if (du * du + dv * dv).sqrt() > check.max_centre_offset_px
                || outline.worst_residual_px > check.max_outline_residual_px
            {
                return Err(BlobRejection::Asymmetric);
            }
        }
    }
    Ok(Centroid {
        u_px: f64::from(roi.x0) + ci,
        v_px: f64::from(roi.y0) + cj,
        area_px,
        sum: sum_p as f64 - background * n,
        peak,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_fill_finds_runs_through_seeds() {
        let mask = 0b0111_0110_1100u64;
        assert_eq!(run_fill(mask, 0b0000_0010_0000), 0b0000_0110_0000);
        assert_eq!(run_fill(mask, 0b0100_0000_1000), 0b0111_0000_1100);
        assert_eq!(run_fill(mask, 0b1000_0001_0000), 0);
        assert_eq!(run_fill(u64::MAX, 1 << 40), u64::MAX);
        assert_eq!(run_fill(u64::MAX << 60, 1 << 63), u64::MAX << 60);
        // Several seeds in one run.
        assert_eq!(run_fill(0b0111_1110, 0b0101_0110), 0b0111_1110);
        assert_eq!(run_fill(0b1111, 0b1111), 0b1111);
        assert_eq!(run_fill(u64::MAX, u64::MAX), u64::MAX);
    }

    /// The 8-connected component of `seed` by a plain flood fill.
    fn naive_component(mask: &[u64], w: usize, seed: (usize, usize)) -> Vec<u64> {
        let h = mask.len();
        let mut comp = vec![0u64; h];
        let mut stack = vec![seed];
        while let Some((i, j)) = stack.pop() {
            if (mask[j] >> i) & 1 == 0 || (comp[j] >> i) & 1 == 1 {
                continue;
            }
            comp[j] |= 1 << i;
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let (ni, nj) = (i as i64 + di, j as i64 + dj);
                    if ni >= 0 && nj >= 0 && (ni as usize) < w && (nj as usize) < h {
                        stack.push((ni as usize, nj as usize));
                    }
                }
            }
        }
        comp
    }

    #[test]
    fn bit_parallel_component_matches_a_flood_fill() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for case in 0..3000 {
            let w = rng.random_range(1..=64usize);
            let h = rng.random_range(1..=64usize);
            let density = rng.random_range(0.2..0.7);
            let width_mask = u64::MAX >> (64 - w);
            let mask: Vec<u64> = (0..h)
                .map(|_| {
                    (0..w).fold(0u64, |m, i| m | (u64::from(rng.random_bool(density)) << i))
                        & width_mask
                })
                .collect();
            let (i, j) = (rng.random_range(0..w), rng.random_range(0..h));
            if (mask[j] >> i) & 1 == 0 {
                continue;
            }
            let mut comp = vec![0u64; h];
            let (lo, hi) = grow_component(&mask, i, j, &mut comp);
            let expected = naive_component(&mask, w, (i, j));
            assert_eq!(comp, expected, "case {case}: {w}x{h}");
            assert_eq!(lo, expected.iter().position(|&c| c != 0).unwrap());
            assert_eq!(hi, expected.iter().rposition(|&c| c != 0).unwrap());
        }
    }

    #[test]
    fn bit_masks_of_pixels() {
        let pixels: Vec<u16> = (0..150u16).map(|k| (k * 37) % 101).collect();
        let mut flat = [0u64; 3];
        flat_above(&pixels, 50, &mut flat);
        for (k, &p) in pixels.iter().enumerate() {
            assert_eq!((flat[k / 64] >> (k % 64)) & 1 == 1, p > 50, "pixel {k}");
        }
        for w in [1, 7, 24, 64] {
            for start in [0, 5, 40, 63, 64, 70] {
                if start + w <= 150 {
                    let expected = (0..w).fold(0u64, |acc, i| {
                        acc | (u64::from(pixels[start + i] > 50) << i)
                    });
                    assert_eq!(bits_at(&flat, start, w), expected);
                }
            }
        }
        assert_eq!(
            first_equal(&pixels, pixels[77]),
            pixels.iter().position(|&p| p == pixels[77]).unwrap()
        );
        assert_eq!(first_equal(&pixels, 1000), 0);
        assert_eq!(first_equal(&pixels[..20], pixels[19]), 19);
    }

    /// An ROI from an ASCII picture: '#' = 200, '+' = 120, '.' = 10.
    fn picture(rows: &[&str]) -> (Vec<u16>, Roi) {
        let h = rows.len() as u32;
        let w = rows[0].len() as u32;
        let pixels = rows
            .iter()
            .flat_map(|r| {
                r.chars().map(|c| match c {
                    '#' => 200,
                    '+' => 120,
                    _ => 10,
                })
            })
            .collect();
        (pixels, Roi::new(100, 50, w, h))
    }

    #[test]
    fn u_shaped_component_is_found_whole_and_other_blobs_ignored() {
        let (pixels, roi) = picture(&[
            "............",
            ".#...#......",
            ".#...#...##.",
            ".#...#...##.",
            ".#####......",
            "............",
            "......#.....",
            "............",
        ]);
        let opts = CentroidOptions {
            threshold: Threshold::Fixed(100),
            intensity_weighted: false,
            ..Default::default()
        };
        let c = measure_blob(&pixels, &roi, &opts).unwrap();
        assert_eq!(c.area_px, 11);
        // Binary moments of the U: columns 1..5, rows 1..4.
        // Column 1 and 5 (rows 1-4), bottom row columns 2-4; rows 1, 2, 3 two pixels each, row 4 five.
        let (si, sj) = (4 + 5 * 4 + 2 + 3 + 4, 2 + 2 * 2 + 3 * 2 + 4 * 5);
        assert!((c.u_px - (100.0 + si as f64 / 11.0)).abs() < 1e-12);
        assert!((c.v_px - (50.0 + sj as f64 / 11.0)).abs() < 1e-12);
        assert_eq!(c.peak, 200);
        assert!((c.sum - 11.0 * 190.0).abs() < 1e-9);
    }

    #[test]
    fn diagonal_neighbours_connect() {
        let (pixels, roi) = picture(&["......", ".#....", "..#...", "...#..", "..#...", "......"]);
        let opts = CentroidOptions {
            min_area_px: 1,
            ..Default::default()
        };
        assert_eq!(measure_blob(&pixels, &roi, &opts).unwrap().area_px, 4);
    }

    #[test]
    fn weighted_centroid_weights_above_the_threshold() {
        let (pixels, roi) = picture(&["......", "..#+..", "..##..", "......"]);
        let opts = CentroidOptions {
            min_area_px: 1,
            ..Default::default()
        };
        let c = measure_blob(&pixels, &roi, &opts).unwrap();
        // Background 10, contrast 190: threshold 10 + 0.15 * 190 = 38.5; all four pixels, weights value - 38.5.
        assert_eq!(c.area_px, 4);
        let (w2, w1) = (200.0 - 38.5, 120.0 - 38.5);
        let u = (2.0 * w2 + 3.0 * w1 + 2.0 * w2 + 3.0 * w2) / (3.0 * w2 + w1);
        assert!((c.u_px - (100.0 + u)).abs() < 1e-12, "{}", c.u_px);
        assert!((c.sum - (3.0 * 190.0 + 110.0)).abs() < 1e-9);
        let fixed = CentroidOptions {
            threshold: Threshold::Fixed(100),
            ..opts
        };
        let c = measure_blob(&pixels, &roi, &fixed).unwrap();
        let u = (2.0 * 100.0 + 3.0 * 20.0 + 2.0 * 100.0 + 3.0 * 100.0) / 320.0;
        assert!((c.u_px - (100.0 + u)).abs() < 1e-12, "{}", c.u_px);
    }

    #[test]
    fn rejections() {
        let opts = CentroidOptions::default();
        let (flat, roi) = picture(&["......"; 6]);
        assert_eq!(measure_blob(&flat, &roi, &opts), Err(BlobRejection::Absent));
        let (cut, roi) = picture(&["......", "....##", "....##", "......"]);
        assert_eq!(
            measure_blob(&cut, &roi, &opts),
            Err(BlobRejection::TouchesBorder)
        );
        let (one, roi) = picture(&["......", "..#...", "......", "......"]);
        assert_eq!(
            measure_blob(&one, &roi, &opts),
            Err(BlobRejection::TooSmall { area_px: 1 })
        );
        let (big, roi) = picture(&["......", ".####.", ".####.", "......"]);
        let small_max = CentroidOptions {
            max_area_px: 5,
            ..opts
        };
        assert_eq!(
            measure_blob(&big, &roi, &small_max),
            Err(BlobRejection::TooLarge { area_px: 8 })
        );
        let fixed = CentroidOptions {
            threshold: Threshold::Fixed(250),
            ..opts
        };
        assert_eq!(measure_blob(&big, &roi, &fixed), Err(BlobRejection::Absent));
        assert_eq!(
            BlobRejection::TooSmall { area_px: 1 }.to_string(),
            "the blob is too small (1 px)"
        );
    }

    #[test]
    fn widest_roi_works() {
        let mut pixels = vec![10u16; 64 * 64];
        for j in 20..30 {
            for i in 50..63 {
                pixels[j * 64 + i] = 200;
            }
        }
        let c = measure_blob(
            &pixels,
            &Roi::new(0, 0, 64, 64),
            &CentroidOptions::default(),
        )
        .unwrap();
        assert_eq!(c.area_px, 130);
        assert!((c.u_px - 56.0).abs() < 1e-12 && (c.v_px - 24.5).abs() < 1e-12);
        pixels[20 * 64 + 63] = 200;
        assert_eq!(
            measure_blob(
                &pixels,
                &Roi::new(0, 0, 64, 64),
                &CentroidOptions::default()
            ),
            Err(BlobRejection::TouchesBorder)
        );
    }

    /// The vectorised kernels (those the CPU runs) and the portable code give the same results, to the bit, on
    /// random ROIs of every size holding disks, rings and diagonal lines (simple components and not), noise, 8 to
    /// 16-bit pixels, and fixed or automatic thresholds.
    #[test]
    fn instruction_sets_agree() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let isas: Vec<Isa> = [Isa::Avx512, Isa::Sse2, Isa::Portable]
            .into_iter()
            .filter(|&isa| isa != Isa::Avx512 || Isa::detect() == Isa::Avx512)
            .collect();
        let mut measured = 0;
        for case in 0..3000 {
            let (w, h) = if case % 3 == 0 {
                (rng.random_range(1..=64usize), rng.random_range(1..=64usize))
            } else {
                (rng.random_range(6..=40usize), rng.random_range(6..=40usize))
            };
            let max = f64::from((1u32 << [8, 8, 10, 12, 16][case % 5]) - 1);
            let background = rng.random_range(0.0..0.2) * max;
            let noise = rng.random_range(0.0..0.02) * max;
            let mut image: Vec<f64> = (0..w * h)
                .map(|_| background + noise * rng.random_range(-1.0..1.0))
                .collect();
            for _ in 0..rng.random_range(1..4) {
                let r = rng.random_range(0.3..(w.min(h) as f64 / 2.0).max(0.6));
                let (cx, cy) = (
                    rng.random_range(-1.0..w as f64 + 1.0),
                    rng.random_range(-1.0..h as f64 + 1.0),
                );
                let (amplitude, kind) =
                    (rng.random_range(0.05..1.0) * (max - background), case % 4);
                for (k, p) in image.iter_mut().enumerate() {
                    let (dx, dy) = ((k % w) as f64 - cx, (k / w) as f64 - cy);
                    let d = dx.hypot(dy);
                    *p += amplitude
                        * match kind {
                            0 | 1 => (1.0 - (d / r).powi(2)).max(0.0),
                            2 => f64::from(u8::from((d - r).abs() < 1.0)),
                            _ => f64::from(u8::from((dx - dy).abs() < 0.8 && d < r)),
                        };
                }
            }
            let pixels: Vec<u16> = image
                .iter()
                .map(|&p| p.round().clamp(0.0, max) as u16)
                .collect();
            let roi = Roi::new(100, 200, w as u32, h as u32);
            let top = f64::from(*pixels.iter().max().unwrap());
            for opts in [
                CentroidOptions::default(),
                CentroidOptions::binary(),
                CentroidOptions {
                    threshold: Threshold::Fixed((rng.random_range(0.1..1.0) * top) as u16),
                    min_area_px: 1,
                    ..Default::default()
                },
            ] {
                let results: Vec<_> = isas
                    .iter()
                    .map(|&isa| measure_blob_with(isa, &pixels, &roi, &opts))
                    .collect();
                for (isa, r) in isas.iter().zip(&results) {
                    assert_eq!(*r, results[0], "case {case}: {w}x{h} {opts:?} {isa:?}");
                }
                measured += usize::from(results[0].is_ok());
            }
        }
        assert!(measured > 1500, "{measured}");
    }
}
