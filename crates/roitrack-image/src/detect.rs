//! Blob detection in a full frame: threshold, connected components (8-connectivity), first-order moments.

use crate::centroid::{
    AUTO_MIN_CONTRAST_DN, AUTO_MIN_CONTRAST_SIGMAS, AUTO_THRESHOLD_FRACTION, Centroid,
    CentroidOptions, Threshold,
};
use crate::components::{Labeller, RunSums};

/// Moments of a component (integers: exact).
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    n: u64,
    sum_i: u64,
    sum_j: u64,
    sum_p: u64,
    sum_pi: u64,
    sum_pj: u64,
    peak: u16,
    touches_border: bool,
}

impl RunSums for Moments {
    fn of_run(
        row: &[u16],
        start: usize,
        end: usize,
        j: usize,
        width: usize,
        height: usize,
    ) -> Self {
        let mut m = Moments::default();
        for (i, &value) in row.iter().enumerate().take(end).skip(start) {
            let p = u64::from(value);
            m.n += 1;
            m.sum_i += i as u64;
            m.sum_p += p;
            m.sum_pi += p * i as u64;
            m.peak = m.peak.max(value);
        }
        m.sum_j = m.n * j as u64;
        m.sum_pj = m.sum_p * j as u64;
        m.touches_border = j == 0 || j + 1 == height || start == 0 || end == width;
        m
    }

    fn add(&mut self, o: &Moments) {
        self.n += o.n;
        self.sum_i += o.sum_i;
        self.sum_j += o.sum_j;
        self.sum_p += o.sum_p;
        self.sum_pi += o.sum_pi;
        self.sum_pj += o.sum_pj;
        self.peak = self.peak.max(o.peak);
        self.touches_border |= o.touches_border;
    }
}

/// Background (DN), integer threshold and weight origin (DN) of a full frame; `None` if nothing stands out.
fn frame_levels(pixels: &[u16], threshold: Threshold) -> Option<(f64, u16, f64)> {
    let peak = pixels.iter().copied().max()?;
    let histogram = crate::histogram::Histogram::of(pixels, peak);
    let percentile = |fraction: f64| f64::from(histogram.percentile(fraction));
    let background = percentile(0.5);
    match threshold {
        Threshold::Fixed(t) => (peak > t).then_some((background, t, f64::from(t))),
        Threshold::Auto => {
            // One standard deviation below the median of a normal background is its 15.87th percentile.
            let sigma = background - percentile(0.158_655);
            let contrast = f64::from(peak) - background;
            let level = background + AUTO_THRESHOLD_FRACTION * contrast;
            (contrast >= (AUTO_MIN_CONTRAST_SIGMAS * sigma).max(AUTO_MIN_CONTRAST_DN))
                .then(|| (background, level.floor() as u16, level))
        }
    }
}

