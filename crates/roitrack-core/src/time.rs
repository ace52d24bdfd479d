//! When a measurement was taken: the one place that turns a camera's readout into the time of each blob.
//!
//! The spatio-temporal model gives every blob centroid its own time. How that time follows from what the camera
//! reports depends on how the camera reads its pixels:
//!
//! - [`Readout::SequentialRois`]: the camera exposes and reads one small region of interest at a time (the paper's
//!   camera); a blob's time is the exposure mid-time of its ROI.
//! - [`Readout::GlobalShutter`]: every pixel of a frame is exposed over the same interval; every blob of the frame is
//!   at the frame's mid-exposure time.
//! - [`Readout::RollingShutter`]: rows are exposed one after another, `line_delay_s` apart; a blob centred on row `v`
//!   is at `t0 + v * line_delay_s`, where `t0` is the mid-exposure time of row 0. The line delay is the sensor's
//!   readout time divided by its number of rows (datasheet, or a calibration).
//!
//! A [`TimeModel`] also holds the exposure duration, which the simulated camera uses for motion blur and the ROI
//! scheduler for the blob's motion during the exposure. It is part of the [`crate::CameraModel`], so it is configured
//! once, with the camera.

use thiserror::Error;

/// How the camera reads its pixels (see the [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Readout {
    /// One ROI at a time; each ROI's time is its exposure mid-time.
    #[default]
    SequentialRois,
    /// Whole frames, every pixel exposed over the same interval.
    GlobalShutter,
    /// Whole frames, row `v` exposed `v * line_delay_s` after row 0.
    RollingShutter {
        /// The time (s) between the exposures of two successive rows: the sensor's readout time over its rows.
        line_delay_s: f64,
    },
}

/// When each blob of a readout was taken, and for how long it was exposed.
///
/// ```
/// use roitrack_core::time::{Readout, TimeModel};
///
/// // A rolling-shutter camera reading 1,000 rows in 10 ms: 10 µs a row.
/// let rolling = TimeModel { readout: Readout::RollingShutter { line_delay_s: 10e-6 }, exposure_s: 1e-3 };
/// assert!((rolling.blob_time_s(2.0, 500.0) - 2.005).abs() < 1e-12);
/// // A global shutter puts every blob of the frame at the frame's time.
/// let global = TimeModel { readout: Readout::GlobalShutter, ..rolling };
/// assert_eq!(global.blob_time_s(2.0, 500.0), 2.0);
/// assert!(rolling.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeModel {
    /// How the camera reads its pixels, which sets each blob's time.
    pub readout: Readout,
    /// Exposure duration (s), centred on each blob's time.
    pub exposure_s: f64,
}

impl Default for TimeModel {
    /// Sequential ROIs exposed for 100 µs (the paper's camera).
    fn default() -> Self {
        Self {
            readout: Readout::SequentialRois,
            exposure_s: 100e-6,
        }
    }
}

/// Why a time model is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TimeModelError {
    /// The exposure given (s) is outside 0 to [`MAX_EXPOSURE_S`], or not finite.
    #[error("the exposure must be from 0 to {MAX_EXPOSURE_S} s, got {0} s")]
    Exposure(f64),
    /// The rolling shutter's line delay given (s) is outside 0 to [`MAX_LINE_DELAY_S`], or not finite.
    #[error(
        "the rolling shutter's line delay must be from 0 to {MAX_LINE_DELAY_S} s (a 1,000-row frame read in a second), \
         got {0} s"
    )]
    LineDelay(f64),
}

/// The longest exposure (s) a time model may have: over 10 s a moving target is a streak, not a blob.
pub const MAX_EXPOSURE_S: f64 = 10.0;
/// The longest line delay (s) of a rolling shutter: 1 ms a row, a 1,000-row frame read in a second (real sensors
/// take 5 to 50 µs a row).
pub const MAX_LINE_DELAY_S: f64 = 1e-3;

impl TimeModel {
    /// Refuses an exposure outside 0 to [`MAX_EXPOSURE_S`] and a line delay outside 0 to [`MAX_LINE_DELAY_S`]
    /// (non-finite values included).
    ///
    /// ```
    /// use roitrack_core::time::{Readout, TimeModel};
    ///
    /// let slow = TimeModel { readout: Readout::RollingShutter { line_delay_s: 0.5 }, exposure_s: 1e-3 };
    /// assert!(slow.validate().unwrap_err().to_string().contains("line delay must be from 0 to 0.001 s"));
    /// ```
    pub fn validate(&self) -> Result<(), TimeModelError> {
        if !(0.0..=MAX_EXPOSURE_S).contains(&self.exposure_s) {
            return Err(TimeModelError::Exposure(self.exposure_s));
        }
        if let Readout::RollingShutter { line_delay_s } = self.readout
            && !(0.0..=MAX_LINE_DELAY_S).contains(&line_delay_s)
        {
            return Err(TimeModelError::LineDelay(line_delay_s));
        }
        Ok(())
    }

    /// The mid-exposure time (s) of a blob centred `rows` rows below the first row of a readout (an ROI, or a frame)
    /// whose timestamp `t_s` is the mid-exposure time of that first row: `t_s` but for a rolling shutter, `t_s + rows *
    /// line_delay_s`. For a frame, `rows` is the blob's row `v_px`; for an ROI whose first row is `y0`, `v_px - y0`.
    #[inline]
    pub fn blob_time_s(&self, t_s: f64, rows: f64) -> f64 {
        match self.readout {
            Readout::SequentialRois | Readout::GlobalShutter => t_s,
            Readout::RollingShutter { line_delay_s } => t_s + rows * line_delay_s,
        }
    }

    /// The interval (s) over which a blob whose mid-exposure time is `t_mid_s` was exposed.
    #[inline]
    pub fn exposure_interval_s(&self, t_mid_s: f64) -> (f64, f64) {
        let half = 0.5 * self.exposure_s;
        (t_mid_s - half, t_mid_s + half)
    }

    /// Whether blobs of one readout can have different times (a rolling shutter with a non-zero line delay).
    pub fn is_rolling(&self) -> bool {
        matches!(self.readout, Readout::RollingShutter { line_delay_s } if line_delay_s > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blob_times_follow_the_readout() {
        let base = TimeModel::default();
        assert_eq!(base.blob_time_s(1.5, 700.0), 1.5);
        let rolling = TimeModel {
            readout: Readout::RollingShutter { line_delay_s: 2e-5 },
            ..base
        };
        assert!((rolling.blob_time_s(1.0, 0.0) - 1.0).abs() < 1e-15);
        assert!((rolling.blob_time_s(1.0, 100.0) - 1.002).abs() < 1e-15);
        assert!(rolling.is_rolling() && !base.is_rolling());
        let (start, end) = base.exposure_interval_s(1.0);
        assert!((end - start - 100e-6).abs() < 1e-15 && (0.5 * (start + end) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn bad_times_are_refused() {
        let bad_exposure = TimeModel {
            exposure_s: -1e-3,
            ..TimeModel::default()
        };
        assert_eq!(
            bad_exposure.validate(),
            Err(TimeModelError::Exposure(-1e-3))
        );
        let bad_delay = TimeModel {
            readout: Readout::RollingShutter {
                line_delay_s: f64::NAN,
            },
            ..TimeModel::default()
        };
        assert!(matches!(
            bad_delay.validate(),
            Err(TimeModelError::LineDelay(_))
        ));
    }
}
