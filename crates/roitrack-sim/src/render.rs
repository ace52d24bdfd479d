//! A simulated ROI camera: physically based images of the target's blobs.
//!
//! Each blob is a flat, uniformly bright disk of the model point's diameter, centred on the model point:
//!
//! - for a **planar** target the disk lies in the target's plane (z = 0 of the object frame for `grid4x4`; in general
//!   the plane through the points, found from their principal axes), so it is imaged as the exact perspective ellipse
//!   and rotates with the target;
//! - for a **non-planar** target there is no plane to lie in: each disk faces the camera (its normal points from the
//!   disk's centre to the camera centre at every instant), close to the image of a sphere of that diameter: a circle
//!   on the optical axis, slightly elongated radially off-axis, whatever the target's orientation.
//!
//! Disks are two-sided (seen from behind as from the front), opaque to nothing (no occlusion between blobs), and
//! never clipped by the near plane: a blob any part of which is within 1 mm of the camera's centre plane is skipped.
//!
//! Rendering a region ([`RoiRenderer::render_roi`]):
//! 1. **Exposure sampling.** The true pose is read at the start, middle and end of the exposure
//!    (`t_mid ± exposure/2`, the exposure of the camera's time model); the blobs that may reach the region are kept, and the exposure is sampled at `n`
//!    instants (midpoints of `n` equal slices), `n` = ceil(image motion of the fastest blob / `motion_step_px`), at
//!    most `max_time_samples`, 1 for a static scene. Motion blur is the average over these instants.
//! 2. **Geometry per instant.** A disk's plane maps to the image by a homography `H = [e1 e2 C]` (in-plane axes and
//!    centre, camera frame); a ray `(x, y, 1)` meets the plane at in-plane coordinates `H⁻¹ (x, y, 1)` (dehomogenised)
//!    and is inside the disk when they are within the radius: the exact conic `q₀² + q₁² - r² q₂² ≤ 0`, `q = H⁻¹ (x, y,
//!    1)`.
//! 3. **Rays.** Raw (distorted) pixel positions are mapped to undistorted normalised rays with the camera's exact
//!    inverse distortion ([`roitrack_core::CameraModel::undistort_pixel`], Newton) at every pixel *corner* of the region the
//!    blobs cover; inside a pixel the ray is the bilinear interpolation of its four corners (exact without distortion;
//!    with the strong distortion of a wide-angle lens, k1 = -0.28, the interpolation error is below 2e-4 px in the
//!    image's corners).
//! 4. **Coverage.** The conic's sign at a pixel's four corners classifies it: all inside, the whole pixel is (the
//!    image is convex, the pixel within its corners' hull); some inside, the rim crosses it; none inside, the rim can
//!    only poke through one side, which is checked (minimum of the conic along each side) for the pixels near the
//!    rim. Only crossed pixels are supersampled: `supersampling` horizontal sub-rows, each intersected *exactly* with
//!    the ellipse (the conic is a quadratic along a straight sub-row), so the coverage is exact across and
//!    midpoint-sampled down.
//! 5. **Optics and sensor.** The coverage (computed on a margin of ceil(3 sigma) pixels around the region) is blurred
//!    by a separable sampled Gaussian, converted to expected electrons (`background_e + blob_signal_e * coverage`),
//!    then shot and read noise are drawn (in the region's row-major order, so the image is a deterministic function of
//!    the rng's state), and the electrons are converted to DN, rounded and clamped to the bit depth.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Rotation3, Vector2, Vector3};
use rand::Rng;
use roitrack_core::{CameraModel, MotionState, Target};

use roitrack_image::{Frame, Roi};

use crate::sensor::{SensorError, SensorModel};

/// Diameter of a blob whose model point has none (m).
pub const DEFAULT_BLOB_DIAMETER_M: f64 = 0.006;

/// A blob any point of which is closer than this to the camera's centre plane (z) is not rendered (m).
const MIN_DEPTH_M: f64 = 1e-3;

/// Points on a disk's rim projected to bound its image.
const RIM_POINTS: usize = 16;

/// Margin on the bound of a pixel's footprint on a disk's plane (the footprint is computed from the projection's
/// Jacobian at five points of the disk and varies smoothly in between). It only selects the pixels near the rim whose
/// sides are checked for a poking rim.
const FOOTPRINT_SAFETY: f64 = 1.25;

/// How the blob disks are oriented (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DiskOrientation {
    /// Disks in the target's plane, with orthonormal in-plane axes `e1`, `e2` (object frame).
    InTargetPlane {
        /// The first in-plane axis.
        e1_obj: Vector3<f64>,
        /// The second in-plane axis.
        e2_obj: Vector3<f64>,
    },
    /// Disks facing the camera (non-planar targets).
    FacingCamera,
}

/// Reusable buffers for rendering, so that steady-state rendering does not allocate: keep one per renderer user.
#[derive(Debug, Clone, Default)]
pub struct RenderScratch {
    /// Coverage (0..1) of the rendered area (region plus blur margin), row-major.
    coverage: Vec<f64>,
    /// After the horizontal blur pass.
    blurred_rows: Vec<f64>,
    /// One row after both passes.
    line: Vec<f64>,
    /// Undistorted normalised ray (x/z, y/z) at the pixel corners of the area covered by blobs.
    corners: Vec<[f64; 2]>,
    /// The conic of one disk at the corners of its bounding box.
    corner_f: Vec<f64>,
    /// The disks to draw, one per blob and time sample.
    disks: Vec<DiskInstant>,
    /// Indices of the blobs that may reach the area.
    relevant: Vec<usize>,
}

impl RenderScratch {
    /// Empty buffers, grown by the first renderings.
    pub fn new() -> Self {
        Self::default()
    }
}

