//! The levels of an ROI: its background, the threshold that classifies pixels as blob and the level weights are
//! measured from, all from the border pixels and the peak (pass 1's statistics).
//!
//! Scalar arithmetic on a few numbers: the vectorised pass over the pixels that gives the border's minimum, maximum
//! and sum is in [`super::kernels`]; only the rarer cases (a bright pixel on the border, a contrast that needs the
//! border's noise) read the border again here, a pixel at a time.

use super::{
    AUTO_MIN_CONTRAST_DN, AUTO_MIN_CONTRAST_SIGMAS, AUTO_THRESHOLD_FRACTION, BlobRejection,
    Threshold,
};

/// Background level (DN), the integer threshold (pixels `> threshold` are blob) and the level weights are measured
/// from (DN) of an ROI.
pub(super) struct Levels {
    pub(super) background: f64,
    pub(super) threshold: u16,
    pub(super) weight_origin: f64,
    /// Range (maximum less minimum) of the border pixels that set the background (DN): twice a bound on their
    /// standard deviation.
    pub(super) noise_range: f64,
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
#[inline]
pub(super) fn levels(
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
                noise_range: f64::from(below.max.saturating_sub(below.min)),
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
                noise_range: range,
            })
        }
    }
}
