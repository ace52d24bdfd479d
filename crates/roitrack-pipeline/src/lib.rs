//! # roitrack-pipeline
//!
//! The system end to end, around the pure estimator: the placement of each next ROI ([`scheduler`]), and the
//! real-time loop of two threads, acquisition and estimation, joined by lock-free single-producer single-consumer
//! queues ([`realtime`]), driving any [`roitrack_image::RoiCamera`]; the same loop for a rig of cameras that share no
//! clock, one acquisition thread per camera and one fused tracker ([`rig_loop`]); the same tracking offline, from recorded ROI
//! images ([`offline`]); and tracking from whole frames of a global or rolling shutter, one estimate per frame
//! ([`frames`]). Tracks start and restart from the target found in a whole image with no prior, by
//! `roitrack-detect`.
#![deny(missing_docs)]

pub mod frames;
pub mod offline;
pub mod realtime;
pub mod rig_loop;
pub mod rs_smoothing;
pub mod scheduler;

pub use frames::{
    FrameError, FrameMethod, FrameOutcome, FrameStreamError, FrameTrackReport, FrameTracker,
    FrameTrackerConfig, track_frame_stream, track_frame_stream_leaving_out,
};
pub use offline::{RoiEvent, RoiTrackReport, track_rois, track_rois_with};
pub use realtime::{
    AcquisitionCounts, LoopConfig, LoopReport, PipelineError, run_loop, run_loop_with_progress,
    run_loop_with_sink,
};
pub use rig_loop::{RigLoopReport, run_rig_loop};
pub use scheduler::{Predictor, RoiRequest, RoiScheduler, ScheduleOrder, SchedulerConfig};
