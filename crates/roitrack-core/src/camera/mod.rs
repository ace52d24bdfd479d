//! The camera: pinhole intrinsics with skew and a lens distortion model, in OpenCV's conventions.
//!
//! The lens models ([`Distortion`]: none, plumb_bob, rational_polynomial, equidistant) live in [`lens`], one file
//! each; each acts on the normalised image point `(x, y) = (X/Z, Y/Z)` of a point `(X, Y, Z)` in the camera frame
//! before the intrinsics turn it into pixels.
//!
//! Pixels come in two kinds. *Raw* pixels are what the sensor measures (distorted). *Ideal* pixels are the pinhole
//! projection `u = fx x/z + s y/z + cx`, `v = fy y/z + cy` of the same ray, with the distortion removed. The estimator
//! works in ideal pixels: measured centroids are undistorted once, on arrival.
//!
//! A camera also says when its pixels were exposed ([`TimeModel`]: one ROI at a time, a global or a rolling shutter,
//! and the exposure duration).

use nalgebra::{Matrix2, Vector2, Vector3};
use thiserror::Error;

use crate::time::{TimeModel, TimeModelError};

pub mod lens;

pub use lens::*;

/// Why a camera model is unusable, or why a pixel could not be undistorted.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CameraError {
    /// An intrinsic or a lens coefficient is NaN or infinite.
    #[error("{field} must be a finite number, got {value}")]
    NotFinite {
        /// The intrinsic (`fx`, `fy`, `skew`, `cx`, `cy`) or the lens coefficient (`k1`, `p1`, ...).
        field: &'static str,
        /// The value given (px for an intrinsic).
        value: f64,
    },
    /// A focal length is zero or negative: the camera matrix would not be invertible.
    #[error("{field} must be positive, got {value}")]
    NotPositive {
        /// The focal length: `fx` or `fy`.
        field: &'static str,
        /// The value given (px).
        value: f64,
    },
    /// The image has no pixels.
    #[error("image size must be positive, got {width_px} x {height_px}")]
    EmptyImage {
        /// The image width given (px).
        width_px: u32,
        /// The image height given (px).
        height_px: u32,
    },
    /// The iterative inversion of the lens model found no undistorted point for a raw pixel.
    #[error(
        "undistortion did not converge at raw pixel ({u_px}, {v_px}): the pixel lies outside the region where the \
         distortion model is invertible"
    )]
    UndistortionDiverged {
        /// The raw pixel's column (px).
        u_px: f64,
        /// The raw pixel's row (px).
        v_px: f64,
    },
    /// The camera's time model (exposure, line delay) is out of range.
    #[error("{0}")]
    TimeModel(#[from] TimeModelError),
    /// The image is over [`MAX_IMAGE_SIDE_PX`] a side or [`MAX_IMAGE_PIXELS`] in all.
    #[error(
        "image of {width_px} x {height_px} px: an image is at most {MAX_IMAGE_SIDE_PX} px a side and \
         {MAX_IMAGE_PIXELS} px in all (the largest sensors have under 200 million)"
    )]
    ImageTooLarge {
        /// The image width given (px).
        width_px: u32,
        /// The image height given (px).
        height_px: u32,
    },
    /// An intrinsic that no camera has for its image (see [`CameraModel::new`] for the ranges). Boxed, as the
    /// other details below, so that the error stays small to move.
    #[error("{0}")]
    Implausible(Box<ImplausibleIntrinsic>),
    /// A lens model that is not a lens over its image (see [`check_lens`]).
    #[error("{0}")]
    Lens(Box<LensError>),
}

/// An intrinsic that no camera of its image has ([`CameraError::Implausible`]).
#[derive(Debug, Clone, PartialEq, Error)]
#[error(
    "{field} = {} px is not a camera's for a {width_px} x {height_px} px image: {expected}",
    number(*.value)
)]
pub struct ImplausibleIntrinsic {
    /// `fx`, `fy`, `skew`, `cx` or `cy`.
    pub field: &'static str,
    /// The value given (px).
    pub value: f64,
    /// The width of the image it was given for (px).
    pub width_px: u32,
    /// The height of the image it was given for (px).
    pub height_px: u32,
    /// The range it should be in, and why.
    pub expected: &'static str,
}

