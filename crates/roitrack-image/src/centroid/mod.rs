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
//! With the default options the blob must then pass a shape check ([`SymmetryCheck`], in [`crate::symmetry`]): a
//! reflection merged with a blob pulls its moments by up to half a pixel, and is caught by the skew it adds to the
//! blob's third-order moments (summed in one more integer pass over the component's rows).
//!
//! The passes over the pixels take 8 pixels a vector with SSE2 (every x86_64 CPU) or 32 with AVX-512 where the CPU
//! has it, a pixel at a time elsewhere; the vectorised ones are written once, generic over a trait of lane primitives
//! that each instruction set implements. The moments are integer sums (exact), so every path gives the same centroid
//! to the bit.
//!
//! This file holds the public API and [`measure_blob`]'s steps in order, so that the whole measurement reads in one
//! place; each step's internals have a file by concern, to be read and tested on its own:
//! - `levels.rs`: background, threshold and weight origin from the border's statistics and the peak;
//! - `component.rs`: the component of the brightest pixel from the rows' masks (bit operations a row at a time);
//! - `moments.rs`: the integer moments of a component (`Moments`), and their measurement a row at a time; the
//!   second- and third-order sums of the shape check (`ShapeSums`), a pixel at a time;
//! - `kernels/`: the passes over the pixels and the choice of instructions: `mod.rs` the choice (`Isa`) and the
//!   calls, `lanes.rs` the trait of lane primitives, `scan.rs` the generic peak, border statistics and row masks,
//!   `walk.rs` the generic moment sums (the one-pass walk of a simple component, the window moments), `shape.rs` the
//!   shape check's sums (SSE2, or AVX2 where the CPU has it), `sse2.rs` and
//!   `avx512.rs` the primitives of each instruction set, `portable.rs` the pixel-at-a-time kernels (the reference);
//! - `test_rois.rs` (tests only): synthetic and rendered ROIs of any size, for the comparisons of instruction sets.

mod component;
mod kernels;
mod levels;
pub(crate) mod moments;
#[cfg(test)]
mod test_rois;

use thiserror::Error;

use crate::roi::Roi;
use crate::symmetry::{Skew, skew, trefoil_rejected_on_second_look};
use component::{component_moments, component_rows};
use kernels::Isa;
use levels::{Levels, levels};
use moments::{Moments, scalar_shape_sums};

/// Widest ROI [`measure_blob`] accepts (pixels): a row's mask is one `u64`.
pub const MAX_ROI_WIDTH: u32 = 64;
/// Tallest ROI [`measure_blob`] accepts (pixels).
pub const MAX_ROI_HEIGHT: u32 = 64;

/// With [`Threshold::Auto`], the threshold is the background plus this fraction of the peak's contrast. Low, so that
/// the weighted centroid sees nearly the whole blurred edge (a higher threshold lets the pixels entering and leaving
/// the component as the blob moves sub-pixel lock the centroid to the grid: measured in docs/results.md, "Design
/// measurements behind the code"), yet about 50 noise sigmas above the background for the default sensor (33 DN over
/// a 0.6 DN noise).
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
    /// How the level that separates the blob from its background is chosen.
    pub threshold: Threshold,
    /// `true` (the default, the more accurate): first-order moments weighted by `value - threshold` over the
    /// component's pixels. Measuring from the threshold rather than from the background makes the weights vanish
    /// where pixels enter or leave the component as the blob moves, so the centroid does not lock to the pixel grid
    /// as it does weighting by `value - background`. `false`: the paper's binary first-order moments of the
    /// thresholded pixels, an order of magnitude less precise (every pixel counts fully or not at all). Both measured
    /// in docs/results.md, "Design measurements behind the code".
    pub intensity_weighted: bool,
    /// Smallest accepted component (pixels). Default 4.
    pub min_area_px: u32,
    /// Largest accepted component (pixels). Default 4096 (a full 64 x 64 ROI).
    pub max_area_px: u32,
    /// Reject blobs that are not centrally symmetric (see [`SymmetryCheck`]). Default on.
    pub symmetry: Option<SymmetryCheck>,
    /// The background's noise (DN, one standard deviation) when the caller has measured it, as the frame tracker
    /// does on the windows it flattens; `None` (the default): bounded by half the range of the ROI's border pixels
    /// below the threshold. Sets the shape check's allowance for noise in the coma: a border that crosses a shadow's
    /// edge or a neighbour's rim has a wide range, and with it the check passed real printed circles lit unevenly
    /// enough to move their weighted centroids by a large fraction of a pixel; with the measured noise they are flagged
    /// and measured from their capped weights (see [`SymmetryCheck`]). The trefoil's allowance keeps the border's range.
    /// A value that is not finite or is negative counts as `None`.
    pub background_noise_dn: Option<f64>,
}

