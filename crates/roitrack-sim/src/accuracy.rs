//! Accuracy of the ROI centroid against the truth, on rendered images.

use nalgebra::{Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::{MotionState, so3};

use roitrack_image::{BlobRejection, CentroidOptions, Roi, measure_blob};

use crate::reflection::ReflectionFault;
use crate::render::{RenderScratch, RoiRenderer};

/// Largest random shift of the position about the bench pose, per axis (m).
pub const ACCURACY_POSITION_SPREAD_M: f64 = 0.005;
/// Largest random rotation about the bench rotation, per axis of the rotation vector (rad): 5 degrees.
pub const ACCURACY_ROTATION_SPREAD_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Largest random speed of the origin (m/s): the paper's peak speed, 0.25 px of motion blur in 100 µs.
pub const ACCURACY_MAX_SPEED_MPS: f64 = 1.0;
/// Largest random angular speed (rad/s).
pub const ACCURACY_MAX_ANGULAR_SPEED_RADPS: f64 = 3.0;
/// Largest random offset of the ROI's centre from the true blob centre, per axis (px).
pub const ACCURACY_ROI_OFFSET_PX: f64 = 3.0;

/// Error statistics of centroids against the true projected blob centres (px; error = measured - true).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CentroidAccuracy {
    /// Measured blobs.
    pub count: usize,
    /// ROIs that gave no centroid (the 9 mm key blob, 22 px wide, does not fit a 24 px ROI: about 1 in 16).
    pub rejected: usize,
    /// Mean error along u.
    pub bias_u_px: f64,
    /// Mean error along v.
    pub bias_v_px: f64,
    /// Standard deviation of the error along u.
    pub std_u_px: f64,
    /// Standard deviation of the error along v.
    pub std_v_px: f64,
    /// Root mean square of the error vector's length, sqrt(mean(du² + dv²)) (divide by √2 for a per-axis figure).
    pub rms_px: f64,
}

/// Renders `count` ROIs of `roi_size` x `roi_size` pixels, each of a random blob of the renderer's target at a random
/// state near the bench pose (position within ±5 mm per axis, rotation within ±5° per axis, speed up to 1 m/s,
/// angular speed up to 3 rad/s, so motion blur is exercised), with the ROI centred on the true blob centre plus a
/// random offset of up to ±3 px per axis; measures each with `opts` and compares with the TRUE projected centre
/// (`camera.raw_pixel_from_cam` of the model point at mid-exposure). Deterministic for a `seed`.
///
/// With the defaults the bias is the perspective offset of the disks' image centres from the projected centres (see
/// [`RoiRenderer::disk_image_centre_px`]), not an error of the centroid; docs/image-side.md gives it with the spread.
///
/// # Panics
/// If `roi_size` is larger than [`roitrack_image::MAX_ROI_WIDTH`] (64).
pub fn centroid_accuracy(
    renderer: &RoiRenderer,
    opts: &CentroidOptions,
    roi_size: u32,
    count: usize,
    seed: u64,
) -> CentroidAccuracy {
    let (mut n, mut rejected) = (0usize, 0usize);
    let (mut sum_u, mut sum_v, mut sum_uu, mut sum_vv) = (0.0, 0.0, 0.0, 0.0);
    for_each_random_roi(renderer, roi_size, count, seed, |rendered| {
        let Some((roi, pixels, truth)) = rendered else {
            rejected += 1;
            return;
        };
        match measure_blob(pixels, roi, opts) {
            Ok(c) => {
                let (eu, ev) = (c.u_px - truth.x, c.v_px - truth.y);
                n += 1;
                sum_u += eu;
                sum_v += ev;
                sum_uu += eu * eu;
                sum_vv += ev * ev;
            }
            Err(_) => rejected += 1,
        }
    });
    let nf = n.max(1) as f64;
    let (bias_u_px, bias_v_px) = (sum_u / nf, sum_v / nf);
    let spread = |sum_sq: f64, bias: f64| {
        if n > 1 {
            ((sum_sq - nf * bias * bias) / (nf - 1.0)).max(0.0).sqrt()
        } else {
            0.0
        }
    };
    CentroidAccuracy {
        count: n,
        rejected,
        bias_u_px,
        bias_v_px,
        std_u_px: spread(sum_uu, bias_u_px),
        std_v_px: spread(sum_vv, bias_v_px),
        rms_px: ((sum_uu + sum_vv) / nf).sqrt(),
    }
}

/// The centroid's errors on ROIs with a reflection, and what its symmetry check rejects, clean and with the spot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectionAccuracy {
    /// ROIs measured both clean and with a spot (the clean blob was accepted).
    pub count: usize,
    /// Of them, clean blobs the options rejected as [`BlobRejection::Asymmetric`].
    pub clean_rejected_asymmetric: usize,
    /// Of them, blobs with the spot rejected (for any reason).
    pub reflected_rejected: usize,
    /// Blobs with the spot accepted whose centroid is more than [`REFLECTION_CAPTURED_PX`] from the clean one: the
    /// spot, brighter than the blob and apart from it, took the centroid (a gross outlier, left to the estimator).
    pub reflected_captured: usize,
    /// Blobs with the spot accepted whose centroid moved by more than [`REFLECTION_MOVED_PX`] (and was not captured).
    pub reflected_moved: usize,
    /// The largest distance between the centroid with the spot and the clean one, over accepted blobs not captured
    /// (px).
    pub worst_accepted_shift_px: f64,
    /// Root mean square of that distance over the same blobs (px).
    pub rms_accepted_shift_px: f64,
}