/// The conic `F(x, y) = a x² + b xy + c y² + d x + e y + f` (normalised image coordinates): F ≤ 0 inside the disk.
#[derive(Debug, Clone, Copy)]
struct Conic {
    a: f64,
    b: f64,
    c: f64,
    d: f64,
    e: f64,
    f: f64,
}

impl Conic {
    /// The image of the disk of radius `r` centred on the origin of the plane frame `H = [e1 e2 C]`, whose inverse is
    /// `h`: F = q₀² + q₁² - r² q₂², q = h (x, y, 1).
    fn of_disk(h: &Matrix3<f64>, radius_m: f64) -> Self {
        let s = [1.0, 1.0, -radius_m * radius_m];
        let mut k = Self {
            a: 0.0,
            b: 0.0,
            c: 0.0,
            d: 0.0,
            e: 0.0,
            f: 0.0,
        };
        for (row, s) in s.iter().enumerate() {
            let (h0, h1, h2) = (h[(row, 0)], h[(row, 1)], h[(row, 2)]);
            k.a += s * h0 * h0;
            k.b += 2.0 * s * h0 * h1;
            k.c += s * h1 * h1;
            k.d += 2.0 * s * h0 * h2;
            k.e += 2.0 * s * h1 * h2;
            k.f += s * h2 * h2;
        }
        k
    }

    #[inline]
    fn eval(&self, x: f64, y: f64) -> f64 {
        x * (self.a * x + self.b * y + self.d) + y * (self.c * y + self.e) + self.f
    }

    /// Centre of the ellipse (where the gradient vanishes), if it is one.
    fn centre(&self) -> Option<Vector2<f64>> {
        Matrix2::new(2.0 * self.a, self.b, self.b, 2.0 * self.c)
            .try_inverse()
            .map(|m| -(m * Vector2::new(self.d, self.e)))
    }
}

/// One blob's disk at one instant, ready to rasterise.
#[derive(Debug, Clone, Copy)]
struct DiskInstant {
    /// Plane coordinates (homogeneous) of a normalised ray: q = h (x, y, 1), in-plane point (q₀/q₂, q₁/q₂) metres.
    h: Matrix3<f64>,
    conic: Conic,
    radius_m: f64,
    /// Radius (on the disk's plane, m) of a disk containing any pixel's footprint around its centre's point.
    footprint_m: f64,
    /// Inclusive pixel range (absolute sensor coordinates) that the disk may cover, clipped to the rendered area.
    i0: i64,
    i1: i64,
    j0: i64,
    j1: i64,
    /// Weight of this instant in the exposure (1 / number of time samples).
    weight: f64,
    /// Whether the image is under 2 px across: then every pixel of its box is sampled (it may fall between corners).
    tiny: bool,
}

/// A disk in the camera frame: centre, in-plane orthonormal axes, radius.
#[derive(Debug, Clone, Copy)]
struct DiskFrame {
    centre: Vector3<f64>,
    e1: Vector3<f64>,
    e2: Vector3<f64>,
    radius_m: f64,
}

/// A rectangle of pixels in absolute sensor coordinates (may extend beyond the sensor: the blur margin).
#[derive(Debug, Clone, Copy)]
struct Area {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
}

impl Area {
    fn x1(&self) -> i64 {
        self.x0 + self.width as i64 - 1
    }
    fn y1(&self) -> i64 {
        self.y0 + self.height as i64 - 1
    }
}

/// The simulated camera: a camera model, the target and a sensor. See the module documentation for the physics.
#[derive(Debug, Clone)]
pub struct RoiRenderer {
    camera: CameraModel,
    target: Target,
    sensor: SensorModel,
    orientation: DiskOrientation,
    /// Blob radius of each target point (m).
    radii_m: Vec<f64>,
    /// Sampled, normalised Gaussian blur kernel, 2 * margin + 1 taps.
    kernel: Vec<f64>,
}

impl RoiRenderer {
    /// A renderer; refuses an invalid sensor (see [`SensorModel::validate`]) or time model (the camera's exposure).
    pub fn new(
        camera: CameraModel,
        target: Target,
        sensor: SensorModel,
    ) -> Result<Self, SensorError> {
        sensor.validate()?;
        camera.time.validate()?;
        let orientation = if target.is_planar() {
            let (e1_obj, e2_obj) = plane_axes(&target);
            DiskOrientation::InTargetPlane { e1_obj, e2_obj }
        } else {
            DiskOrientation::FacingCamera
        };
        let radii_m = target
            .points()
            .iter()
            .map(|p| p.diameter_m.unwrap_or(DEFAULT_BLOB_DIAMETER_M) / 2.0)
            .collect();
        let kernel = gaussian_kernel(sensor.blur_sigma_px);
        Ok(Self {
            camera,
            target,
            sensor,
            orientation,
            radii_m,
            kernel,
        })
    }

    /// The camera it renders through.
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// The target it renders.
    pub fn target(&self) -> &Target {
        &self.target
    }

    /// The sensor's model (noise, bit depth, exposure).
    pub fn sensor(&self) -> &SensorModel {
        &self.sensor
    }

    /// How its blob disks are oriented.
    pub fn orientation(&self) -> DiskOrientation {
        self.orientation
    }

    /// Diameter of the blob of target point `index` (index into `target.points()`), m.
    pub fn blob_diameter_m(&self, index: usize) -> f64 {
        2.0 * self.radii_m[index]
    }

    /// Blur margin rendered around a region (pixels): ceil(3 sigma).
    pub fn margin_px(&self) -> usize {
        self.kernel.len() / 2
    }

