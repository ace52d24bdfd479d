//! Measuring ROI images: the blob centroid of a grabbed or recorded [`RoiImage`] as a timed measurement, and the
//! tally of blobs rejected, by reason. The real-time loop and the offline tracking of recordings both measure here.

use roitrack_core::{Measurement, TimeModel};

use crate::{
    BlobRejection, CentroidOptions, MAX_ROI_HEIGHT, MAX_ROI_WIDTH, RoiImage, measure_blob,
};

/// The centroid of an ROI image's blob as a measurement of its target point, timed by the camera's time model (a
/// rolling-shutter ROI's blob is at its own row's time, counted from the ROI's first row); a blob the centroid
/// rejects, an ROI too large for it, or an image whose pixel buffer does not match its ROI (nothing to measure) is a
/// rejection.
///
/// ```
/// use roitrack_core::TimeModel;
/// use roitrack_image::{CentroidOptions, Roi, RoiImage, measure_roi};
///
/// // A 3 x 3 square blob of value 200 centred on pixel (10, 20) of a dark 9 x 9 ROI whose corner is (6, 16).
/// let mut image = RoiImage::default();
/// image.set(0.125, 4, Roi::new(6, 16, 9, 9), 8);
/// for j in 3..6 {
///     for i in 3..6 {
///         image.pixels[j * 9 + i] = 200;
///     }
/// }
/// let m = measure_roi(&image, &CentroidOptions::default(), &TimeModel::default()).unwrap();
/// assert_eq!((m.t_s, m.id), (0.125, 4));
/// assert!((m.u_px - 10.0).abs() < 1e-9 && (m.v_px - 20.0).abs() < 1e-9);
/// ```
pub fn measure_roi(
    image: &RoiImage,
    options: &CentroidOptions,
    time: &TimeModel,
) -> Result<Measurement, BlobRejection> {
    let roi = &image.roi;
    if !image.is_consistent() {
        return Err(BlobRejection::Absent);
    }
    if roi.width > MAX_ROI_WIDTH || roi.height > MAX_ROI_HEIGHT {
        return Err(BlobRejection::TooLarge {
            area_px: roi.width * roi.height,
        });
    }
    let c = measure_blob(&image.pixels, roi, options)?;
    Ok(Measurement {
        t_s: time.blob_time_s(image.t_s, c.v_px - f64::from(roi.y0)),
        id: image.point_id,
        u_px: c.u_px,
        v_px: c.v_px,
    })
}

/// Counts of rejected blobs, by reason.
///
/// ```
/// use roitrack_image::{BlobRejection, RejectionCounts};
/// let mut counts = RejectionCounts::default();
/// counts.count(&BlobRejection::Absent);
/// counts.count(&BlobRejection::Asymmetric);
/// assert_eq!(counts.total(), 2);
/// assert!(counts.to_string().starts_with("1 absent"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RejectionCounts {
    /// No blob in the ROI.
    pub absent: usize,
    /// The ROI cut the blob.
    pub touches_border: usize,
    /// Too few pixels.
    pub too_small: usize,
    /// Too many pixels.
    pub too_large: usize,
    /// Not centrally symmetric: a reflection or an occluder merged with the blob.
    pub asymmetric: usize,
}

impl RejectionCounts {
    /// Counts one rejection.
    pub fn count(&mut self, r: &BlobRejection) {
        match r {
            BlobRejection::Absent => self.absent += 1,
            BlobRejection::TouchesBorder => self.touches_border += 1,
            BlobRejection::TooSmall { .. } => self.too_small += 1,
            BlobRejection::TooLarge { .. } => self.too_large += 1,
            BlobRejection::Asymmetric => self.asymmetric += 1,
        }
    }

    /// Every rejection counted.
    pub fn total(&self) -> usize {
        self.absent + self.touches_border + self.too_small + self.too_large + self.asymmetric
    }
}

impl std::fmt::Display for RejectionCounts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} absent, {} touching the ROI border, {} too small, {} too large, {} asymmetric",
            self.absent, self.touches_border, self.too_small, self.too_large, self.asymmetric
        )
    }
}
