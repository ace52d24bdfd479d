//! A blob's centre from the symmetry of its outline, robust to a spot merged with it (a reflection, a glint).
//!
//! A blob is the image of a disk: an ellipse, blurred, so its outline at any level is centrally symmetric. The
//! midpoints of its horizontal chords then lie on a line through the centre (for an ellipse exactly: the conjugate
//! diameter), and so do the midpoints of its vertical chords; the centre is where the two lines cross. A spot merged
//! with the blob moves the ends of a few chords only (those of the rows or columns it crosses), so a robust line fit
//! (least squares, then Tukey reweighting) leaves them out, or shows them far off the line, where it pulls a
//! first-order moment by a fraction of a pixel.
//! The chord ends are the level's crossings, interpolated linearly between neighbouring pixels.
//!
//! Allocation-free: everything lives in fixed arrays sized for [`crate::MAX_ROI_WIDTH`] x [`crate::MAX_ROI_HEIGHT`].

use crate::centroid::{MAX_ROI_HEIGHT, MAX_ROI_WIDTH};

/// Chords shorter than this fraction of the longest are left out: near the blob's top and bottom the outline runs
/// nearly along the chord, so its crossing is ill-defined (a circle: the rows within 0.8 radii of the centre).
const MIN_CHORD_FRACTION: f64 = 0.6;
/// Smallest residual scale of the line fits (px): the clean midpoints scatter by about 0.01-0.02 px (noise and the
/// linear interpolation of the crossings), so the scale from their median absolute residual can collapse.
const MIN_SCALE_PX: f64 = 0.02;
/// Tukey's constant (95 % efficiency on Gaussian residuals).
const TUKEY_C: f64 = 4.685;
/// Reweighting rounds of each line fit.
const REWEIGHTING_ROUNDS: usize = 3;
/// Fewest chords that fit a line (after the short ones are left out): 3 lets blobs of about 7 px be tested (with 4,
/// a tenth of the spots merged with them passed untested).
const MIN_CHORDS: usize = 3;

const MAX_CHORDS: usize = 64;
const _: () =
    assert!(MAX_ROI_WIDTH as usize <= MAX_CHORDS && MAX_ROI_HEIGHT as usize <= MAX_CHORDS);

/// A line `y = intercept + slope * (x - x_mean)` fitted to chord midpoints.
#[derive(Debug, Clone, Copy, PartialEq)]
struct MidpointLine {
    x_mean: f64,
    intercept: f64,
    slope: f64,
    /// Largest distance of a midpoint from the line (px).
    worst_residual: f64,
}

/// The centre of a blob's outline, and how far its chords are from a centrally symmetric outline's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct OutlineCentre {
    /// In the ROI's pixel coordinates (pixel (i, j) centred on (i, j)).
    pub centre_px: (f64, f64),
    /// The largest distance of a chord's midpoint from its line (px).
    pub worst_residual_px: f64,
}

/// The centre of a blob from its outline at `level` (DN): where the line of the midpoints of its horizontal chords
/// meets the line of the midpoints of its vertical chords, in the ROI's pixel coordinates (pixel (i, j) centred on
/// (i, j)). `above[j]` has bit i set where pixel (i, j) is above `level` and belongs to the blob's rows and columns;
/// the rows `rows.0..=rows.1` hold the blob, which must leave one pixel on each side inside the ROI (it does not touch
/// the ROI's border). `None` when the blob is too small to have enough chords (a blob of less than about 5 px across)
/// or the lines do not cross.
pub(crate) fn outline_centre(
    pixels: &[u16],
    w: usize,
    above: &[u64],
    rows: (usize, usize),
    level: f64,
) -> Option<OutlineCentre> {
    let value = |i: usize, j: usize| f64::from(pixels[j * w + i]);
    let band = || above.iter().enumerate().take(rows.1 + 1).skip(rows.0);
    let mut chords = Chords::new();
    for (j, &m) in band() {
        if m != 0 {
            let (first, last) = (m.trailing_zeros() as usize, 63 - m.leading_zeros() as usize);
            chords.add(j, first, last, level, |i| value(i, j));
        }
    }
    let rows_line = chords.robust_line()?;
    // Each column's first and last rows above the level.
    let (mut top, mut bottom) = ([0usize; 64], [0usize; 64]);
    let mut columns = 0u64;
    for (j, &m) in band() {
        for_each_bit(m & !columns, |i| top[i] = j);
        columns |= m;
    }
    let mut seen = 0u64;
    for (j, &m) in band().rev() {
        for_each_bit(m & !seen, |i| bottom[i] = j);
        seen |= m;
    }
    let mut chords = Chords::new();
    for_each_bit(columns, |i| {
        chords.add(i, top[i], bottom[i], level, |j| value(i, j));
    });
    let cols_line = chords.robust_line()?;
    // u = a1 + b1 (v - v1), v = a2 + b2 (u - u2).
    let (a1, b1, v1) = (rows_line.intercept, rows_line.slope, rows_line.x_mean);
    let (a2, b2, u2) = (cols_line.intercept, cols_line.slope, cols_line.x_mean);
    let det = 1.0 - b1 * b2;
    // For an ellipse b1 b2 = B² / 4AC < 1; near 1 the lines are nearly parallel and the crossing meaningless.
    if det < 0.1 {
        return None;
    }
    let u = (a1 + b1 * (a2 - b2 * u2 - v1)) / det;
    let v = a2 + b2 * (u - u2);
    Some(OutlineCentre {
        centre_px: (u, v),
        worst_residual_px: rows_line.worst_residual.max(cols_line.worst_residual),
    })
}

