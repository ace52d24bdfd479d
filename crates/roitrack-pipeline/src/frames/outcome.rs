//! What the frame tracker gives: each frame's outcome and how it was measured, the tally of a run, and why a frame
//! could not be processed.

use roitrack_estimators::{Estimate, EstimatorReport, TrackError};
use roitrack_image::{Polarity, RejectionCounts};
use thiserror::Error;

#[cfg(doc)]
use super::FrameTracker;
#[cfg(doc)]
use roitrack_detect::photo::PolarityChoice;

/// How a frame was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameMethod {
    /// In windows around the predicted blobs.
    Windows,
    /// By a full-frame search, continuing the track.
    FullFrame,
    /// By a full-frame search that started a new track.
    Restart,
    /// The target was not found: no estimate.
    NotFound,
}

impl FrameMethod {
    /// `windows`, `full-frame`, `restart` or `not-found`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Windows => "windows",
            Self::FullFrame => "full-frame",
            Self::Restart => "restart",
            Self::NotFound => "not-found",
        }
    }
}

/// What one frame gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOutcome {
    /// The frame's estimate, if the target was measured and the estimator gave one.
    pub estimate: Option<Estimate>,
    /// How the frame was measured ([`FrameMethod::NotFound`]: not at all, and `estimate` is `None`).
    pub method: FrameMethod,
    /// Blobs measured in the frame.
    pub measured: usize,
}

/// What a [`FrameTracker`] has done.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTrackReport {
    /// Frames taken by [`FrameTracker::process`]: all but those refused for their size or their time.
    pub frames: usize,
    /// Frames measured in windows around the predicted blobs ([`FrameMethod::Windows`]).
    pub by_windows: usize,
    /// Frames measured by a full-frame search that continued the running track ([`FrameMethod::FullFrame`]).
    pub by_full_frame: usize,
    /// Frames that started a new track from the target identified whole ([`FrameMethod::Restart`]): the first
    /// frame, a frame after a lost track, or one whose estimate disagreed with its blobs.
    pub restarts: usize,
    /// Frames in which the target was not found.
    pub not_found: usize,
    /// Frames that gave an estimate.
    pub estimates: usize,
    /// Blobs not found in their windows, by reason.
    pub window_rejections: RejectionCounts,
    /// Blobs left out of their windows because they were nearer another point's prediction than their own: a
    /// neighbour of a dense target, when the point's own blob was not seen or the prediction missed it.
    pub neighbour_blobs: usize,
    /// The weight of the blobs' outlines in the centres of the last frame measured in windows (their moments' is 1
    /// minus it; see `CentreBlend` in the source); 0 before any.
    pub outline_weight: f64,
    /// The polarity in use (decided by the first full-frame search with [`PolarityChoice::Auto`]).
    pub polarity: Option<Polarity>,
    /// The estimator's own counts (measurements, estimates by status, gated measurements, covariance resets). They
    /// include the estimates of frames whose track was replaced by a new one within the frame, which `estimates`
    /// counts once.
    pub estimator: EstimatorReport,
}

/// Why a frame could not be processed at all (a frame in which the target is not found is not an error).
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::Frame;
/// use roitrack_pipeline::frames::{FrameError, FrameTracker, FrameTrackerConfig};
///
/// let mut tracker =
///     FrameTracker::new(CameraModel::canonical(), Target::grid4x4(), FrameTrackerConfig::default()).unwrap();
/// let mut frame = Frame::default();
/// frame.resize(640, 480, 8);
/// assert!(matches!(tracker.process(&frame), Err(FrameError::Size { width: 640, camera_width: 1024, .. })));
/// frame.resize(1024, 1024, 8);
/// frame.t_s = 0.1;
/// assert!(tracker.process(&frame).is_ok()); // a black frame: no target, no error
/// frame.t_s = 0.05;
/// assert!(matches!(tracker.process(&frame), Err(FrameError::TimeOrder { .. })));
/// ```
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FrameError {
    /// The frame is not of the camera model's size.
    #[error("the frame is {width} x {height} px, the camera's {camera_width} x {camera_height} px")]
    Size {
        /// The frame's width (px).
        width: u32,
        /// The frame's height (px).
        height: u32,
        /// The camera model's image width (px).
        camera_width: u32,
        /// The camera model's image height (px).
        camera_height: u32,
    },
    /// The frame's time `t_s` (the value given, s) is NaN or infinite.
    #[error("the frame's time is not finite ({0})")]
    Time(f64),
    /// The frame's time is not after the latest time of the frame tracked before it: frame times must increase,
    /// and a rolling shutter's readout must end before the next frame starts.
    #[error(
        "the frame's time {t_s} s does not come after the previous frame's measurements ({previous_s} s): frame times \
         must increase, and a rolling shutter's readout must end before the next frame starts"
    )]
    TimeOrder {
        /// The frame's time (s): the mid-exposure time of its row 0.
        t_s: f64,
        /// The latest time of the frame before (s): its row 0's or its last measurement's, whichever is later.
        previous_s: f64,
    },
    /// The estimator refused a measurement of the frame, or of the recent frames a new track is fitted to.
    #[error("the estimator refused a measurement: {0}")]
    Refused(#[from] TrackError),
}
