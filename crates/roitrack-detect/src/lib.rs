//! # roitrack-detect
//!
//! Finding a known target in a whole image with no prior: the blobs of a full frame matched to the model
//! ([`matching`], [`find_target`]), and the target detected in a photograph ([`photo`], [`detect_target`]: either
//! polarity, clutter, partial views, symmetric and hexagonal grids). Which blob is which model point is decided by
//! hypothesis and verification ([`identify`](mod@identify): lattice growth for grids, triples of blobs for other
//! layouts), each labelling judged against its rivals under the noise the camera and the model's own error predict.
//! The blobs themselves come from `roitrack-image`; the poses from the static pose of `roitrack-estimators`. The
//! frame tracker and the real-time loop (`roitrack-pipeline`) start and restart their tracks from here.
#![deny(missing_docs)]

pub mod identify;
pub mod matching;
pub mod photo;

pub use identify::{Identification, identify};
pub use matching::{MatchError, TargetDetection, find_target, match_full_frame};
pub use photo::{
    PhotoDetection, PhotoError, PhotoOptions, PhotoPoint, PolarityChoice, detect_target,
};