/// Calls `f` with the index of each set bit of `bits`, lowest first.
fn for_each_bit(mut bits: u64, mut f: impl FnMut(usize)) {
    while bits != 0 {
        f(bits.trailing_zeros() as usize);
        bits &= bits - 1;
    }
}

/// The chords of a blob along one direction: where each line (a row, or a column) crosses the level.
struct Chords {
    at: [f64; MAX_CHORDS],
    midpoint: [f64; MAX_CHORDS],
    length: [f64; MAX_CHORDS],
    n: usize,
}

impl Chords {
    fn new() -> Self {
        Self {
            at: [0.0; MAX_CHORDS],
            midpoint: [0.0; MAX_CHORDS],
            length: [0.0; MAX_CHORDS],
            n: 0,
        }
    }

    /// The chord of line `line` whose first and last positions above `level` are `first` and `last` (the positions
    /// just outside exist: the blob does not touch the ROI's border); `value(k)` reads position k of the line.
    fn add(
        &mut self,
        line: usize,
        first: usize,
        last: usize,
        level: f64,
        value: impl Fn(usize) -> f64,
    ) {
        if first == 0 || self.n == MAX_CHORDS {
            return;
        }
        let crossing = |inside: usize, outside: usize| {
            let (a, b) = (value(inside), value(outside));
            inside as f64 + (outside as f64 - inside as f64) * (a - level) / (a - b)
        };
        let (start, end) = (crossing(first, first - 1), crossing(last, last + 1));
        self.at[self.n] = line as f64;
        self.midpoint[self.n] = 0.5 * (start + end);
        self.length[self.n] = end - start;
        self.n += 1;
    }

    /// The robust line through the midpoints of the chords at least [`MIN_CHORD_FRACTION`] of the longest.
    fn robust_line(&mut self) -> Option<MidpointLine> {
        let longest = self.length[..self.n].iter().copied().fold(0.0, f64::max);
        let mut kept = 0;
        for k in 0..self.n {
            if self.length[k] >= MIN_CHORD_FRACTION * longest {
                self.at[kept] = self.at[k];
                self.midpoint[kept] = self.midpoint[k];
                kept += 1;
            }
        }
        robust_line(&self.at[..kept], &self.midpoint[..kept])
    }
}

/// A line through points `(x, y)`, robust to a minority of outliers: least squares, then Tukey-weighted least squares
/// with the scale from the median absolute residual. (A Theil-Sen start, more robust, rejected the same blobs with
/// merged reflections on the test of `tests/rendered.rs`, at twice the cost: a spot that moves enough chords to break
/// the fit leaves them far from the line anyway.) `None` with fewer than [`MIN_CHORDS`] points.
fn robust_line(x: &[f64], y: &[f64]) -> Option<MidpointLine> {
    let n = x.len();
    if n < MIN_CHORDS {
        return None;
    }
    let x_mean = x.iter().sum::<f64>() / n as f64;
    let (mut sxx, mut sxy, mut sy) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let dx = x[k] - x_mean;
        sxx += dx * dx;
        sxy += dx * y[k];
        sy += y[k];
    }
    if sxx <= 0.0 {
        return None;
    }
    let mut slope = sxy / sxx;
    let mut intercept = sy / n as f64;
    let mut scratch = [0.0; MAX_CHORDS];
    for _ in 0..REWEIGHTING_ROUNDS {
        for k in 0..n {
            scratch[k] = (y[k] - intercept - slope * (x[k] - x_mean)).abs();
        }
        let scale = (1.4826 * median(&mut scratch[..n])).max(MIN_SCALE_PX);
        let inverse_cutoff = 1.0 / (TUKEY_C * scale);
        // Weighted least squares in one pass, about x_mean.
        let (mut sw, mut swx, mut swy, mut swxx, mut swxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for k in 0..n {
            let dx = x[k] - x_mean;
            let r = (y[k] - intercept - slope * dx) * inverse_cutoff;
            let w = if r.abs() < 1.0 {
                (1.0 - r * r) * (1.0 - r * r)
            } else {
                0.0
            };
            sw += w;
            swx += w * dx;
            swy += w * y[k];
            swxx += w * dx * dx;
            swxy += w * dx * y[k];
        }
        let det = sw * swxx - swx * swx;
        if sw <= 0.0 || det <= 1e-12 * sw * swxx {
            return None;
        }
        slope = (sw * swxy - swx * swy) / det;
        intercept = (swy - slope * swx) / sw;
    }
    let worst_residual = (0..n)
        .map(|k| (y[k] - intercept - slope * (x[k] - x_mean)).abs())
        .fold(0.0, f64::max);
    Some(MidpointLine {
        worst_residual,
        x_mean,
        intercept,
        slope,
    })
}