    /// Renders `roi` as exposed from `t_mid_s - exposure/2` to `t_mid_s + exposure/2`, `state_at(t)` giving the true
    /// pose at absolute time `t` (its `cam_r_obj`, `cam_t_obj_m`; the twist is not used). Allocates scratch buffers:
    /// use [`Self::render_roi_with_scratch`] in a loop.
    ///
    /// The ROI may extend beyond the sensor (the image is extrapolated there).
    ///
    /// # Panics
    /// If `out.len() != roi.len()`.
    pub fn render_roi(
        &self,
        state_at: &impl Fn(f64) -> MotionState,
        roi: &Roi,
        t_mid_s: f64,
        rng: &mut impl Rng,
        out: &mut [u16],
    ) {
        let mut scratch = RenderScratch::new();
        self.render_roi_with_scratch(state_at, roi, t_mid_s, rng, &mut scratch, out);
    }

    /// [`Self::render_roi`] with caller-kept buffers: once they have grown to the largest ROI, no allocation.
    pub fn render_roi_with_scratch(
        &self,
        state_at: &impl Fn(f64) -> MotionState,
        roi: &Roi,
        t_mid_s: f64,
        rng: &mut impl Rng,
        scratch: &mut RenderScratch,
        out: &mut [u16],
    ) {
        assert_eq!(out.len(), roi.len(), "output buffer length");
        let area = Area {
            x0: i64::from(roi.x0),
            y0: i64::from(roi.y0),
            width: roi.width as usize,
            height: roi.height as usize,
        };
        self.render_area(state_at, area, t_mid_s, rng, scratch, out);
    }

    /// Renders the whole sensor into `frame` (resized to the camera's size and the sensor's bit depth), exposed
    /// around `t_s` as the camera's time model says: every row at `t_s` for a global shutter or ROI camera, row `v`
    /// at `t_s + v * line_delay_s` for a rolling shutter (rendered row by row, each at its own time: what a rolling
    /// shutter sees of a moving target, skew and all). The scratch buffers are reused.
    ///
    /// ```
    /// use rand::SeedableRng;
    /// use rand_chacha::ChaCha8Rng;
    /// use roitrack_core::{CameraModel, MotionState, Target};
    /// use roitrack_image::Frame;
    /// use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};
    /// use nalgebra::Vector3;
    ///
    /// let renderer = RoiRenderer::new(CameraModel::canonical(), Target::grid4x4(), SensorModel::default()).unwrap();
    /// let still = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
    /// let mut frame = Frame::default();
    /// let mut rng = ChaCha8Rng::seed_from_u64(1);
    /// renderer.render_frame(&|_t| still, 0.0, &mut rng, &mut RenderScratch::new(), &mut frame);
    /// // The target's centre (between four blobs) is dark, the blob at (-30, -30) mm bright.
    /// assert!(frame.pixels[frame.index(512, 512)] < 40);
    /// assert!(frame.pixels[frame.index(437, 437)] > 150);
    /// ```
    pub fn render_frame(
        &self,
        state_at: &impl Fn(f64) -> MotionState,
        t_s: f64,
        rng: &mut impl Rng,
        scratch: &mut RenderScratch,
        frame: &mut Frame,
    ) {
        let (width, height) = (self.camera.width_px, self.camera.height_px);
        frame.resize(width, height, self.sensor.bit_depth as u8);
        frame.t_s = t_s;
        let roi = Roi::full(width, height);
        self.render_readout(state_at, &roi, t_s, rng, scratch, &mut frame.pixels);
    }

    /// Renders `roi` as the camera reads it: every row exposed around `t_s`, but for a rolling shutter, whose row
    /// `y0 + k` is exposed around `t_s + k * line_delay_s` (rendered row by row). What [`crate::SimulatedCamera`]
    /// grabs; without a rolling shutter it is [`Self::render_roi_with_scratch`].
    ///
    /// # Panics
    /// If `out.len() != roi.len()`.
    pub fn render_readout(
        &self,
        state_at: &impl Fn(f64) -> MotionState,
        roi: &Roi,
        t_s: f64,
        rng: &mut impl Rng,
        scratch: &mut RenderScratch,
        out: &mut [u16],
    ) {
        let time = self.camera.time;
        if !time.is_rolling() {
            self.render_roi_with_scratch(state_at, roi, t_s, rng, scratch, out);
            return;
        }
        assert_eq!(out.len(), roi.len(), "output buffer length");
        for (k, row) in out.chunks_exact_mut(roi.width as usize).enumerate() {
            let area = Area {
                x0: i64::from(roi.x0),
                y0: i64::from(roi.y0) + k as i64,
                width: roi.width as usize,
                height: 1,
            };
            self.render_area(
                state_at,
                area,
                time.blob_time_s(t_s, k as f64),
                rng,
                scratch,
                row,
            );
        }
    }

    /// Raw pixel position of the area centroid of blob `index`'s image at the pose of `state` (its reference time).
    ///
    /// Perspective moves the centre of a tilted disk's image ellipse away from the projection of the disk's centre
    /// (the near half looks bigger, the offset grows as the square of the size): by 0.010-0.012 px for the 6 mm blobs
    /// and 0.026 px for the 9 mm key blob at the bench pose. The centre is exact for a pinhole camera; with distortion
    /// it is the distorted centre of the pinhole ellipse (the distortion's own effect on the centroid is of second
    /// order). `None` if the blob is not visible.
    pub fn disk_image_centre_px(&self, state: &MotionState, index: usize) -> Option<Vector2<f64>> {
        let frame = self.disk_frame(index, &state.cam_r_obj, &state.cam_t_obj_m);
        let h = plane_homography(&frame)?.try_inverse()?;
        let n = Conic::of_disk(&h, frame.radius_m).centre()?;
        let k = &self.camera.intrinsics;
        Some(k.pixel_from_normalized(&self.camera.distortion.distort(&n)))
    }

