//! Measuring one blob in a window of a frame around its predicted position: the window copied with its background
//! taken away ([`flatten_window`]: a plane fitted to the border pixels that belong to the background, subtracted for
//! bright blobs, divided out for dark ones), the blob's centroid with a threshold taken from that background
//! ([`measure_flat_window`]), and the centre of its outline ([`window_outline_centre`]). The frame tracker of
//! roitrack-pipeline measures each predicted blob this way; the background plane itself is [`crate::background`]'s.

use nalgebra::Vector2;

use crate::centroid::{AUTO_MIN_CONTRAST_DN, AUTO_MIN_CONTRAST_SIGMAS, AUTO_THRESHOLD_FRACTION};
use crate::photo::{OutlineScratch, outline_centre};
use crate::{
    BlobRejection, Centroid, CentroidOptions, Frame, Polarity, Roi, Threshold, measure_blob,
    measure_blob_near,
};

/// Copies the window `roi` of `frame` into `out` with its background taken away, so that the blob stands bright on
/// a flat, dark background whatever the light: the background is a least-squares plane through the border pixels
/// that belong to it, not to the blob or its neighbours (see `border_plane`). Bright blobs: `value - plane`; dark
/// blobs: the contrast `1 - value / plane`, scaled to the frame's range (under uneven light a printed circle keeps
/// its contrast, not its difference in grey level). An offset of 1/16 of the range keeps the background's noise above
/// zero. The frame tracker of roitrack-pipeline measures every window through it. Windows up to 64 x 64 px, the largest the centroid
/// takes: the border pixels of a larger one beyond the first 256 are not used.
///
/// # Panics
/// If `roi` does not lie inside `frame`.
///
/// ```
/// use roitrack_image::{Frame, Polarity, Roi};
/// use roitrack_image::window::flatten_window;
///
/// // A light background brighter to the right, with one dark pixel in the middle of a 5 x 5 window.
/// let mut frame = Frame { width: 5, height: 5, bit_depth: 8, t_s: 0.0, pixels: vec![0; 25] };
/// for (k, value) in frame.pixels.iter_mut().enumerate() {
///     *value = 150 + 10 * (k % 5) as u16;
/// }
/// frame.pixels[12] = 40;
/// let mut window = Vec::new();
/// flatten_window(&frame, &Roi::new(0, 0, 5, 5), Polarity::Dark, &mut window);
/// // The background is flat at the offset (16 of 255), the dark pixel bright.
/// assert!(window.iter().enumerate().all(|(k, &v)| if k == 12 { v > 180 } else { v == 16 }));
/// ```
pub fn flatten_window(
    frame: &Frame,
    roi: &Roi,
    polarity: Polarity,
    out: &mut Vec<u16>,
) -> FlatWindow {
    let (w, h) = (roi.width as usize, roi.height as usize);
    out.clear();
    out.resize(w * h, 0);
    let max_value = ((1u32 << frame.bit_depth.clamp(1, 16)) - 1) as f64;
    let offset = f64::from(window_offset(frame));
    let at = |i: usize, j: usize| {
        f64::from(frame.pixels[(roi.y0 as usize + j) * frame.width as usize + roi.x0 as usize + i])
    };
    // The blob's extreme value: where the contrast is measured from (row slices, integer extremes).
    let rows = (0..h).map(|j| {
        let start = (roi.y0 as usize + j) * frame.width as usize + roi.x0 as usize;
        &frame.pixels[start..start + w]
    });
    let blob_extreme = f64::from(match polarity {
        Polarity::Dark => rows
            .map(|row| row.iter().copied().min().unwrap_or(u16::MAX))
            .min()
            .unwrap_or(0),
        Polarity::Bright => rows
            .map(|row| row.iter().copied().max().unwrap_or(0))
            .max()
            .unwrap_or(0),
    });
    let (a, b, c, noise) = border_plane(w, h, polarity, blob_extreme, at);
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let frame_width = frame.width as usize;
    // The hot loop of the windows path: row slices (no per-pixel index checks), the polarity chosen once per window,
    // and rounding as +0.5 then truncation (`f64::round` is a library call; the values are clamped non-negative
    // first, where the two agree).
    // The flattened window's peak, kept as it is filled: the centroid's threshold is measured from it.
    let mut peak = 0u16;
    let mut fill = |flat: fn(f64, f64, f64) -> f64| {
        for (j, out_row) in out.chunks_exact_mut(w).enumerate() {
            // The coordinates through `u32` (the window's size is one): one instruction, where a `usize`'s conversion
            // takes several on x86_64; the same values.
            let y = f64::from(j as u32) - cy;
            let start = (roi.y0 as usize + j) * frame_width + roi.x0 as usize;
            let row = &frame.pixels[start..start + w];
            for (i, (o, &v)) in out_row.iter_mut().zip(row).enumerate() {
                let plane = a + b * (f64::from(i as u32) - cx) + c * y;
                let value = flat(f64::from(v), plane, max_value) + offset;
                *o = (value + 0.5).clamp(0.0, max_value) as u16;
                peak = peak.max(*o);
            }
        }
    };
    let noise_dn = match polarity {
        Polarity::Bright => {
            fill(|v, plane, _| v - plane);
            noise
        }
        Polarity::Dark => {
            fill(|v, plane, max_value| {
                if plane > 0.0 {
                    (1.0 - v / plane) * max_value
                } else {
                    0.0
                }
            });
            if a > 0.0 { noise * max_value / a } else { 0.0 }
        }
    };
    FlatWindow {
        background_dn: offset,
        noise_dn,
        peak_dn: peak,
    }
}