/// Why a lens model is not a lens over its image ([`CameraError::Lens`], found by [`check_lens`]); each names the
/// coefficient whose removal most relieves the failure.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LensError {
    /// The lens model is not invertible over the image: along a ray from the principal point, the distorted radius
    /// stops growing (or the map's Jacobian turns singular) before the image's farthest corner, so pixels there have
    /// two undistorted points or none.
    #[error(
        "{coefficient} = {}: the {model} lens model folds back {radius_px:.1} px from the principal point, inside \
         the image (its farthest corner is {corner_px:.1} px away): beyond that its pixels have no single undistorted \
         point, so the model is not invertible over the image (is {coefficient} right? a calibration's polynomial \
         may turn back where it had no points)",
        number(*.value)
    )]
    Folds {
        /// The lens model's name (`plumb_bob`, `rational_polynomial`, `equidistant`).
        model: &'static str,
        /// The coefficient blamed (`k1`, `p2`, ...): the one whose removal most relieves the failure.
        coefficient: &'static str,
        /// That coefficient's value.
        value: f64,
        /// The distance from the principal point (px, distorted) where the model folds back.
        radius_px: f64,
        /// The distance from the principal point to the image's farthest corner (px).
        corner_px: f64,
    },
    /// The lens model does not reach the image's farthest corner before 90° off the axis.
    #[error(
        "{coefficient} = {}: the {model} lens model reaches no further than {radius_px:.1} px from the principal \
         point before 90° off the axis, but the image's farthest corner is {corner_px:.1} px away: pixels beyond \
         have no undistorted point",
        number(*.value)
    )]
    Short {
        /// The lens model's name (`plumb_bob`, `rational_polynomial`, `equidistant`).
        model: &'static str,
        /// The coefficient blamed (`k1`, `p2`, ...): the one whose removal most relieves the failure.
        coefficient: &'static str,
        /// That coefficient's value.
        value: f64,
        /// The farthest distance from the principal point (px, distorted) the model reaches before 90° off the axis.
        radius_px: f64,
        /// The distance from the principal point to the image's farthest corner (px).
        corner_px: f64,
    },
    /// The lens model moves a point of the image by more than its distance from the principal point.
    #[error(
        "{coefficient} = {}: the {model} lens model scales a point {radius_px:.1} px from the principal point \
         by {scale:.3} (a distortion moves points by a fraction of their distance from the centre: its scale stays \
         between 0 and 2 over the image, within 0.5 of 1 for real lenses): not a lens's coefficient",
        number(*.value)
    )]
    TooStrong {
        /// The lens model's name (`plumb_bob`, `rational_polynomial`, `equidistant`).
        model: &'static str,
        /// The coefficient blamed (`k1`, `p2`, ...): the one whose removal most relieves the failure.
        coefficient: &'static str,
        /// That coefficient's value.
        value: f64,
        /// The distance from the principal point (px, distorted) of the point scaled too much.
        radius_px: f64,
        /// The factor by which the model scales that point's distance from the centre (distorted over undistorted).
        scale: f64,
    },
}

impl LensError {
    /// The coefficient named (`k1`, ...).
    pub fn coefficient(&self) -> &'static str {
        match self {
            Self::Folds { coefficient, .. }
            | Self::Short { coefficient, .. }
            | Self::TooStrong { coefficient, .. } => coefficient,
        }
    }
}

/// `v` for a message: plain between 1e-4 and 1e9, else in exponent form (`1e-300`, not 300 zeros).
fn number(v: f64) -> String {
    if v == 0.0 || (1e-4..1e9).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// The largest image side (px) a camera may have: 65,536, four times the widest sensors'.
pub const MAX_IMAGE_SIDE_PX: u32 = 1 << 16;
/// The most pixels an image may have: 2^28 (268 million; the largest sensors have about 150 million), so that a
/// 16-bit frame stays within 512 MiB.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;
/// The longest focal length (px) a camera may have: 1e8, a 100 m focal length over 1 µm pixels (a large telescope's).
pub const MAX_FOCAL_PX: f64 = 1e8;
/// How far off the optical axis (as the tangent of the angle, in normalised units) a pinhole of the given focal
/// lengths may see the image's corners: 100 is 89.4°. A shorter focal length makes every pixel a sliver of the last
/// degree before 90°, which no lens does.
pub const MAX_CORNER_NORMALISED_RADIUS: f64 = 100.0;

/// Pinhole intrinsics (pixels): the camera matrix `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeIntrinsics {
    /// Horizontal focal length (px): pixels per unit of normalised `x`.
    pub fx_px: f64,
    /// Vertical focal length (px): pixels per unit of normalised `y`.
    pub fy_px: f64,
    /// Skew (px): how much of normalised `y` enters `u`; 0 for square pixel axes.
    pub skew_px: f64,
    /// Principal point's column (px): where the optical axis meets the image.
    pub cx_px: f64,
    /// Principal point's row (px).
    pub cy_px: f64,
}

