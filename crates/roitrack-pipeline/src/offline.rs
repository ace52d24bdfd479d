//! Tracking recorded ROI images offline: each ROI's blob centroided and timed ([`roitrack_image::measure_roi`]), then
//! handed to an estimator, as the real-time loop does, but from a stream of images instead of a live camera.

use roitrack_core::Measurement;
use roitrack_core::TimeModel;
use roitrack_estimators::{Estimate, Estimator, EstimatorReport, StreamError, TrackError};
use roitrack_image::{BlobRejection, CentroidOptions, RejectionCounts, RoiImage, measure_roi};

/// What [`track_rois`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RoiTrackReport {
    /// ROI images read.
    pub rois: usize,
    /// Blobs the centroid rejected, by reason (their ROIs gave no measurement).
    pub rejections: RejectionCounts,
    /// The estimator's own counts.
    pub estimator: EstimatorReport,
}

/// Tracks a stream of ROI images (times not decreasing): each image's blob is centroided with `options` and timed
/// by `time` (the camera's time model), then pushed to `estimator`; every estimate goes to `sink` as it comes
/// (constant memory). An image of a point the target does not have is refused (with its index in the stream), as is
/// a measurement the estimator refuses.
///
/// ```
/// use roitrack_core::TimeModel;
/// use roitrack_estimators::{Tracker, TrackerConfig};
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::{CentroidOptions, Roi, RoiImage};
/// use roitrack_pipeline::offline::track_rois;
///
/// let mut tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
/// let mut dark = RoiImage::default();
/// dark.set(0.0, 5, Roi::new(500, 500, 24, 24), 8);
/// let report = track_rois(
///     &mut tracker,
///     &CentroidOptions::default(),
///     &TimeModel::default(),
///     [Ok::<_, std::io::Error>(dark)],
///     |_estimate| Ok::<_, std::io::Error>(()),
/// )
/// .unwrap();
/// // A dark ROI holds no blob.
/// assert_eq!((report.rois, report.rejections.absent, report.estimator.measurements), (1, 1, 0));
/// ```
pub fn track_rois<S, K>(
    estimator: &mut dyn Estimator,
    options: &CentroidOptions,
    time: &TimeModel,
    images: impl IntoIterator<Item = Result<RoiImage, S>>,
    mut sink: impl FnMut(&Estimate) -> Result<(), K>,
) -> Result<RoiTrackReport, StreamError<S, K>> {
    track_rois_with(estimator, options, time, images, |event| match event {
        RoiEvent::Estimate(e) => sink(e),
        RoiEvent::Roi { .. } => Ok(()),
    })
}

/// What [`track_rois_with`] hands its observer, in the order it happens.
#[derive(Debug, Clone, Copy)]
pub enum RoiEvent<'a> {
    /// A ROI image read and centroided, before its measurement goes to the estimator: `measured` is the measurement
    /// (the centroid in the sensor's pixels, at its time) or why the blob was rejected.
    Roi {
        /// The ROI image as read: its point id, its place on the sensor, its time and its pixels.
        image: &'a RoiImage,
        /// The measurement its blob gave, or why the blob was rejected (then nothing goes to the estimator).
        measured: Result<&'a Measurement, BlobRejection>,
    },
    /// An estimate.
    Estimate(&'a Estimate),
}

/// [`track_rois`], with every ROI (its image and what its centroid gave) as well as every estimate handed to
/// `observe`, so that a consumer can record what the tracker saw (the ROS 2 bag's ROI images and measurements).
///
/// ```
/// use roitrack_core::TimeModel;
/// use roitrack_estimators::{Tracker, TrackerConfig};
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::{CentroidOptions, Roi, RoiImage};
/// use roitrack_pipeline::offline::{RoiEvent, track_rois_with};
///
/// let mut tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
/// let mut dark = RoiImage::default();
/// dark.set(0.0, 5, Roi::new(500, 500, 24, 24), 8);
/// let mut rejected = 0;
/// track_rois_with(
///     &mut tracker,
///     &CentroidOptions::default(),
///     &TimeModel::default(),
///     [Ok::<_, std::io::Error>(dark)],
///     |event| {
///         if let RoiEvent::Roi { measured: Err(_), .. } = event {
///             rejected += 1;
///         }
///         Ok::<_, std::io::Error>(())
///     },
/// )
/// .unwrap();
/// assert_eq!(rejected, 1);
/// ```
pub fn track_rois_with<S, K>(
    estimator: &mut dyn Estimator,
    options: &CentroidOptions,
    time: &TimeModel,
    images: impl IntoIterator<Item = Result<RoiImage, S>>,
    mut observe: impl FnMut(RoiEvent<'_>) -> Result<(), K>,
) -> Result<RoiTrackReport, StreamError<S, K>> {
    let mut report = RoiTrackReport::default();
    for (index, image) in images.into_iter().enumerate() {
        let image = image.map_err(StreamError::Source)?;
        report.rois += 1;
        if estimator.target().index_of(image.point_id).is_none() {
            return Err(StreamError::Refused {
                index,
                source: TrackError::UnknownId {
                    t_s: image.t_s,
                    id: image.point_id,
                },
            });
        }
        let measured = measure_roi(&image, options, time);
        observe(RoiEvent::Roi {
            image: &image,
            measured: measured.as_ref().map_err(|r| *r),
        })
        .map_err(StreamError::Sink)?;
        let m = match measured {
            Ok(m) => m,
            Err(rejection) => {
                report.rejections.count(&rejection);
                continue;
            }
        };
        if let Some(estimate) = estimator
            .push(&m)
            .map_err(|source| StreamError::Refused { index, source })?
        {
            observe(RoiEvent::Estimate(&estimate)).map_err(StreamError::Sink)?;
        }
    }
    report.estimator = estimator.report();
    Ok(report)
}
