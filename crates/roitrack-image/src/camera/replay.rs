//! A camera that plays back ROIs read earlier.

use super::{GrabError, RoiCamera, RoiTrigger};
use crate::{Frame, RoiImage};

/// Replays recorded ROIs in order, whatever is requested (for throughput benchmarks, where rendering must not count,
/// such as the rendered ROIs of `roitrack_sim::camera::prerendered_replay`, and for recorded camera data), each with
/// its recorded time (or, [`ReplayCamera::with_trigger_times`], the time it is asked for), then ends
/// ([`GrabError::EndOfRecording`]); its full frame comes with the time it is asked for. The schedule that recorded
/// the ROIs must match the one that replays them: a request for another point than the recorded one is counted in
/// [`ReplayCamera::mismatches`].
///
/// ```
/// use roitrack_image::{GrabError, Frame, Roi, RoiCamera, RoiImage, RoiTrigger, ReplayCamera};
///
/// let mut recorded = RoiImage::default();
/// recorded.set(0.5, 3, Roi::new(0, 0, 4, 4), 8);
/// let mut camera = ReplayCamera::new(vec![recorded], Frame::new(8, 8, 8));
/// let mut image = RoiImage::default();
/// let trigger = RoiTrigger { point_id: 3, roi: Roi::new(0, 0, 4, 4), t_s: 0.5 };
/// camera.grab_roi(&trigger, &mut image).unwrap();
/// assert_eq!(image.t_s, 0.5);
/// assert_eq!(camera.grab_roi(&trigger, &mut image), Err(GrabError::EndOfRecording));
/// ```
#[derive(Debug, Clone)]
pub struct ReplayCamera {
    rois: Vec<RoiImage>,
    full_frame: Frame,
    cursor: usize,
    /// Stamp each ROI with the time it was asked for instead of its recorded time.
    trigger_times: bool,
    /// Requests for another point than the recorded ROI's.
    pub mismatches: usize,
}

impl ReplayCamera {
    /// A camera that gives `rois` in order and `full_frame` when a full frame is asked for.
    pub fn new(rois: Vec<RoiImage>, full_frame: Frame) -> Self {
        Self {
            rois,
            full_frame,
            cursor: 0,
            trigger_times: false,
            mismatches: 0,
        }
    }

    /// The same replay, each ROI taken as exposed when it is asked for (its trigger time) rather than when it was
    /// recorded: for benchmarks that replay the same pixels at another rate, as a live camera would expose them.
    pub fn with_trigger_times(mut self) -> Self {
        self.trigger_times = true;
        self
    }

    /// Number of ROIs recorded.
    pub fn len(&self) -> usize {
        self.rois.len()
    }

    /// Whether the recording holds no ROI.
    pub fn is_empty(&self) -> bool {
        self.rois.is_empty()
    }

    /// Starts the replay again from the first ROI.
    pub fn rewind(&mut self) {
        self.cursor = 0;
        self.mismatches = 0;
    }
}

impl RoiCamera for ReplayCamera {
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
        let recorded = self
            .rois
            .get(self.cursor)
            .ok_or(GrabError::EndOfRecording)?;
        self.cursor += 1;
        if recorded.point_id != trigger.point_id {
            self.mismatches += 1;
        }
        let t_s = if self.trigger_times {
            trigger.t_s
        } else {
            recorded.t_s
        };
        image.set(t_s, recorded.point_id, recorded.roi, recorded.bit_depth);
        image.pixels.copy_from_slice(&recorded.pixels);
        Ok(())
    }

    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
        let recorded = &self.full_frame;
        frame.resize(recorded.width, recorded.height, recorded.bit_depth);
        frame.pixels.copy_from_slice(&recorded.pixels);
        frame.t_s = t_s;
        Ok(())
    }
}
