//! Synthetic photographs of a planar circle target: a printed board of flat disks seen by a real camera (perspective
//! and lens distortion), lying in a cluttered scene under uneven light, with blur, noise and quantisation, and the
//! true centre of every circle. For testing the detection of targets in full photographs without real photos.
//!
//! Pure: no I/O, no threads; the same scene (seed included) gives the same photograph, bit for bit.
//!
//! # The scene
//!
//! The target's points lie on a plane (a [`Target`] that is not planar is refused). Each point carries a circle: a
//! flat disk of its diameter ([`TargetPoint::diameter_m`], [`PhotoScene::default_diameter_m`] when it has none)
//! centred on it, in the target's plane. The circles are printed on a rectangular board (the paper) in the same plane,
//! axis-aligned with the target's object x axis projected on the plane (its y axis when x is normal to the plane),
//! reaching [`PhotoScene::paper_margin_m`] beyond the outermost circle edges. Outside the board lies the
//! [`Background`], seen through the image plane (a flat level or a random texture), with [`Clutter`] drawn on it:
//! random dark and bright disks, ellipses, strokes, rectangles and text-like marks. The board hides whatever lies
//! behind it, so clutter never covers the board; optional printed marks on the paper ([`Clutter::board_marks`]) stay
//! in its margin, at least [`Clutter::board_mark_gap_m`] away from every circle.
//!
//! # Rendering
//!
//! 1. **Rays.** Every pixel *corner* of the image (and of a margin for the blur) is undistorted to a ray by Newton's
//!    method on the camera's plumb_bob distortion (to 1e-12 px); inside a pixel the ray is the bilinear interpolation
//!    of its corners' (exact without distortion; with a strong lens, k1 = -0.25 to -0.28, it is off by at most 1e-4
//!    to 3e-4 px, in the image's corners). Pixel (i, j) is centred on the raw pixel (u, v) = (i, j), OpenCV's
//!    convention.
//! 2. **Coverage.** A ray meets the target's plane at the in-plane point `q = H⁻¹ (x, y, 1)`, dehomogenised, with
//!    `H = [e1 e2 C]` the plane's axes and origin in the camera frame (`q₂ > 0`: in front of the camera). A pixel's
//!    samples lie in the convex hull of its corners' plane points, so the corners classify it: wholly off the board,
//!    wholly on paper, wholly inside one circle, or crossed by an edge. Only crossed pixels are supersampled
//!    ([`PhotoScene::supersampling`]² samples), each sample intersected exactly with the plane and tested against the
//!    board and the circles. A pixel's value is its area coverage: board reflectance where the board is, the
//!    background's where it is not.
//! 3. **Light.** Reflectance times illumination (a linear gradient across the image, cos⁴ vignetting of the ray's
//!    angle off the axis, a soft-edged shadow polygon), plus an additive glare spot.
//! 4. **Sensor.** A separable Gaussian blur ([`PhotoScene::blur_sigma_px`]), Gaussian read noise and optional shot
//!    noise, optional JPEG-like 8 x 8 DCT quantisation, then rounding and clipping to the bit depth.
//!
//! The truth ([`PhotoPoint`]) is the raw (distorted) pixel of each circle's *centre*, `camera.raw_pixel_from_cam(R p +
//! t)`, and the area centroid of its image: perspective moves the centroid of a tilted circle's image away from the
//! centre's image (the near half looks bigger), by tenths of a pixel for circles tens of pixels across.
//!
//! ```
//! use nalgebra::Rotation3;
//! use roitrack_core::target::{CircleGrid, GridLayout};
//! use roitrack_core::{CameraModel, Target};
//! use roitrack_sim::photo::{PhotoScene, render_photo};
//!
//! let spec = CircleGrid { rows: 4, cols: 5, spacing_m: 0.03, diameter_m: 0.012, layout: GridLayout::Square };
//! let target = Target::circle_grid(&spec).unwrap();
//! let tilt = Rotation3::from_euler_angles(0.3, -0.2, 0.1);
//! let scene = PhotoScene::facing(CameraModel::canonical(), target, 0.8, tilt).harsh();
//! let photo = render_photo(&scene).unwrap();
//! assert_eq!(photo.frame.pixels.len(), 1024 * 1024);
//! assert!(photo.truth.iter().all(|p| p.fully_visible));
//! ```