    /// The disk of target point `index` at pose (R, t), camera frame.
    fn disk_frame(&self, index: usize, r: &Rotation3<f64>, t: &Vector3<f64>) -> DiskFrame {
        let centre = r * self.target.points()[index].point_in_obj_m + t;
        let (e1, e2) = match self.orientation {
            DiskOrientation::InTargetPlane { e1_obj, e2_obj } => (r * e1_obj, r * e2_obj),
            DiskOrientation::FacingCamera => {
                let normal = -centre.normalize();
                orthonormal_axes(&normal)
            }
        };
        DiskFrame {
            centre,
            e1,
            e2,
            radius_m: self.radii_m[index],
        }
    }

    /// Fast, generous bound of blob `index`'s image at pose (R, t): projected centre and a radius (px) that contains
    /// the whole disk's image. `None` if the blob is too close to or behind the camera.
    fn quick_bound(
        &self,
        index: usize,
        r: &Rotation3<f64>,
        t: &Vector3<f64>,
    ) -> Option<(Vector2<f64>, f64)> {
        let c = r * self.target.points()[index].point_in_obj_m + t;
        let radius_m = self.radii_m[index];
        if c.z - radius_m < MIN_DEPTH_M || !c.z.is_finite() {
            return None;
        }
        let n = Vector2::new(c.x / c.z, c.y / c.z);
        let (dist, jac) = self.camera.distortion.distort_with_jacobian(&n);
        let k = &self.camera.intrinsics;
        // Any point within r of C projects within r (1 + |n|) / (z - r) of n (normalised units).
        let radius_norm = radius_m * (1.0 + n.norm()) / (c.z - radius_m);
        let scale = k.fx_px.max(k.fy_px) + k.skew_px.abs();
        let radius_px = 1.2 * scale * jac.norm() * radius_norm + 2.0;
        Some((k.pixel_from_normalized(&dist), radius_px))
    }

    /// The rasterisable disk of `frame`, clipped to `area`; `None` if invisible (behind, edge-on) or outside.
    fn disk_instant(&self, frame: &DiskFrame, area: &Area, weight: f64) -> Option<DiskInstant> {
        let DiskFrame {
            centre,
            e1,
            e2,
            radius_m,
        } = *frame;
        let h = plane_homography(frame)?.try_inverse()?;
        // Bounding box from rim points (a 16-gon inscribed in the ellipse falls short of it by < 2 % of its size).
        let (mut u_min, mut u_max, mut v_min, mut v_max) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for k in 0..RIM_POINTS {
            let angle = std::f64::consts::TAU * k as f64 / RIM_POINTS as f64;
            let p = centre + radius_m * (angle.cos() * e1 + angle.sin() * e2);
            if p.z < MIN_DEPTH_M {
                return None;
            }
            let px = self.camera.raw_pixel_from_cam(&p)?;
            u_min = u_min.min(px.x);
            u_max = u_max.max(px.x);
            v_min = v_min.min(px.y);
            v_max = v_max.max(px.y);
        }
        let pad = 1.0 + 0.03 * (u_max - u_min).max(v_max - v_min);
        let pixel = |x: f64| (x + 0.5).floor() as i64;
        let (i0, i1) = (
            pixel(u_min - pad).max(area.x0),
            pixel(u_max + pad).min(area.x1()),
        );
        let (j0, j1) = (
            pixel(v_min - pad).max(area.y0),
            pixel(v_max + pad).min(area.y1()),
        );
        if i0 > i1 || j0 > j1 || !(u_min.is_finite() && v_max.is_finite()) {
            return None;
        }
        // The footprint of a pixel on the plane: half the sum of the columns of d(plane)/d(pixel), at five points.
        let mut footprint_m: f64 = 0.0;
        for (a, b) in [(0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)] {
            let p = centre + radius_m * (a * e1 + b * e2);
            let m = self.pixel_jacobian_on_plane(&p, &e1, &e2).try_inverse()?;
            footprint_m = footprint_m.max(0.5 * (m.column(0).norm() + m.column(1).norm()));
        }
        Some(DiskInstant {
            h,
            conic: Conic::of_disk(&h, radius_m),
            radius_m,
            footprint_m: FOOTPRINT_SAFETY * footprint_m,
            i0,
            i1,
            j0,
            j1,
            weight,
            tiny: (u_max - u_min).max(v_max - v_min) < 2.0,
        })
    }

    /// d(raw pixel)/d(a, b) for the plane point `p` = C + a e1 + b e2 (pixels per metre).
    fn pixel_jacobian_on_plane(
        &self,
        p: &Vector3<f64>,
        e1: &Vector3<f64>,
        e2: &Vector3<f64>,
    ) -> Matrix2<f64> {
        let inv_z = 1.0 / p.z;
        let n = Vector2::new(p.x * inv_z, p.y * inv_z);
        let (_, jd) = self.camera.distortion.distort_with_jacobian(&n);
        let k = &self.camera.intrinsics;
        let kmat = Matrix2::new(k.fx_px, k.skew_px, 0.0, k.fy_px);
        let dn_dp = Matrix2x3::new(inv_z, 0.0, -n.x * inv_z, 0.0, inv_z, -n.y * inv_z);
        let axes = nalgebra::Matrix3x2::from_columns(&[*e1, *e2]);
        kmat * jd * dn_dp * axes
    }

    fn render_area(
        &self,
        state_at: &impl Fn(f64) -> MotionState,
        region: Area,
        t_mid_s: f64,
        rng: &mut impl Rng,
        scratch: &mut RenderScratch,
        out: &mut [u16],
    ) {
        let margin = self.margin_px();
        let area = Area {
            x0: region.x0 - margin as i64,
            y0: region.y0 - margin as i64,
            width: region.width + 2 * margin,
            height: region.height + 2 * margin,
        };
        scratch.coverage.clear();
        scratch.coverage.resize(area.width * area.height, 0.0);
        let drawn = self.rasterise(state_at, &area, t_mid_s, scratch);
        self.expose(region, area, drawn, rng, scratch, out);
    }