impl PinholeIntrinsics {
    /// Checks that the intrinsics are finite with positive focal lengths (so the camera matrix is invertible).
    pub fn validate(&self) -> Result<(), CameraError> {
        for (field, value) in [
            ("fx", self.fx_px),
            ("fy", self.fy_px),
            ("skew", self.skew_px),
            ("cx", self.cx_px),
            ("cy", self.cy_px),
        ] {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { field, value });
            }
        }
        for (field, value) in [("fx", self.fx_px), ("fy", self.fy_px)] {
            if value <= 0.0 {
                return Err(CameraError::NotPositive { field, value });
            }
        }
        Ok(())
    }

    /// Ideal pixel of a normalised image point (x/z, y/z).
    #[inline]
    pub fn pixel_from_normalized(&self, n: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(
            self.fx_px * n.x + self.skew_px * n.y + self.cx_px,
            self.fy_px * n.y + self.cy_px,
        )
    }

    /// Normalised image point of an ideal pixel (the inverse of [`Self::pixel_from_normalized`]).
    #[inline]
    pub fn normalized_from_pixel(&self, p: &Vector2<f64>) -> Vector2<f64> {
        let y = (p.y - self.cy_px) / self.fy_px;
        Vector2::new((p.x - self.cx_px - self.skew_px * y) / self.fx_px, y)
    }

    /// Ideal pixel of a point in the camera frame, or `None` if it is not in front of the camera.
    #[inline]
    pub fn pixel_from_cam(&self, point_in_cam: &Vector3<f64>) -> Option<Vector2<f64>> {
        if point_in_cam.z <= 0.0 || !point_in_cam.z.is_finite() {
            return None;
        }
        let inv_z = 1.0 / point_in_cam.z;
        Some(self.pixel_from_normalized(&Vector2::new(
            point_in_cam.x * inv_z,
            point_in_cam.y * inv_z,
        )))
    }

    /// d(u, v)/d(point in camera frame), the paper's eq. 24, at a point with z > 0.
    #[inline]
    pub fn pixel_jacobian_wrt_cam(&self, p: &Vector3<f64>) -> nalgebra::Matrix2x3<f64> {
        let inv_z = 1.0 / p.z;
        let xz = p.x * inv_z;
        let yz = p.y * inv_z;
        // [[fx, s], [0, fy]] * [[1/z, 0, -x/z²], [0, 1/z, -y/z²]]
        nalgebra::Matrix2x3::new(
            self.fx_px * inv_z,
            self.skew_px * inv_z,
            -(self.fx_px * xz + self.skew_px * yz) * inv_z,
            0.0,
            self.fy_px * inv_z,
            -self.fy_px * yz * inv_z,
        )
    }
}

/// The image's corners (pixel edges, at -0.5 and size - 0.5) in normalised (distorted) coordinates.
fn corners_normalised(k: &PinholeIntrinsics, width_px: u32, height_px: u32) -> [Vector2<f64>; 4] {
    let (w, h) = (f64::from(width_px) - 0.5, f64::from(height_px) - 0.5);
    [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h)]
        .map(|(u, v)| k.normalized_from_pixel(&Vector2::new(u, v)))
}