mod background;
mod board;
mod clutter;
mod light;
mod rays;
mod scene;
mod sensor;
#[cfg(test)]
mod tests;
mod truth;

pub use background::Background;
pub use clutter::Clutter;
pub use light::{Glare, Illumination, Shadow};
pub use scene::{CircleShade, DEFAULT_CIRCLE_DIAMETER_M, PhotoScene};

use nalgebra::Vector2;
use roitrack_core::CameraError;
use roitrack_image::Frame;
use thiserror::Error;

use background::background_layer;
use board::Board;
use light::Light;
use rays::{Area, corner_rays};
use sensor::{add_noise, blur, jpeg_like};
use truth::truth;

#[cfg(doc)]
use roitrack_core::{Target, TargetPoint};

/// Largest image rendered (pixels): 32 Mpx (rendering takes about 80 bytes a pixel at its peak).
const MAX_PIXELS: u64 = 1 << 25;

/// Streams of the scene's random generator: each part draws from its own, so that turning one on or off leaves the
/// others unchanged.
const NOISE_STREAM: u64 = 1;
const CLUTTER_STREAM: u64 = 2;
const MARKS_STREAM: u64 = 3;

/// Why a scene cannot be rendered.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PhotoError {
    /// The target's points do not lie in one plane.
    #[error("the target is not planar: its circles need a plane to lie in")]
    NotPlanar,
    /// Every corner of the board is behind the camera.
    #[error("the board is behind the camera (every corner at z <= 0)")]
    BoardBehindCamera,
    /// The bit depth asked for is not 8 to 16.
    #[error("bit depth must be 8 to 16, got {0}")]
    BitDepth(u8),
    /// A scene parameter is out of its range or not finite.
    #[error("{field} must be {expected}, got {value}")]
    InvalidParameter {
        /// The parameter's name.
        field: &'static str,
        /// The value given.
        value: f64,
        /// The range it must be in, in words.
        expected: &'static str,
    },
    /// The camera's image has more than `MAX_PIXELS` pixels.
    #[error(
        "an image of {width_px} x {height_px} px is too large to render (at most {MAX_PIXELS} px)"
    )]
    ImageTooLarge {
        /// The image's width (px).
        width_px: u32,
        /// The image's height (px).
        height_px: u32,
    },
    /// The camera model is invalid.
    #[error("camera: {0}")]
    Camera(#[from] CameraError),
}

/// A rendered photograph and the truth about its circles.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedPhoto {
    /// The photograph: the camera's size, the scene's bit depth and time.
    pub frame: Frame,
    /// One entry per target point, in the order of [`Target::points`].
    pub truth: Vec<PhotoPoint>,
}

/// The truth about one circle of a photograph.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_sim::photo::{PhotoScene, render_photo};
/// let scene = PhotoScene::new(CameraModel::canonical(), Target::grid4x4(), Rotation3::identity(), Vector3::new(0.0, 0.0, 0.5));
/// let p = &render_photo(&scene).unwrap().truth[5];
/// assert_eq!(p.id, 5);
/// let expected = scene.camera.raw_pixel_from_cam(&Vector3::new(-0.01, -0.01, 0.5)).unwrap();
/// assert!((p.centre_px.unwrap() - expected).norm() < 1e-9);
/// assert!(p.fully_visible);
/// assert!((p.diameter_px.unwrap() - 1500.0 * 0.006 / 0.5).abs() < 1e-3);
/// // Facing the camera squarely, without distortion: the image is centred on the centre's image.
/// assert!((p.area_centroid_px.unwrap() - expected).norm() < 1e-9);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoPoint {
    /// The target point's id.
    pub id: u32,
    /// Raw (distorted) pixel of the circle's centre, `camera.raw_pixel_from_cam(R p + t)`; `None` if the centre is
    /// not in front of the camera. May lie outside the image.
    pub centre_px: Option<Vector2<f64>>,
    /// Whether the whole circle is in front of the camera and its image inside the image's bounds (pixel edges, from
    /// -0.5 to size - 0.5), judged on 128 rim points.
    pub fully_visible: bool,
    /// Mean diameter of the circle's image (px): twice the mean distance from `centre_px` to the images of 128 rim
    /// points; `None` unless the whole circle is in front of the camera.
    pub diameter_px: Option<f64>,
    /// Area centroid of the circle's image (raw pixels, by quadrature): what an unbiased blob centroid measures. It
    /// is not `centre_px`: the near half of a tilted circle looks bigger, which moves the centroid towards it, by
    /// 0.1-0.2 px for circles 25-30 px across tilted by 30-40° (growing as the square of the size), and lens
    /// distortion adds its own shift; they agree for a fronto-parallel circle without distortion. `None` unless the
    /// whole circle is in front of the camera.
    pub area_centroid_px: Option<Vector2<f64>>,
}

