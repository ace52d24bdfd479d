//! A blob's centre from the symmetry of its outline, robust to a spot merged with it (a reflection, a glint).
//!
//! A blob is the image of a disk: an ellipse, blurred, so its outline at any level is centrally symmetric. The
//! midpoints of its horizontal chords then lie on a line through the centre (for an ellipse exactly: the conjugate
//! diameter), and so do the midpoints of its vertical chords; the centre is where the two lines cross. A spot merged
//! with the blob moves the ends of a few chords only (those of the rows or columns it crosses), so a robust line fit
//! (Theil-Sen start, Tukey reweighting) leaves them out, where it pulls a first-order moment by a fraction of a pixel.
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
const REWEIGHTING_ROUNDS: usize = 4;
/// Fewest chords that fit a line (after the short ones are left out).
const MIN_CHORDS: usize = 4;

const MAX_CHORDS: usize = if MAX_ROI_WIDTH > MAX_ROI_HEIGHT {
    MAX_ROI_WIDTH as usize
} else {
    MAX_ROI_HEIGHT as usize
};

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
/// (i, j)). `rows` and `cols` bound the blob (inclusive); they must leave one pixel on each side inside the ROI (the
/// blob does not touch the ROI's border). `None` when the blob is too small to have enough chords (a blob of less than
/// about 5 px across) or the lines do not cross.
pub(crate) fn outline_centre(
    pixels: &[u16],
    w: usize,
    rows: (usize, usize),
    cols: (usize, usize),
    level: f64,
) -> Option<OutlineCentre> {
    let across = |j: usize, i: usize| f64::from(pixels[j * w + i]);
    let down = |i: usize, j: usize| f64::from(pixels[j * w + i]);
    let rows_line = midpoint_line(rows, cols, level, across)?;
    let cols_line = midpoint_line(cols, rows, level, down)?;
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

/// The robust line through the midpoints of the chords at `level` of lines `lines.0..=lines.1` (rows, or columns),
/// each read along `span` with `value(line, position)`.
fn midpoint_line(
    lines: (usize, usize),
    span: (usize, usize),
    level: f64,
    value: impl Fn(usize, usize) -> f64,
) -> Option<MidpointLine> {
    let mut at = [0.0; MAX_CHORDS];
    let mut midpoint = [0.0; MAX_CHORDS];
    let mut length = [0.0; MAX_CHORDS];
    let mut n = 0;
    for line in lines.0..=lines.1 {
        let Some(first) = (span.0..=span.1).find(|&k| value(line, k) > level) else {
            continue;
        };
        let last = (span.0..=span.1)
            .rev()
            .find(|&k| value(line, k) > level)
            .expect("a first crossing has a last");
        // The blob does not touch the ROI's border, so both outer neighbours exist.
        if first == 0 {
            continue;
        }
        let crossing = |inside: usize, outside: usize| {
            let (a, b) = (value(line, inside), value(line, outside));
            inside as f64 + (outside as f64 - inside as f64) * (a - level) / (a - b)
        };
        let start = crossing(first, first - 1);
        let end = crossing(last, last + 1);
        at[n] = line as f64;
        midpoint[n] = 0.5 * (start + end);
        length[n] = end - start;
        n += 1;
    }
    let longest = length[..n].iter().copied().fold(0.0, f64::max);
    let mut kept = 0;
    for k in 0..n {
        if length[k] >= MIN_CHORD_FRACTION * longest {
            at[kept] = at[k];
            midpoint[kept] = midpoint[k];
            kept += 1;
        }
    }
    robust_line(&at[..kept], &midpoint[..kept])
}

/// A line through points `(x, y)`, robust to a minority of outliers: Theil-Sen (the median of pairwise slopes, then
/// the median intercept) as a start, then Tukey-weighted least squares with the scale from the median absolute
/// residual. `None` with fewer than [`MIN_CHORDS`] points.
fn robust_line(x: &[f64], y: &[f64]) -> Option<MidpointLine> {
    let n = x.len();
    if n < MIN_CHORDS {
        return None;
    }
    let x_mean = x.iter().sum::<f64>() / n as f64;
    let mut scratch = [0.0; MAX_CHORDS * (MAX_CHORDS - 1) / 2];
    let mut pairs = 0;
    for k in 0..n {
        for l in k + 1..n {
            if x[l] != x[k] {
                scratch[pairs] = (y[l] - y[k]) / (x[l] - x[k]);
                pairs += 1;
            }
        }
    }
    if pairs == 0 {
        return None;
    }
    let mut slope = median(&mut scratch[..pairs]);
    for k in 0..n {
        scratch[k] = y[k] - slope * (x[k] - x_mean);
    }
    let mut intercept = median(&mut scratch[..n]);
    for _ in 0..REWEIGHTING_ROUNDS {
        for k in 0..n {
            scratch[k] = (y[k] - intercept - slope * (x[k] - x_mean)).abs();
        }
        let scale = (1.4826 * median(&mut scratch[..n])).max(MIN_SCALE_PX);
        let cutoff = TUKEY_C * scale;
        let (mut sw, mut swx, mut swy) = (0.0, 0.0, 0.0);
        let mut weight = [0.0; MAX_CHORDS];
        for k in 0..n {
            let r = (y[k] - intercept - slope * (x[k] - x_mean)) / cutoff;
            weight[k] = if r.abs() < 1.0 {
                (1.0 - r * r).powi(2)
            } else {
                0.0
            };
            sw += weight[k];
            swx += weight[k] * (x[k] - x_mean);
            swy += weight[k] * y[k];
        }
        if sw <= 0.0 {
            return None;
        }
        let (xw, yw) = (swx / sw, swy / sw);
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for k in 0..n {
            let dx = x[k] - x_mean - xw;
            sxx += weight[k] * dx * dx;
            sxy += weight[k] * dx * (y[k] - yw);
        }
        if sxx <= 0.0 {
            return None;
        }
        slope = sxy / sxx;
        intercept = yw - slope * xw;
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