/// A centroid moved by more than this by a spot counts in [`ReflectionAccuracy::reflected_moved`] (px): several
/// times the clean centroid's noise with the default sensor (docs/image-side.md, "Blob centroids").
pub const REFLECTION_MOVED_PX: f64 = 0.1;
/// A centroid moved by more than this by a spot counts in [`ReflectionAccuracy::reflected_captured`] (px).
pub const REFLECTION_CAPTURED_PX: f64 = 2.0;

/// Renders ROIs as [`centroid_accuracy`] does, measures each clean, adds a spot of `fault` to it (its `fraction`
/// ignored: every ROI gets one) and measures it again, comparing the centroid with the clean one. Deterministic for a
/// `seed`.
pub fn reflection_accuracy(
    renderer: &RoiRenderer,
    opts: &CentroidOptions,
    roi_size: u32,
    count: usize,
    seed: u64,
    fault: &ReflectionFault,
) -> ReflectionAccuracy {
    let mut spot_rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5907);
    let mut with_spot = vec![0u16; (roi_size * roi_size) as usize];
    let max_dn = renderer.sensor().max_dn();
    let mut stats = ReflectionAccuracy {
        count: 0,
        clean_rejected_asymmetric: 0,
        reflected_rejected: 0,
        reflected_captured: 0,
        reflected_moved: 0,
        worst_accepted_shift_px: 0.0,
        rms_accepted_shift_px: 0.0,
    };
    let (mut accepted, mut sum_sq) = (0usize, 0.0);
    for_each_random_roi(renderer, roi_size, count, seed, |rendered| {
        let Some((roi, pixels, _)) = rendered else {
            return;
        };
        with_spot.copy_from_slice(pixels);
        fault.add_spot(&mut spot_rng, roi, &mut with_spot, max_dn);
        let clean = match measure_blob(pixels, roi, opts) {
            Ok(c) => c,
            Err(BlobRejection::Asymmetric) => {
                stats.count += 1;
                stats.clean_rejected_asymmetric += 1;
                return;
            }
            Err(_) => return,
        };
        stats.count += 1;
        let Ok(c) = measure_blob(&with_spot, roi, opts) else {
            stats.reflected_rejected += 1;
            return;
        };
        let shift = (c.u_px - clean.u_px).hypot(c.v_px - clean.v_px);
        if shift > REFLECTION_CAPTURED_PX {
            stats.reflected_captured += 1;
            return;
        }
        accepted += 1;
        sum_sq += shift * shift;
        stats.worst_accepted_shift_px = stats.worst_accepted_shift_px.max(shift);
        if shift > REFLECTION_MOVED_PX {
            stats.reflected_moved += 1;
        }
    });
    stats.rms_accepted_shift_px = (sum_sq / accepted.max(1) as f64).sqrt();
    stats
}

/// Calls `visit` with each of `count` random ROIs of [`centroid_accuracy`] (ROI, pixels, true blob centre), or
/// `None` where the blob does not project or its ROI leaves the sensor.
fn for_each_random_roi(
    renderer: &RoiRenderer,
    roi_size: u32,
    count: usize,
    seed: u64,
    mut visit: impl FnMut(Option<(&Roi, &[u16], Vector2<f64>)>),
) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let camera = renderer.camera();
    let target = renderer.target();
    let mut scratch = RenderScratch::new();
    let mut pixels = vec![0u16; (roi_size * roi_size) as usize];
    let bench = MotionState::bench();
    for _ in 0..count {
        let mut symmetric = |half: f64| Vector3::from_fn(|_, _| rng.random_range(-half..=half));
        let position = bench.cam_t_obj_m + symmetric(ACCURACY_POSITION_SPREAD_M);
        let rotation = so3::exp(&symmetric(ACCURACY_ROTATION_SPREAD_RAD)) * bench.cam_r_obj;
        let velocity = random_in_ball(&mut rng, ACCURACY_MAX_SPEED_MPS);
        let angular = random_in_ball(&mut rng, ACCURACY_MAX_ANGULAR_SPEED_RADPS);
        let state = MotionState {
            cam_r_obj: rotation,
            cam_t_obj_m: position,
            velocity_mps: velocity,
            angular_velocity_radps: angular,
        };
        // Mid-exposure at t = 0; the true state at t follows the constant twist.
        let state_at = |t: f64| state.predicted(t);
        let index = rng.random_range(0..target.len());
        let point = state.point_in_cam_at(&target.points()[index].point_in_obj_m, 0.0);
        let Some(truth) = camera.raw_pixel_from_cam(&point) else {
            visit(None);
            continue;
        };
        let (du, dv) = (
            rng.random_range(-ACCURACY_ROI_OFFSET_PX..=ACCURACY_ROI_OFFSET_PX),
            rng.random_range(-ACCURACY_ROI_OFFSET_PX..=ACCURACY_ROI_OFFSET_PX),
        );
        let Some(roi) = Roi::centred(
            truth.x + du,
            truth.y + dv,
            roi_size,
            camera.width_px,
            camera.height_px,
        ) else {
            visit(None);
            continue;
        };
        renderer.render_roi_with_scratch(&state_at, &roi, 0.0, &mut rng, &mut scratch, &mut pixels);
        visit(Some((&roi, &pixels, truth)));
    }
}

/// A vector uniformly distributed in the ball of radius `radius`.
fn random_in_ball(rng: &mut impl Rng, radius: f64) -> Vector3<f64> {
    loop {
        let v = Vector3::from_fn(|_, _| rng.random_range(-1.0..=1.0));
        if v.norm_squared() <= 1.0 {
            return v * radius;
        }
    }
}
