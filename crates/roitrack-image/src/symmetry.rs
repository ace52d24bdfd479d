//! The shape check of a blob's centroid ([`crate::SymmetryCheck`]): is the blob the image of a disk, with nothing
//! merged with it? Computed from the second- and third-order moments of the component's weights
//! `v = value - threshold`, summed in one more integer pass over the component's rows (`centroid/kernels/shape.rs`:
//! about twenty vector operations a row), then about a hundred floating-point operations: one division and no square
//! root in the statistic.
//!
//! **What it measures.** The image of a disk (an ellipse, blurred by the optics and the pixels, motion-blurred along a
//! line, clipped where it saturates) is centrally symmetric: its odd central moments vanish. Whitened by its second
//! moments (an affine map that makes its covariance the identity, so that an ellipse of any aspect and tilt becomes a
//! circle), its third moments are two complex numbers: the *trefoil* `tau = E[(y1 + i y2)³]` (three-fold) and the
//! *coma* `kappa = E[|y|² (y1 + i y2)]` (one-fold), in units of the blob's spread. Both are 0 for a clean disk.
//!
//! - `Re z³` and `Im z³` are harmonic polynomials, so a rotationally symmetric lump (a Gaussian spot, a glint) of
//!   weight `m` at `d` from the centroid adds exactly `m d³ e^{3iθ}` to `M tau`: a spot that moves the centroid by
//!   `delta = m d / M` shows as `|tau| = (delta / sigma) (d / sigma)²` (`sigma²` the variance per axis: `R²/4` for a
//!   flat disk of radius `R`); and as `|kappa| = (delta / sigma) |(d / sigma)² - 4|` for a flat disk. Spots beyond the
//!   rim show in both; spots inside the blob (`d` about `R / 2`) mostly in the coma.
//! - A linear brightness ramp across the blob (a background gradient, uneven lighting) moves the centroid too, but it
//!   is one-fold: it adds coma and no trefoil. The centroid's own offset from the centre changes the trefoil only by
//!   `3 delta E[y²]`, which whitening makes 0. So the trefoil is blind to slants; the coma is not, and bounds them.
//!
//! **What a clean disk can show.** Not exactly 0: (1) the pixel grid samples the blob, and the threshold cuts it, at
//! positions that are not symmetric about its centre; the skew this leaves falls with the blob's pixel count `n` about
//! as `1/n`, and grows as the edge gets sharper than a pixel (a sharp or saturated blob is nearly binary, and its
//! moments lock to the grid); (2) pixel noise of standard deviation `s` gives each component a standard deviation of
//! about `2.8 s √n / M` (`M = Σ v`; for a flat disk, `√(Σ |y|⁶ / 2) s / M` with `|y| <= 2`). A blob is rejected when
//! `|tau|` or `|kappa|` exceeds
//!
//! `sampling * g(e) / n + noise_sigmas * s * √n / M`
//!
//! (`sampling` [`crate::SymmetryCheck::trefoil_sampling`] or [`crate::SymmetryCheck::coma_sampling`]), plus, for the
//! trefoil, [`crate::SymmetryCheck::trefoil_floor`] (real outlines are not perfect ellipses: a three-fold wobble `w`
//! px on the outline of a flat disk of radius `R` is a trefoil of `8 w / R`, a harmless one since a three-fold shape
//! keeps its centroid; the two terms above fall with the blob's size below what printed circles of 30 to 40 px show),
//! with
//!
//! - `e = (1 - M / (vmax n)) √(n / π)` the width of the blob's edge (px): a flat disk whose edge ramps over `e` pixels
//!   loses about `e` times half its perimeter in weight (`vmax` the peak above the threshold); `g(e) = (1.5 / e)³`,
//!   between 1 (edges 1.5 px wide and wider) and 30 (binary blobs);
//! - `s² = (r / 2)² + 1/12`, `r` the range of the border pixels that set the background (half a range bounds their
//!   standard deviation; it grows with the background's shot noise, a gradient or another blob's tail, which all come
//!   with a noisier blob), plus the variance of the quantisation.
//!
//! The constants were fitted on 100,000 rendered clean blobs (the generator of `tests/clean_disks.rs`, another seed
//! than its test: diameters 3 to 20 px, sub-pixel positions, blur 0 to 1.5 px, read and shot noise, 8 and 12 bits,
//! clipped cores, ellipses of aspect up to 1.5, background gradients and curvature, brightness uneven by up to 2 % a
//! radius), with a margin over the largest skew any of them showed (docs/results.md, "Reflections in the ROIs: the
//! symmetry check"). Blobs of fewer than [`crate::SymmetryCheck::min_area_px`] pixels (30: about 5 px across) are not
//! tested: their sampling alone skews them as much as a merged spot.
//!
//! **A second look at what the moments flag.** The allowances fall with the blob's size; real blobs of 30 to 40 px
//! (printed circles in JPEG photographs) go beyond them in two ways that a merged spot does not explain, and a float
//! pass over the component, run only for the blobs the moment test flags, tells these apart:
//!
//! - *A trefoil with no five-fold moment* (`trefoil_rejected_on_second_look`). A spot, a lump, adds `m d^k e^{ikθ}`
//!   to every harmonic moment `M E[z^k]`, so its five-fold moment `E[z⁵]` is `(d / sigma)²` times its trefoil (4
//!   times on the rim, more beyond it); a smooth three-fold wobble of the outline, which a print, a lens and a JPEG
//!   encoder leave, has a trefoil and nearly no five-fold moment, and it does not move the centroid. Accepted when
//!   `|E[z⁵]|` is at most [`crate::SymmetryCheck::five_fold_ratio`] times `|tau|` and `|tau|` at most
//!   [`crate::SymmetryCheck::trefoil_ceiling`].
//! - *A coma from uneven light on a flat top.* Glare on ink or a shadow's edge across a printed circle tilts its
//!   plateau by a few percent a radius; the weights `value - threshold` follow the light and pull the centroid by
//!   about `ramp * radius / 4`, which the coma rightly flags. Capped at 70 % of the peak
//!   ([`crate::SymmetryCheck::plateau_fraction`]), the weights of a flat top no longer see the light: the capped weights are tested again, against the uncapped blob's
//!   allowances (stricter than the capped weights' own, whose edge looks sharper), and if they pass, their centroid
//!   is the blob's, much nearer the centre of the outline. A merged spot still skews the capped weights
//!   and is rejected. Binary centroids ([`crate::CentroidOptions::binary`]) are rejected as before.
//!
//! The second look changes none of the outcomes that matter on the rendered spots of roitrack-sim's
//! `tests/rendered.rs`, passes nearly none of the spots merged with large blobs of `tests/clean_disks.rs` that move
//! the centroid by more than a tenth of a pixel, and accepts the real printed circles the moments alone rejected:
//! measured in docs/results.md, "Reflections in the ROIs: the symmetry check".

