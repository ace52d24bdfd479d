//! # roitrack-pipeline
//!
//! The system end to end, around the pure estimator: finding the target in a full frame with no prior
//! ([`matching`], [`find_target`]) or in a photograph ([`photo`], [`detect_target`]: either polarity, clutter, partial
//! views, symmetric and hexagonal grids, by hypothesis and verification in [`identify`](mod@identify)), the placement
//! of each next ROI ([`scheduler`]), and the real-time loop of two threads, acquisition and estimation, joined by
//! lock-free single-producer single-consumer queues ([`realtime`]), driving any [`roitrack_image::RoiCamera`]; the same
//! tracking offline, from recorded ROI images ([`offline`]); and tracking from whole frames of a global or rolling
//! shutter, one estimate per frame ([`frames`]).
#![deny(missing_docs)]

pub mod frames;
pub mod identify;
pub mod matching;
pub mod offline;
pub mod photo;
pub mod realtime;
pub mod rs_smoothing;
pub mod scheduler;

pub use frames::{
    FrameError, FrameMethod, FrameOutcome, FrameStreamError, FrameTrackReport, FrameTracker,
    FrameTrackerConfig, track_frame_stream, track_frame_stream_leaving_out,
};
pub use identify::{Identification, identify};
pub use matching::{MatchError, TargetDetection, find_target, match_full_frame};
pub use offline::{RoiEvent, RoiTrackReport, track_rois, track_rois_with};
pub use photo::{
    PhotoDetection, PhotoError, PhotoOptions, PhotoPoint, PolarityChoice, detect_target,
};
pub use realtime::{
    LoopConfig, LoopReport, PipelineError, run_loop, run_loop_with_progress, run_loop_with_sink,
};
pub use scheduler::{Predictor, RoiRequest, RoiScheduler, ScheduleOrder, SchedulerConfig};