/// A test that the blob is the image of a disk, and nothing merged with it: a reflection or a glint touching the blob,
/// or an occluder cutting it, pulls the first-order moments by up to about half a pixel while the blob still looks like
/// one blob. A disk's image (an ellipse, blurred, motion-blurred along a line, clipped where it saturates) is centrally
/// symmetric, so its third-order central moments vanish; a spot merged with it skews them. The check whitens the blob
/// by its second moments (an ellipse becomes a circle) and measures the skew's three-fold part (the trefoil) and
/// one-fold part (the coma), from sums accumulated in one more integer pass over the component's rows (see
/// [`crate::symmetry`]); when either exceeds what pixel sampling and noise can give a clean disk of the blob's pixel
/// count, edge width and background noise, it takes a second look (below) and rejects the blob as
/// [`BlobRejection::Asymmetric`] unless that clears it.
///
/// A spot that moves the centroid by `delta` at `d` from it adds `(delta / sigma) (d / sigma)²` to the trefoil and
/// `(delta / sigma) |(d / sigma)² - 4|` to the coma (`sigma` the blob's radius over 2): spots beyond the rim show in
/// both, spots inside the blob mostly in the coma. The allowances are fitted so that no clean rendered blob
/// (`tests/clean_disks.rs`: any size from 3 to 20 px, sub-pixel position, blur, noise, bit depth, clipping, ellipse
/// and background gradient) is rejected, while nearly every merged spot that moves the centroid by more than a tenth
/// of a pixel is (roitrack-sim's `tests/rendered.rs`).
///
/// The allowances fall with the blob's size, and large real blobs go beyond them in two ways a spot does not explain;
/// a second look, a float pass run only for the flagged blobs, tells them apart (see [`crate::symmetry`]): a trefoil
/// with no matching five-fold moment is an outline that is not quite an ellipse, and accepted
/// ([`SymmetryCheck::five_fold_ratio`]); a coma that goes once the weights are capped at 70 % of the peak is uneven
/// light on a flat top, which pulled the weighted centroid (by `ramp * radius / 4`), and the capped weights' centroid
/// is returned. Where the caller has measured the background's noise ([`CentroidOptions::background_noise_dn`], as the
/// frame tracker's flattened windows do), the coma is judged against it rather than against the border's range. The
/// second look costs nothing on blobs it does not flag.
///
/// What it rejects and passes on rendered and real blobs (printed circles in photographs, the example
/// `realdata_rois` of roitrack-bench), and what it costs: docs/results.md, "Reflections in the ROIs: the symmetry
/// check".
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetryCheck {
    /// The trefoil allowed for pixel sampling, times the blob's pixel count, for a blurred edge (1.5 px or wider;
    /// sharper edges are allowed up to 30 times more). Default 7.
    pub trefoil_sampling: f64,
    /// The same for the coma. Default 5.
    pub coma_sampling: f64,
    /// The skew allowed for noise, in standard deviations (from the border's noise). Default 24.
    pub noise_sigmas: f64,
    /// The trefoil allowed whatever the blob's size and noise, for outlines that are not perfect ellipses: a print, a
    /// lens and a JPEG encoder leave a three-fold wobble on the outline of a large dark circle (a trefoil of about
    /// `8 * wobble / radius`; measured in docs/results.md, "Reflections in the ROIs: the symmetry check"), which the
    /// sampling and noise terms, falling with the blob's size, no longer cover beyond about 500 px. Default 0.02.
    pub trefoil_floor: f64,
    /// A blob whose trefoil exceeds its allowance is still taken for a disk when its whitened five-fold moment
    /// `|E[z⁵]|` is at most this many times its trefoil (a spot's is 1.4 to 6 times; see [`crate::symmetry`]).
    /// Default 1.
    pub five_fold_ratio: f64,
    /// ... but never when its trefoil exceeds this (a three-fold wobble of about `0.15 R / 8` px on the outline of a
    /// disk of radius `R`: no disk). Default 0.15.
    pub trefoil_ceiling: f64,
    /// A blob flagged for its coma is measured again with its weights capped at this fraction of its peak above the
    /// threshold (intensity-weighted centroids only): a flat top lit unevenly loses its coma and its bias, a merged
    /// spot does not (see [`crate::symmetry`]). Default 0.7.
    pub plateau_fraction: f64,
    /// Blobs of fewer pixels are not tested (their sampling alone can look like a merged spot). Default 30.
    pub min_area_px: u32,
}