/// Refuses intrinsics that no camera of a `width_px` x `height_px` image has (see [`CameraModel::new`]).
fn check_intrinsics(
    k: &PinholeIntrinsics,
    width_px: u32,
    height_px: u32,
) -> Result<(), CameraError> {
    let implausible = |field, value, expected| {
        CameraError::Implausible(Box::new(ImplausibleIntrinsic {
            field,
            value,
            width_px,
            height_px,
            expected,
        }))
    };
    let (w, h) = (f64::from(width_px), f64::from(height_px));
    let half_diagonal_px = 0.5 * w.hypot(h);
    for (field, f) in [("fx", k.fx_px), ("fy", k.fy_px)] {
        if f > MAX_FOCAL_PX {
            return Err(implausible(
                field,
                f,
                "a focal length is at most 1e8 px (a 100 m focal length over 1 µm pixels)",
            ));
        }
        if half_diagonal_px / f > MAX_CORNER_NORMALISED_RADIUS {
            return Err(implausible(
                field,
                f,
                "a focal length is at least a hundredth of the image's half-diagonal (else a pinhole would see its \
                 corner more than 89.4° off the axis)",
            ));
        }
    }
    if !(0.1..=10.0).contains(&(k.fy_px / k.fx_px)) {
        return Err(implausible(
            "fy",
            k.fy_px,
            "fy is within a factor of 10 of fx (pixels are near square)",
        ));
    }
    if k.skew_px.abs() > 0.1 * k.fx_px {
        return Err(implausible(
            "skew",
            k.skew_px,
            "the skew is at most a tenth of fx (pixel axes within 6° of square; real sensors have under 0.1 px)",
        ));
    }
    for (field, c, size) in [("cx", k.cx_px, w), ("cy", k.cy_px, h)] {
        if !(-0.5 * size..=1.5 * size).contains(&c) {
            return Err(implausible(
                field,
                c,
                "the principal point is at most half the image's size beyond its edge (a calibration of a larger \
                 image than this one?)",
            ));
        }
    }
    Ok(())
}

/// How many rays from the principal point [`check_lens`] follows: a lens's tangential terms vary as twice the
/// azimuth, so 32 rays sample them every 11.25°.
const LENS_CHECK_RAYS: usize = 32;

