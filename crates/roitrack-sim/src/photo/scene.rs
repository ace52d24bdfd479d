//! The scene of a photograph: the camera, the target and its pose, the paper and the circles' shades, and the
//! settings of every other part (light, background, clutter, sensor), with their checks.

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use roitrack_core::{CameraError, CameraModel, MotionState, Target, TargetPoint};

use super::background::Background;
use super::board::board_frame;
use super::clutter::Clutter;
use super::light::{Glare, Illumination, Shadow};
use super::{MAX_PIXELS, PhotoError};

#[cfg(doc)]
use super::render_photo;

/// Diameter of the circle of a target point that has none (m).
pub const DEFAULT_CIRCLE_DIAMETER_M: f64 = 0.01;

/// Largest supersampling factor (per axis).
const MAX_SUPERSAMPLING: u32 = 32;

/// Which of paper and circles is the bright one, with typical levels ([`PhotoScene::with_shade`]).
///
/// ```
/// use roitrack_sim::photo::CircleShade;
/// let (paper, circle) = CircleShade::DarkOnLight.levels();
/// assert!(paper > circle);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CircleShade {
    /// Black circles printed on white paper: paper 0.85, circles 0.08 of full scale.
    DarkOnLight,
    /// White (or retro-reflective) circles on a black board: paper 0.06, circles 0.92 of full scale.
    BrightOnDark,
}

impl CircleShade {
    /// The (paper, circle) reflectance levels of this shade, fractions of full scale under unit light.
    pub fn levels(self) -> (f64, f64) {
        match self {
            Self::DarkOnLight => (0.85, 0.08),
            Self::BrightOnDark => (0.06, 0.92),
        }
    }
}

/// A photograph to render: the camera, the target and its pose, the board, the scene around it, the light and the
/// sensor. [`PhotoScene::new`] gives a clean, evenly lit board of black circles on white paper; change fields or use
/// the builders for more.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_sim::photo::{CircleShade, PhotoScene, render_photo};
///
/// let scene = PhotoScene::new(CameraModel::canonical(), Target::grid4x4(), Rotation3::identity(), Vector3::new(0.0, 0.0, 0.5))
///     .with_shade(CircleShade::BrightOnDark)
///     .with_bit_depth(12);
/// let photo = render_photo(&scene).unwrap();
/// assert_eq!(photo.frame.bit_depth, 12);
/// // The centre of the bright circle of point 0 is bright.
/// let c = photo.truth[0].centre_px.unwrap();
/// let value = photo.frame.pixels[photo.frame.index(c.x.round() as u32, c.y.round() as u32)];
/// assert!(f64::from(value) > 0.8 * 4095.0);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoScene {
    /// The camera (its image size is the photograph's).
    pub camera: CameraModel,
    /// A planar target: one circle per point.
    pub target: Target,
    /// Rotation of the object in the camera: `x_cam = cam_r_obj x_obj + cam_t_obj_m`.
    pub cam_r_obj: Rotation3<f64>,
    /// Position of the object's origin in the camera frame (m): `x_cam = cam_r_obj x_obj + cam_t_obj_m`.
    pub cam_t_obj_m: Vector3<f64>,
    /// Diameter of the circles of points without one (m).
    pub default_diameter_m: f64,
    /// How far the board reaches beyond the outermost circle edges, in its plane (m).
    pub paper_margin_m: f64,
    /// Reflectance of the paper (fraction of full scale under unit light).
    pub paper_level: f64,
    /// Reflectance of the circles (fraction of full scale under unit light).
    pub circle_level: f64,
    /// What is seen around the board.
    pub background: Background,
    /// How the scene is lit (gradient, vignetting, shadow, glare).
    pub illumination: Illumination,
    /// Distractor shapes scattered over the background.
    pub clutter: Clutter,
    /// Sigma of the Gaussian blur of the optics (px; 0: none).
    pub blur_sigma_px: f64,
    /// Sigma of the Gaussian read noise (fraction of full scale).
    pub noise_sigma: f64,
    /// Shot noise: electrons at full scale (a level `x` has Poisson noise of sigma `sqrt(x / full_well)`); `None`:
    /// none.
    pub shot_noise_full_well_e: Option<f64>,
    /// Bits per pixel value, 8 to 16.
    pub bit_depth: u8,
    /// JPEG-like compression at this quality (1..=100, IJG scaling of the standard luminance table): 8 x 8 DCT
    /// blocks quantised on 8-bit values; the photograph then holds 8-bit levels scaled to the bit depth.
    pub jpeg_quality: Option<u8>,
    /// Samples per axis in pixels crossed by an edge (1..=32).
    pub supersampling: u32,
    /// Time stamp of the frame (s).
    pub t_s: f64,
    /// Seed of every random choice (noise, clutter, texture, marks).
    pub seed: u64,
}