impl Default for SymmetryCheck {
    fn default() -> Self {
        Self {
            trefoil_sampling: 7.0,
            coma_sampling: 5.0,
            noise_sigmas: 24.0,
            trefoil_floor: 0.02,
            five_fold_ratio: 1.0,
            trefoil_ceiling: 0.15,
            plateau_fraction: 0.7,
            min_area_px: 30,
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
            background_noise_dn: None,
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
    /// Centroid, full-sensor raw (distorted) pixel coordinates (pixel (i, j) is centred on (i, j)): column.
    pub u_px: f64,
    /// Its row.
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
    /// Nothing stands out of the background.
    #[error("no blob in the ROI (nothing stands out of the background)")]
    Absent,
    /// The ROI cuts the blob.
    #[error("the blob touches the ROI's border (the ROI cuts it)")]
    TouchesBorder,
    /// Fewer pixels than a blob has.
    #[error("the blob is too small ({area_px} px)")]
    TooSmall {
        /// The component's pixels.
        area_px: u32,
    },
    /// More pixels than a blob has.
    #[error("the blob is too large ({area_px} px)")]
    TooLarge {
        /// The component's pixels.
        area_px: u32,
    },
    /// Not centrally symmetric: a reflection or an occluder merged with it.
    #[error(
        "the blob is not centrally symmetric (a reflection or an occluder merged with it would bias its centroid)"
    )]
    Asymmetric,
}

/// Measures the blob of an ROI: the connected component (8-connectivity) of above-threshold pixels that contains the
/// brightest pixel (the first in row-major order if several), so another blob or a reflection elsewhere in the ROI
/// does not bias it (a blob of equal brightness elsewhere in the ROI may win the tie: size the ROI to hold one blob).
/// The centroid is the component's first-order moments, weighted by `value - threshold` or binary (see
/// [`CentroidOptions`]), in full-sensor pixel coordinates; for a blob whose shape check flags a coma that goes once
/// its weights are capped at its plateau (uneven light on a flat top), those of the capped weights (see
/// [`SymmetryCheck::plateau_fraction`]).
///
/// Rejections, in this order: [`BlobRejection::Absent`] (nothing above the threshold or too little contrast),
/// [`BlobRejection::TouchesBorder`] (the component reaches the ROI's outer rows or columns), the area limits, then
/// [`BlobRejection::Asymmetric`] (with [`CentroidOptions::symmetry`], the default: something merged with the blob).
///
/// ```
/// use roitrack_image::{BlobRejection, CentroidOptions, Roi, measure_blob};
///
/// // A 3 x 3 blob of value 200 on a dark 9 x 9 ROI whose top-left pixel is (100, 40).
/// let roi = Roi::new(100, 40, 9, 9);
/// let mut pixels = vec![10u16; roi.len()];
/// for j in 4..7 {
///     for i in 2..5 {
///         pixels[j * 9 + i] = 200;
///     }
/// }
/// let c = measure_blob(&pixels, &roi, &CentroidOptions::default()).unwrap();
/// assert!((c.u_px - 103.0).abs() < 1e-9 && (c.v_px - 45.0).abs() < 1e-9);
/// assert_eq!(c.area_px, 9);
/// // Nothing stands out of a flat ROI.
/// let flat = vec![10u16; roi.len()];
/// assert_eq!(measure_blob(&flat, &roi, &CentroidOptions::default()), Err(BlobRejection::Absent));
/// ```
///
/// # Panics
/// If `pixels.len() != roi.len()`, or the ROI is empty or larger than [`MAX_ROI_WIDTH`] x [`MAX_ROI_HEIGHT`].
pub fn measure_blob(
    pixels: &[u16],
    roi: &Roi,
    opts: &CentroidOptions,
) -> Result<Centroid, BlobRejection> {
    measure_blob_with(Isa::detect(), pixels, roi, opts, None)
}