/// Checks that `distortion` is a lens over the image of `k`, `width_px` x `height_px`: along rays from the principal
/// point (undistorted directions, every 360° / 32), the undistorted point `n` walking out from the axis to 90° off it,
/// until its distorted point is beyond the image's farthest corner, the model must
///
/// 1. keep the distorted radius growing and its Jacobian's determinant positive: invertible over the image (each of
///    its pixels has one undistorted point). Where it folds back, [`LensError::Folds`];
/// 2. reach the image's farthest corner before 90° off the axis ([`LensError::Short`]), except the
///    equidistant model, whose normalised plane ends at 90°: a fisheye's image may extend beyond (its dark corners);
/// 3. move the point by less than its distance from the centre, `|d(n) - n| < |n|`: a scale between 0 and 2, the
///    symmetric bound of the barrel side's (below 0 a point would cross the centre). Real lenses stay within about
///    0.5 of 1; beyond 2 the "distortion" is most of the projection ([`LensError::TooStrong`]).
///
/// The rays are sampled finely near the axis (where large coefficients act first) and every 0.06° beyond. The
/// coefficient named is the one whose removal most relieves the failure where it is found.
///
/// ```
/// use roitrack_core::camera::{CameraModel, Distortion, PlumbBob, check_lens};
///
/// let k = CameraModel::canonical().intrinsics;
/// // A barrel lens whose radial map r (1 - 0.5 r²) turns back at r = 0.82, at a distorted radius of 0.54 (816 px
/// // at fx = 1500): fine for the 1024 px image, whose farthest corner is 724 px from (512, 512), not for 2048 px.
/// let lens = Distortion::from(PlumbBob::from_coefficients([-0.5, 0.0, 0.0, 0.0, 0.0]));
/// assert!(check_lens(&k, &lens, 1024, 1024).is_ok());
/// assert!(check_lens(&k, &lens, 2048, 2048).unwrap_err().to_string().starts_with("k1 = -0.5: the plumb_bob"));
/// ```
pub fn check_lens(
    k: &PinholeIntrinsics,
    distortion: &Distortion,
    width_px: u32,
    height_px: u32,
) -> Result<(), CameraError> {
    if distortion.is_identity() {
        return Ok(());
    }
    let corner = corners_normalised(k, width_px, height_px)
        .iter()
        .map(|c| c.norm())
        .fold(0.0, f64::max);
    let radius_px =
        |d: &Vector2<f64>| (k.pixel_from_normalized(d) - Vector2::new(k.cx_px, k.cy_px)).norm();
    let corner_px = corners_normalised(k, width_px, height_px)
        .iter()
        .map(&radius_px)
        .fold(0.0, f64::max);
    let model = distortion.model_name();
    // The angles off the axis (rad) sampled: geometric from 1e-6 rad to 1e-3 rad, then every 1e-3 rad (0.06°) to
    // within 1e-3 rad of 90°.
    let near_axis = (0..)
        .map(|i| 1e-6 * 1.1f64.powi(i))
        .take_while(|&a| a < 1e-3);
    let beyond = (0..)
        .map(|i| 1e-3 * f64::from(i + 1))
        .take_while(|&a| a < std::f64::consts::FRAC_PI_2 - 1e-3);
    let angles: Vec<f64> = near_axis.chain(beyond).collect();
    for ray in 0..LENS_CHECK_RAYS {
        let azimuth = std::f64::consts::TAU * ray as f64 / LENS_CHECK_RAYS as f64;
        let direction = Vector2::new(azimuth.cos(), azimuth.sin());
        let mut reached = 0.0f64;
        let mut covered = false;
        for &angle in &angles {
            let n = direction * angle.tan();
            let (d, j) = distortion.distort_with_jacobian(&n);
            let d_norm = d.norm();
            // d|d|/dr along the ray, and the map's local orientation.
            let radial_slope = if d_norm > 0.0 {
                d.dot(&(j * direction)) / d_norm
            } else {
                0.0
            };
            if !(radial_slope > 0.0 && j.determinant() > 0.0 && d_norm > reached) {
                let (coefficient, value) = blame(distortion, |lens| {
                    let (d, j) = lens.distort_with_jacobian(&n);
                    let slope = d.dot(&(j * direction)) / d.norm().max(f64::MIN_POSITIVE);
                    slope.min(j.determinant())
                });
                return Err(lens_error(LensError::Folds {
                    model,
                    coefficient,
                    value,
                    radius_px: radius_px(&d).min(corner_px),
                    corner_px,
                }));
            }
            let scale_error = (d - n).norm() / n.norm();
            if scale_error >= 1.0 {
                let (coefficient, value) =
                    blame(distortion, |lens| -(lens.distort(&n) - n).norm() / n.norm());
                return Err(lens_error(LensError::TooStrong {
                    model,
                    coefficient,
                    value,
                    radius_px: radius_px(&d),
                    scale: d_norm / n.norm(),
                }));
            }
            reached = d_norm;
            if d_norm >= corner {
                covered = true;
                break;
            }
        }
        if !covered && !distortion.ends_at_90_degrees() {
            let n = direction * angles.last().copied().unwrap_or(1.0).tan();
            let (coefficient, value) = blame(distortion, |lens| lens.distort(&n).norm());
            return Err(lens_error(LensError::Short {
                model,
                coefficient,
                value,
                radius_px: radius_px(&distortion.distort(&n)),
                corner_px,
            }));
        }
    }
    Ok(())
}

fn lens_error(error: LensError) -> CameraError {
    CameraError::Lens(Box::new(error))
}

/// The coefficient of `distortion` (name and value) whose removal raises `goodness` the most: the one to blame for
/// a failure found where `goodness` is evaluated.
fn blame(distortion: &Distortion, goodness: impl Fn(&Distortion) -> f64) -> (&'static str, f64) {
    let names = distortion.coefficient_names();
    let values = distortion.coefficients();
    let base = goodness(distortion);
    let mut best = (
        names.first().copied().unwrap_or("distortion"),
        values.first().copied().unwrap_or(0.0),
    );
    let mut best_gain = f64::NEG_INFINITY;
    for (i, (&name, &value)) in names.iter().zip(&values).enumerate() {
        if value == 0.0 {
            continue;
        }
        let mut without = values.clone();
        without[i] = 0.0;
        let gain = goodness(&distortion.with_coefficients(&without)) - base;
        // NaN (a map that overflowed without it) counts as no gain.
        if gain > best_gain {
            best_gain = gain;
            best = (name, value);
        }
    }
    best
}

