//! A simulated ROI camera: renders each requested ROI from the true motion.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::MotionState;
use roitrack_image::{Frame, GrabError, RoiCamera, RoiImage, RoiTrigger};

use crate::{ReflectionFault, RenderScratch, RoiRenderer};

/// A simulated camera: renders each requested ROI from the true motion `truth(t)` (pixels, noise, blur, and the
/// exposure and readout of the camera's time model), exposed when it is triggered, deterministic per seed, with
/// optional reflections. It never fails.
///
/// ```
/// use rand::SeedableRng;
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_image::{Frame, RoiCamera};
/// use roitrack_sim::{RoiRenderer, SensorModel, SimulatedCamera};
/// use nalgebra::Vector3;
///
/// let renderer = RoiRenderer::new(CameraModel::canonical(), Target::grid4x4(), SensorModel::default()).unwrap();
/// let still = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
/// let mut camera = SimulatedCamera::new(renderer, move |_t: f64| still, 1);
/// let mut frame = Frame::default();
/// camera.grab_full_frame(0.0, &mut frame).unwrap();
/// assert_eq!((frame.width, frame.height), (1024, 1024));
/// ```
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
    /// A camera rendering with `renderer` the target at the pose `truth` gives for each ROI's time, its noise drawn
    /// from `seed`.
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
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
        let bit_depth = self.renderer.sensor().bit_depth as u8;
        image.set(trigger.t_s, trigger.point_id, trigger.roi, bit_depth);
        self.renderer.render_readout(
            &self.truth,
            &trigger.roi,
            trigger.t_s,
            &mut self.rng,
            &mut self.scratch,
            &mut image.pixels,
        );
        if let Some(fault) = &self.reflections
            && self.fault_rng.random::<f64>() < fault.fraction
        {
            let max_dn = self.renderer.sensor().max_dn();
            fault.add_spot(&mut self.fault_rng, &trigger.roi, &mut image.pixels, max_dn);
        }
        Ok(())
    }

    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
        self.renderer
            .render_frame(&self.truth, t_s, &mut self.rng, &mut self.scratch, frame);
        Ok(())
    }
}
