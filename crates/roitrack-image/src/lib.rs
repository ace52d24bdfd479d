//! # roitrack-image
//!
//! The image side of roitrack (docs/image-side.md), pure computation (no I/O, no threads), on images from any camera:
//!
//! - [`roi`]: regions of interest ([`Roi`]), centred on a predicted blob and clamped to the sensor, and the pixels a
//!   camera read in one ([`RoiImage`]); [`frame`]: full frames ([`Frame`]);
//! - [`camera`]: the cameras the real-time loop drives ([`RoiCamera`]: fallible, timestamped grabs into buffers the
//!   caller owns), a replay of recorded ROIs ([`ReplayCamera`]) and a camera whose ROIs are also shown to a callback
//!   ([`camera::ObservedCamera`]);
//! - [`centroid`]: the blob centroid of an ROI ([`measure_blob`]): threshold, connected component of the brightest
//!   pixel, first-order moments, a symmetry check against merged reflections ([`symmetry`]), allocation-free;
//! - [`measure`]: an ROI image's centroid as a timed measurement ([`measure_roi`]) and the tally of rejections;
//! - [`detect`]: blob detection in a full frame ([`detect_blobs`]) for initialisation;
//! - [`photo`]: blob detection in photographs ([`detect_photo_blobs`]): dark or bright blobs under uneven light, shape
//!   filters, grey-level sub-pixel centres;
//! - [`background`]: the background under a blob as a least-squares plane ([`background::fit_plane`]);
//! - [`window`]: one blob measured in a window of a frame around its predicted position, its background plane taken
//!   away ([`window::flatten_window`], [`window::measure_flat_window`]).
//!
//! The simulator that makes images to try all this on (the renderer and sensor model, the simulated ROI camera,
//! simulated reflections, the centroid's accuracy on rendered ROIs) is in `roitrack-sim`, so that this crate holds
//! only what runs on a real camera's pixels and needs no random numbers.
//!
//! Pixel convention (everywhere): pixel (i, j) (column i, row j) has its centre at image coordinates (u, v) = (i, j)
//! and covers [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5], as the raw pixels of [`roitrack_core::CameraModel`]. Images are
//! row-major `u16` buffers of values 0 to 2^bits - 1.
#![deny(missing_docs)]

pub mod background;
pub mod camera;
pub mod centroid;
mod components;
pub mod detect;
pub mod frame;
mod histogram;
pub mod measure;
pub mod photo;
pub mod roi;
pub mod symmetry;
pub mod window;

pub use camera::{GrabError, ReplayCamera, RoiCamera, RoiTrigger};
pub use centroid::{
    BlobRejection, Centroid, CentroidOptions, MAX_ROI_HEIGHT, MAX_ROI_WIDTH, SymmetryCheck,
    Threshold, measure_blob, measure_blob_near,
};
pub use detect::detect_blobs;
pub use frame::Frame;
pub use measure::{RejectionCounts, measure_roi};
pub use photo::{PhotoBlob, PhotoBlobOptions, PhotoScratch, Polarity, detect_photo_blobs};
pub use roi::{Roi, RoiImage};