/// A calibrated camera: image size, pinhole intrinsics, a lens distortion model, and when its pixels are exposed.
///
/// ```
/// use nalgebra::{Vector2, Vector3};
/// use roitrack_core::CameraModel;
/// use roitrack_core::time::{Readout, TimeModel};
///
/// let camera = CameraModel::canonical();
/// let px = camera.raw_pixel_from_cam(&Vector3::new(0.01, -0.02, 0.6)).unwrap();
/// assert!((px - Vector2::new(537.0, 462.0)).norm() < 1e-9);
/// // A rolling-shutter version of the same camera, 20 µs a row, 1 ms exposure.
/// let rolling = camera
///     .with_time_model(TimeModel { readout: Readout::RollingShutter { line_delay_s: 20e-6 }, exposure_s: 1e-3 })
///     .unwrap();
/// assert!(rolling.time.is_rolling());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    /// The camera's name (from its calibration file), for messages and outputs.
    pub name: String,
    /// Image width (px).
    pub width_px: u32,
    /// Image height (px).
    pub height_px: u32,
    /// The pinhole camera matrix: ideal pixels of normalised image points.
    pub intrinsics: PinholeIntrinsics,
    /// The lens model: raw (distorted) normalised points of ideal ones.
    pub distortion: Distortion,
    /// When each blob is exposed (default: sequential ROIs, 100 µs).
    pub time: TimeModel,
}

impl CameraModel {
    /// Builds a camera, refusing what no camera has:
    ///
    /// - a non-finite value, a non-positive focal length, an empty image, an image over [`MAX_IMAGE_SIDE_PX`] a side
    ///   or [`MAX_IMAGE_PIXELS`] in all;
    /// - focal lengths over [`MAX_FOCAL_PX`], or so short that the image's corner would be more than
    ///   [`MAX_CORNER_NORMALISED_RADIUS`] (89.4°) off the axis of a pinhole; `fy` more than 10 times `fx` or less than
    ///   a tenth of it; a skew over a tenth of `fx` (pixel axes more than 6° from square); a principal point more
    ///   than half the image's size beyond its edge;
    /// - a lens model that is not invertible over the image ([`CameraError::Lens`]: [`LensError::Folds`],
    ///   [`LensError::Short`]) or that scales a point of the image by a factor outside (0, 2)
    ///   ([`LensError::TooStrong`]), checked along 32 rays from the principal point out to the image's
    ///   farthest corner (see [`check_lens`]).
    ///
    /// ```
    /// use roitrack_core::camera::{CameraError, CameraModel, LensError, PlumbBob};
    ///
    /// let k = CameraModel::canonical().intrinsics;
    /// assert!(CameraModel::new("ok", 1024, 1024, k, PlumbBob::from_coefficients([-0.2, 0.05, 0.0, 0.0, 0.0])).is_ok());
    /// // k1 = -1e6 folds back a fraction of a pixel from the centre; k1 = 1e6 scales the image 60 times.
    /// let folds = CameraModel::new("x", 1024, 1024, k, PlumbBob::from_coefficients([-1e6, 0.0, 0.0, 0.0, 0.0]));
    /// assert!(matches!(folds, Err(CameraError::Lens(e)) if matches!(*e, LensError::Folds { coefficient: "k1", .. })));
    /// let strong = CameraModel::new("x", 1024, 1024, k, PlumbBob::from_coefficients([1e6, 0.0, 0.0, 0.0, 0.0]));
    /// assert!(matches!(strong, Err(CameraError::Lens(e)) if matches!(*e, LensError::TooStrong { coefficient: "k1", .. })));
    /// ```
    pub fn new(
        name: impl Into<String>,
        width_px: u32,
        height_px: u32,
        intrinsics: PinholeIntrinsics,
        distortion: impl Into<Distortion>,
    ) -> Result<Self, CameraError> {
        let distortion = distortion.into();
        if width_px == 0 || height_px == 0 {
            return Err(CameraError::EmptyImage {
                width_px,
                height_px,
            });
        }
        if width_px > MAX_IMAGE_SIDE_PX
            || height_px > MAX_IMAGE_SIDE_PX
            || u64::from(width_px) * u64::from(height_px) > MAX_IMAGE_PIXELS
        {
            return Err(CameraError::ImageTooLarge {
                width_px,
                height_px,
            });
        }
        intrinsics.validate()?;
        check_intrinsics(&intrinsics, width_px, height_px)?;
        distortion.validate()?;
        check_lens(&intrinsics, &distortion, width_px, height_px)?;
        Ok(Self {
            name: name.into(),
            width_px,
            height_px,
            intrinsics,
            distortion,
            time: TimeModel::default(),
        })
    }