    /// Accumulates the exposure-averaged coverage of all blobs over `area` into `scratch.coverage`. Returns whether
    /// anything was drawn.
    fn rasterise(
        &self,
        state_at: &impl Fn(f64) -> MotionState,
        area: &Area,
        t_mid_s: f64,
        scratch: &mut RenderScratch,
    ) -> bool {
        let exposure_s = self.camera.time.exposure_s;
        let pose = |t: f64| {
            let s = state_at(t);
            (s.cam_r_obj, s.cam_t_obj_m)
        };
        let mid = pose(t_mid_s);
        let ends = (exposure_s > 0.0).then(|| {
            let (start_s, end_s) = self.camera.time.exposure_interval_s(t_mid_s);
            (pose(start_s), pose(end_s))
        });
        // 1. Blobs that may reach the area, and the number of time samples their motion needs.
        scratch.relevant.clear();
        let mut samples = 1u32;
        let (ax0, ay0) = (area.x0 as f64 - 0.5, area.y0 as f64 - 0.5);
        let (ax1, ay1) = (area.x1() as f64 + 0.5, area.y1() as f64 + 0.5);
        for index in 0..self.target.len() {
            let Some((c_mid, radius_px)) = self.quick_bound(index, &mid.0, &mid.1) else {
                continue;
            };
            let (mut lo, mut hi) = (c_mid, c_mid);
            let mut motion_px = 0.0;
            if let Some((start, end)) = &ends {
                let (Some((c0, _)), Some((c1, _))) = (
                    self.quick_bound(index, &start.0, &start.1),
                    self.quick_bound(index, &end.0, &end.1),
                ) else {
                    continue;
                };
                lo = lo.inf(&c0).inf(&c1);
                hi = hi.sup(&c0).sup(&c1);
                // Rim points also move by the rotation: angle * image radius.
                let turn = (end.0 * start.0.inverse()).angle();
                motion_px = (c1 - c_mid).norm() + (c_mid - c0).norm() + turn * radius_px;
            }
            if hi.x + radius_px < ax0
                || lo.x - radius_px > ax1
                || hi.y + radius_px < ay0
                || lo.y - radius_px > ay1
            {
                continue;
            }
            scratch.relevant.push(index);
            let needed = (motion_px / self.sensor.motion_step_px).ceil();
            samples = samples.max(needed.min(f64::from(self.sensor.max_time_samples)) as u32);
        }
        if scratch.relevant.is_empty() {
            return false;
        }
        // 2. The disks at each time sample.
        scratch.disks.clear();
        let weight = 1.0 / f64::from(samples);
        for k in 0..samples {
            let (r, t) = if samples == 1 {
                mid
            } else {
                pose(t_mid_s + exposure_s * ((f64::from(k) + 0.5) * weight - 0.5))
            };
            for &index in &scratch.relevant {
                let frame = self.disk_frame(index, &r, &t);
                if let Some(disk) = self.disk_instant(&frame, area, weight) {
                    scratch.disks.push(disk);
                }
            }
        }
        if scratch.disks.is_empty() {
            return false;
        }
        // 3. Rays at the pixel corners of the covered area.
        let (bx0, by0) = (
            scratch.disks.iter().map(|d| d.i0).min().unwrap_or(0),
            scratch.disks.iter().map(|d| d.j0).min().unwrap_or(0),
        );
        let (bx1, by1) = (
            scratch.disks.iter().map(|d| d.i1).max().unwrap_or(0),
            scratch.disks.iter().map(|d| d.j1).max().unwrap_or(0),
        );
        let lattice_w = (bx1 - bx0 + 2) as usize;
        let lattice_h = (by1 - by0 + 2) as usize;
        self.corner_rays(bx0, by0, lattice_w, lattice_h, &mut scratch.corners);
        // 4. Coverage. The conic at the cell corners classifies each pixel: all four corners inside means the whole
        // pixel is (the disk's image is convex, the cell within its corners' hull); some inside means the rim
        // crosses it; none inside leaves a sliver possible only where the rim pokes through one side, which is
        // looked for only near the rim.
        let s = self.sensor.supersampling;
        let corners = &scratch.corners;
        let corner_f = &mut scratch.corner_f;
        for disk in &scratch.disks {
            let h = &disk.h;
            let k = &disk.conic;
            let outer2 = (disk.radius_m + disk.footprint_m).powi(2);
            let bw = (disk.i1 - disk.i0 + 2) as usize;
            corner_f.clear();
            for j in disk.j0..=disk.j1 + 1 {
                let l = (j - by0) as usize * lattice_w + (disk.i0 - bx0) as usize;
                corner_f.extend(corners[l..l + bw].iter().map(|c| k.eval(c[0], c[1])));
            }
            for j in disk.j0..=disk.j1 {
                let lattice_row = (j - by0) as usize * lattice_w;
                let f_row = (j - disk.j0) as usize * bw;
                let cov_row = (j - area.y0) as usize * area.width;
                for i in disk.i0..=disk.i1 {
                    let fi = f_row + (i - disk.i0) as usize;
                    let (f00, f10, f01, f11) = (
                        corner_f[fi],
                        corner_f[fi + 1],
                        corner_f[fi + bw],
                        corner_f[fi + bw + 1],
                    );
                    let inside = u8::from(f00 <= 0.0)
                        + u8::from(f10 <= 0.0)
                        + u8::from(f01 <= 0.0)
                        + u8::from(f11 <= 0.0);
                    if inside == 4 && !disk.tiny {
                        scratch.coverage[cov_row + (i - area.x0) as usize] += disk.weight;
                        continue;
                    }
                    let l = lattice_row + (i - bx0) as usize;
                    let (c00, c10) = (corners[l], corners[l + 1]);
                    let (c01, c11) = (corners[l + lattice_w], corners[l + lattice_w + 1]);
                    if inside == 0 && !disk.tiny {
                        // Far from the rim (in-plane distance of the centre's point, times q2², no division)?
                        let x = 0.25 * (c00[0] + c10[0] + c01[0] + c11[0]);
                        let y = 0.25 * (c00[1] + c10[1] + c01[1] + c11[1]);
                        let q0 = h[(0, 0)] * x + h[(0, 1)] * y + h[(0, 2)];
                        let q1 = h[(1, 0)] * x + h[(1, 1)] * y + h[(1, 2)];
                        let q2 = h[(2, 0)] * x + h[(2, 1)] * y + h[(2, 2)];
                        // Rays meeting the plane behind the camera (or NaN rays) miss the disk.
                        if q2.is_nan()
                            || q2 <= 0.0
                            || q0 * q0 + q1 * q1 > outer2 * q2 * q2
                            || !(dips_below_zero(k, c00, c10, f00)
                                || dips_below_zero(k, c10, c11, f10)
                                || dips_below_zero(k, c11, c01, f11)
                                || dips_below_zero(k, c01, c00, f01))
                        {
                            continue;
                        }
                    }
                    let fraction = edge_fraction(k, c00, c10, c01, c11, s);
                    scratch.coverage[cov_row + (i - area.x0) as usize] += disk.weight * fraction;
                }
            }
        }
        true
    }