/// What [`flatten_window`] knows of the window it flattened: its background's level and noise in the flattened
/// values, measured on the border pixels that belong to the background.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlatWindow {
    /// The flattened background's level (DN): 1/16 of the frame's range.
    pub background_dn: f64,
    /// Its noise (DN, one standard deviation: 1.2533 times the mean absolute residual of the border's
    /// background pixels about the plane).
    pub noise_dn: f64,
    /// The flattened window's largest value (DN).
    pub peak_dn: u16,
}

/// Measures the blob of `window` as [`flatten_window`] flattened it into `flat`, with `options`, but for an automatic
/// threshold taken from the background it found rather than from the window's border: the threshold is the background
/// plus [`AUTO_THRESHOLD_FRACTION`] of the peak's contrast, and the blob absent when the contrast is under
/// [`AUTO_MIN_CONTRAST_SIGMAS`] times its noise (or [`AUTO_MIN_CONTRAST_DN`]). The border of a window in a dense grid
/// crosses the neighbouring blobs: the centroid's own estimate from it takes their rims for noise and finds nothing
/// standing out (on real photographs of a hexagonal grid of printed circles, most of the windows).
///
/// ```
/// use roitrack_image::{CentroidOptions, Frame, Polarity, Roi};
/// use roitrack_image::window::{flatten_window, measure_flat_window};
///
/// // A dark 3 x 3 blob on a light, uneven background.
/// let mut frame = Frame { width: 15, height: 15, bit_depth: 8, t_s: 0.0, pixels: vec![0; 225] };
/// for (k, value) in frame.pixels.iter_mut().enumerate() {
///     *value = 150 + (k % 15) as u16;
/// }
/// for j in 6..9 {
///     for i in 7..10 {
///         frame.pixels[j * 15 + i] = 40;
///     }
/// }
/// let roi = Roi::new(0, 0, 15, 15);
/// let mut window = Vec::new();
/// let flat = flatten_window(&frame, &roi, Polarity::Dark, &mut window);
/// let c = measure_flat_window(&window, &roi, &flat, &CentroidOptions::default(), None).unwrap();
/// // Its contrast varies a little with the light across it: within a hundredth of a pixel of its centre.
/// assert!((c.u_px - 8.0).abs() < 0.01 && (c.v_px - 7.0).abs() < 0.01);
/// ```
///
/// # Panics
/// As [`measure_blob`].
pub fn measure_flat_window(
    window: &[u16],
    roi: &Roi,
    flat: &FlatWindow,
    options: &CentroidOptions,
    near_px: Option<[f64; 2]>,
) -> Result<Centroid, BlobRejection> {
    let measure = |options: &CentroidOptions| match near_px {
        Some(near_px) => measure_blob_near(window, roi, options, near_px),
        None => measure_blob(window, roi, options),
    };
    if options.threshold != Threshold::Auto {
        return measure(options);
    }
    let contrast = f64::from(flat.peak_dn) - flat.background_dn;
    if contrast < (AUTO_MIN_CONTRAST_SIGMAS * flat.noise_dn).max(AUTO_MIN_CONTRAST_DN) {
        return Err(BlobRejection::Absent);
    }
    let threshold = (flat.background_dn + AUTO_THRESHOLD_FRACTION * contrast) as u16;
    let options = CentroidOptions {
        threshold: Threshold::Fixed(threshold),
        // 0 where the flattening could not measure it (no plane, or a black background): the border's range then.
        background_noise_dn: (flat.noise_dn > 0.0).then_some(flat.noise_dn),
        ..*options
    };
    measure(&options)
}

