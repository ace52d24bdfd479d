//! # roitrack-pipeline
//!
//! The system end to end, around the pure estimator: initialisation from a full frame ([`matching`]), the placement
//! of each next ROI ([`scheduler`]), and the real-time loop of two threads, acquisition and estimation, joined by
//! lock-free single-producer single-consumer queues ([`realtime`]).

pub mod cameras;
pub mod matching;
pub mod realtime;
pub mod scheduler;