/// Detects the blobs of a row-major `width` x `height` frame: the connected components (8-connectivity) of the
/// pixels above the threshold ([`Threshold::Auto`]: the image's median, taken as the background, plus
/// [`AUTO_THRESHOLD_FRACTION`] of the contrast of its maximum), skipping those that touch the image's border or fall
/// outside `opts`' area limits. Each centroid is measured as by [`crate::measure_blob`] (weighted by
/// `value - threshold`, or binary). Blobs come in the order of their first pixel (row-major).
///
/// ```
/// use roitrack_image::{CentroidOptions, detect_blobs};
/// // Two bright 3 x 3 squares on a dark 32 x 16 frame.
/// let (w, h) = (32u32, 16u32);
/// let mut frame = vec![10u16; (w * h) as usize];
/// for (ci, cj) in [(8usize, 8usize), (22, 6)] {
///     for j in cj - 1..=cj + 1 {
///         for i in ci - 1..=ci + 1 {
///             frame[j * w as usize + i] = 200;
///         }
///     }
/// }
/// let blobs = detect_blobs(&frame, w, h, &CentroidOptions::default());
/// assert_eq!(blobs.len(), 2);
/// assert!((blobs[0].u_px - 22.0).abs() < 1e-9 && (blobs[0].v_px - 6.0).abs() < 1e-9);
/// ```
///
/// # Panics
/// If `pixels.len() != width * height`.
pub fn detect_blobs(
    pixels: &[u16],
    width: u32,
    height: u32,
    opts: &CentroidOptions,
) -> Vec<Centroid> {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(pixels.len(), w * h, "pixel buffer length");
    let Some((background, threshold, weight_origin)) = frame_levels(pixels, opts.threshold) else {
        return Vec::new();
    };
    let mut components: Vec<Moments> = Vec::new();
    Labeller::<Moments>::default().components(pixels, w, h, threshold, |m| components.push(*m));
    components
        .into_iter()
        .filter(|m| !m.touches_border)
        .filter_map(|m| {
            let area_px = u32::try_from(m.n).ok()?;
            if area_px < opts.min_area_px || area_px > opts.max_area_px {
                return None;
            }
            let n = m.n as f64;
            let weight_sum = m.sum_p as f64 - weight_origin * n;
            let (u_px, v_px) = if opts.intensity_weighted && weight_sum > 0.0 {
                (
                    (m.sum_pi as f64 - weight_origin * m.sum_i as f64) / weight_sum,
                    (m.sum_pj as f64 - weight_origin * m.sum_j as f64) / weight_sum,
                )
            } else {
                (m.sum_i as f64 / n, m.sum_j as f64 / n)
            };
            Some(Centroid {
                u_px,
                v_px,
                area_px,
                sum: m.sum_p as f64 - background * n,
                peak: m.peak,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Roi, measure_blob};

    fn frame(w: usize, h: usize, blobs: &[(usize, usize, usize, usize)]) -> Vec<u16> {
        let mut f = vec![12u16; w * h];
        for &(x, y, bw, bh) in blobs {
            for j in y..y + bh {
                for i in x..x + bw {
                    f[j * w + i] = 220;
                }
            }
        }
        f
    }

    #[test]
    fn finds_components_skips_border_and_limits() {
        // A U (one component), a diagonal pair (one), a single pixel (too small), one on the border.
        let mut f = frame(
            40,
            30,
            &[
                (3, 3, 2, 6),
                (9, 3, 2, 6),
                (3, 9, 8, 2),
                (20, 20, 3, 3),
                (37, 10, 3, 3),
            ],
        );
        f[10 * 40 + 25] = 220;
        f[11 * 40 + 26] = 220;
        f[26 * 40 + 5] = 220;
        let opts = CentroidOptions::default();
        let blobs = detect_blobs(&f, 40, 30, &opts);
        let areas: Vec<u32> = blobs.iter().map(|b| b.area_px).collect();
        assert_eq!(areas, vec![40, 9]);
        assert!((blobs[1].u_px - 21.0).abs() < 1e-12 && (blobs[1].v_px - 21.0).abs() < 1e-12);
        let with_small = CentroidOptions {
            min_area_px: 1,
            ..opts
        };
        assert_eq!(detect_blobs(&f, 40, 30, &with_small).len(), 4);
        let flat = vec![12u16; 100];
        assert!(detect_blobs(&flat, 10, 10, &opts).is_empty());
    }

    #[test]
    fn agrees_with_measure_blob() {
        let mut f = frame(30, 30, &[(10, 11, 5, 4)]);
        f[12 * 30 + 12] = 180;
        f[11 * 30 + 15] = 150;
        // The blob is deliberately irregular: leave the symmetry check (measure_blob's alone) out.
        for opts in [CentroidOptions::default(), CentroidOptions::binary()] {
            let opts = CentroidOptions {
                symmetry: None,
                ..opts
            };
            let d = detect_blobs(&f, 30, 30, &opts);
            let roi = Roi::new(0, 0, 30, 30);
            let m = measure_blob(&f, &roi, &opts).unwrap();
            assert_eq!(d.len(), 1);
            assert!((d[0].u_px - m.u_px).abs() < 1e-12 && (d[0].v_px - m.v_px).abs() < 1e-12);
            assert_eq!(d[0].area_px, m.area_px);
        }
    }
}