    /// The same camera with another time model (refused if invalid).
    pub fn with_time_model(self, time: TimeModel) -> Result<Self, CameraError> {
        time.validate()?;
        Ok(Self { time, ..self })
    }

    /// The built-in camera (docs/model.md): 1024 x 1024 px, fx = fy = 1500, no skew, centre (512, 512), no distortion.
    pub fn canonical() -> Self {
        Self {
            name: "roitrack_canonical".to_string(),
            width_px: 1024,
            height_px: 1024,
            intrinsics: PinholeIntrinsics {
                fx_px: 1500.0,
                fy_px: 1500.0,
                skew_px: 0.0,
                cx_px: 512.0,
                cy_px: 512.0,
            },
            distortion: Distortion::default(),
            time: TimeModel::default(),
        }
    }

    /// A strongly distorting but realistic 1024 x 1024 wide-angle lens (an industrial lens calibrated with OpenCV:
    /// k1 = -0.28, skew 0.8 px), for exercising the distortion paths in tests and benchmarks.
    pub fn wide_angle_example() -> Self {
        Self {
            name: "wide".to_string(),
            width_px: 1024,
            height_px: 1024,
            intrinsics: PinholeIntrinsics {
                fx_px: 1480.0,
                fy_px: 1510.0,
                skew_px: 0.8,
                cx_px: 515.0,
                cy_px: 506.0,
            },
            distortion: PlumbBob::from_coefficients([-0.28, 0.12, 1.2e-3, -8e-4, -0.03]).into(),
            time: TimeModel::default(),
        }
    }

    /// Raw (distorted) pixel of a point in the camera frame, or `None` if it is behind the camera.
    pub fn raw_pixel_from_cam(&self, point_in_cam: &Vector3<f64>) -> Option<Vector2<f64>> {
        if point_in_cam.z <= 0.0 || !point_in_cam.z.is_finite() {
            return None;
        }
        let n = Vector2::new(
            point_in_cam.x / point_in_cam.z,
            point_in_cam.y / point_in_cam.z,
        );
        Some(
            self.intrinsics
                .pixel_from_normalized(&self.distortion.distort(&n)),
        )
    }

    /// Raw (distorted) pixel of a point in the camera frame and its 2x3 Jacobian with respect to that point, or `None`
    /// if the point is not in front of the camera.
    ///
    /// ```
    /// use nalgebra::Vector3;
    /// use roitrack_core::CameraModel;
    ///
    /// let camera = CameraModel::wide_angle_example();
    /// let p = Vector3::new(0.05, -0.03, 0.6);
    /// let (px, jacobian) = camera.raw_pixel_with_jacobian_wrt_cam(&p).unwrap();
    /// assert_eq!(Some(px), camera.raw_pixel_from_cam(&p));
    /// let dz = Vector3::new(0.0, 0.0, 1e-6);
    /// let moved = camera.raw_pixel_from_cam(&(p + dz)).unwrap();
    /// assert!((moved - px - jacobian * dz).norm() < 1e-9);
    /// ```
    pub fn raw_pixel_with_jacobian_wrt_cam(
        &self,
        point_in_cam: &Vector3<f64>,
    ) -> Option<(Vector2<f64>, nalgebra::Matrix2x3<f64>)> {
        let z = point_in_cam.z;
        if z <= 0.0 || !z.is_finite() {
            return None;
        }
        let inv_z = 1.0 / z;
        // Divided as in raw_pixel_from_cam, so that both give the same pixel to the bit.
        let n = Vector2::new(point_in_cam.x / z, point_in_cam.y / z);
        let (distorted, jd) = self.distortion.distort_with_jacobian(&n);
        let k = &self.intrinsics;
        let dn_dp = nalgebra::Matrix2x3::new(inv_z, 0.0, -n.x * inv_z, 0.0, inv_z, -n.y * inv_z);
        let dk = Matrix2::new(k.fx_px, k.skew_px, 0.0, k.fy_px);
        Some((k.pixel_from_normalized(&distorted), dk * jd * dn_dp))
    }

    /// Raw (distorted) pixel of an ideal pixel.
    pub fn distort_pixel(&self, ideal: &Vector2<f64>) -> Vector2<f64> {
        let n = self.intrinsics.normalized_from_pixel(ideal);
        self.intrinsics
            .pixel_from_normalized(&self.distortion.distort(&n))
    }

