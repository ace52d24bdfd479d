//! # roitrack-sim
//!
//! The simulator: a high-speed camera's images and the motions it sees, each with its ground truth.
//!
//! The simulated camera: [`sensor`] and [`render`], a simulated high-speed camera ([`RoiRenderer`], [`SensorModel`])
//! that renders ROIs or full frames of the target's blobs as exact perspective images of flat disks, with lens
//! distortion, area coverage, optical and motion blur, shot and read noise and quantisation; [`camera`], the ROI camera
//! the real-time loop drives that renders each ROI it is asked for from the true motion ([`SimulatedCamera`]), and a
//! replay of ROIs rendered beforehand; [`reflection`], a simulated reflection, a second bright spot in an ROI
//! ([`ReflectionFault`]); [`accuracy`], the centroid's bias and spread against the truth on rendered ROIs
//! ([`centroid_accuracy`], [`reflection_accuracy`]).
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

pub mod accuracy;
pub mod camera;
pub mod frames;
pub mod glints;
pub mod measurements;
pub mod multi_camera;
pub mod photo;
pub mod reflection;
pub mod render;
pub mod rigs;
pub mod rois;
pub mod scenario;
pub mod sensor;
pub mod user_cameras;

pub use accuracy::{CentroidAccuracy, ReflectionAccuracy, centroid_accuracy, reflection_accuracy};
pub use camera::SimulatedCamera;
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
pub use reflection::ReflectionFault;
pub use render::{DEFAULT_BLOB_DIAMETER_M, DiskOrientation, RenderScratch, RoiRenderer};
pub use rois::{RenderError, RoiImageRenderer, render_roi_images};
pub use scenario::{Scenario, ScenarioKind};
pub use sensor::{SensorError, SensorModel};
