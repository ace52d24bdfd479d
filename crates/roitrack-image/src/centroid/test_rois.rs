//! ROIs of any size for the tests that compare instruction sets: synthetic ones (disks, rings, diagonal lines, noise,
//! 8- to 16-bit pixels) and ones rendered by the simulator around the canonical target's blobs. In one place so that
//! the kernel-level and the [`super::measure_blob`]-level comparisons see the same kinds of images.

use nalgebra::Vector3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};

use crate::render::RoiRenderer;
use crate::roi::Roi;
use crate::sensor::SensorModel;

/// A `w` x `h` ROI of background and noise holding 1 to 3 disks, rings or diagonal lines (by `kind % 4`, simple
/// components and not), anywhere in or just off it, in pixels of 8 to 16 bits (by `kind % 5`).
pub(super) fn synthetic(rng: &mut ChaCha8Rng, w: usize, h: usize, kind: usize) -> Vec<u16> {
    let max = f64::from((1u32 << [8, 8, 10, 12, 16][kind % 5]) - 1);
    let background = rng.random_range(0.0..0.2) * max;
    let noise = rng.random_range(0.0..0.02) * max;
    let mut image: Vec<f64> = (0..w * h)
        .map(|_| background + noise * rng.random_range(-1.0..1.0))
        .collect();
    for _ in 0..rng.random_range(1..4) {
        let r = rng.random_range(0.3..(w.min(h) as f64 / 2.0).max(0.6));
        let (cx, cy) = (
            rng.random_range(-1.0..w as f64 + 1.0),
            rng.random_range(-1.0..h as f64 + 1.0),
        );
        let amplitude = rng.random_range(0.05..1.0) * (max - background);
        for (k, p) in image.iter_mut().enumerate() {
            let (dx, dy) = ((k % w) as f64 - cx, (k / w) as f64 - cy);
            let d = dx.hypot(dy);
            *p += amplitude
                * match kind % 4 {
                    0 | 1 => (1.0 - (d / r).powi(2)).max(0.0),
                    2 => f64::from(u8::from((d - r).abs() < 1.0)),
                    _ => f64::from(u8::from((dx - dy).abs() < 0.8 && d < r)),
                };
        }
    }
    image
        .iter()
        .map(|&p| p.round().clamp(0.0, max) as u16)
        .collect()
}

/// The simulated camera looking at the canonical target, moving.
pub(super) struct Scene {
    renderer: RoiRenderer,
    state: MotionState,
}

impl Scene {
    pub(super) fn new() -> Self {
        let renderer = RoiRenderer::new(
            CameraModel::canonical(),
            Target::grid4x4(),
            SensorModel::default(),
        )
        .unwrap();
        let state = MotionState {
            velocity_mps: Vector3::new(0.8, -0.4, 0.1),
            angular_velocity_radps: Vector3::new(1.0, -2.0, 0.5),
            ..MotionState::bench()
        };
        Self { renderer, state }
    }

    /// A rendered `w` x `h` ROI around blob `blob` (of 16), off its centre by up to 30 % of the ROI's size.
    pub(super) fn rendered(
        &self,
        rng: &mut ChaCha8Rng,
        w: u32,
        h: u32,
        blob: usize,
    ) -> (Vec<u16>, Roi) {
        let target = self.renderer.target();
        let p = self
            .state
            .point_in_cam_at(&target.points()[blob % 16].point_in_obj_m, 0.0);
        let c = self.renderer.camera().raw_pixel_from_cam(&p).unwrap();
        let (dx, dy) = (
            rng.random_range(-0.3..0.3) * f64::from(w),
            rng.random_range(-0.3..0.3) * f64::from(h),
        );
        let (width, height) = (
            self.renderer.camera().width_px,
            self.renderer.camera().height_px,
        );
        let x0 = (c.x + dx - f64::from(w) / 2.0)
            .round()
            .clamp(0.0, f64::from(width - w)) as u32;
        let y0 = (c.y + dy - f64::from(h) / 2.0)
            .round()
            .clamp(0.0, f64::from(height - h)) as u32;
        let roi = Roi::new(x0, y0, w, h);
        let mut pixels = vec![0; roi.len()];
        let state = self.state;
        self.renderer
            .render_roi(&|t| state.predicted(t), &roi, 0.0, rng, &mut pixels);
        (pixels, roi)
    }
}