impl PhotoScene {
    /// A clean photograph: black circles (0.08) on white paper (0.85) with a 2 cm margin, on a flat 0.32 background,
    /// under uniform unit light, no clutter, 0.6 px blur, no noise, 8 bits, 8 x 8 samples on edges, seed 0.
    pub fn new(
        camera: CameraModel,
        target: Target,
        cam_r_obj: Rotation3<f64>,
        cam_t_obj_m: Vector3<f64>,
    ) -> Self {
        let (paper_level, circle_level) = CircleShade::DarkOnLight.levels();
        Self {
            camera,
            target,
            cam_r_obj,
            cam_t_obj_m,
            default_diameter_m: DEFAULT_CIRCLE_DIAMETER_M,
            paper_margin_m: 0.02,
            paper_level,
            circle_level,
            background: Background::default(),
            illumination: Illumination::default(),
            clutter: Clutter::default(),
            blur_sigma_px: 0.6,
            noise_sigma: 0.0,
            shot_noise_full_well_e: None,
            bit_depth: 8,
            jpeg_quality: None,
            supersampling: 8,
            t_s: 0.0,
            seed: 0,
        }
    }

    /// [`Self::new`] at the pose of `state` (its twist is not used: no motion blur).
    ///
    /// ```
    /// use nalgebra::Vector3;
    /// use roitrack_core::{CameraModel, MotionState, Target};
    /// use roitrack_sim::photo::PhotoScene;
    /// let state = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
    /// let scene = PhotoScene::from_state(CameraModel::canonical(), Target::grid4x4(), &state);
    /// assert_eq!(scene.cam_t_obj_m.z, 0.6);
    /// ```
    pub fn from_state(camera: CameraModel, target: Target, state: &MotionState) -> Self {
        Self::new(camera, target, state.cam_r_obj, state.cam_t_obj_m)
    }

    /// [`Self::new`] with the board facing the camera: the centroid of the target's points on the optical axis at
    /// `distance_m` (imaged on the principal point), the board's in-plane axes along the camera's x and y (the
    /// target's own x and y for a target in its z = 0 plane, so that the photograph shows it unmirrored, x to the
    /// right and y down), then the board turned by `tilt` (camera frame) about that centroid. A non-planar target
    /// keeps its orientation ([`render_photo`] refuses it).
    ///
    /// ```
    /// use nalgebra::{Rotation3, Vector3};
    /// use roitrack_core::{CameraModel, Target};
    /// use roitrack_core::target::{CircleGrid, GridLayout};
    /// use roitrack_sim::photo::PhotoScene;
    ///
    /// let spec = CircleGrid { rows: 3, cols: 4, spacing_m: 0.02, diameter_m: 0.008, layout: GridLayout::Square };
    /// let target = Target::circle_grid(&spec).unwrap();
    /// let scene = PhotoScene::facing(CameraModel::canonical(), target, 0.5, Rotation3::identity());
    /// // The grid spans (0..0.06, 0..0.04) m: its centroid (0.03, 0.02, 0) is on the optical axis.
    /// let centroid = scene.cam_r_obj * Vector3::new(0.03, 0.02, 0.0) + scene.cam_t_obj_m;
    /// assert!((centroid - Vector3::new(0.0, 0.0, 0.5)).norm() < 1e-12);
    /// assert!(scene.cam_r_obj.angle() < 1e-12);
    /// ```
    pub fn facing(
        camera: CameraModel,
        target: Target,
        distance_m: f64,
        tilt: Rotation3<f64>,
    ) -> Self {
        let (origin, facing) = match board_frame(&target) {
            Some((origin, e1, e2)) => {
                let rows = Matrix3::from_rows(&[
                    e1.transpose(),
                    e2.transpose(),
                    e1.cross(&e2).transpose(),
                ]);
                (origin, Rotation3::from_matrix_unchecked(rows))
            }
            None => {
                let points = target.points();
                let sum: Vector3<f64> = points.iter().map(|p| p.point_in_obj_m).sum();
                (sum / points.len().max(1) as f64, Rotation3::identity())
            }
        };
        let cam_r_obj = tilt * facing;
        let cam_t_obj_m = Vector3::new(0.0, 0.0, distance_m) - cam_r_obj * origin;
        Self::new(camera, target, cam_r_obj, cam_t_obj_m)
    }