/// Renders the photograph of `scene` (see the module documentation). Errors: an invalid parameter, a target that is
/// not planar, a board wholly behind the camera, or a pixel the camera's distortion cannot undistort.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_sim::photo::{PhotoError, PhotoScene, render_photo};
///
/// let camera = CameraModel::wide_angle_example();
/// let mut scene = PhotoScene::new(camera, Target::grid4x4(), Rotation3::identity(), Vector3::new(0.0, 0.0, 0.5));
/// let photo = render_photo(&scene).unwrap();
/// let frame = &photo.frame;
/// assert_eq!((frame.width, frame.height, frame.bit_depth), (1024, 1024, 8));
/// // Paper between the circles, the background far away.
/// let paper = frame.pixels[frame.index(512, 512)];
/// assert_eq!(paper, (0.85_f64 * 255.0).round() as u16);
/// assert_eq!(frame.pixels[frame.index(5, 5)], (0.32_f64 * 255.0).round() as u16);
///
/// scene.cam_t_obj_m.z = -0.5;
/// assert_eq!(render_photo(&scene), Err(PhotoError::BoardBehindCamera));
/// ```
pub fn render_photo(scene: &PhotoScene) -> Result<RenderedPhoto, PhotoError> {
    scene.validate()?;
    let board = Board::new(scene)?;
    let (w, h) = (
        scene.camera.width_px as usize,
        scene.camera.height_px as usize,
    );
    let kernel = crate::render::gaussian_kernel(scene.blur_sigma_px);
    let area = Area {
        margin: kernel.len() / 2,
        width: w + kernel.len() - 1,
        height: h + kernel.len() - 1,
    };
    let rays = corner_rays(&scene.camera, &area)?;
    let n = area.width * area.height;
    let mut board_level = vec![0.0; n];
    let mut background_fraction = vec![1.0; n];
    board.rasterise(
        &rays,
        &area,
        scene.supersampling as usize,
        &mut board_level,
        &mut background_fraction,
    );
    let background = background_layer(scene, &area, &background_fraction);
    let light = Light::new(&scene.illumination, w, h);
    let cw = area.width + 1;
    let mut radiance = board_level;
    for j in 0..area.height {
        let v = area.raw(j);
        for i in 0..area.width {
            let k = j * area.width + i;
            let c = j * cw + i;
            let ray = [
                0.25 * (rays[c][0] + rays[c + 1][0] + rays[c + cw][0] + rays[c + cw + 1][0]),
                0.25 * (rays[c][1] + rays[c + 1][1] + rays[c + cw][1] + rays[c + cw + 1][1]),
            ];
            let u = area.raw(i);
            let reflectance = radiance[k] + background_fraction[k] * background[k];
            radiance[k] = reflectance * light.factor(u, v, ray) + light.glare(u, v);
        }
    }
    let mut values = blur(&radiance, &area, &kernel, w, h);
    add_noise(&mut values, scene);
    let full_scale = f64::from((1u32 << scene.bit_depth) - 1);
    let pixels: Vec<u16> = if let Some(quality) = scene.jpeg_quality {
        jpeg_like(&mut values, w, h, quality);
        values
            .iter()
            .map(|&x| ((x * 255.0).round().clamp(0.0, 255.0) / 255.0 * full_scale).round() as u16)
            .collect()
    } else {
        values
            .iter()
            .map(|&x| ((x * full_scale).clamp(0.0, full_scale) + 0.5) as u16)
            .collect()
    };
    let frame = Frame {
        t_s: scene.t_s,
        width: scene.camera.width_px,
        height: scene.camera.height_px,
        bit_depth: scene.bit_depth,
        pixels,
    };
    Ok(RenderedPhoto {
        frame,
        truth: truth(scene, &board),
    })
}