/// The median of `values` (the mean of the middle two for an even count), reordering them.
fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    let (below, &mut upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        upper
    } else {
        let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w` x `w` image of a tilted ellipse (semi-axes `a`, `b` px, tilt `theta`) centred on `centre`, with a soft
    /// edge about a pixel wide, on a background of 12 DN with a plateau of 230 DN, plus a Gaussian spot
    /// (`spot`: centre, peak DN, sigma px).
    fn ellipse_image(
        w: usize,
        centre: (f64, f64),
        (a, b, theta): (f64, f64, f64),
        spot: Option<((f64, f64), f64, f64)>,
    ) -> Vec<u16> {
        let (s, c) = theta.sin_cos();
        (0..w * w)
            .map(|k| {
                let (x, y) = ((k % w) as f64 - centre.0, (k / w) as f64 - centre.1);
                let (p, q) = ((c * x + s * y) / a, (-s * x + c * y) / b);
                // Signed distance to the outline, approximately (px).
                let d = ((p * p + q * q).sqrt() - 1.0) * a.min(b);
                let mut value = 12.0 + 218.0 / (1.0 + (2.5 * d).exp());
                if let Some(((sx, sy), peak, sigma)) = spot {
                    let r2 = ((k % w) as f64 - sx).powi(2) + ((k / w) as f64 - sy).powi(2);
                    value += peak * (-r2 / (2.0 * sigma * sigma)).exp();
                }
                value.round().min(255.0) as u16
            })
            .collect()
    }

    /// The outline centre of the whole image at half contrast (121 DN).
    fn outline_of(pixels: &[u16], w: usize) -> Option<OutlineCentre> {
        let level = 121.0;
        let above: Vec<u64> = pixels
            .chunks_exact(w)
            .map(|row| {
                row.iter()
                    .enumerate()
                    .filter(|(_, p)| f64::from(**p) > level)
                    .fold(0u64, |m, (i, _)| m | 1 << i)
            })
            .collect();
        let lo = above.iter().position(|&m| m != 0)?;
        let hi = above.iter().rposition(|&m| m != 0)?;
        outline_centre(pixels, w, &above, (lo - 1, hi + 1), level)
    }

    #[test]
    fn finds_the_centre_of_tilted_ellipses() {
        for (centre, shape) in [
            ((15.3, 16.7), (7.5, 7.5, 0.0)),
            ((15.8, 15.1), (8.0, 5.0, 0.6)),
            ((16.2, 14.6), (4.0, 9.0, -1.1)),
            ((15.5, 15.5), (3.5, 3.0, 0.3)),
        ] {
            let image = ellipse_image(32, centre, shape, None);
            let outline = outline_of(&image, 32).expect("a centre");
            let (u, v) = outline.centre_px;
            assert!(
                (u - centre.0).hypot(v - centre.1) < 0.03,
                "{shape:?}: {:?} against {centre:?}",
                outline.centre_px
            );
            assert!(outline.worst_residual_px < 0.1, "{outline:?}");
        }
    }

    #[test]
    fn a_spot_on_the_edge_shows() {
        let centre = (15.4, 16.2);
        let image = ellipse_image(
            32,
            centre,
            (7.5, 7.0, 0.2),
            Some(((23.0, 15.0), 200.0, 1.2)),
        );
        let outline = outline_of(&image, 32).expect("a centre");
        assert!(outline.worst_residual_px > 0.3, "{outline:?}");
    }

    #[test]
    fn too_small_blobs_have_no_outline_centre() {
        let image = ellipse_image(16, (7.5, 7.5), (1.5, 1.5, 0.0), None);
        assert_eq!(outline_of(&image, 16), None);
    }

    #[test]
    fn robust_line_leaves_out_a_minority_of_outliers() {
        let x: Vec<f64> = (0..13).map(f64::from).collect();
        let mut y: Vec<f64> = x.iter().map(|x| 2.0 + 0.3 * x).collect();
        let clean = robust_line(&x, &y).unwrap();
        assert!((clean.slope - 0.3).abs() < 1e-12 && clean.worst_residual < 1e-12);
        assert!((clean.intercept - (2.0 + 0.3 * 6.0)).abs() < 1e-12);
        for k in [3, 4, 5] {
            y[k] += 1.0;
        }
        let line = robust_line(&x, &y).unwrap();
        assert!((line.slope - 0.3).abs() < 1e-9, "{line:?}");
        assert!((line.worst_residual - 1.0).abs() < 1e-9, "{line:?}");
        assert_eq!(robust_line(&x[..2], &y[..2]), None);
        assert_eq!(robust_line(&[1.0; 5], &[0.0, 1.0, 2.0, 3.0, 4.0]), None);
    }

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
    }
}