    /// Undistorted normalised rays at the corners (i - 0.5, j - 0.5) of pixels i in x0..x0 + w - 1, j likewise
    /// (NaN where the distortion cannot be inverted).
    fn corner_rays(&self, x0: i64, y0: i64, w: usize, h: usize, corners: &mut Vec<[f64; 2]>) {
        corners.clear();
        corners.reserve(w * h);
        let k = &self.camera.intrinsics;
        let distortion = &self.camera.distortion;
        if distortion.is_identity() {
            // The inverse camera matrix, with multiplications only.
            let (inv_fx, inv_fy) = (1.0 / k.fx_px, 1.0 / k.fy_px);
            for j in 0..h {
                let y = ((y0 + j as i64) as f64 - 0.5 - k.cy_px) * inv_fy;
                let x_offset = k.cx_px + k.skew_px * y;
                corners.extend(
                    (0..w).map(|i| [((x0 + i as i64) as f64 - 0.5 - x_offset) * inv_fx, y]),
                );
            }
            return;
        }
        for j in 0..h {
            for i in 0..w {
                let raw = Vector2::new((x0 + i as i64) as f64 - 0.5, (y0 + j as i64) as f64 - 0.5);
                let n = distortion.undistort(&k.normalized_from_pixel(&raw));
                corners.push(n.map_or([f64::NAN; 2], |n| [n.x, n.y]));
            }
        }
    }

    /// Optical blur, photometry, noise and quantisation of the coverage of `area` into `out` (`region`'s pixels).
    fn expose(
        &self,
        region: Area,
        area: Area,
        drawn: bool,
        rng: &mut impl Rng,
        scratch: &mut RenderScratch,
        out: &mut [u16],
    ) {
        let (w, h) = (region.width, region.height);
        let sensor = &self.sensor;
        if !drawn {
            for o in out.iter_mut() {
                *o = sensor.quantise(sensor.sample_electrons(sensor.background_e, rng));
            }
            return;
        }
        let taps = self.kernel.len();
        let cov = &mut scratch.coverage;
        for c in cov.iter_mut() {
            // Overlapping blobs (several disks on one pixel) saturate at full coverage.
            *c = c.min(1.0);
        }
        let rows = &mut scratch.blurred_rows;
        rows.clear();
        rows.resize(w * area.height, 0.0);
        for (src, dst) in cov.chunks_exact(area.width).zip(rows.chunks_exact_mut(w)) {
            for (i, d) in dst.iter_mut().enumerate() {
                *d = src[i..i + taps]
                    .iter()
                    .zip(&self.kernel)
                    .map(|(c, k)| c * k)
                    .sum();
            }
        }
        let line = &mut scratch.line;
        line.clear();
        line.resize(w, 0.0);
        for (j, out_row) in out.chunks_exact_mut(w.max(1)).enumerate().take(h) {
            line.fill(0.0);
            for (t, k) in self.kernel.iter().enumerate() {
                let src = &rows[(j + t) * w..(j + t + 1) * w];
                line.iter_mut().zip(src).for_each(|(l, r)| *l += k * r);
            }
            for (o, blurred) in out_row.iter_mut().zip(line.iter()) {
                let mean_e = sensor.background_e + sensor.blob_signal_e * blurred;
                *o = sensor.quantise(sensor.sample_electrons(mean_e, rng));
            }
        }
    }
}

/// Fraction of the pixel with ray corners `c00` (top-left), `c10`, `c01`, `c11` inside the conic (F ≤ 0): the pixel is
/// cut into `rows` horizontal strips, and the centre line of each (a straight segment in normalised coordinates: the
/// rays are bilinear between the corners) is intersected exactly with the conic, F being a quadratic along it. Exact
/// across, midpoint rule down (error O(1 / rows²) where the edge is not horizontal).
#[inline]
fn edge_fraction(
    k: &Conic,
    c00: [f64; 2],
    c10: [f64; 2],
    c01: [f64; 2],
    c11: [f64; 2],
    rows: u32,
) -> f64 {
    let inv = 1.0 / f64::from(rows);
    let down = [c01[0] - c00[0], c01[1] - c00[1]];
    let across = [c10[0] - c00[0], c10[1] - c00[1]];
    let twist = [
        c11[0] - c10[0] - c01[0] + c00[0],
        c11[1] - c10[1] - c01[1] + c00[1],
    ];
    let mut covered = 0.0;
    for row in 0..rows {
        let t = (f64::from(row) + 0.5) * inv;
        // The strip's centre line: from (x, y) at s = 0 to (x + dx, y + dy) at s = 1.
        let (x, y) = (c00[0] + t * down[0], c00[1] + t * down[1]);
        let (dx, dy) = (across[0] + t * twist[0], across[1] + t * twist[1]);
        let quad = k.a * dx * dx + k.b * dx * dy + k.c * dy * dy;
        let slope = (2.0 * k.a * x + k.b * y + k.d) * dx + (k.b * x + 2.0 * k.c * y + k.e) * dy;
        covered += sublevel_length(quad, slope, k.eval(x, y));
    }
    covered * inv
}

