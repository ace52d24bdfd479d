//! # roitrack-image
//!
//! The image side of roitrack (docs/image-side.md), pure computation (no I/O, no threads):
//!
//! - [`roi`]: regions of interest ([`Roi`]), centred on a predicted blob and clamped to the sensor, and the pixels a
//!   camera read in one ([`RoiImage`]); [`frame`]: full frames ([`Frame`]);
//! - [`camera`]: the cameras the real-time loop drives ([`RoiCamera`]: fallible, timestamped grabs into buffers the
//!   caller owns), a simulated one ([`SimulatedCamera`]) and a replay of recorded ROIs ([`ReplayCamera`]);
//! - [`sensor`] and [`render`]: a simulated high-speed camera ([`RoiRenderer`], [`SensorModel`]) that renders ROIs or
//!   full frames of the target's blobs as exact perspective images of flat disks, with lens distortion, area coverage,
//!   optical and motion blur, shot and read noise and quantisation;
//! - [`centroid`]: the blob centroid of an ROI ([`measure_blob`]): threshold, connected component of the brightest
//!   pixel, first-order moments, a symmetry check against merged reflections ([`symmetry`]), allocation-free;
//! - [`measure`]: an ROI image's centroid as a timed measurement ([`measure_roi`]) and the tally of rejections;
//! - [`detect`]: blob detection in a full frame ([`detect_blobs`]) for initialisation;
//! - [`photo`]: blob detection in photographs ([`detect_photo_blobs`]): dark or bright blobs under uneven light, shape
//!   filters, grey-level sub-pixel centres;
//! - [`reflection`]: a simulated reflection, a second bright spot in an ROI ([`ReflectionFault`]);
//! - [`accuracy`]: the centroid's bias and spread against the truth ([`centroid_accuracy`]);
//! - [`background`]: the background under a blob as a least-squares plane ([`background::fit_plane`]);
//! - [`window`]: one blob measured in a window of a frame around its predicted position, its background plane taken
//!   away ([`window::flatten_window`], [`window::measure_flat_window`]).
//!
//! Pixel convention (everywhere): pixel (i, j) (column i, row j) has its centre at image coordinates (u, v) = (i, j)
//! and covers [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5], as the raw pixels of [`roitrack_core::CameraModel`]. Images are
//! row-major `u16` buffers of values 0 to 2^bits - 1.
#![deny(missing_docs)]

pub mod accuracy;
pub mod background;
pub mod camera;
pub mod centroid;
mod components;
pub mod detect;
pub mod frame;
mod histogram;
pub mod measure;
pub mod photo;
pub mod reflection;
pub mod render;
pub mod roi;
pub mod sensor;
pub mod symmetry;
pub mod window;

pub use accuracy::{CentroidAccuracy, ReflectionAccuracy, centroid_accuracy, reflection_accuracy};
pub use camera::{GrabError, ReplayCamera, RoiCamera, RoiTrigger, SimulatedCamera};
pub use centroid::{
    BlobRejection, Centroid, CentroidOptions, MAX_ROI_HEIGHT, MAX_ROI_WIDTH, SymmetryCheck,
    Threshold, measure_blob, measure_blob_near,
};
pub use detect::detect_blobs;
pub use frame::Frame;
pub use measure::{RejectionCounts, measure_roi};
pub use photo::{PhotoBlob, PhotoBlobOptions, PhotoScratch, Polarity, detect_photo_blobs};
pub use reflection::ReflectionFault;
pub use render::{DEFAULT_BLOB_DIAMETER_M, DiskOrientation, RenderScratch, RoiRenderer};
pub use roi::{Roi, RoiImage};
pub use sensor::{SensorError, SensorModel};
