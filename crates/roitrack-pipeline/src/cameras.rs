//! Cameras for the loop: a simulated ROI camera rendering the true motion, and a replay of pre-rendered ROIs.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::MotionState;
pub use roitrack_image::ReflectionFault;
use roitrack_image::{RenderScratch, Roi, RoiRenderer};

use crate::realtime::RoiCamera;

/// A simulated camera: renders each requested ROI from the true motion `truth(t)` (pixels, noise, blur), deterministic
/// per seed, with optional faults.
pub struct SimulatedCamera<F> {
    renderer: RoiRenderer,
    truth: F,
    rng: ChaCha8Rng,
    scratch: RenderScratch,
    reflections: Option<ReflectionFault>,
    /// The faults' own generator, so that every ROI is rendered (noise included) the same with and without them.
    fault_rng: ChaCha8Rng,
}

impl<F: Fn(f64) -> MotionState + Send> SimulatedCamera<F> {
    pub fn new(renderer: RoiRenderer, truth: F, seed: u64) -> Self {
        Self {
            renderer,
            truth,
            rng: ChaCha8Rng::seed_from_u64(seed),
            scratch: RenderScratch::new(),
            reflections: None,
            fault_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_FA17),
        }
    }

    /// The same camera with reflections in a fraction of its ROIs.
    pub fn with_reflections(mut self, fault: ReflectionFault) -> Self {
        self.reflections = Some(fault);
        self
    }
}

impl<F: Fn(f64) -> MotionState + Send> RoiCamera for SimulatedCamera<F> {
    fn grab_roi(
        &mut self,
        _point_index: usize,
        request: &Roi,
        t_mid_s: f64,
        pixels: &mut [u16],
    ) -> Roi {
        let n = request.len();
        self.renderer.render_roi_with_scratch(
            &self.truth,
            request,
            t_mid_s,
            &mut self.rng,
            &mut self.scratch,
            &mut pixels[..n],
        );
        if let Some(fault) = &self.reflections
            && self.fault_rng.random::<f64>() < fault.fraction
        {
            let max_dn = self.renderer.sensor().max_dn();
            fault.add_spot(&mut self.fault_rng, request, &mut pixels[..n], max_dn);
        }
        *request
    }

    fn grab_full_frame(&mut self, t_mid_s: f64) -> Vec<u16> {
        self.renderer
            .render_full_frame(&self.truth, t_mid_s, &mut self.rng)
    }
}

/// One pre-rendered ROI.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedRoi {
    pub point_index: usize,
    pub roi: Roi,
    pub pixels: Vec<u16>,
}

/// Replays pre-rendered ROIs in order, whatever is requested (for throughput benchmarks, where rendering must not
/// count, and for recorded camera data). The schedule that recorded them must match the one that replays them: a
/// request for another point than the recorded one is counted in [`ReplayCamera::mismatches`].
pub struct ReplayCamera {
    rois: Vec<RecordedRoi>,
    full_frame: Vec<u16>,
    cursor: usize,
    pub mismatches: usize,
}

impl ReplayCamera {
    pub fn new(rois: Vec<RecordedRoi>, full_frame: Vec<u16>) -> Self {
        Self {
            rois,
            full_frame,
            cursor: 0,
            mismatches: 0,
        }
    }

    /// Renders `count` ROIs of side `size` at the true blob positions, cycling through `order`, starting at
    /// `t_start_s`, plus one full frame at `t_start_s`.
    #[allow(clippy::too_many_arguments)]
    pub fn prerender(
        renderer: &RoiRenderer,
        truth: &impl Fn(f64) -> MotionState,
        order: &[usize],
        size: u32,
        t_start_s: f64,
        rate_hz: f64,
        count: usize,
        seed: u64,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let camera = renderer.camera().clone();
        let full_frame = renderer.render_full_frame(truth, t_start_s, &mut rng);
        let mut scratch = RenderScratch::new();
        let rois = (0..count)
            .filter_map(|k| {
                let t = t_start_s + k as f64 / rate_hz;
                let point_index = order[k % order.len()];
                let centre = renderer.disk_image_centre_px(&truth(t), point_index)?;
                let roi =
                    Roi::centred(centre.x, centre.y, size, camera.width_px, camera.height_px)?;
                let mut pixels = vec![0u16; roi.len()];
                renderer.render_roi_with_scratch(
                    truth,
                    &roi,
                    t,
                    &mut rng,
                    &mut scratch,
                    &mut pixels,
                );
                Some(RecordedRoi {
                    point_index,
                    roi,
                    pixels,
                })
            })
            .collect();
        Self::new(rois, full_frame)
    }

    pub fn len(&self) -> usize {
        self.rois.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rois.is_empty()
    }

    /// A copy of the recording, rewound (allocates: make it before timing or counting anything).
    pub fn rewound_copy(&self) -> Self {
        Self::new(self.rois.clone(), self.full_frame.clone())
    }

    /// Starts the replay again from the first ROI.
    pub fn rewind(&mut self) {
        self.cursor = 0;
        self.mismatches = 0;
    }
}

impl RoiCamera for ReplayCamera {
    fn grab_roi(
        &mut self,
        point_index: usize,
        request: &Roi,
        _t_mid_s: f64,
        pixels: &mut [u16],
    ) -> Roi {
        let Some(recorded) = self.rois.get(self.cursor) else {
            // Past the end: an empty (dark) ROI, which the centroider rejects as absent.
            pixels[..request.len()].iter_mut().for_each(|p| *p = 0);
            return *request;
        };
        self.cursor += 1;
        if recorded.point_index != point_index {
            self.mismatches += 1;
        }
        pixels[..recorded.pixels.len()].copy_from_slice(&recorded.pixels);
        recorded.roi
    }

    fn grab_full_frame(&mut self, _t_mid_s: f64) -> Vec<u16> {
        self.full_frame.clone()
    }
}