use crate::centroid::SymmetryCheck;
use crate::centroid::moments::{ShapeSums, scalar_shape_sums, visit_shape_weights};

/// What the moment test found in a component: nothing a clean disk cannot show, a trefoil beyond it (and no coma),
/// or a coma beyond it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Skew {
    Within,
    Trefoil,
    Coma,
}

/// Whether the component's whitened trefoil or coma exceeds what a clean disk can show (see the module's
/// documentation): `sums` its [`ShapeSums`], `n` its pixel count, `(weight, vmax)` the sum of its weights
/// `value - threshold` and its peak above the threshold (DN), which set the allowances (a second look at capped
/// weights passes the uncapped blob's), `noise_ranges` the range of the border pixels that set the background (DN),
/// or twice the background's measured noise, for the trefoil and for the coma. Degenerate weights (all on a line)
/// are not tested.
#[inline(always)]
pub(crate) fn skew(
    sums: &ShapeSums,
    n: f64,
    (weight, vmax): (f64, f64),
    (trefoil_range, coma_range): (f64, f64),
    check: &SymmetryCheck,
) -> Skew {
    let Some((trefoil_a3, coma_a3, a3)) = trefoil_and_coma_a3(sums) else {
        return Skew::Within;
    };
    let (per_sampling, noise) = allowances(n, weight, vmax, trefoil_range, check.noise_sigmas);
    let coma_noise = if coma_range == trefoil_range {
        noise
    } else {
        allowances(n, weight, vmax, coma_range, check.noise_sigmas).1
    };
    let trefoil_max = check.trefoil_sampling * per_sampling + noise + check.trefoil_floor;
    let coma_max = check.coma_sampling * per_sampling + coma_noise;
    if coma_a3 > coma_max * coma_max * a3 {
        Skew::Coma
    } else if trefoil_a3 > trefoil_max * trefoil_max * a3 {
        Skew::Trefoil
    } else {
        Skew::Within
    }
}