    /// The same scene with the paper and circle levels of `shade`.
    pub fn with_shade(mut self, shade: CircleShade) -> Self {
        (self.paper_level, self.circle_level) = shade.levels();
        self
    }

    /// Which of paper and circles is the brighter.
    ///
    /// ```
    /// use nalgebra::{Rotation3, Vector3};
    /// use roitrack_core::{CameraModel, Target};
    /// use roitrack_sim::photo::{CircleShade, PhotoScene};
    /// let scene = PhotoScene::new(CameraModel::canonical(), Target::grid4x4(), Rotation3::identity(), Vector3::z());
    /// assert_eq!(scene.shade(), CircleShade::DarkOnLight);
    /// ```
    pub fn shade(&self) -> CircleShade {
        if self.circle_level < self.paper_level {
            CircleShade::DarkOnLight
        } else {
            CircleShade::BrightOnDark
        }
    }

    /// The same scene with another seed.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// The same scene with another bit depth.
    pub fn with_bit_depth(mut self, bit_depth: u8) -> Self {
        self.bit_depth = bit_depth;
        self
    }

    /// The same scene photographed badly: a textured background with 60 clutter items (allowed to touch the board)
    /// and 4 marks on the paper, light falling to 0.6 across the image with 0.35 vignetting, a soft shadow (light
    /// 0.45) over the left quarter and a glare spot up right, 1 px blur, 1 % read noise with shot noise (5000 e⁻ at
    /// full scale) and JPEG quality 85. Geometry, levels, bit depth and seed are kept.
    pub fn harsh(mut self) -> Self {
        let (w, h) = (
            f64::from(self.camera.width_px),
            f64::from(self.camera.height_px),
        );
        self.background = Background::Texture {
            mean_level: 0.4,
            contrast: 0.3,
            scale_px: 0.08 * w.min(h),
        };
        self.illumination = Illumination {
            gradient_min: 0.6,
            gradient_angle_rad: 0.5,
            vignetting: 0.35,
            shadow: Some(Shadow::half_plane(
                Vector2::new(0.25 * w, 0.5 * h),
                Vector2::new(-1.0, -0.3),
                0.45,
                0.04 * w.min(h),
            )),
            glare: Some(Glare {
                centre_px: Vector2::new(0.78 * w, 0.2 * h),
                radius_px: 0.05 * w.min(h),
                level: 0.3,
            }),
        };
        self.clutter = Clutter {
            count: 60,
            clearance_px: None,
            board_marks: 4,
            ..Clutter::default()
        };
        self.blur_sigma_px = 1.0;
        self.noise_sigma = 0.01;
        self.shot_noise_full_well_e = Some(5000.0);
        self.jpeg_quality = Some(85);
        self
    }

    /// Diameter of the circle of `point` (m): its own, or [`Self::default_diameter_m`].
    pub fn circle_diameter_m(&self, point: &TargetPoint) -> f64 {
        point.diameter_m.unwrap_or(self.default_diameter_m)
    }