/// Farthest (px) the outline's centre may lie from the window's moments for a blob: beyond, the outline found is not
/// the blob's alone (a neighbour's rim, clutter touching it), and the moments stand.
pub const MAX_OUTLINE_SHIFT_PX: f64 = 0.5;

/// The centre of the outline ([`outline_centre`]) of the blob whose moments in the flattened `window` (of `roi`) are
/// `moments`; the moments when it cannot be found, or lies farther than [`MAX_OUTLINE_SHIFT_PX`] from them. The
/// frame tracker blends the two centres, weighted by how well each fits a static pose.
pub fn window_outline_centre(
    window: &[u16],
    roi: &Roi,
    moments: &Centroid,
    scratch: &mut OutlineScratch,
) -> Vector2<f64> {
    let at = Vector2::new(moments.u_px, moments.v_px);
    let origin = Vector2::new(f64::from(roi.x0), f64::from(roi.y0));
    outline_centre(
        window,
        roi.width as usize,
        roi.height as usize,
        at - origin,
        f64::from(moments.area_px),
        scratch,
    )
    .map(|local| local + origin)
    .filter(|centre| (centre - at).norm() <= MAX_OUTLINE_SHIFT_PX)
    .unwrap_or(at)
}

/// The level a flattened window's background is lifted to (1/16 of the frame's range): see [`flatten_window`].
fn window_offset(frame: &Frame) -> u16 {
    let max_value = (1u32 << frame.bit_depth.clamp(1, 16)) - 1;
    ((max_value + 1) / 16) as u16
}

/// The background plane `[a, b, c]` (`a + b x + c y`) through the `border` pixels that `keep` marks
/// ([`crate::background::fit_plane`]).
fn fit_plane(border: &[(f64, f64, f64)], keep: &[bool]) -> Option<[f64; 3]> {
    crate::background::fit_plane(
        border
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p),
    )
}

/// Most border pixels of a window (64 x 64).
const MAX_BORDER_PX: usize = 4 * 64;

