//! # roitrack-sim
//!
//! Ground-truth motions ([`scenario`]) and a measurement-level simulator of a camera that reads one ROI at a time
//! ([`measurements`]): every centroid is the projection of the true pose at its own exposure-midpoint time, with
//! Gaussian noise, dropped ROIs and outliers as options, and faults (occlusions, time gaps, bursts of lost ROIs, a
//! sudden jump of the target, blobs leaving the image); and the ROI images of a run, rendered by the simulated camera
//! ([`rois`]); and synthetic photographs of planar circle targets in cluttered, unevenly lit scenes, with the true
//! circle centres ([`photo`]); and the full frames a global- or rolling-shutter camera takes of a scenario, bright blobs
//! or dark ones on an unevenly lit background, with dense ground truth and each blob's true centre at its row time
//! ([`frames`]); and several ROI cameras around one scenario, each on its own clock, with the truth in the rig's frame
//! ([`multi_camera`]). A scenario's motion can be seen by any camera and carry any target
//! ([`Scenario::with_camera`], [`Scenario::with_target`]); the cameras of users' footage and the nominal files users
//! have for them are in [`user_cameras`].
#![deny(missing_docs)]

pub mod frames;
pub mod glints;
pub mod measurements;
pub mod multi_camera;
pub mod photo;
pub mod rigs;
pub mod rois;
pub mod scenario;
pub mod user_cameras;

pub use frames::{
    DARK_BLOB_CONTRAST, DEFAULT_TRUTH_RATE_HZ, FrameOptions, FrameSequence, FrameSequenceError,
    FrameTruth, MAX_FRAMES,
};
pub use measurements::{
    Excursion, Jump, MAX_ROI_RATE_HZ, MAX_SIMULATED_ROIS, Occlusion, RoiBurst, SimError,
    SimulatedRoi, SimulatedRun, Simulation, SimulationOptions, TimeGap, simulate,
};
pub use photo::{
    Background, CircleShade, Clutter, Glare, Illumination, PhotoError, PhotoPoint, PhotoScene,
    RenderedPhoto, Shadow, render_photo,
};
pub use rois::{RenderError, RoiImageRenderer, render_roi_images};
pub use scenario::{Scenario, ScenarioKind};