/// [`measure_blob`] for the blob nearest `near_px` (full-sensor pixel coordinates) rather than the brightest one: the
/// component that contains the above-threshold pixel nearest that point. A window of a dense target holds whole
/// neighbours of the same contrast as its own blob, and which of them holds the brightest pixel is down to noise; the
/// blob the prediction points at is the one nearest it. Only that component must stay off the ROI's border: a
/// neighbour's rim there does not reject it.
///
/// ```
/// use roitrack_image::{CentroidOptions, Roi, measure_blob, measure_blob_near};
///
/// // Two 3 x 3 blobs in a 15 x 9 ROI; the right one is a little brighter.
/// let roi = Roi::new(0, 0, 15, 9);
/// let mut pixels = vec![10u16; roi.len()];
/// for j in 3..6 {
///     for i in 2..5 {
///         pixels[j * 15 + i] = 200;
///         pixels[j * 15 + i + 8] = 210;
///     }
/// }
/// let brightest = measure_blob(&pixels, &roi, &CentroidOptions::default()).unwrap();
/// assert!((brightest.u_px - 11.0).abs() < 1e-9);
/// let near = measure_blob_near(&pixels, &roi, &CentroidOptions::default(), [4.5, 4.0]).unwrap();
/// assert!((near.u_px - 3.0).abs() < 1e-9 && (near.v_px - 4.0).abs() < 1e-9);
/// ```
///
/// # Panics
/// As [`measure_blob`].
pub fn measure_blob_near(
    pixels: &[u16],
    roi: &Roi,
    opts: &CentroidOptions,
    near_px: [f64; 2],
) -> Result<Centroid, BlobRejection> {
    let local = [
        near_px[0] - f64::from(roi.x0),
        near_px[1] - f64::from(roi.y0),
    ];
    measure_blob_with(Isa::detect(), pixels, roi, opts, Some(local))
}

/// The above-threshold pixel of a `w`-wide ROI nearest `near` (ROI coordinates), as an index; `None` if no pixel is
/// above `threshold`.
/// (The first of them in index order when several are as near.) Read row by row, without a division per pixel.
fn nearest_above(pixels: &[u16], w: usize, threshold: u16, near: [f64; 2]) -> Option<usize> {
    let mut nearest: Option<(usize, f64)> = None;
    for (j, row) in pixels.chunks(w.max(1)).enumerate() {
        // Through `u32` (a ROI is at most 64 px wide): one instruction where `usize` takes several; the same values.
        let dj = f64::from(j as u32) - near[1];
        for (i, &p) in row.iter().enumerate() {
            if p <= threshold {
                continue;
            }
            let di = f64::from(i as u32) - near[0];
            let d2 = di * di + dj * dj;
            if nearest.is_none_or(|(_, best)| d2.total_cmp(&best).is_lt()) {
                nearest = Some((j * w + i, d2));
            }
        }
    }
    nearest.map(|(k, _)| k)
}

