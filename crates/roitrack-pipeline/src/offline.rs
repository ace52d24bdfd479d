//! Tracking recorded ROI images offline: each ROI's blob centroided and timed ([`roitrack_image::measure_roi`]), then
//! handed to an estimator, as the real-time loop does, but from a stream of images instead of a live camera.

use roitrack_core::TimeModel;
use roitrack_core::estimator::{Estimate, Estimator, EstimatorReport, StreamError, TrackError};
use roitrack_image::{CentroidOptions, RejectionCounts, RoiImage, measure_roi};

/// What [`track_rois`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
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
/// use roitrack_core::estimator::{Tracker, TrackerConfig};
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
        let m = match measure_roi(&image, options, time) {
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
            sink(&estimate).map_err(StreamError::Sink)?;
        }
    }
    report.estimator = estimator.report();
    Ok(report)
}
