//! The camera side of a real-time run: the [`LoopClockCamera`] that tells the scene each grab's time and ends the
//! run when told, and the servo's camera model and target.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use roitrack_core::time::{Readout, TimeModel};
use roitrack_core::{CameraModel, Target};
use roitrack_image::{Frame, GrabError, RoiCamera, RoiImage, RoiTrigger};

use super::scene::RobotScene;
use crate::ServoConfig;

/// A camera of the live loop, its grabs telling a [`RobotScene`] the loop's time (so that the scene learns the
/// offset between the clocks before the ROI is rendered), and ending the run with [`GrabError::Stopped`] once
/// [`Self::stop_flag`] is set (the control thread's end of the path).
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::RoiCamera;
/// use roitrack_sim::{RoiRenderer, SensorModel, SimulatedCamera};
/// use roitrack_servo::live::{LoopClockCamera, RobotScene};
/// use roitrack_servo::reference::ReferencePath;
///
/// let scene = RobotScene::new(&ReferencePath::orthoglide(1.0));
/// let renderer = RoiRenderer::new(CameraModel::canonical(), Target::grid4x4(), SensorModel::default()).unwrap();
/// let truth = { let scene = scene.clone(); move |t: f64| scene.camera_state_at_loop_s(t) };
/// let mut camera = LoopClockCamera::new(SimulatedCamera::new(renderer, truth, 1), scene.clone());
/// camera.grab_full_frame(0.0, &mut Default::default()).unwrap();
/// assert!(scene.loop_offset_s().unwrap() >= 0.0);
/// camera.stop_flag().store(true, std::sync::atomic::Ordering::Release);
/// assert!(camera.grab_full_frame(0.0, &mut Default::default()).is_err());
/// ```
pub struct LoopClockCamera<C> {
    inner: C,
    scene: RobotScene,
    stop: Arc<AtomicBool>,
}

impl<C: RoiCamera> LoopClockCamera<C> {
    /// `inner`, telling `scene` the time of each grab.
    pub fn new(inner: C, scene: RobotScene) -> Self {
        Self {
            inner,
            scene,
            stop: Arc::new(AtomicBool::new(false)),
        }
    }

    /// Set: the next grab ends the run.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// The camera inside.
    pub fn inner(&self) -> &C {
        &self.inner
    }

    fn check(&self, t_s: f64) -> Result<(), GrabError> {
        if self.stop.load(Ordering::Acquire) {
            return Err(GrabError::Stopped {
                reason: "the control thread ended the run".into(),
            });
        }
        self.scene.observe_loop_time(t_s);
        Ok(())
    }
}

impl<C: RoiCamera> RoiCamera for LoopClockCamera<C> {
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
        self.check(trigger.t_s)?;
        self.inner.grab_roi(trigger, image)
    }

    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
        self.check(t_s)?;
        self.inner.grab_full_frame(t_s, frame)
    }
}

/// The camera model of the servo's ROI camera for `config` (the canonical camera, ROIs read one after the other,
/// the timing's exposure), as [`crate::run_servo`] renders: give it to the camera that renders the live run.
///
/// ```
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
/// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
/// assert_eq!(roitrack_servo::live::roi_camera_model(&config).time.exposure_s, 100e-6);
/// ```
pub fn roi_camera_model(config: &ServoConfig) -> CameraModel {
    let mut camera = CameraModel::canonical();
    camera.time = TimeModel {
        readout: Readout::SequentialRois,
        exposure_s: config.camera_timing().exposure_s,
    };
    camera
}

/// The servo's target (the 4 x 4 grid), as [`crate::run_servo`] renders.
///
/// ```
/// assert_eq!(roitrack_servo::live::servo_target().points().len(), 16);
/// ```
pub fn servo_target() -> Target {
    Target::grid4x4()
}