    /// Ideal (undistorted) pixel of a raw measured pixel.
    pub fn undistort_pixel(&self, raw: &Vector2<f64>) -> Result<Vector2<f64>, CameraError> {
        let distorted = self.intrinsics.normalized_from_pixel(raw);
        match self.distortion.undistort(&distorted) {
            Some(n) => Ok(self.intrinsics.pixel_from_normalized(&n)),
            None => Err(CameraError::UndistortionDiverged {
                u_px: raw.x,
                v_px: raw.y,
            }),
        }
    }

    /// Whether a raw pixel lies on the sensor (pixel centres at integer coordinates, edges at -0.5 and size - 0.5).
    pub fn contains_raw_pixel(&self, raw: &Vector2<f64>) -> bool {
        raw.x >= -0.5
            && raw.y >= -0.5
            && raw.x <= self.width_px as f64 - 0.5
            && raw.y <= self.height_px as f64 - 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistortion_round_trip_over_the_whole_image() {
        let camera = CameraModel::wide_angle_example();
        let mut worst_px: f64 = 0.0;
        for i in 0..=64 {
            for j in 0..=64 {
                let raw = Vector2::new(i as f64 * 1023.0 / 64.0, j as f64 * 1023.0 / 64.0);
                let ideal = camera.undistort_pixel(&raw).unwrap();
                worst_px = worst_px.max((camera.distort_pixel(&ideal) - raw).norm());
                // And the other way round, starting from an ideal pixel.
                let raw2 = camera.distort_pixel(&raw);
                worst_px = worst_px.max((camera.undistort_pixel(&raw2).unwrap() - raw).norm());
            }
        }
        assert!(worst_px < 1e-6, "worst round trip error {worst_px} px");
    }

    #[test]
    fn skew_sits_in_u_only() {
        let k = CameraModel::wide_angle_example().intrinsics;
        let p = Vector3::new(0.1, 0.2, 1.0);
        let px = k.pixel_from_cam(&p).unwrap();
        assert!((px.x - (1480.0 * 0.1 + 0.8 * 0.2 + 515.0)).abs() < 1e-12);
        assert!((px.y - (1510.0 * 0.2 + 506.0)).abs() < 1e-12);
        assert!((k.normalized_from_pixel(&px) - Vector2::new(0.1, 0.2)).norm() < 1e-15);
    }

    #[test]
    fn pixel_jacobian_matches_central_differences() {
        use rand::Rng;
        let k = CameraModel::wide_angle_example().intrinsics;
        roitrack_testkit::check_jacobian(
            "pixel_jacobian_wrt_cam",
            Vector3::new(0.0, 0.0, 0.6),
            |rng, spread| {
                let off_axis = Vector3::new(
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                    0.0,
                );
                Vector3::new(0.0, 0.0, rng.random_range(0.2..2.0)) + spread * off_axis
            },
            &Vector3::repeat(1.0),
            |p, delta| k.pixel_from_cam(&(p + delta)).unwrap(),
            |p| k.pixel_jacobian_wrt_cam(p),
        );
    }

    #[test]
    fn invalid_cameras_are_refused() {
        let mut k = CameraModel::canonical().intrinsics;
        k.fx_px = 0.0;
        assert!(matches!(
            CameraModel::new("x", 10, 10, k, PlumbBob::default()),
            Err(CameraError::NotPositive { field: "fx", .. })
        ));
        k.fx_px = f64::NAN;
        assert!(matches!(
            CameraModel::new("x", 10, 10, k, PlumbBob::default()),
            Err(CameraError::NotFinite { field: "fx", .. })
        ));
        let k = CameraModel::canonical().intrinsics;
        assert!(CameraModel::new("x", 0, 10, k, PlumbBob::default()).is_err());
    }

    #[test]
    fn points_behind_the_camera_do_not_project() {
        let camera = CameraModel::canonical();
        assert!(
            camera
                .raw_pixel_from_cam(&Vector3::new(0.0, 0.0, -1.0))
                .is_none()
        );
        assert!(
            camera
                .intrinsics
                .pixel_from_cam(&Vector3::new(0.0, 0.0, 0.0))
                .is_none()
        );
    }
}