/// Whether the conic goes negative strictly inside the segment from `p` to `q` (`f_p` = F(p) > 0 and F(q) > 0 known):
/// F along it is a quadratic whose minimum is checked without division.
#[inline]
fn dips_below_zero(k: &Conic, p: [f64; 2], q: [f64; 2], f_p: f64) -> bool {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let quad = k.a * dx * dx + k.b * dx * dy + k.c * dy * dy;
    let slope =
        (2.0 * k.a * p[0] + k.b * p[1] + k.d) * dx + (k.b * p[0] + 2.0 * k.c * p[1] + k.e) * dy;
    // Vertex at s* = -slope / (2 quad) in (0, 1), minimum f_p - slope² / (4 quad) ≤ 0.
    quad > 0.0 && -slope > 0.0 && -slope < 2.0 * quad && slope * slope >= 4.0 * quad * f_p
}

/// Length of { s in [0, 1] : q s² + g s + f ≤ 0 }.
#[inline]
fn sublevel_length(q: f64, g: f64, f: f64) -> f64 {
    if q == 0.0 {
        if g == 0.0 {
            return if f <= 0.0 { 1.0 } else { 0.0 };
        }
        let root = (-f / g).clamp(0.0, 1.0);
        return if g > 0.0 { root } else { 1.0 - root };
    }
    let disc = g * g - 4.0 * q * f;
    if disc.is_nan() || disc <= 0.0 {
        // No sign change: the sign of q decides (a tangent line has zero length).
        return if q < 0.0 { 1.0 } else { 0.0 };
    }
    // One division; the roots' relative error is about eps * |g / q| (< 1e-13 here: q / g is the pixel size over the
    // distance to the ellipse's centre).
    let root = disc.sqrt();
    let inv = 0.5 / q;
    let (r1, r2) = ((-g - root) * inv, (-g + root) * inv);
    let (lo, hi) = if r1 < r2 { (r1, r2) } else { (r2, r1) };
    let between = (hi.min(1.0) - lo.max(0.0)).max(0.0);
    if q > 0.0 { between } else { 1.0 - between }
}

/// The homography `[e1 e2 C]` from homogeneous plane coordinates (a, b, 1) to the camera frame; `None` if the plane
/// passes through the camera centre (the disk is seen edge-on).
fn plane_homography(frame: &DiskFrame) -> Option<Matrix3<f64>> {
    let h = Matrix3::from_columns(&[frame.e1, frame.e2, frame.centre]);
    (h.determinant().abs() > 1e-12).then_some(h)
}

/// Two unit vectors completing `normal` (unit) to an orthonormal basis.
fn orthonormal_axes(normal: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if normal.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = helper.cross(normal).normalize();
    (e1, normal.cross(&e1))
}

/// In-plane axes of a planar target (object frame): the two principal axes of its points (for `grid4x4`, ±x and ±y).
fn plane_axes(target: &Target) -> (Vector3<f64>, Vector3<f64>) {
    let n = target.len() as f64;
    let mean = target
        .points()
        .iter()
        .map(|p| p.point_in_obj_m)
        .sum::<Vector3<f64>>()
        / n;
    let mut scatter = Matrix3::zeros();
    for p in target.points() {
        let d = p.point_in_obj_m - mean;
        scatter += d * d.transpose();
    }
    let eig = scatter.symmetric_eigen();
    let smallest = eig.eigenvalues.imin();
    let normal = eig.eigenvectors.column(smallest).into_owned().normalize();
    orthonormal_axes(&normal)
}