/// Whether a component whose trefoil exceeds what pixel sampling and noise give a clean disk (see [`skew`]) owes it
/// to a spot merged with it (or is no disk) rather than to an outline that is not a perfect ellipse: `pixels` the
/// ROI (`w` wide), `comp` the component's row masks (`None`: every pixel above `threshold` in its rows and columns), `rows` and
/// `cols` its first and last row and column, each pixel weighing `value - threshold`, at most `cap`.
///
/// A rotationally symmetric lump of weight `m` at `d` from the centroid adds `m d^k e^{ikθ}` to every harmonic moment
/// `M E[z^k]` (`z` the whitened position), so a spot's five-fold moment is `(d / sigma)²` times its trefoil: 4 times
/// on the rim, more beyond it (about 1.4 to 6 times measured, the threshold cutting the spot's tail). A smooth
/// three-fold wobble of the outline (a print, a lens, a JPEG encoder) has a trefoil and hardly any five-fold moment
/// (0.04 to 0.74 times its trefoil on the 13 real printed circles of 30 to 40 px that the trefoil alone rejected); and
/// it does not move the centroid, a three-fold shape keeping its centre. So the blob is taken for spotted when its
/// five-fold moment exceeds [`SymmetryCheck::five_fold_ratio`] times its trefoil, or its trefoil exceeds
/// [`SymmetryCheck::trefoil_ceiling`] (no disk). An integer pass and a float pass over the component: it runs only
/// for the blobs the moment test flags for their trefoil.
pub(crate) fn trefoil_rejected_on_second_look(
    pixels: &[u16],
    w: usize,
    comp: Option<&[u64]>,
    (lo, hi): (usize, usize),
    (first, last): (usize, usize),
    (threshold, cap): (u16, u16),
    check: &SymmetryCheck,
) -> bool {
    // The centroid and covariance from the integer sums, as the moment test has them.
    let sums = scalar_shape_sums(
        pixels,
        w,
        comp,
        (lo, hi),
        (first, last),
        first,
        (threshold, cap),
    );
    let [m, sx, sy, sxx, sxy, syy, ..] = sums.s.map(|x| x as f64);
    if m <= 0.0 {
        return false;
    }
    let (cx, cy) = (sx / m, sy / m);
    let a = sxx / m - cx * cx;
    let b = sxy / m - cx * cy;
    let c = syy / m - cy * cy;
    let d = a * c - b * b;
    if a <= 0.0 || d <= 1e-9 * (a + c) * (a + c) {
        return false;
    }
    let (inv_sa, inv_sad) = (1.0 / a.sqrt(), 1.0 / (a * d).sqrt());
    // Sums of v z³ and v z⁵ (real and imaginary parts).
    let (mut t_re, mut t_im, mut f_re, mut f_im) = (0.0, 0.0, 0.0, 0.0);
    let levels = (threshold, cap);
    visit_shape_weights(
        pixels,
        w,
        comp,
        (lo, hi),
        (first, last),
        levels,
        |i, j, v| {
            if v == 0 {
                return;
            }
            let v = v as f64;
            let (x, y) = ((i - first) as f64 - cx, (j - lo) as f64 - cy);
            let (z_re, z_im) = (x * inv_sa, (a * y - b * x) * inv_sad);
            let (z2_re, z2_im) = (z_re * z_re - z_im * z_im, 2.0 * z_re * z_im);
            let (z3_re, z3_im) = (z2_re * z_re - z2_im * z_im, z2_re * z_im + z2_im * z_re);
            let (z5_re, z5_im) = (z3_re * z2_re - z3_im * z2_im, z3_re * z2_im + z3_im * z2_re);
            t_re += v * z3_re;
            t_im += v * z3_im;
            f_re += v * z5_re;
            f_im += v * z5_im;
        },
    );
    let (trefoil, five_fold) = (t_re.hypot(t_im) / m, f_re.hypot(f_im) / m);
    trefoil > check.trefoil_ceiling || five_fold > check.five_fold_ratio * trefoil
}

