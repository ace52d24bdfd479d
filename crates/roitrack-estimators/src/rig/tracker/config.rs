//! The rig tracker's options ([`RigTrackerConfig`]) and why it refuses a measurement or its options
//! ([`RigError`]).

use thiserror::Error;

#[cfg(doc)]
use super::RigTracker;
use crate::{ConfigError, TrackError, TrackerConfig};

/// Options of a [`RigTracker`].
///
/// ```
/// use roitrack_estimators::rig::RigTrackerConfig;
/// let config = RigTrackerConfig::default();
/// assert_eq!(config.max_offset_s, 0.1);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigTrackerConfig {
    /// The options of every camera's own tracker, and of the fused one: `every` (an estimate every `every` fused
    /// measurements), `noise_px` (the starting noise), the Kalman tuning (the gate, the densities and whether the
    /// process noise adapts).
    pub tracker: TrackerConfig,
    /// The search for an unknown clock offset spans `±max_offset_s` (s).
    pub max_offset_s: f64,
    /// The stretch of both tracks (s) an offset is searched on.
    pub sync_span_s: f64,
    /// The reference camera's track must move at least this far (m) over the stretch: a still target tells no time.
    pub min_sync_motion_m: f64,
    /// The standard deviation (s) of an offset found by the search, as the filter starts from it.
    pub offset_prior_sigma_s: f64,
    /// The standard deviation (ppm) of an unknown drift as the filter starts from its stated value (or 0).
    pub drift_prior_sigma_ppm: f64,
    /// The fused filter takes each measurement this long (s, rig time) after the newest one of any camera, in the
    /// order of their rig times: the bound of the reorder buffer, and the latency of the fused estimates. Streams
    /// merged by their cameras' own clocks (their offsets unknown) come out of order by up to twice the largest
    /// offset.
    pub reorder_latency_s: f64,
}

impl Default for RigTrackerConfig {
    fn default() -> Self {
        Self {
            tracker: TrackerConfig::default(),
            max_offset_s: 0.1,
            sync_span_s: 0.25,
            min_sync_motion_m: 0.01,
            offset_prior_sigma_s: 0.3e-3,
            drift_prior_sigma_ppm: 100.0,
            reorder_latency_s: 0.12,
        }
    }
}

/// Why a [`RigTracker`] refused a measurement or its configuration.
///
/// ```
/// use roitrack_estimators::rig::{Rig, RigMeasurement, RigTracker, RigTrackerConfig};
/// use roitrack_core::{CameraModel, Measurement, Target};
///
/// let mut tracker =
///     RigTracker::new(Rig::single("left", CameraModel::canonical()), Target::grid4x4(), RigTrackerConfig::default())
///         .unwrap();
/// let m = Measurement { t_s: 0.0, id: 99, u_px: 500.0, v_px: 500.0 };
/// let e = tracker.push(&RigMeasurement { camera: 0, measurement: m }).unwrap_err();
/// assert!(e.to_string().starts_with("camera 'left': ") && e.to_string().contains("id 99"));
/// ```
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RigError {
    /// The tracker's options are refused.
    #[error("invalid tracker options: {0}")]
    Config(#[from] ConfigError),
    /// A measurement names a camera number the rig does not have.
    #[error("a measurement of camera number {camera}, but the rig has {cameras} cameras")]
    UnknownCamera {
        /// The camera number given.
        camera: usize,
        /// How many cameras the rig has.
        cameras: usize,
    },
    /// A camera's `camera_T_rig` is unknown: the tracker needs every mount.
    #[error(
        "camera '{camera}': its camera_T_rig is not given: find it with calibrate-rig (RigCalibrator) first"
    )]
    MountUnknown {
        /// The camera.
        camera: String,
    },
    /// A camera's own tracker refused a measurement.
    #[error("camera '{camera}': {source}")]
    Measurement {
        /// The camera.
        camera: String,
        /// Why its tracker refused it.
        #[source]
        source: TrackError,
    },
    /// A camera's clock offset was searched and the best match lies at the search's edge.
    #[error(
        "camera '{camera}': its track never matches the first camera's within the clock offset search of ±{max_offset_s} s \
         (best match at the search's edge, {rms_mm:.1} mm apart): check its clock offset, its camera_T_rig and that it \
         sees the same target"
    )]
    ClockBeyondSearch {
        /// The camera.
        camera: String,
        /// The half-width of the offset search (s).
        max_offset_s: f64,
        /// The RMS distance between the tracks at the best offset searched (mm).
        rms_mm: f64,
    },
}