/// The background plane `a + b x + c y` (x, y from the window's centre) through the border pixels of a `w` x `h` window
/// whose pixel (i, j) is `at(i, j)` and whose blob's extreme value (the darkest pixel for dark blobs, the brightest for
/// bright ones) is `blob_extreme`, and the background's noise (one standard deviation). First fitted through the border
/// pixels within a quarter of the contrast of the border's background extreme (its lightest pixel for dark blobs), then
/// up to three more times through those that stand towards the blob less than twice the noise from the last plane (a
/// pixel away from the blob, a highlight on a dark blob's border, stays in), the noise taken each time from the
/// residuals on the background's side of the plane. A dense grid puts parts of the neighbouring circles on a window's
/// border, often most of it, and partly covered pixels at their rims: a plane fitted through them tilts and sinks
/// towards them, which gives the flattened blob a slant that moves its centroid. On photographs of a dense hexagonal
/// grid of printed circles this fit puts the window centroids an order of magnitude nearer the circles' outline
/// centres than the plane through the whole border, and finds many more circles in their windows (measured in
/// docs/frames.md, with its command).
fn border_plane(
    w: usize,
    h: usize,
    polarity: Polarity,
    blob_extreme: f64,
    at: impl Fn(usize, usize) -> f64,
) -> (f64, f64, f64, f64) {
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let mut border = [(0.0f64, 0.0f64, 0.0f64); MAX_BORDER_PX];
    let mut n = 0;
    let mut push = |i: usize, j: usize| {
        if n < MAX_BORDER_PX {
            border[n] = (i as f64 - cx, j as f64 - cy, at(i, j));
            n += 1;
        }
    };
    for i in 0..w {
        push(i, 0);
        if h > 1 {
            push(i, h - 1);
        }
    }
    for j in 1..h.saturating_sub(1) {
        push(0, j);
        if w > 1 {
            push(w - 1, j);
        }
    }
    let border = &border[..n];
    // Values measured towards the blob: +v for bright blobs, -v for dark ones.
    let towards_blob = match polarity {
        Polarity::Dark => -1.0,
        Polarity::Bright => 1.0,
    };
    let background_level = border
        .iter()
        .map(|p| towards_blob * p.2)
        .fold(f64::INFINITY, f64::min);
    let midpoint = background_level + 0.25 * (towards_blob * blob_extreme - background_level);
    let mut background = [false; MAX_BORDER_PX];
    for (keep, p) in background.iter_mut().zip(border) {
        *keep = towards_blob * p.2 <= midpoint;
    }
    let Some(first) = fit_plane(border, &background[..n]) else {
        let mean = border.iter().map(|p| p.2).sum::<f64>() / n.max(1) as f64;
        return (mean, 0.0, 0.0, 0.0);
    };
    let (plane, noise) = refit_background(border, &mut background[..n], towards_blob, first);
    (plane[0], plane[1], plane[2], noise)
}

/// Refits the background plane `first` through the `border` pixels up to three times, each time without those that
/// stand towards the blob (`towards_blob`: +1 for bright blobs, -1 for dark ones) by more than twice the
/// background's noise (`background` marks the pixels kept); returns the plane and the noise.
fn refit_background(
    border: &[(f64, f64, f64)],
    background: &mut [bool],
    towards_blob: f64,
    first: [f64; 3],
) -> ([f64; 3], f64) {
    let plane_at =
        |plane: &[f64; 3], p: &(f64, f64, f64)| plane[0] + plane[1] * p.0 + plane[2] * p.1;
    // Refits without the pixels that stand towards the blob by more than twice the background's noise, the noise
    // taken from the residuals on the background's own side of the plane, where no blob's rim reaches (half a normal
    // distribution, whose mean absolute value is 0.798 standard deviations). Partly covered pixels at a neighbour's
    // rim pass the midpoint split and pull the first plane towards the blobs; each refit leaves more of them out.
    let background_noise = |plane: &[f64; 3]| {
        let (mut sum, mut m) = (0.0, 0.0);
        for p in border {
            let r = p.2 - plane_at(plane, p);
            if towards_blob * r <= 0.0 {
                sum -= towards_blob * r;
                m += 1.0;
            }
        }
        if m > 0.0 { 1.2533 * sum / m } else { 0.0 }
    };
    let mut plane = first;
    let mut noise = background_noise(&plane);
    for _ in 0..3 {
        let limit = (2.0 * noise).max(2.0);
        let mut changed = false;
        for (keep, p) in background.iter_mut().zip(border) {
            let is_background = towards_blob * (p.2 - plane_at(&plane, p)) <= limit;
            changed |= is_background != *keep;
            *keep = is_background;
        }
        if !changed {
            break;
        }
        let Some(refit) = fit_plane(border, background) else {
            break;
        };
        plane = refit;
        noise = background_noise(&plane);
    }
    (plane, noise)
}