    /// Checks every parameter (ranges, finiteness, bit depth, image size); [`render_photo`] calls it.
    pub fn validate(&self) -> Result<(), PhotoError> {
        self.check_image()?;
        self.check_pose_and_paper()?;
        self.background.check()?;
        self.illumination.check()?;
        self.clutter.check()?;
        self.check_sensor()
    }

    /// The camera's image: not empty, not too large, a valid lens, a bit depth of 8 to 16.
    fn check_image(&self) -> Result<(), PhotoError> {
        let camera = &self.camera;
        if camera.width_px == 0 || camera.height_px == 0 {
            return Err(CameraError::EmptyImage {
                width_px: camera.width_px,
                height_px: camera.height_px,
            }
            .into());
        }
        if u64::from(camera.width_px) * u64::from(camera.height_px) > MAX_PIXELS {
            return Err(PhotoError::ImageTooLarge {
                width_px: camera.width_px,
                height_px: camera.height_px,
            });
        }
        camera.intrinsics.validate()?;
        camera.distortion.validate()?;
        if !(8..=16).contains(&self.bit_depth) {
            return Err(PhotoError::BitDepth(self.bit_depth));
        }
        Ok(())
    }

    /// The pose (a rotation, finite), the time, the circles' default size, the paper's margin and the levels.
    fn check_pose_and_paper(&self) -> Result<(), PhotoError> {
        let r = self.cam_r_obj.matrix();
        let orthonormality = (r.transpose() * r - Matrix3::identity()).norm();
        check(
            "cam_r_obj (orthonormality error)",
            orthonormality,
            orthonormality < 1e-6,
            "a rotation",
        )?;
        for (field, value) in [
            ("cam_t_obj_m.x", self.cam_t_obj_m.x),
            ("cam_t_obj_m.y", self.cam_t_obj_m.y),
            ("cam_t_obj_m.z", self.cam_t_obj_m.z),
            ("t_s", self.t_s),
            (
                "illumination.gradient_angle_rad",
                self.illumination.gradient_angle_rad,
            ),
        ] {
            check(field, value, value.is_finite(), "finite")?;
        }
        let d = self.default_diameter_m;
        check(
            "default_diameter_m",
            d,
            d > 0.0 && d.is_finite(),
            "positive",
        )?;
        let m = self.paper_margin_m;
        check("paper_margin_m", m, (0.0..1e6).contains(&m), "0 or more")?;
        unit("paper_level", self.paper_level)?;
        unit("circle_level", self.circle_level)?;
        Ok(())
    }

    /// Blur, noise, compression and supersampling.
    fn check_sensor(&self) -> Result<(), PhotoError> {
        let b = self.blur_sigma_px;
        check("blur_sigma_px", b, (0.0..=50.0).contains(&b), "0 to 50")?;
        unit("noise_sigma", self.noise_sigma)?;
        if let Some(fw) = self.shot_noise_full_well_e {
            check(
                "shot_noise_full_well_e",
                fw,
                fw > 0.0 && fw.is_finite(),
                "positive",
            )?;
        }
        if let Some(q) = self.jpeg_quality {
            check(
                "jpeg_quality",
                f64::from(q),
                (1..=100).contains(&q),
                "1 to 100",
            )?;
        }
        let s = self.supersampling;
        check(
            "supersampling",
            f64::from(s),
            (1..=MAX_SUPERSAMPLING).contains(&s),
            "1 to 32",
        )?;
        Ok(())
    }
}

pub(super) fn check(
    field: &'static str,
    value: f64,
    ok: bool,
    expected: &'static str,
) -> Result<(), PhotoError> {
    if ok {
        Ok(())
    } else {
        Err(PhotoError::InvalidParameter {
            field,
            value,
            expected,
        })
    }
}

pub(super) fn unit(field: &'static str, value: f64) -> Result<(), PhotoError> {
    check(field, value, (0.0..=1.0).contains(&value), "within 0..1")
}
