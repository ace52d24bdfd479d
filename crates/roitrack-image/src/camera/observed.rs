//! [`ObservedCamera`]: any [`RoiCamera`] whose grabbed ROIs are also shown to a callback.

use super::{GrabError, RoiCamera, RoiTrigger};
use crate::{Frame, RoiImage};

/// A [`RoiCamera`] that hands every ROI it grabs, once grabbed, to `observe` (on the grabbing thread, before the
/// loop centroids it): a record of what the camera read, such as the ROI images of a ROS 2 bag. Full frames and
/// failed grabs are not shown. The observer's time is the grab's: a slow one slows the camera side.
///
/// ```
/// use roitrack_image::camera::ObservedCamera;
/// use roitrack_image::{Frame, ReplayCamera, Roi, RoiCamera, RoiImage, RoiTrigger};
///
/// let mut recorded = RoiImage::default();
/// recorded.set(0.0, 5, Roi::new(500, 500, 24, 24), 8);
/// let replay = ReplayCamera::new(vec![recorded], Frame::new(1024, 1024, 8));
/// let mut seen = Vec::new();
/// let mut camera = ObservedCamera::new(replay, |image: &RoiImage| {
///     seen.push((image.point_id, image.roi));
/// });
/// let trigger = RoiTrigger { point_id: 5, roi: Roi::new(500, 500, 24, 24), t_s: 0.0 };
/// camera.grab_roi(&trigger, &mut RoiImage::with_capacity(24 * 24)).unwrap();
/// drop(camera);
/// assert_eq!(seen, vec![(5, Roi::new(500, 500, 24, 24))]);
/// ```
#[derive(Debug)]
pub struct ObservedCamera<C, F> {
    camera: C,
    observe: F,
}

impl<C: RoiCamera, F: FnMut(&RoiImage) + Send> ObservedCamera<C, F> {
    /// `camera`, each of its ROIs also handed to `observe`.
    pub fn new(camera: C, observe: F) -> Self {
        Self { camera, observe }
    }

    /// The camera back.
    pub fn into_inner(self) -> C {
        self.camera
    }
}

impl<C: RoiCamera, F: FnMut(&RoiImage) + Send> RoiCamera for ObservedCamera<C, F> {
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
        self.camera.grab_roi(trigger, image)?;
        (self.observe)(image);
        Ok(())
    }

    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
        self.camera.grab_full_frame(t_s, frame)
    }
}
