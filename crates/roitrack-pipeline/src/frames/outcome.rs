//! What the frame tracker gives: each frame's outcome and how it was measured, the tally of a run, and why a frame
//! could not be processed.

use roitrack_core::estimator::{Estimate, EstimatorReport, TrackError};
use roitrack_image::{Polarity, RejectionCounts};
use thiserror::Error;

#[cfg(doc)]
use super::FrameTracker;
#[cfg(doc)]
use crate::photo::PolarityChoice;

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
    pub method: FrameMethod,
    /// Blobs measured in the frame.
    pub measured: usize,
}

/// What a [`FrameTracker`] has done.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameTrackReport {
    pub frames: usize,
    /// Frames measured in windows, by a full-frame search that continued the track, or that started a new one.
    pub by_windows: usize,
    pub by_full_frame: usize,
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
    pub estimator: EstimatorReport,
}

/// Why a frame could not be processed at all (a frame in which the target is not found is not an error).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FrameError {
    #[error("the frame is {width} x {height} px, the camera's {camera_width} x {camera_height} px")]
    Size {
        width: u32,
        height: u32,
        camera_width: u32,
        camera_height: u32,
    },
    #[error("the frame's time is not finite ({0})")]
    Time(f64),
    #[error(
        "the frame's time {t_s} s does not come after the previous frame's measurements ({previous_s} s): frame times \
         must increase, and a rolling shutter's readout must end before the next frame starts"
    )]
    TimeOrder { t_s: f64, previous_s: f64 },
    #[error("the estimator refused a measurement: {0}")]
    Refused(#[from] TrackError),
}