/// The squares of the whitened trefoil `|tau|` and coma `|kappa|` of a component (see the module's documentation)
/// from its [`ShapeSums`], each times `a³`, and `a³` (`a` its variance along x), all in units where the weight is
/// `M = Σ v` (so that no division by `M` comes first: the ratios are the same), or `None` when its weights are
/// degenerate (no weight, or all on a line).
///
/// Whitened by the inverse of the Cholesky factor of the covariance `[[a, b], [b, c]]` (a whitening, like any other
/// up to a rotation, which leaves `|tau|` and `|kappa|` as they are): `y1 = x / √a`, `y2 = (a y - b x) / √(a D)`,
/// `D = ac - b²`, x and y from the centroid. With `Q1 = E[x (ay - bx)²]`, `Q2 = E[x² (ay - bx)]`,
/// `Q3 = E[(ay - bx)³]` (`u` the central moments):
/// `a³ |tau|² = (u30 - 3 Q1 / D)² + (3 Q2 - Q3 / D)² / D` and `a³ |kappa|² = (u30 + Q1 / D)² + (Q2 + Q3 / D)² / D`.
/// Both sides are homogeneous in the moments: with the second moments times `M²` and the third times `M³`, one
/// division (by `D`) and no square root.
#[inline(always)]
pub(crate) fn trefoil_and_coma_a3(sums: &ShapeSums) -> Option<(f64, f64, f64)> {
    // Through i64 (the sums are below 2^53): a single instruction, where u64 takes several.
    let [m, s10, s01, s20, s11, s02, s30, s21, s12, s03] = sums.s.map(|x| x as i64 as f64);
    if m <= 0.0 {
        return None;
    }
    // Central moments, the second times M², the third times M³.
    let (mm, x2, y2) = (m * m, s10 * s10, s01 * s01);
    let a = m * s20 - x2;
    let b = m * s11 - s10 * s01;
    let c = m * s02 - y2;
    let u30 = mm * s30 - s10 * (3.0 * m * s20 - 2.0 * x2);
    let u03 = mm * s03 - s01 * (3.0 * m * s02 - 2.0 * y2);
    let u21 = mm * s21 - m * (2.0 * s10 * s11 + s01 * s20) + 2.0 * x2 * s01;
    let u12 = mm * s12 - m * (2.0 * s01 * s11 + s10 * s02) + 2.0 * y2 * s10;
    let d = a * c - b * b;
    if d.is_nan() || a <= 0.0 || d <= 1e-9 * (a + c) * (a + c) {
        return None;
    }
    let inv_d = 1.0 / d;
    let (aa, ab, bb) = (a * a, a * b, b * b);
    let q1 = (aa * u12 - 2.0 * ab * u21 + bb * u30) * inv_d;
    let q2 = a * u21 - b * u30;
    let q3 = (aa * a * u03 - 3.0 * aa * b * u12 + 3.0 * a * bb * u21 - bb * b * u30) * inv_d;
    let (re3, im3) = (u30 - 3.0 * q1, 3.0 * q2 - q3);
    let (re1, im1) = (u30 + q1, q2 + q3);
    Some((
        re3 * re3 + im3 * im3 * inv_d,
        re1 * re1 + im1 * im1 * inv_d,
        aa * a,
    ))
}

