//! Cameras that read one ROI at a time: the trait the real-time loop drives ([`RoiCamera`]), what can go wrong
//! ([`GrabError`]), and two cameras of roitrack's own: [`ReplayCamera`], which plays back ROIs read earlier, and
//! [`ObservedCamera`], which shows another camera's ROIs to a callback. The simulated camera, which renders the true
//! motion, is `roitrack_sim::SimulatedCamera`.
//!
//! Grabbing is fallible, because real cameras time out, drop buffers and disconnect, and it fills buffers the caller
//! owns ([`RoiImage`], [`Frame`]), so that a loop running at kHz rates allocates nothing.

mod observed;
mod replay;

use thiserror::Error;

pub use observed::ObservedCamera;
pub use replay::ReplayCamera;

use crate::{Frame, Roi, RoiImage};

/// What the loop asks a camera for: expose `roi` (placed on target point `point_id`) around time `t_s`.
///
/// Times are on the loop's clock (that of its trigger times, [`crate::RoiImage::t_s`] and the estimates): a camera
/// whose images carry timestamps of its own clock converts them to the loop's, e.g. from the offset it measures
/// between the two.
///
/// ```
/// use roitrack_image::{Roi, RoiTrigger};
/// let trigger = RoiTrigger { point_id: 3, roi: Roi::new(100, 100, 24, 24), t_s: 0.25 };
/// assert_eq!(trigger.roi.len(), 576);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoiTrigger {
    /// The target point the ROI is for.
    pub point_id: u32,
    /// The window to read.
    pub roi: Roi,
    /// Requested mid-exposure time (s). The camera reports the time it actually exposed in the [`RoiImage`].
    pub t_s: f64,
}

/// Why a grab gave no image.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum GrabError {
    /// No image within the camera's timeout: the grab may be retried.
    #[error("the camera gave no image within {timeout_s} s")]
    Timeout {
        /// The camera's timeout.
        timeout_s: f64,
    },
    /// The camera delivered an incomplete or corrupt buffer, or dropped it: the grab may be retried.
    #[error("the camera dropped the image: {reason}")]
    Dropped {
        /// What the camera said.
        reason: String,
    },
    /// The camera cannot be asked for this ROI (off the sensor, too large, or not on its increments).
    #[error("the camera cannot read ROI {roi:?}: {reason}")]
    InvalidRoi {
        /// The window asked for.
        roi: Roi,
        /// Why the camera cannot read it.
        reason: String,
    },
    /// The camera is gone (unplugged, powered off, the link lost): nothing more will come.
    #[error("the camera is disconnected: {reason}")]
    Disconnected {
        /// What the camera's driver said.
        reason: String,
    },
    /// A replayed recording has no more images.
    #[error("the recording has no more images")]
    EndOfRecording,
    /// The run was asked to stop (Ctrl-C): a live camera ends the run like the end of a recording, and what was
    /// estimated until then is kept.
    #[error("stopped: {reason}")]
    Stopped {
        /// What asked it to stop.
        reason: String,
    },
    /// The camera's frames are not the size its camera model says: the calibration is of another camera, or of
    /// another mode.
    #[error(
        "the camera delivered a {width} x {height} frame, its camera model is {expected_width} x {expected_height}"
    )]
    FrameSize {
        /// The frame's width (px).
        width: u32,
        /// The frame's height (px).
        height: u32,
        /// The camera model's width (px).
        expected_width: u32,
        /// The camera model's height (px).
        expected_height: u32,
    },
}

impl GrabError {
    /// Whether later grabs may succeed (a timeout, a dropped buffer, a bad ROI request), as opposed to the end of
    /// the camera (disconnected, end of recording).
    pub fn is_transient(&self) -> bool {
        matches!(
            self,
            Self::Timeout { .. } | Self::Dropped { .. } | Self::InvalidRoi { .. }
        )
    }
}

/// A camera that reads one ROI at a time and, to initialise, a full frame.
///
/// An implementation for a camera of your own needs the two grabs; the real-time loop places the ROIs, centroids them
/// and tracks. See `examples/own_camera.rs` of the `roitrack` crate for a complete one.
///
/// ```
/// use roitrack_image::{GrabError, Frame, Roi, RoiCamera, RoiImage, RoiTrigger};
///
/// /// A camera that sees a black scene.
/// struct Dark;
/// impl RoiCamera for Dark {
///     fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
///         image.set(trigger.t_s, trigger.point_id, trigger.roi, 8);
///         image.pixels.fill(0);
///         Ok(())
///     }
///     fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
///         frame.resize(640, 480, 8);
///         frame.t_s = t_s;
///         frame.pixels.fill(0);
///         Ok(())
///     }
/// }
/// let mut image = RoiImage::with_capacity(32 * 32);
/// let trigger = RoiTrigger { point_id: 0, roi: Roi::new(10, 10, 32, 32), t_s: 1.0 };
/// Dark.grab_roi(&trigger, &mut image).unwrap();
/// assert_eq!((image.t_s, image.pixels.len()), (1.0, 1024));
/// ```
pub trait RoiCamera: Send {
    /// Exposes and reads the ROI of `trigger`; fills `image` with its pixels, the ROI actually read (a camera may
    /// move it onto its increments) and the actual mid-exposure time of its first row, on the loop's clock (see
    /// [`RoiTrigger`]). The pixel buffer is reused: within its capacity this must not allocate.
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError>;

    /// Reads a full frame exposed around `t_s` into `frame` (resized to the sensor; its buffer is reused).
    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError>;
}