/// [`measure_blob`] with the given instructions; the component nearest `near` (ROI coordinates) when given, else the
/// brightest pixel's.
fn measure_blob_with(
    isa: Isa,
    pixels: &[u16],
    roi: &Roi,
    opts: &CentroidOptions,
    near: Option<[f64; 2]>,
) -> Result<Centroid, BlobRejection> {
    let (w, h) = (roi.width as usize, roi.height as usize);
    assert!(
        (1..=MAX_ROI_WIDTH).contains(&roi.width) && (1..=MAX_ROI_HEIGHT).contains(&roi.height),
        "measure_blob handles ROIs of 1x1 to {MAX_ROI_WIDTH}x{MAX_ROI_HEIGHT} pixels, got {w}x{h}"
    );
    assert_eq!(pixels.len(), w * h, "pixel buffer length");
    // Pass 1: the peak and its first position; the border's statistics.
    let (peak, seed) = kernels::peak(isa, pixels);
    let border = kernels::border_min_max_sum(isa, pixels, w, h);
    let Levels {
        background,
        threshold,
        weight_origin,
        noise_range,
    } = levels(pixels, w, h, peak, border, opts.threshold)?;
    let seed = match near {
        Some(near) => nearest_above(pixels, w, threshold, near).ok_or(BlobRejection::Absent)?,
        None => seed,
    };

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
        grown,
    ) = match kernels::walk_simple(isa, pixels, (w, h), seed.1, (threshold, peak)) {
        Some((moments, rows, cols)) => (moments, rows, cols, false),
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
    let (mut ci, mut cj) = if opts.intensity_weighted {
        weighted
    } else {
        binary
    };
    if let Some(check) = &opts.symmetry
        && area_px >= check.min_area_px
    {
        let columns = (
            cols.trailing_zeros() as usize,
            63 - cols.leading_zeros() as usize,
        );
        let vmax = peak - threshold;
        // The coma's allowance for noise from the background's measured noise where the caller gives it (s² =
        // (r / 2)² + 1/12 in the allowance: a range of 2 s stands for a standard deviation s); the trefoil's from the
        // border's range either way (see `CentroidOptions::background_noise_dn`).
        let measured = opts
            .background_noise_dn
            .filter(|s| s.is_finite() && *s >= 0.0);
        let noise_ranges = (noise_range, measured.map_or(noise_range, |s| 2.0 * s));
        // Err: rejected; Ok(None): the centroid stands; Ok(Some): the centroid of the plateau-capped weights replaces
        // it (ROI coordinates).
        let judge = |comp: Option<&[u64]>| -> Result<Option<(f64, f64)>, BlobRejection> {
            let sums = kernels::shape_sums(isa, pixels, w, comp, (lo, hi), cols, (threshold, peak));
            let spotted = |cap: u16| {
                trefoil_rejected_on_second_look(
                    pixels,
                    w,
                    comp,
                    (lo, hi),
                    columns,
                    (threshold, cap),
                    check,
                )
            };
            let weight = sums.s[0] as i64 as f64;
            let levels = (weight, f64::from(vmax));
            match skew(&sums, n, levels, noise_ranges, check) {
                Skew::Within => Ok(None),
                Skew::Trefoil if !spotted(u16::MAX) => Ok(None),
                Skew::Coma if opts.intensity_weighted => {
                    let cap = (f64::from(vmax) * check.plateau_fraction) as u16;
                    let capped = scalar_shape_sums(
                        pixels,
                        w,
                        comp,
                        (lo, hi),
                        columns,
                        columns.0,
                        (threshold, cap),
                    );
                    let [m, sx, sy, ..] = capped.s.map(|x| x as f64);
                    let clean = match skew(&capped, n, levels, noise_ranges, check) {
                        Skew::Within => true,
                        Skew::Trefoil => !spotted(cap),
                        Skew::Coma => false,
                    };
                    if clean && m > 0.0 {
                        Ok(Some((columns.0 as f64 + sx / m, lo as f64 + sy / m)))
                    } else {
                        Err(BlobRejection::Asymmetric)
                    }
                }
                _ => Err(BlobRejection::Asymmetric),
            }
        };
        // The component's rows, found again, when not every above-threshold pixel of its rows is its own (rare).
        let capped_centre = if grown {
            let mut comp = [0u64; MAX_ROI_HEIGHT as usize];
            component_rows(isa, pixels, (w, h), seed, threshold, &mut comp[..h]);
            judge(Some(&comp[..h]))?
        } else {
            judge(None)?
        };
        if let Some(centre) = capped_centre {
            (ci, cj) = centre;
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

    /// The instruction sets this CPU runs, and the portable code.
    fn isas() -> Vec<Isa> {
        [Isa::Avx512, Isa::Sse2, Isa::Portable]
            .into_iter()
            .filter(|&isa| isa != Isa::Avx512 || Isa::detect() == Isa::Avx512)
            .collect()
    }

    /// Measures the ROI with every instruction set of `isas` and asserts the results are equal, to the bit; returns
    /// whether a blob was measured.
    fn assert_isas_agree(isas: &[Isa], pixels: &[u16], roi: &Roi, opts: &CentroidOptions) -> bool {
        let results: Vec<_> = isas
            .iter()
            .map(|&isa| measure_blob_with(isa, pixels, roi, opts, None))
            .collect();
        for (isa, r) in isas.iter().zip(&results) {
            assert_eq!(*r, results[0], "{roi:?} {opts:?} {isa:?} {pixels:?}");
        }
        results[0].is_ok()
    }

    /// The vectorised kernels (those the CPU runs) and the portable code give the same results, to the bit, on
    /// random ROIs of random sizes holding disks, rings and diagonal lines (simple components and not), noise, 8 to
    /// 16-bit pixels, and fixed or automatic thresholds.
    #[test]
    fn instruction_sets_agree() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let isas = isas();
        let mut measured = 0;
        for case in 0..3000 {
            let (w, h) = if case % 3 == 0 {
                (rng.random_range(1..=64usize), rng.random_range(1..=64usize))
            } else {
                (rng.random_range(6..=40usize), rng.random_range(6..=40usize))
            };
            let pixels = test_rois::synthetic(&mut rng, w, h, case);
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
                measured += usize::from(assert_isas_agree(&isas, &pixels, &roi, &opts));
            }
        }
        assert!(measured > 1500, "{measured}");
    }

    /// As [`instruction_sets_agree`], on a synthetic ROI and one of a camera-like blob of every size from 1 x 1 to
    /// 64 x 64, each with the default options, binary moments, a fixed threshold and no symmetry check.
    #[test]
    fn instruction_sets_agree_at_every_size() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        let isas = isas();
        let mut measured = 0;
        for w in 1..=64 {
            for h in 1..=64 {
                let kind = w * 64 + h;
                let synthetic = (
                    test_rois::synthetic(&mut rng, w, h, kind),
                    Roi::new(100, 200, w as u32, h as u32),
                );
                let blob = test_rois::blob(&mut rng, w as u32, h as u32, kind);
                for (pixels, roi) in [synthetic, blob] {
                    let top = *pixels.iter().max().unwrap();
                    for opts in [
                        CentroidOptions::default(),
                        CentroidOptions::binary(),
                        CentroidOptions {
                            threshold: Threshold::Fixed(
                                (rng.random_range(0.1..1.0) * f64::from(top)) as u16,
                            ),
                            min_area_px: 1,
                            ..Default::default()
                        },
                        CentroidOptions {
                            symmetry: None,
                            ..Default::default()
                        },
                    ] {
                        measured += usize::from(assert_isas_agree(&isas, &pixels, &roi, &opts));
                    }
                }
            }
        }
        assert!(measured > 6_000, "{measured}");
    }
}