/// The largest trefoil and coma a clean disk can show (see the module's documentation), per unit sampling
/// coefficient, and the noise's part: `(g(e) / n, noise_sigmas s √n / M)`, `n` the component's pixels, `weight`
/// `M = Σ v`, `vmax` the peak above the threshold (DN), `noise_range` the range of the background's border pixels
/// (DN).
#[inline(always)]
pub(crate) fn allowances(
    n: f64,
    weight: f64,
    vmax: f64,
    noise_range: f64,
    noise_sigmas: f64,
) -> (f64, f64) {
    let full = vmax * n;
    let lost = (full - weight).max(0.0);
    // g = (1.5 / e)³ = (2.25 / e²)^1.5 with e² = (lost / full)² n / π, between 1 and 30: 1 for the usual blurred
    // edges (tested without a division).
    let g = if lost * lost * n >= 2.25 * std::f64::consts::PI * full * full {
        1.0
    } else {
        let x = 2.25 * std::f64::consts::PI * full * full / (lost * lost * n).max(1e-300);
        (x * x.sqrt()).min(30.0)
    };
    let variance = 0.25 * noise_range * noise_range + 1.0 / 12.0;
    (g / n, noise_sigmas * (variance * n).sqrt() / weight)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The [`ShapeSums`] of weights given per pixel (x, y from 0).
    fn sums_of(w: usize, weights: &[f64]) -> ShapeSums {
        let mut s = [0u64; 10];
        for (k, &v) in weights.iter().enumerate() {
            let v = v.round() as u64;
            let (x, y) = ((k % w) as u64, (k / w) as u64);
            for (slot, (p, q)) in [
                (0, 0),
                (1, 0),
                (0, 1),
                (2, 0),
                (1, 1),
                (0, 2),
                (3, 0),
                (2, 1),
                (1, 2),
                (0, 3),
            ]
            .into_iter()
            .enumerate()
            {
                s[slot] += v * x.pow(p) * y.pow(q);
            }
        }
        ShapeSums { s }
    }

    /// A `w` x `w` image of a tilted ellipse (semi-axes `a`, `b` px, tilt `theta`) centred on `centre`, with a soft
    /// edge about a pixel wide and a plateau of 1000, plus a linear ramp `slope` (per px, along x) and a Gaussian spot
    /// (`spot`: centre, peak, sigma px).
    fn ellipse(
        w: usize,
        centre: (f64, f64),
        (a, b, theta): (f64, f64, f64),
        slope: f64,
        spot: Option<((f64, f64), f64, f64)>,
    ) -> Vec<f64> {
        let (s, c) = theta.sin_cos();
        (0..w * w)
            .map(|k| {
                let (x, y) = ((k % w) as f64 - centre.0, (k / w) as f64 - centre.1);
                let (p, q) = ((c * x + s * y) / a, (-s * x + c * y) / b);
                let d = ((p * p + q * q).sqrt() - 1.0) * a.min(b);
                let mut value = 1000.0 / (1.0 + (2.5 * d).exp()) * (1.0 + slope * x);
                if let Some(((sx, sy), peak, sigma)) = spot {
                    let r2 = ((k % w) as f64 - sx).powi(2) + ((k / w) as f64 - sy).powi(2);
                    value += peak * (-r2 / (2.0 * sigma * sigma)).exp();
                }
                // The weights above a threshold of 150.
                (value - 150.0).max(0.0)
            })
            .collect()
    }

    #[test]
    fn tilted_ellipses_and_ramps_have_no_trefoil() {
        for (centre, shape, slope) in [
            ((15.3, 16.7), (7.5, 7.5, 0.0), 0.0),
            ((15.8, 15.1), (8.0, 5.5, 0.6), 0.0),
            ((16.2, 14.6), (5.0, 8.0, -1.1), 0.02),
            ((15.5, 15.5), (6.0, 6.0, 0.3), -0.03),
        ] {
            let tau = trefoil_and_coma_a3(&sums_of(32, &ellipse(32, centre, shape, slope, None)))
                .map(|(t, _, a3)| t / a3);
            // Pixel sampling of the steep edge leaves about 0.01.
            assert!(tau.unwrap().sqrt() < 0.02, "{shape:?} {slope}: {tau:?}");
        }
    }

    #[test]
    fn a_spot_on_the_rim_makes_a_trefoil() {
        let clean = ellipse(32, (15.4, 16.2), (7.5, 7.0, 0.2), 0.0, None);
        let spotted = ellipse(
            32,
            (15.4, 16.2),
            (7.5, 7.0, 0.2),
            0.0,
            Some(((23.0, 15.0), 500.0, 1.2)),
        );
        let (m0, m1) = (clean.iter().sum::<f64>(), spotted.iter().sum::<f64>());
        let moved = |img: &[f64], m: f64| {
            img.iter()
                .enumerate()
                .map(|(k, v)| (k % 32) as f64 * v)
                .sum::<f64>()
                / m
        };
        let delta = moved(&spotted, m1) - moved(&clean, m0);
        let (t, _, a3) = trefoil_and_coma_a3(&sums_of(32, &spotted)).unwrap();
        let tau = (t / a3).sqrt();
        // The spot moved the centroid by about 0.1 px and shows as (delta / sigma) (d / sigma)², sigma about 3.6 px.
        assert!(delta > 0.05, "{delta}");
        let sigma = 3.6;
        let expected = delta / sigma * (7.6f64 / sigma).powi(2);
        assert!(
            (tau / expected - 1.0).abs() < 0.3,
            "{tau} against {expected}"
        );
    }

    /// A flat 64 x 64 disk of radius `radius` px centred on (31.6, 32.3), its outline wobbling three-fold by
    /// `wobble` px, with an edge about a pixel wide and a plateau of 120 above the threshold (DN), plus a Gaussian
    /// spot (`spot`: distance from the centre along x (px), peak (DN), sigma 1.5 px).
    fn wobbly_disk(radius: f64, wobble: f64, spot: Option<(f64, f64)>) -> Vec<f64> {
        let (cx, cy) = (31.6, 32.3);
        (0..64 * 64)
            .map(|k| {
                let (x, y) = ((k % 64) as f64 - cx, (k / 64) as f64 - cy);
                let outline = radius + wobble * (3.0 * y.atan2(x)).cos();
                let mut value = 135.0 / (1.0 + (2.5 * (x.hypot(y) - outline)).exp());
                if let Some((d, peak)) = spot {
                    value += peak * (-((x - d).powi(2) + y * y) / (2.0 * 1.5 * 1.5)).exp();
                }
                (value - 15.0).max(0.0).round()
            })
            .collect()
    }

    fn rejected(weights: &[f64]) -> bool {
        let n = weights.iter().filter(|&&v| v > 0.0).count() as f64;
        let vmax = weights.iter().cloned().fold(0.0, f64::max);
        let sums = sums_of(64, weights);
        let weight = sums.s[0] as f64;
        skew(
            &sums,
            n,
            (weight, vmax),
            (6.0, 6.0),
            &SymmetryCheck::default(),
        ) != Skew::Within
    }

    #[test]
    fn a_large_disk_with_a_wobbly_outline_passes_and_a_spot_does_not() {
        // As measured on 35 px printed circles in JPEG photographs: a trefoil of about 0.045 (8 * 0.1 / 17.5).
        let wobbly = wobbly_disk(17.5, 0.1, None);
        let (t, _, a3) = trefoil_and_coma_a3(&sums_of(64, &wobbly)).unwrap();
        assert!(
            ((t / a3).sqrt() - 0.045).abs() < 0.008,
            "{}",
            (t / a3).sqrt()
        );
        assert!(!rejected(&wobbly));
        // Without the floor, the sampling and noise terms alone reject it.
        let n = wobbly.iter().filter(|&&v| v > 0.0).count() as f64;
        let no_floor = SymmetryCheck {
            trefoil_floor: 0.0,
            ..SymmetryCheck::default()
        };
        assert_eq!(
            skew(
                &sums_of(64, &wobbly),
                n,
                (sums_of(64, &wobbly).s[0] as f64, 120.0),
                (6.0, 6.0),
                &no_floor
            ),
            Skew::Trefoil
        );
        // A spot as bright as the disk on its rim, which moves the centroid by about a quarter of a pixel, still is
        // rejected.
        let spotted = wobbly_disk(17.5, 0.0, Some((18.5, 120.0)));
        let mean_x = |w: &[f64]| {
            w.iter()
                .enumerate()
                .map(|(k, v)| (k % 64) as f64 * v)
                .sum::<f64>()
                / w.iter().sum::<f64>()
        };
        let moved = mean_x(&spotted) - mean_x(&wobbly_disk(17.5, 0.0, None));
        assert!(moved > 0.2 && moved < 0.3, "{moved}");
        assert!(rejected(&spotted));
    }

    /// Whether the moment test and, for a trefoil, the second look reject the 64 x 64 `weights`.
    fn rejected_after_a_second_look(weights: &[f64]) -> bool {
        let n = weights.iter().filter(|&&v| v > 0.0).count() as f64;
        let vmax = weights.iter().cloned().fold(0.0, f64::max);
        let check = SymmetryCheck::default();
        let sums = sums_of(64, weights);
        match skew(&sums, n, (sums.s[0] as f64, vmax), (6.0, 6.0), &check) {
            Skew::Within => false,
            Skew::Coma => true,
            Skew::Trefoil => {
                let pixels: Vec<u16> = weights.iter().map(|&v| v.round() as u16).collect();
                let lit = |k: &usize| weights[*k] > 0.0;
                let rows = (0..64 * 64).filter(lit).map(|k| k / 64);
                let cols = (0..64 * 64).filter(lit).map(|k| k % 64);
                let span = |it: &mut dyn Iterator<Item = usize>| {
                    it.fold((usize::MAX, 0), |(lo, hi), x| (lo.min(x), hi.max(x)))
                };
                let (rows, cols) = (span(&mut rows.into_iter()), span(&mut cols.into_iter()));
                trefoil_rejected_on_second_look(
                    &pixels,
                    64,
                    None,
                    rows,
                    cols,
                    (0, u16::MAX),
                    &check,
                )
            }
        }
    }

    #[test]
    fn a_wobbly_outline_is_told_from_a_spot_by_its_five_fold_moment() {
        // A three-fold wobble of 0.2 px on a 35 px disk: a trefoil of about 0.09, beyond the floor.
        let wobbly = wobbly_disk(17.5, 0.2, None);
        let (t, _, a3) = trefoil_and_coma_a3(&sums_of(64, &wobbly)).unwrap();
        let tau_wobbly = (t / a3).sqrt();
        assert!(tau_wobbly > 0.07, "{tau_wobbly}");
        assert!(rejected(&wobbly));
        assert!(!rejected_after_a_second_look(&wobbly));
        // A spot as bright as the disk on the rim of the round one, with a trefoil about as large: rejected.
        let spotted = wobbly_disk(17.5, 0.0, Some((18.5, 130.0)));
        let (t, _, a3) = trefoil_and_coma_a3(&sums_of(64, &spotted)).unwrap();
        let tau_spotted = (t / a3).sqrt();
        assert!(
            (tau_spotted / tau_wobbly - 1.0).abs() < 0.3,
            "{tau_spotted} against {tau_wobbly}"
        );
        assert!(rejected_after_a_second_look(&spotted));
        // Even a wobble of 0.4 px (a trefoil of about 0.18, beyond the ceiling) is no disk.
        assert!(rejected_after_a_second_look(&wobbly_disk(17.5, 0.4, None)));
    }

    #[test]
    fn degenerate_weights_have_no_trefoil() {
        assert_eq!(trefoil_and_coma_a3(&ShapeSums::default()), None);
        // A line.
        let mut line = vec![0.0; 64];
        for k in 0..8 {
            line[k * 8 + k] = 10.0;
        }
        assert_eq!(trefoil_and_coma_a3(&sums_of(8, &line)), None);
    }

    #[test]
    fn the_allowances_grow_with_noise_and_sharpness() {
        let total = |(sampling, noise): (f64, f64)| 7.0 * sampling + noise;
        let blurred = total(allowances(200.0, 200.0 * 120.0, 200.0, 3.0, 24.0));
        let sharp = total(allowances(200.0, 200.0 * 190.0, 200.0, 3.0, 24.0));
        let noisy = total(allowances(200.0, 200.0 * 120.0, 200.0, 30.0, 24.0));
        assert!(
            sharp > 2.0 * blurred && noisy > 2.0 * blurred,
            "{blurred} {sharp} {noisy}"
        );
        // A blurred blob's: the sampling term at its floor.
        let noise = 24.0 * 1.5f64.hypot(12f64.sqrt().recip()) * 200f64.sqrt() / 24_000.0;
        assert!((blurred - (7.0 / 200.0 + noise)).abs() < 1e-12, "{blurred}");
    }
}
