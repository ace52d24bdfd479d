//! ROIs rendered beforehand and replayed, for benchmarks and tests where rendering must not count.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::MotionState;
use roitrack_image::{Frame, ReplayCamera, Roi, RoiImage};

use crate::{RenderScratch, RoiRenderer};

/// A [`ReplayCamera`] of `count` ROIs of side `size` rendered beforehand at the true blob positions, cycling through
/// the target point indices of `order`, at `rate_hz` from `t_start_s`, plus one full frame at `t_start_s`; the noise
/// drawn from `seed`. ROIs whose blob is off the image are left out.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_image::{Roi, RoiCamera, RoiImage, RoiTrigger};
/// use roitrack_sim::camera::prerendered_replay;
/// use roitrack_sim::{RoiRenderer, SensorModel};
///
/// let renderer = RoiRenderer::new(CameraModel::canonical(), Target::grid4x4(), SensorModel::default()).unwrap();
/// let still = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
/// let mut camera = prerendered_replay(&renderer, &|_t: f64| still, &[0, 5], 24, 0.0, 4000.0, 3, 1);
/// assert_eq!(camera.len(), 3);
/// let mut image = RoiImage::with_capacity(24 * 24);
/// let trigger = RoiTrigger { point_id: 0, roi: Roi::new(0, 0, 24, 24), t_s: 0.0 };
/// camera.grab_roi(&trigger, &mut image).unwrap();
/// assert_eq!((image.point_id, image.pixels.len()), (0, 24 * 24));
/// ```
#[allow(clippy::too_many_arguments)]
pub fn prerendered_replay(
    renderer: &RoiRenderer,
    truth: &impl Fn(f64) -> MotionState,
    order: &[usize],
    size: u32,
    t_start_s: f64,
    rate_hz: f64,
    count: usize,
    seed: u64,
) -> ReplayCamera {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let camera = renderer.camera().clone();
    let mut scratch = RenderScratch::new();
    let mut full_frame = Frame::default();
    renderer.render_frame(truth, t_start_s, &mut rng, &mut scratch, &mut full_frame);
    let bit_depth = renderer.sensor().bit_depth as u8;
    let rois = (0..count)
        .filter_map(|k| {
            let t = t_start_s + k as f64 / rate_hz;
            let point_index = order[k % order.len()];
            let centre = renderer.disk_image_centre_px(&truth(t), point_index)?;
            let roi = Roi::centred(centre.x, centre.y, size, camera.width_px, camera.height_px)?;
            let mut image = RoiImage::default();
            image.set(
                t,
                renderer.target().points()[point_index].id,
                roi,
                bit_depth,
            );
            renderer.render_roi_with_scratch(
                truth,
                &roi,
                t,
                &mut rng,
                &mut scratch,
                &mut image.pixels,
            );
            Some(image)
        })
        .collect();
    ReplayCamera::new(rois, full_frame)
}