/// Sampled Gaussian of standard deviation `sigma_px`, radius ceil(3 sigma), normalised to sum 1 (its variance is
/// within 3 % of sigma² for sigma ≥ 0.5). A single tap for no blur.
///
/// ```
/// let k = roitrack_sim::render::gaussian_kernel(1.0);
/// assert_eq!(k.len(), 7);
/// assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-12 && k[3] > k[2]);
/// ```
pub fn gaussian_kernel(sigma_px: f64) -> Vec<f64> {
    if sigma_px < 1e-3 {
        return vec![1.0];
    }
    let radius = (3.0 * sigma_px).ceil() as i64;
    let mut k: Vec<f64> = (-radius..=radius)
        .map(|x| (-(x * x) as f64 / (2.0 * sigma_px * sigma_px)).exp())
        .collect();
    let sum: f64 = k.iter().sum();
    k.iter_mut().for_each(|w| *w /= sum);
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn kernel_is_normalised_with_the_right_variance() {
        let k = gaussian_kernel(0.6);
        assert_eq!(k.len(), 5);
        assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        let var: f64 = k
            .iter()
            .enumerate()
            .map(|(i, w)| w * (i as f64 - 2.0).powi(2))
            .sum();
        assert!((var / 0.36 - 1.0).abs() < 0.03, "{var}");
        assert_eq!(gaussian_kernel(0.0), vec![1.0]);
    }

    #[test]
    fn edge_fraction_of_a_half_plane_and_a_circle() {
        // Unit-square pixel with corners at x, y in [0, 1]: the half plane x <= 0.3 covers 0.3 exactly at s = 10.
        let half = Conic {
            a: 0.0,
            b: 0.0,
            c: 0.0,
            d: 1.0,
            e: 0.0,
            f: -0.3,
        };
        let f = edge_fraction(&half, [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], 3);
        assert!((f - 0.3).abs() < 1e-12, "{f}");
        // A slanted half plane x + y <= 0.5: exactly 1/8 (the strip lengths are linear in t).
        let slanted = Conic {
            e: 1.0,
            f: -0.5,
            ..half
        };
        let f = edge_fraction(&slanted, [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], 4);
        assert!((f - 0.125).abs() < 1e-12, "{f}");
        // Outside of a circle (F <= 0 outside when the conic is negated).
        assert!((sublevel_length(-1.0, 0.0, 0.25) - 0.5).abs() < 1e-15);
        assert!((sublevel_length(-1.0, 1.0, 0.0) - 0.0).abs() < 1e-15);
        assert!((sublevel_length(1.0, -1.0, 0.0) - 1.0).abs() < 1e-15);
        assert!((sublevel_length(1.0, -1.0, 0.1875) - 0.5).abs() < 1e-15);
        // The quarter disk x² + y² <= 1 in the unit square: pi / 4.
        let circle = Conic {
            a: 1.0,
            b: 0.0,
            c: 1.0,
            d: 0.0,
            e: 0.0,
            f: -1.0,
        };
        let f = edge_fraction(&circle, [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], 32);
        assert!((f - std::f64::consts::FRAC_PI_4).abs() < 5e-3, "{f}");
        // A skewed (bilinear) cell against dense point sampling.
        let (c00, c10, c01, c11) = ([0.1, 0.0], [1.2, 0.1], [0.0, 0.9], [1.0, 1.1]);
        let f = edge_fraction(&circle, c00, c10, c01, c11, 16);
        let n = 400;
        let mut dense = 0;
        for r in 0..n {
            for c in 0..n {
                let (s, t) = ((c as f64 + 0.5) / n as f64, (r as f64 + 0.5) / n as f64);
                let bil = |k: usize| {
                    c00[k] * (1.0 - s) * (1.0 - t)
                        + c10[k] * s * (1.0 - t)
                        + c01[k] * (1.0 - s) * t
                        + c11[k] * s * t
                };
                dense += usize::from(circle.eval(bil(0), bil(1)) <= 0.0);
            }
        }
        assert!((f - dense as f64 / (n * n) as f64).abs() < 1e-3, "{f}");
    }

    #[test]
    fn bilinear_rays_match_exact_undistortion() {
        // A strongly distorting wide-angle lens; the worst place is the image's corner.
        let camera = CameraModel::wide_angle_example();
        let renderer =
            RoiRenderer::new(camera.clone(), Target::grid4x4(), SensorModel::default()).unwrap();
        let mut corners = Vec::new();
        let (x0, y0, w, h) = (1000, 1000, 24, 24);
        renderer.corner_rays(x0, y0, w + 1, h + 1, &mut corners);
        let mut worst_px: f64 = 0.0;
        for j in 0..h {
            for i in 0..w {
                let l = j * (w + 1) + i;
                let (c00, c10, c01, c11) = (
                    corners[l],
                    corners[l + 1],
                    corners[l + w + 1],
                    corners[l + w + 2],
                );
                for (s, t) in [(0.5, 0.5), (0.25, 0.75), (0.9, 0.1)] {
                    let bil = |k: usize| {
                        c00[k] * (1.0 - s) * (1.0 - t)
                            + c10[k] * s * (1.0 - t)
                            + c01[k] * (1.0 - s) * t
                            + c11[k] * s * t
                    };
                    let raw = Vector2::new(
                        (x0 + i as i64) as f64 - 0.5 + s,
                        (y0 + j as i64) as f64 - 0.5 + t,
                    );
                    let exact = camera.undistort_pixel(&raw).unwrap();
                    let approx = camera
                        .intrinsics
                        .pixel_from_normalized(&Vector2::new(bil(0), bil(1)));
                    worst_px = worst_px.max((approx - exact).norm());
                }
            }
        }
        assert!(worst_px < 2e-4, "worst interpolation error {worst_px} px");
    }

    #[test]
    fn plane_axes_of_grid4x4_are_x_and_y() {
        let (e1, e2) = plane_axes(&Target::grid4x4());
        assert!(e1.z.abs() < 1e-12 && e2.z.abs() < 1e-12);
        assert!((e1.dot(&e2)).abs() < 1e-12 && (e1.norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn conic_matches_the_in_plane_test() {
        let frame = DiskFrame {
            centre: Vector3::new(0.03, -0.02, 0.5),
            e1: Vector3::new(0.9, 0.1, 0.3).normalize(),
            e2: Vector3::zeros(),
            radius_m: 0.004,
        };
        let normal = Vector3::new(0.2, -0.3, -1.0).normalize();
        let e1 = (frame.e1 - normal * normal.dot(&frame.e1)).normalize();
        let frame = DiskFrame {
            e1,
            e2: normal.cross(&e1),
            ..frame
        };
        let h = plane_homography(&frame).unwrap().try_inverse().unwrap();
        let conic = Conic::of_disk(&h, frame.radius_m);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let c = frame.centre / frame.centre.z;
        for _ in 0..1000 {
            let (x, y) = (
                c.x + rng.random_range(-0.02..0.02),
                c.y + rng.random_range(-0.02..0.02),
            );
            let q = h * Vector3::new(x, y, 1.0);
            let inside = (q.x / q.z).hypot(q.y / q.z) <= frame.radius_m;
            assert_eq!(conic.eval(x, y) <= 0.0, inside);
        }
    }
}
