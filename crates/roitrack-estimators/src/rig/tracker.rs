//! The rig's tracker: one pose and twist of the target, in the rig's frame and on the rig's clock, from the
//! centroids of every camera as they come, and each camera's clock learnt from them.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

use nalgebra::{DMatrix, Matrix3, Matrix6, Vector2, Vector3, Vector6};
use thiserror::Error;

use super::{Rig, offset_chi2, rig_projection, search_offset_s};
use crate::kalman::pose_matching_scale;
use crate::{
    ConfigError, Emit, Estimate, Estimator, EstimatorConfig, KalmanTuning, Matrix12, TrackError,
    TrackStatus, Tracker, TrackerConfig,
};
use roitrack_core::stats::{chi2_upper_0_1_percent, chi2_upper_quantile};
use roitrack_core::{Measurement, MotionState, SpatioTemporalModel, Target, Vector12};

use super::RigMeasurement;

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

/// A camera's clock as the tracker knows it: the offset and drift, and their standard deviations (0 when known).
///
/// ```
/// use roitrack_estimators::rig::{Rig, RigTracker, RigTrackerConfig};
/// use roitrack_core::{CameraModel, Target};
///
/// let tracker = RigTracker::new(Rig::single("cam", CameraModel::canonical()), Target::grid4x4(), RigTrackerConfig::default())
///     .unwrap();
/// let clock = tracker.clocks()[0];
/// assert!(clock.synced && clock.offset_s == 0.0 && clock.offset_sigma_s == 0.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockEstimate {
    /// The camera clock's offset from the rig's (s).
    pub offset_s: f64,
    /// The camera clock's drift against the rig's (ppm).
    pub drift_ppm: f64,
    /// The offset's standard deviation (s).
    pub offset_sigma_s: f64,
    /// The drift's standard deviation (ppm).
    pub drift_sigma_ppm: f64,
    /// Whether the offset has been found (known, or searched); `false` while the camera waits for its search.
    pub synced: bool,
}

/// One estimate of a [`RigTracker`]: the state is `rig_T_object` with its twist in the rig frame, its time on the
/// rig's clock; and every camera's clock as known then.
#[derive(Debug, Clone, PartialEq)]
pub struct RigEstimate {
    /// The fused estimate of `rig_T_object`, in the rig frame and on the rig's clock.
    pub estimate: Estimate,
    /// Every camera's clock at that time, in the rig's camera order.
    pub clocks: Vec<ClockEstimate>,
}

/// What a [`RigTracker`] has done.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigTrackerReport {
    /// Measurements taken.
    pub measurements: usize,
    /// Measurements the fused filter used.
    pub fused: usize,
    /// Measurements the fused filter's gate rejected.
    pub gated: usize,
    /// Fused tracks started (a lost one is started again from a camera's own track).
    pub starts: usize,
    /// Estimates given.
    pub estimates: usize,
    /// Instants (a global-shutter frame's blobs) whose pose lay beyond the prediction's uncertainty, the fused
    /// covariance widened to meet them.
    pub instants_widened: usize,
}

/// Gauss-Newton steps of an instant's pose fit ([`RigTracker::match_instant`]): from a prediction millimetres off,
/// the third step moves the pose by nanometres.
const POSE_FIT_ITERATIONS: usize = 4;
/// Gated measurements in a row, per target point, after which the fused track is lost.
const LOST_AFTER_GATED_CYCLES: usize = 4;
/// One camera's measurements rejected in a row, per target point, after which its clock is searched again (the first
/// camera's: the fused track is started again from its own).
const CAMERA_GATED_CYCLES: usize = 2;
/// The covariance is made exactly symmetric again after this many updates (as the single-camera filter's).
const SYMMETRISE_EVERY_UPDATES: u64 = 16;
/// Measurements rejected in a row that dispute an estimate, and the normalised innovation squared beyond which one
/// rejection alone does (the single-camera filter's: 3 in a row happen by chance once in 700,000 good measurements;
/// 25 is 5 sigma).
const DISPUTED_AFTER_GATED_IN_A_ROW: usize = 3;
const DISPUTED_NIS: f64 = 25.0;
/// Estimates given as converging after a fused track starts.
const CONVERGING_ESTIMATES: usize = 3;
/// How far back (s) a measurement may be behind the fused filter's time and still be used (it is predicted back).
const MAX_LATENESS_S: f64 = 0.05;
/// Grid step (s) of the coarse offset search.
const SEARCH_STEP_S: f64 = 0.5e-3;
/// The process noise scales' rate of adaptation, range and trend spans: the single-camera filter's.
const PROCESS_ADAPTATION_RATE: f64 = 0.05;
const PROCESS_SCALE_RANGE: (f64, f64) = (1e-4, 1e4);
const TREND_MIN_UPDATES: f64 = 32.0;

/// The fused filter: the rig's state, the unknown clocks, their joint covariance.
#[derive(Debug, Clone)]
struct Fused {
    /// The time the track started from: measurements before it are left out.
    start_s: f64,
    t_s: f64,
    state: MotionState,
    /// Covariance of (δ state (12), then the unknown clock parameters).
    p: DMatrix<f64>,
    trend: Vector12,
    trend_rate: f64,
    last_dt_s: f64,
    process_log_scale: [f64; 2],
    gated_in_a_row: usize,
    newest_gated: bool,
    /// The newest update's normalised innovation squared, and the measurements gated since the last estimate.
    newest_nis: f64,
    gated_since_estimate: usize,
    sum_squares_px2: f64,
    count: usize,
    estimates: usize,
    /// Updates applied (the covariance is symmetrised every [`SYMMETRISE_EVERY_UPDATES`]), and the scratch of `P Hᵀ`
    /// and of the gain, one row per state.
    updates: u64,
    ph_t: Vec<[f64; 2]>,
    gain: Vec<[f64; 2]>,
}

/// Many asynchronous cameras, one pose and twist.
///
/// # How it works
///
/// Every camera also runs the single-camera tracker of its own measurements ([`Tracker`]): it starts the tracks (a
/// static pose and a 12-dof fit of its first cycles, as a single camera does), learns that camera's centroid noise,
/// and gives the coarse offset of its clock (the shift that lays its track over the first camera's,
/// [`search_offset_s`]). The fused filter is then an error-state Kalman filter of the rig's 12-dof state augmented by
/// each unknown clock offset and drift: every centroid is one update at its own rig time, through its camera's
/// projection, the image velocity of the point being the clock's column of the Jacobian ([`rig_projection`]).
///
/// A rig of one camera that is the rig (identity mount, reference clock) runs the single-camera tracker alone: its
/// estimates are the single-camera tracker's, bit for bit.
///
/// ```
/// use roitrack_estimators::rig::{Rig, RigMeasurement, RigTracker, RigTrackerConfig};
/// use roitrack_core::{CameraModel, Measurement, Target};
///
/// let rig = Rig::single("cam", CameraModel::canonical());
/// let mut tracker = RigTracker::new(rig, Target::grid4x4(), RigTrackerConfig::default()).unwrap();
/// let m = Measurement { t_s: 0.0, id: 0, u_px: 480.0, v_px: 480.0 };
/// assert!(tracker.push(&RigMeasurement { camera: 0, measurement: m }).unwrap().is_empty());
/// assert!(tracker.push(&RigMeasurement { camera: 3, measurement: m }).is_err());
/// ```
#[derive(Debug)]
pub struct RigTracker {
    rig: Rig,
    target: Target,
    config: RigTrackerConfig,
    tuning: KalmanTuning,
    models: Vec<SpatioTemporalModel>,
    singles: Vec<Tracker>,
    /// One camera's newest measurements that share one time (a global-shutter frame's blobs), held for its own
    /// tracker until a measurement of another time or camera comes, and given to it together
    /// ([`Tracker::push_batch`]): blob after blob, each linearised where the blobs before it had moved the state, a
    /// 30 Hz frame camera's own track was disputed on nearly every frame of a fast target and vouched for nothing.
    held: Vec<Measurement>,
    /// The camera of [`Self::held`].
    held_camera: usize,
    /// Per camera: the time of its newest measurement, and whether two of its measurements have shared a time (a
    /// frame camera, whose instants are held; a camera whose measurements each have their own time, ROIs, gives
    /// each to its tracker as it comes).
    newest_t_s: Vec<f64>,
    reads_instants: Vec<bool>,
    /// Per camera: the newest centroid noise its own tracker learnt (px).
    noise_px: Vec<f64>,
    /// Per camera: whether its clock offset is known or found.
    synced: Vec<bool>,
    /// Per camera: its own vouched track (time on its clock, position in the rig frame), for the offset search.
    tracks: Vec<VecDeque<TrackSample>>,
    /// Per camera, the standard deviation (s) its clock offset joins the fused filter with: the configured prior, or
    /// what its search's fit allows, if wider ([`Self::try_sync`]).
    offset_sigma_s: Vec<f64>,
    /// Per camera: the filter's indices of its offset and drift, when estimated.
    clock_states: Vec<(Option<usize>, Option<usize>)>,
    /// Per camera: its clock as known now.
    clocks: Vec<super::ClockModel>,
    /// Per camera: the newest vouched estimate of its own tracker (rig frame and clock).
    newest_single: Vec<Option<Estimate>>,
    /// Each camera's own `tracking` estimates of the last [`CROSS_CHECK_SPAN_S`] behind the newest (rig frame and
    /// time, in time order, at most [`CROSS_CHECK_CAPACITY`]): the fused estimates, which lag by the reorder buffer, are checked
    /// against the one nearest in time.
    recent_singles: Vec<VecDeque<Estimate>>,
    fused: Option<Fused>,
    /// Measurements waiting for the fused filter, by rig time ([`RigTrackerConfig::reorder_latency_s`]).
    pending: BinaryHeap<Reverse<Pending>>,
    /// The newest rig time of any measurement, and how many have come (to order equal times by arrival).
    newest_rig_s: f64,
    arrivals: u64,
    since_estimate: usize,
    last_emitted_s: f64,
    report: RigTrackerReport,
    /// Per camera: measurements the fused filter used, and those its gate rejected.
    camera_counts: Vec<CameraCounts>,
}

/// What the fused filter did with one camera's measurements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CameraCounts {
    /// Measurements it updated with.
    pub fused: usize,
    /// Measurements its gate rejected.
    pub gated: usize,
    /// Its newest measurements rejected in a row.
    pub gated_in_a_row: usize,
    /// Times its clock was searched again after a run of rejections.
    pub resyncs: usize,
    /// Offsets its clock's search found that did not lay its track over the first camera's within their errors (each
    /// searched again with its next estimate).
    pub offsets_refused: usize,
}

/// A measurement in the reorder buffer: its rig time when it came, its arrival number, its camera.
#[derive(Debug, Clone, Copy)]
struct Pending {
    t_rig_s: f64,
    arrival: u64,
    camera: usize,
    measurement: Measurement,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}

impl Eq for Pending {}

impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.t_rig_s
            .total_cmp(&other.t_rig_s)
            .then(self.arrival.cmp(&other.arrival))
    }
}

impl RigTracker {
    /// A tracker for `rig` and `target`.
    pub fn new(rig: Rig, target: Target, config: RigTrackerConfig) -> Result<Self, RigError> {
        if let Some(c) = rig.cameras().iter().find(|c| !c.mount_known) {
            return Err(RigError::MountUnknown {
                camera: c.name.clone(),
            });
        }
        let n = rig.len();
        let singles = rig
            .cameras()
            .iter()
            .map(|c| Tracker::new(c.camera.clone(), target.clone(), config.tracker))
            .collect::<Result<Vec<_>, _>>()?;
        let tuning = match config.tracker.estimator {
            EstimatorConfig::Kalman(tuning) => tuning,
            _ => KalmanTuning::default(),
        };
        let mut next = 12;
        let clock_states = rig
            .cameras()
            .iter()
            .map(|c| {
                let mut take = |known: bool| {
                    (!known).then(|| {
                        next += 1;
                        next - 1
                    })
                };
                let offset = take(c.offset_known);
                let drift = take(c.drift_known);
                (offset, drift)
            })
            .collect();
        Ok(Self {
            models: rig
                .cameras()
                .iter()
                .map(|c| SpatioTemporalModel::new(c.camera.intrinsics))
                .collect(),
            noise_px: vec![config.tracker.noise_px; n],
            synced: rig.cameras().iter().map(|c| c.offset_known).collect(),
            tracks: vec![VecDeque::new(); n],
            offset_sigma_s: vec![config.offset_prior_sigma_s; n],
            clock_states,
            clocks: rig.cameras().iter().map(|c| c.clock).collect(),
            newest_single: vec![None; n],
            recent_singles: vec![VecDeque::new(); n],
            singles,
            held: Vec::new(),
            held_camera: 0,
            newest_t_s: vec![f64::NAN; n],
            reads_instants: vec![false; n],
            rig,
            target,
            config,
            tuning,
            fused: None,
            pending: BinaryHeap::new(),
            newest_rig_s: f64::NEG_INFINITY,
            arrivals: 0,
            since_estimate: 0,
            last_emitted_s: f64::NEG_INFINITY,
            report: RigTrackerReport::default(),
            camera_counts: vec![CameraCounts::default(); n],
        })
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// What it has done.
    pub fn report(&self) -> RigTrackerReport {
        self.report
    }

    /// Per camera: what the fused filter did with its measurements.
    pub fn camera_counts(&self) -> &[CameraCounts] {
        &self.camera_counts
    }

    /// Whether the rig is one camera that is the rig: the single-camera tracker alone.
    pub fn is_single(&self) -> bool {
        let cameras = self.rig.cameras();
        cameras.len() == 1 && cameras[0].mount.is_identity() && cameras[0].clock.is_reference()
    }

    /// The single-camera tracker of camera `camera` (for a one-camera rig, the whole tracker).
    pub fn camera_tracker(&mut self, camera: usize) -> Option<&mut Tracker> {
        self.singles.get_mut(camera)
    }

    /// Every camera's clock as known now.
    pub fn clocks(&self) -> Vec<ClockEstimate> {
        (0..self.rig.len())
            .map(|c| {
                let (offset, drift) = self.clock_states[c];
                let sigma = |i: Option<usize>| match (i, &self.fused) {
                    (Some(i), Some(f)) => f.p[(i, i)].max(0.0).sqrt(),
                    (Some(_), None) if self.synced[c] => self.offset_sigma_s[c],
                    (Some(_), None) => f64::INFINITY,
                    (None, _) => 0.0,
                };
                let drift_sigma_ppm = match (drift, &self.fused) {
                    (Some(_), None) => self.config.drift_prior_sigma_ppm,
                    _ => sigma(drift),
                };
                ClockEstimate {
                    offset_s: self.clocks[c].offset_s,
                    drift_ppm: self.clocks[c].drift_ppm,
                    offset_sigma_s: if self.synced[c] || offset.is_none() {
                        sigma(offset)
                    } else {
                        f64::INFINITY
                    },
                    drift_sigma_ppm,
                    synced: self.synced[c],
                }
            })
            .collect()
    }

    /// Takes one centroid of one camera (its time on that camera's clock; each camera's times must not decrease; the
    /// cameras' streams merged in the order of their rig times as far as their clocks are known, within
    /// [`RigTrackerConfig::reorder_latency_s`]). Returns the estimates that became due: one every `every` fused
    /// measurements once a fused track runs, [`RigTrackerConfig::reorder_latency_s`] behind the newest measurement
    /// ([`Self::finish`] gives the last ones). A one-camera rig that is the rig gives the single-camera tracker's
    /// estimates, as they come.
    pub fn push(&mut self, m: &RigMeasurement) -> Result<Vec<RigEstimate>, RigError> {
        let c = m.camera;
        if c >= self.rig.len() {
            return Err(RigError::UnknownCamera {
                camera: c,
                cameras: self.rig.len(),
            });
        }
        if self.is_single() {
            let single = self.singles[c]
                .push(&m.measurement)
                .map_err(|source| self.measurement_error(c, source))?;
            self.report.measurements += 1;
            return Ok(single
                .map(|estimate| {
                    self.report.estimates += 1;
                    RigEstimate {
                        estimate,
                        clocks: self.clocks(),
                    }
                })
                .into_iter()
                .collect());
        }
        if self
            .held
            .first()
            .is_some_and(|h| self.held_camera != c || h.t_s != m.measurement.t_s)
        {
            self.give_held()?;
        }
        if !self.reads_instants[c] && self.newest_t_s[c] == m.measurement.t_s {
            self.reads_instants[c] = true;
        }
        if !self.reads_instants[c] {
            let single = self.singles[c]
                .push(&m.measurement)
                .map_err(|source| self.measurement_error(c, source))?;
            self.newest_t_s[c] = m.measurement.t_s;
            if let Some(e) = single
                && e.status.is_vouched_for()
            {
                self.take_single(c, &e)?;
            }
            return Ok(self.queue_for_fusion(c, m.measurement));
        }
        // Refused now, naming it, if the camera's tracker would refuse it (the measurements held before it share its
        // time, which its tracker's newest does not pass).
        if let Some((_, source)) = self.singles[c].first_refused(&[m.measurement]) {
            return Err(self.measurement_error(c, source));
        }
        self.held.push(m.measurement);
        self.held_camera = c;
        self.newest_t_s[c] = m.measurement.t_s;
        Ok(self.queue_for_fusion(c, m.measurement))
    }

    /// Counts a measurement its camera's tracker took and queues it for the fused filter; returns the estimates that
    /// became due.
    fn queue_for_fusion(&mut self, c: usize, measurement: Measurement) -> Vec<RigEstimate> {
        self.report.measurements += 1;
        let t_rig_s = self.clocks[c].rig_time_s(measurement.t_s);
        self.newest_rig_s = self.newest_rig_s.max(t_rig_s);
        self.arrivals += 1;
        self.pending.push(Reverse(Pending {
            t_rig_s,
            arrival: self.arrivals,
            camera: c,
            measurement,
        }));
        self.release(self.newest_rig_s - self.config.reorder_latency_s)
    }

    /// Fuses every measurement still waiting in the reorder buffer (at the end of the streams), with their estimates.
    pub fn finish(&mut self) -> Vec<RigEstimate> {
        // (The held measurements' only possible error is an offset search that failed on the streams' last instant,
        // which has nothing left to be fused with.)
        let _ = self.give_held();
        self.release(f64::INFINITY)
    }

    /// The held measurements of one instant to their camera's own tracker, and its estimate to the rig.
    fn give_held(&mut self) -> Result<(), RigError> {
        if self.held.is_empty() {
            return Ok(());
        }
        let c = self.held_camera;
        let held = std::mem::take(&mut self.held);
        // (Checked as they came: the tracker takes them all.)
        let single = match held.as_slice() {
            [one] => self.singles[c].push(one),
            batch => self.singles[c].push_batch(batch, Emit::Every),
        };
        self.held = held;
        self.held.clear();
        if let Some(e) = single.map_err(|source| self.measurement_error(c, source))?
            && e.status.is_vouched_for()
        {
            self.take_single(c, &e)?;
        }
        Ok(())
    }

    /// Fuses the waiting measurements up to the rig time `until_s`, in the order of their rig times.
    fn release(&mut self, until_s: f64) -> Vec<RigEstimate> {
        let mut estimates = Vec::new();
        while let Some(Reverse(next)) = self.pending.peek()
            && next.t_rig_s <= until_s
        {
            let Some(Reverse(next)) = self.pending.pop() else {
                break;
            };
            if self.fused.is_none() {
                self.start_fused();
            }
            if self.fused.is_some() && self.synced[next.camera] {
                let taken_whole = self
                    .pending
                    .peek()
                    .is_some_and(|Reverse(after)| after.t_rig_s == next.t_rig_s)
                    && self.match_instant(&next);
                if !taken_whole {
                    self.fuse(next.camera, &next.measurement);
                }
                // The blobs of one instant (a global-shutter frame's) are one readout: an estimate between two of them
                // would be the prediction corrected by a few points only. It waits for the instant's last blob that
                // will be fused: blobs of a camera not yet synced may share the time (cameras triggered together,
                // or clocks still unknown that read alike), and they are not fused (every 30 Hz frame of the first
                // camera of a rig whose other clocks were still unknown ended at such a blob, and no estimate came).
                let instant_continues = self
                    .pending
                    .peek()
                    .is_some_and(|Reverse(after)| after.t_rig_s == next.t_rig_s)
                    && self.pending.iter().any(|Reverse(after)| {
                        after.t_rig_s == next.t_rig_s && self.synced[after.camera]
                    });
                if !instant_continues {
                    estimates.extend(self.estimate_if_due());
                }
            }
        }
        estimates
    }

    /// Covariance matching on the blobs of one camera's instant (a global-shutter frame's), before the first of them
    /// is fused; returns whether it took them all. A fast target seen at frame rates strays from a constant-twist
    /// prediction by more than its covariance allows (9 mm in 1/30 s at 17 m/s²), and blob after blob would be
    /// rejected by the gate until the track is lost. As the single-camera filter does with a frame: the blobs' fit
    /// of the pose alone (Gauss-Newton from the prediction) moves it by `x` with covariance
    /// `C = (Σ Jᵢᵀ Jᵢ / σ²)⁻¹`; if the prediction is right, `xᵀ (P_pose + C)⁻¹ x` is a chi-square of 6 degrees of
    /// freedom. Within its 99.9 % point, nothing is done and the blobs are fused one by one. Beyond it, the pose and
    /// twist block of the covariance is scaled by the `α` that makes it its expected 6 (the clocks' variances kept,
    /// their cross-covariances scaled by `√α`, which keeps the covariance positive), and the fitted pose is taken
    /// as one measurement of the pose with covariance `C`: one update, linearised where the fit converged, instead
    /// of blob-by-blob updates from a prediction millimetres off, which a widened covariance lets run away.
    fn match_instant(&mut self, first: &Pending) -> bool {
        let c = first.camera;
        let same_instant = |p: &Pending| p.camera == c && p.t_rig_s == first.t_rig_s;
        let blobs: Vec<Measurement> = std::iter::once(first.measurement)
            .chain(
                self.pending
                    .iter()
                    .map(|Reverse(p)| p)
                    .filter(|p| same_instant(p))
                    .map(|p| p.measurement),
            )
            .collect();
        // A pose of 6 degrees of freedom from 2 coordinates per blob: fewer than 4 blobs leave its fit too weak to
        // test.
        if blobs.len() < 4 {
            return false;
        }
        let camera = &self.rig.cameras()[c];
        let clock = self.clocks[c];
        let noise2 = self.noise_px[c] * self.noise_px[c];
        let tuning = self.tuning;
        let Some(f) = self.fused.as_mut() else {
            return false;
        };
        let dt = clock.rig_time_s(first.measurement.t_s) - f.t_s;
        if dt <= 0.0 || noise2 <= 0.0 {
            return false;
        }
        f.predict(dt, &tuning);
        let points: Vec<(Vector3<f64>, Vector2<f64>, f64)> = blobs
            .iter()
            .filter_map(|m| {
                let index = self.target.index_of(m.id)?;
                let ideal_px = camera
                    .camera
                    .undistort_pixel(&Vector2::new(m.u_px, m.v_px))
                    .ok()?;
                Some((self.target.points()[index].point_in_obj_m, ideal_px, m.t_s))
            })
            .collect();
        // The pose alone fitted to the blobs, from the prediction: a few Gauss-Newton steps (each a correction on the
        // left, as the filter's), the sum of the steps its move `x`.
        let mut fitted = f.state;
        let mut x = Vector6::zeros();
        let mut fit_covariance = Matrix6::zeros();
        // The blobs' squared residuals at the last linearisation, for the estimate's residual RMS as blob-by-blob
        // updates add theirs.
        let mut sum_squares_px2 = 0.0;
        for _ in 0..POSE_FIT_ITERATIONS {
            let (mut information, mut gradient) = (Matrix6::zeros(), Vector6::zeros());
            sum_squares_px2 = 0.0;
            for (point, ideal_px, t_s) in &points {
                let Some(projected) = rig_projection(
                    &self.models[c],
                    &camera.mount,
                    &clock,
                    &fitted,
                    point,
                    *t_s,
                    f.t_s,
                ) else {
                    continue;
                };
                let j = projected.jacobian.fixed_view::<2, 6>(0, 0).into_owned();
                let residual_px = ideal_px - projected.pixel;
                sum_squares_px2 += residual_px.norm_squared();
                information += j.transpose() * j / noise2;
                gradient += j.transpose() * residual_px / noise2;
            }
            let Some(covariance) = information.try_inverse() else {
                return false;
            };
            let step = covariance * gradient;
            let mut delta = Vector12::zeros();
            delta.fixed_rows_mut::<6>(0).copy_from(&step);
            fitted = fitted.corrected(&delta);
            x += step;
            fit_covariance = covariance;
            if !x.iter().all(|v| v.is_finite()) {
                return false;
            }
        }
        let pose = f.p.fixed_view::<6, 6>(0, 0).into_owned();
        let Some(alpha) =
            pose_matching_scale(&pose, &fit_covariance, &x, chi2_upper_0_1_percent(6.0))
        else {
            return false;
        };
        let root = alpha.sqrt();
        let n = f.p.nrows();
        for j in 0..n {
            for i in 0..n {
                let scale = if i < 12 { root } else { 1.0 } * if j < 12 { root } else { 1.0 };
                f.p[(i, j)] *= scale;
            }
        }
        // The fitted pose as one measurement of the pose: K = P Hᵀ (H P Hᵀ + C)⁻¹ with H = [I₆ 0], P ← P - K H P.
        let p_h_t = f.p.columns(0, 6).into_owned();
        let innovation_covariance = f.p.fixed_view::<6, 6>(0, 0).into_owned() + fit_covariance;
        let Some(s_inv) = innovation_covariance.try_inverse() else {
            return false;
        };
        let gain = &p_h_t * s_inv;
        let correction = &gain * x;
        let delta = Vector12::from_fn(|i, _| correction[i]);
        let corrected = f.state.corrected(&delta);
        if !corrected.is_finite() {
            return false;
        }
        f.state = corrected;
        let (offset_index, drift_index) = self.clock_states[c];
        if let Some(i) = offset_index {
            self.clocks[c].offset_s += correction[i];
        }
        if let Some(j) = drift_index {
            self.clocks[c].drift_ppm += correction[j];
        }
        f.p -= &gain * p_h_t.transpose();
        // Symmetric again after the downdate's rounding.
        let symmetric = (&f.p + f.p.transpose()) * 0.5;
        f.p = symmetric;
        let taken = blobs.len();
        f.count += taken;
        f.sum_squares_px2 += sum_squares_px2;
        f.gated_in_a_row = 0;
        f.newest_gated = false;
        self.pending.retain(|Reverse(p)| !same_instant(p));
        self.report.fused += taken;
        self.report.instants_widened += 1;
        self.camera_counts[c].fused += taken;
        self.camera_counts[c].gated_in_a_row = 0;
        self.since_estimate += taken;
        true
    }

    fn measurement_error(&self, c: usize, source: TrackError) -> RigError {
        RigError::Measurement {
            camera: self.rig.cameras()[c].name.clone(),
            source,
        }
    }

    /// A vouched estimate of camera `c`'s own tracker: its noise, its track for the offset search, and the search
    /// when both tracks are long enough.
    fn take_single(&mut self, c: usize, e: &Estimate) -> Result<(), RigError> {
        self.noise_px[c] = e.noise_px;
        let camera = &self.rig.cameras()[c];
        let rig_state = camera.mount.rig_state(&e.state);
        let covariance = e.covariance.map(|p| camera.mount.covariance_to_rig(&p));
        let rig_estimate = Estimate {
            t_ref_s: self.clocks[c].rig_time_s(e.t_ref_s),
            state: rig_state,
            covariance,
            ..*e
        };
        self.newest_single[c] = Some(rig_estimate);
        let recent = &mut self.recent_singles[c];
        let keep_s = self.config.reorder_latency_s + CROSS_CHECK_SPAN_S;
        while recent.len() >= CROSS_CHECK_CAPACITY
            || recent
                .front()
                .is_some_and(|old| rig_estimate.t_ref_s - old.t_ref_s > keep_s)
        {
            recent.pop_front();
        }
        // Converging estimates too: a frame camera's own track restarts from a whole-frame pose on most frames of a
        // fast target, and its position is as good as its covariance (carried over to the fused time with its
        // twist's, which a new track states broad).
        if rig_estimate.status.is_vouched_for() {
            recent.push_back(rig_estimate);
        }
        if self.synced[c] && c != 0 {
            return Ok(());
        }
        let track = &mut self.tracks[c];
        let position_covariance = covariance
            .unwrap_or_else(broad_prior)
            .fixed_view::<3, 3>(0, 0)
            .into_owned();
        track.push_back((e.t_ref_s, rig_state.cam_t_obj_m, position_covariance));
        let keep_s = 2.0 * self.config.sync_span_s;
        while track
            .front()
            .is_some_and(|(t, _, _)| e.t_ref_s - t > keep_s)
        {
            track.pop_front();
        }
        if c == 0 {
            return Ok(());
        }
        self.try_sync(c)
    }

    /// The coarse offset of camera `c` against the first camera, once both tracks span the stretch and the target has
    /// moved over it.
    fn try_sync(&mut self, c: usize) -> Result<(), RigError> {
        let span = |t: &VecDeque<TrackSample>| match (t.front(), t.back()) {
            (Some(a), Some(b)) => b.0 - a.0,
            _ => 0.0,
        };
        let (reference, camera) = (&self.tracks[0], &self.tracks[c]);
        if span(camera) < self.config.sync_span_s || span(reference) < self.config.sync_span_s {
            return Ok(());
        }
        let path_m: f64 = reference
            .iter()
            .zip(reference.iter().skip(1))
            .map(|(a, b)| (b.1 - a.1).norm())
            .sum();
        if path_m < self.config.min_sync_motion_m {
            return Ok(());
        }
        let reference_clock = self.clocks[0];
        let reference: Vec<TrackSample> = reference
            .iter()
            .map(|(t, p, v)| (reference_clock.rig_time_s(*t), *p, *v))
            .collect();
        let scale = 1.0 / (1.0 + self.clocks[c].drift_ppm * 1e-6);
        let positions = |track: &[TrackSample], scale: f64| -> Vec<(f64, Vector3<f64>)> {
            track.iter().map(|(t, p, _)| (t * scale, *p)).collect()
        };
        let camera: Vec<TrackSample> = camera.iter().copied().collect();
        let Some(found) = search_offset_s(
            &positions(&reference, 1.0),
            &positions(&camera, scale),
            self.config.max_offset_s,
            SEARCH_STEP_S,
        ) else {
            return Ok(());
        };
        if found.at_edge {
            return Err(RigError::ClockBeyondSearch {
                camera: self.rig.cameras()[c].name.clone(),
                max_offset_s: self.config.max_offset_s,
                rms_mm: found.rms_m * 1e3,
            });
        }
        // The offset is taken only if it lays the two tracks over each other as closely as their own errors allow
        // (at 99.9 %): on sparse tracks (a frame camera's, restarted on most frames) the best offset of the grid can
        // be the least bad of wrong ones (three 30 Hz cameras of the random scene: 14.6 ms off, the tracks 23 mm
        // apart at it, and the fused estimates of its frames 10-17 mm off, vouched for). The search is tried again
        // with the next estimate.
        let chi2_at = |offset_s: f64| offset_chi2(&reference, &camera, offset_s, scale);
        let Some((chi2, _)) =
            chi2_at(found.offset_s).filter(|&(chi2, dof)| chi2 <= chi2_upper_0_1_percent(dof))
        else {
            self.camera_counts[c].offsets_refused += 1;
            return Ok(());
        };
        // The offset's standard deviation from the fit's curvature (chi² rises by 1 a sigma away): a few sparse frames
        // pin an offset to milliseconds, a stream of ROIs to microseconds. The filter starts the offset from the
        // wider of it and the configured prior, so that it can still move it (an offset 2.9 ms off from 30 Hz
        // frames, held at the prior's 0.3 ms, left the fused track 5-19 mm off).
        let h_s = SYNC_CURVATURE_STEP_S;
        let sigma_s = match (chi2_at(found.offset_s - h_s), chi2_at(found.offset_s + h_s)) {
            (Some((below, _)), Some((above, _))) if below + above - 2.0 * chi2 > 0.0 => {
                (2.0 * h_s * h_s / (below + above - 2.0 * chi2)).sqrt()
            }
            _ => self.config.max_offset_s,
        };
        self.offset_sigma_s[c] = sigma_s.max(self.config.offset_prior_sigma_s);
        self.clocks[c].offset_s = found.offset_s;
        self.synced[c] = true;
        // Its own estimates so far were put on the rig's clock by the offset before this one.
        self.recent_singles[c].clear();
        // Its waiting measurements move to their rig times: taken out of time order, each would carry the filter
        // back and forth by the offset, and its process noise with it.
        let clock = self.clocks[c];
        let mut pending = std::mem::take(&mut self.pending).into_vec();
        for Reverse(p) in &mut pending {
            if p.camera == c {
                p.t_rig_s = clock.rig_time_s(p.measurement.t_s);
            }
        }
        self.pending = BinaryHeap::from(pending);
        if let (Some(f), (Some(i), drift)) = (&mut self.fused, self.clock_states[c]) {
            // The camera joins the running filter: its offset uncorrelated with the rest.
            for k in 0..f.p.nrows() {
                f.p[(i, k)] = 0.0;
                f.p[(k, i)] = 0.0;
            }
            f.p[(i, i)] = self.offset_sigma_s[c].powi(2);
            if let Some(j) = drift {
                for k in 0..f.p.nrows() {
                    if k != j {
                        f.p[(j, k)] = 0.0;
                        f.p[(k, j)] = 0.0;
                    }
                }
            }
        }
        Ok(())
    }

    /// Camera `c` leaves the fusion until its clock offset is searched again (a run of its measurements rejected: its
    /// clock was wrong, or its track).
    fn resync(&mut self, c: usize) {
        let (offset, drift) = self.clock_states[c];
        if offset.is_none() {
            return;
        }
        self.synced[c] = false;
        self.tracks[c].clear();
        self.recent_singles[c].clear();
        self.camera_counts[c].resyncs += 1;
        if let Some(f) = &mut self.fused {
            for i in [offset, drift].into_iter().flatten() {
                for k in 0..f.p.nrows() {
                    f.p[(i, k)] = 0.0;
                    f.p[(k, i)] = 0.0;
                }
            }
            if let Some(j) = drift {
                f.p[(j, j)] = self.config.drift_prior_sigma_ppm.powi(2);
            }
        }
    }

    /// Starts the fused track from the newest vouched estimate of a synced camera's own tracker (the first camera's
    /// if it has one).
    fn start_fused(&mut self) {
        let Some(start) = (0..self.rig.len())
            .filter(|&c| self.synced[c])
            .find_map(|c| self.newest_single[c])
        else {
            return;
        };
        let clock_count = self
            .clock_states
            .iter()
            .map(|(o, d)| usize::from(o.is_some()) + usize::from(d.is_some()))
            .sum::<usize>();
        let n = 12 + clock_count;
        let mut p = DMatrix::zeros(n, n);
        let pose = start.covariance.unwrap_or_else(broad_prior);
        p.view_mut((0, 0), (12, 12)).copy_from(&pose);
        for (c, &(offset, drift)) in self.clock_states.iter().enumerate() {
            if let Some(i) = offset {
                p[(i, i)] = if self.synced[c] {
                    self.offset_sigma_s[c].powi(2)
                } else {
                    0.0
                };
            }
            if let Some(j) = drift {
                p[(j, j)] = self.config.drift_prior_sigma_ppm.powi(2);
            }
        }
        let (process_log_scale, trend_rate) = self.fused.as_ref().map_or(
            (
                [0.0; 2],
                1.0 / (2.0 * self.target.len() as f64).max(TREND_MIN_UPDATES),
            ),
            |f| (f.process_log_scale, f.trend_rate),
        );
        self.fused = Some(Fused {
            start_s: start.t_ref_s,
            t_s: start.t_ref_s,
            state: start.state,
            p,
            trend: Vector12::zeros(),
            trend_rate,
            last_dt_s: 0.0,
            process_log_scale,
            gated_in_a_row: 0,
            newest_gated: false,
            newest_nis: 0.0,
            gated_since_estimate: 0,
            sum_squares_px2: 0.0,
            count: 0,
            estimates: 0,
            updates: 0,
            ph_t: Vec::with_capacity(n),
            gain: Vec::with_capacity(n),
        });
        self.since_estimate = 0;
        self.report.starts += 1;
    }

    /// One update of the fused filter with a centroid of camera `c` (already checked by its own tracker).
    fn fuse(&mut self, c: usize, m: &Measurement) {
        let camera = &self.rig.cameras()[c];
        let Some(point_index) = self.target.index_of(m.id) else {
            return;
        };
        let Ok(ideal_px) = camera.camera.undistort_pixel(&Vector2::new(m.u_px, m.v_px)) else {
            return;
        };
        let clock = self.clocks[c];
        let t_rig_s = clock.rig_time_s(m.t_s);
        let tuning = self.tuning;
        let (offset_index, drift_index) = self.clock_states[c];
        let Some(f) = self.fused.as_mut() else {
            return;
        };
        let dt = t_rig_s - f.t_s;
        if dt < -MAX_LATENESS_S || t_rig_s < f.start_s {
            return;
        }
        f.predict(dt, &tuning);
        let point = self.target.points()[point_index].point_in_obj_m;
        let Some(projected) = rig_projection(
            &self.models[c],
            &camera.mount,
            &clock,
            &f.state,
            &point,
            m.t_s,
            f.t_s,
        ) else {
            return;
        };
        // H is the state's 12 columns and at most two clock columns: P Hᵀ by those columns of P, into the filter's
        // own scratch (no allocation per measurement).
        let n = f.p.nrows();
        let mut columns = [(0usize, Vector2::zeros()); 14];
        for (k, column) in columns.iter_mut().take(12).enumerate() {
            *column = (k, projected.jacobian.column(k).into_owned());
        }
        let mut used = 12;
        for (index, column) in [
            (offset_index, projected.image_velocity_pxps),
            (drift_index, projected.per_drift_px),
        ] {
            if let Some(i) = index {
                columns[used] = (i, column);
                used += 1;
            }
        }
        let columns = &columns[..used];
        f.ph_t.clear();
        f.ph_t.resize(n, [0.0; 2]);
        for &(j, h) in columns {
            for (row, entry) in f.ph_t.iter_mut().zip(f.p.column(j).iter()) {
                row[0] += entry * h[0];
                row[1] += entry * h[1];
            }
        }
        let mut hph_t = nalgebra::Matrix2::zeros();
        for &(j, h) in columns {
            for r in 0..2 {
                hph_t[(0, r)] += h[0] * f.ph_t[j][r];
                hph_t[(1, r)] += h[1] * f.ph_t[j][r];
            }
        }
        let innovation = ideal_px - projected.pixel;
        let noise2 = self.noise_px[c] * self.noise_px[c];
        let s = nalgebra::Matrix2::new(
            hph_t[(0, 0)] + noise2,
            hph_t[(0, 1)],
            hph_t[(1, 0)],
            hph_t[(1, 1)] + noise2,
        );
        let Some(s_inv) = s.try_inverse() else {
            return;
        };
        let nis = (innovation.transpose() * s_inv * innovation)[0];
        if !nis.is_finite() {
            return;
        }
        f.sum_squares_px2 += innovation.norm_squared();
        f.count += 1;
        f.newest_nis = nis;
        self.report.fused += 1;
        self.since_estimate += 1;
        // Persistence of the innovation along the displacement the recent corrections predict (the single-camera
        // filter's adaptation of the process noise).
        let h12 = projected.jacobian;
        let mut persistence = [0.0; 2];
        for (part, rows) in [(0, [0, 6]), (1, [3, 9])] {
            let expected: Vector2<f64> = rows
                .iter()
                .map(|&r| h12.fixed_columns::<3>(r) * f.trend.fixed_rows::<3>(r))
                .sum();
            let spread2 = (expected.transpose() * s_inv * expected)[0];
            persistence[part] = if spread2 > 0.0 {
                (innovation.transpose() * s_inv * expected)[0] / spread2.sqrt()
            } else {
                0.0
            };
        }
        if nis > tuning.gate_sigma * tuning.gate_sigma {
            f.gated_in_a_row += 1;
            f.newest_gated = true;
            f.gated_since_estimate += 1;
            self.report.gated += 1;
            self.camera_counts[c].gated += 1;
            self.camera_counts[c].gated_in_a_row += 1;
            let n = self.target.len();
            if f.gated_in_a_row >= LOST_AFTER_GATED_CYCLES * n {
                self.fused = None;
            } else if self.camera_counts[c].gated_in_a_row >= CAMERA_GATED_CYCLES * n {
                self.camera_counts[c].gated_in_a_row = 0;
                if c == 0 {
                    // The first camera, which holds the rig's clock, no longer agrees with the fused track: the other
                    // clocks have carried it away. Started again from the first camera's own track, every clock
                    // kept but as uncertain as after its search.
                    self.fused = None;
                    self.start_fused();
                } else {
                    self.resync(c);
                }
            }
            return;
        }
        f.gated_in_a_row = 0;
        f.newest_gated = false;
        self.camera_counts[c].fused += 1;
        self.camera_counts[c].gated_in_a_row = 0;
        // Huber: beyond `huber_sigma`, the noise is inflated in proportion to the distance.
        let distance = nis.sqrt();
        let s_inv = if distance > tuning.huber_sigma {
            let inflated = noise2 * distance / tuning.huber_sigma;
            let s = nalgebra::Matrix2::new(
                hph_t[(0, 0)] + inflated,
                hph_t[(0, 1)],
                hph_t[(1, 0)],
                hph_t[(1, 1)] + inflated,
            );
            match s.try_inverse() {
                Some(inv) => inv,
                None => return,
            }
        } else {
            s_inv
        };
        // K = P Hᵀ S⁻¹, the correction K r, and P - K (P Hᵀ)ᵀ as a rank-2 downdate in place.
        let gain: &mut Vec<[f64; 2]> = &mut f.gain;
        gain.clear();
        gain.extend(f.ph_t.iter().map(|row| {
            [
                row[0] * s_inv[(0, 0)] + row[1] * s_inv[(1, 0)],
                row[0] * s_inv[(0, 1)] + row[1] * s_inv[(1, 1)],
            ]
        }));
        let correction = |i: usize| gain[i][0] * innovation[0] + gain[i][1] * innovation[1];
        let delta = Vector12::from_fn(|i, _| correction(i));
        let corrected = f.state.corrected(&delta);
        if !corrected.is_finite() {
            return;
        }
        f.state = corrected;
        if let Some(i) = offset_index {
            self.clocks[c].offset_s += correction(i);
        }
        if let Some(j) = drift_index {
            self.clocks[c].drift_ppm += correction(j);
        }
        for (j, mut column) in f.p.column_iter_mut().enumerate() {
            let (a, b) = (f.ph_t[j][0], f.ph_t[j][1]);
            for (entry, k) in column.iter_mut().zip(gain.iter()) {
                *entry -= k[0] * a + k[1] * b;
            }
        }
        f.updates += 1;
        if f.updates.is_multiple_of(SYMMETRISE_EVERY_UPDATES) {
            for i in 0..n {
                for j in i + 1..n {
                    let mean = 0.5 * (f.p[(i, j)] + f.p[(j, i)]);
                    f.p[(i, j)] = mean;
                    f.p[(j, i)] = mean;
                }
            }
        }
        if tuning.adapt_motion {
            for (scale, z) in f.process_log_scale.iter_mut().zip(persistence) {
                *scale = (*scale + PROCESS_ADAPTATION_RATE * z.clamp(-3.0, 3.0))
                    .clamp(PROCESS_SCALE_RANGE.0.ln(), PROCESS_SCALE_RANGE.1.ln());
            }
        }
        let rates = f.trend_rates();
        for (row, (trend, correction)) in f.trend.iter_mut().zip(&delta).enumerate() {
            *trend += (correction - *trend) * rates[usize::from(row % 6 >= 3)];
        }
    }

    /// Whether nothing but the fused filter stands behind its position: each synced camera's own estimate (vouched
    /// for) nearest in time within [`CROSS_CHECK_SPAN_S`], carried to the fused time by its twist, refutes the fused
    /// position if their difference lies beyond the [`CROSS_CHECK_Z`] bound of its covariance (at most the sum of
    /// theirs, since they share measurements, plus the white acceleration's over the carry). The fused estimate is
    /// then disputed if no camera has such an estimate near it (on 30 Hz frames of a fast target a fused track ran 2 m
    /// off while the first camera's own track, restarted on every frame, vouched for nothing), if every camera
    /// compared refutes it, or if a camera whose clock is given (the first, or one the rig file times) does: a clock
    /// learnt wrong carries its camera's estimates with the fused track it pulls, and they agree, where the given
    /// clock's camera cannot be wrong in time. One camera with a learnt clock refuting it alone is the camera's own
    /// track gone astray (carried across an occlusion), not the fused one.
    fn contradicted_by_the_cameras(&self) -> bool {
        let Some(f) = &self.fused else {
            return false;
        };
        let bound = chi2_upper_quantile(3.0, CROSS_CHECK_Z);
        let fused_position = f.p.fixed_view::<3, 3>(0, 0).into_owned();
        let verdicts = (0..self.rig.len())
            .filter(|&c| self.synced[c])
            .filter_map(|c| {
                // In time order: the nearest is one of the two around the fused time (a search, not a scan: this
                // runs at every fused estimate).
                let recent = &self.recent_singles[c];
                let after = recent.partition_point(|e| e.t_ref_s < f.t_s);
                [after.checked_sub(1), Some(after)]
                    .into_iter()
                    .flatten()
                    .filter_map(|i| recent.get(i))
                    .filter(|e| (f.t_s - e.t_ref_s).abs() <= CROSS_CHECK_SPAN_S)
                    .min_by(|a, b| {
                        (a.t_ref_s - f.t_s)
                            .abs()
                            .total_cmp(&(b.t_ref_s - f.t_s).abs())
                    })
                    .map(|e| (c, e))
            })
            .filter_map(|(c, e)| {
                let p = e.covariance?;
                let dt = f.t_s - e.t_ref_s;
                // Position covariance carried by the constant twist over dt: P_pp + dt (P_pv + P_vp) + dt² P_vv,
                // plus the white acceleration's dt³/3 per axis.
                let pp = p.fixed_view::<3, 3>(0, 0).into_owned();
                let pv = p.fixed_view::<3, 3>(0, 6).into_owned();
                let vv = p.fixed_view::<3, 3>(6, 6).into_owned();
                let white = self.tuning.linear_accel_psd * dt.abs().powi(3) / 3.0;
                let carried = pp
                    + (pv + pv.transpose()) * dt
                    + vv * (dt * dt)
                    + nalgebra::Matrix3::identity() * white;
                let difference = f.state.cam_t_obj_m - e.state.predicted(dt).cam_t_obj_m;
                let s_inv = (carried + fused_position).try_inverse()?;
                let clock_given = self.clock_states[c].0.is_none();
                Some((
                    clock_given,
                    (difference.transpose() * s_inv * difference)[0] > bound,
                ))
            });
        // No camera's own track vouched for near it: nothing stands behind the fused estimate but the fused filter
        // itself (on 30 Hz frames of a fast target, a fused track 2 m off, the first camera's own track restarted
        // on every frame).
        let verdicts: Vec<(bool, bool)> = verdicts.collect();
        verdicts.is_empty()
            || verdicts.iter().all(|&(_, refuted)| refuted)
            || verdicts
                .iter()
                .any(|&(clock_given, refuted)| clock_given && refuted)
    }

    /// An estimate when `every` fused measurements have come since the previous one.
    fn estimate_if_due(&mut self) -> Option<RigEstimate> {
        let f = self.fused.as_ref()?;
        if self.since_estimate < self.config.tracker.every || f.t_s <= self.last_emitted_s {
            return None;
        }
        let contradicted = self.contradicted_by_the_cameras();
        let f = self.fused.as_mut()?;
        self.since_estimate = 0;
        let covariance: Matrix12 = Matrix12::from_fn(|i, j| f.p[(i, j)]);
        // Disputed as the single-camera filter's estimates are: a run of rejections, a newest one far beyond the gate,
        // or half the measurements since the last estimate rejected (one rejection alone happens once in 90 good
        // measurements).
        let disputed = f.gated_in_a_row >= DISPUTED_AFTER_GATED_IN_A_ROW
            || (f.newest_gated && f.newest_nis > DISPUTED_NIS)
            || 2 * f.gated_since_estimate >= f.count.max(2);
        f.gated_since_estimate = 0;
        let status = if disputed || contradicted {
            TrackStatus::Disputed
        } else if f.estimates < CONVERGING_ESTIMATES {
            TrackStatus::Converging
        } else {
            TrackStatus::Tracking
        };
        let residual_rms_px = if f.count > 0 {
            (f.sum_squares_px2 / (2 * f.count) as f64).sqrt()
        } else {
            0.0
        };
        let measurements_used = f.count;
        f.sum_squares_px2 = 0.0;
        f.count = 0;
        f.estimates += 1;
        self.last_emitted_s = f.t_s;
        let noise_px = self.noise_px.iter().copied().fold(f64::INFINITY, f64::min);
        let estimate = Estimate {
            t_ref_s: f.t_s,
            state: f.state,
            residual_rms_px,
            inverse_condition: inverse_condition(&covariance),
            measurements_used,
            iterations: measurements_used,
            status,
            covariance: Some(covariance),
            noise_px,
            acceleration: None,
        };
        self.report.estimates += 1;
        Some(RigEstimate {
            estimate,
            clocks: self.clocks(),
        })
    }
}

/// The step (s) of the offset's chi² on either side of the offset found, for its curvature: a fraction of the
/// interval of 30 Hz frames, many of a 4 kHz stream's.
const SYNC_CURVATURE_STEP_S: f64 = 1e-3;

/// One vouched estimate of a camera's own track: its time (the camera's clock), its position in the rig frame and
/// that position's covariance (m²).
type TrackSample = (f64, Vector3<f64>, Matrix3<f64>);

/// How far (s, rig time) a camera's own vouched estimate may lie from a fused one to be compared with it.
const CROSS_CHECK_SPAN_S: f64 = 0.05;

/// The cross-check's bound, in standard deviations of one Gaussian error (a false alarm once in 3.5 million checks):
/// every fused estimate is checked against every synced camera, thousands a second at kHz rates, and what the check
/// is for, a fused track gone astray by millimetres to metres, lies far beyond it.
const CROSS_CHECK_Z: f64 = 5.0;

/// The most own estimates kept per camera for the cross-check (a bound on memory whatever the estimate rate).
const CROSS_CHECK_CAPACITY: usize = 512;

/// The broad prior of a track with no covariance: 1 cm, 0.1 rad, 1 m/s, 10 rad/s.
fn broad_prior() -> Matrix12 {
    let sigmas = [
        1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 10.0, 10.0, 10.0,
    ];
    Matrix12::from_diagonal(&Vector12::from_fn(|i, _| sigmas[i] * sigmas[i]))
}

/// The reciprocal condition number of a covariance's correlation matrix (1: its errors uncorrelated, 0: one of them
/// a combination of the others): the conditioning figure of a fused estimate.
fn inverse_condition(covariance: &Matrix12) -> f64 {
    let d = Vector12::from_fn(|i, _| 1.0 / covariance[(i, i)].max(1e-300).sqrt());
    let correlation = Matrix12::from_fn(|i, j| covariance[(i, j)] * d[i] * d[j]);
    let eigen = correlation.symmetric_eigenvalues();
    let (min, max) = eigen.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| {
        (lo.min(e), hi.max(e))
    });
    if max > 0.0 && min.is_finite() {
        (min / max).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

impl Fused {
    /// Moves the state `dt_s` ahead (or back) under its constant twist and grows the covariance.
    fn predict(&mut self, dt_s: f64, tuning: &KalmanTuning) {
        if dt_s == 0.0 {
            return;
        }
        self.last_dt_s = dt_s.abs();
        // F = [I 0 dt·I 0; 0 E 0 B; 0 0 I 0; 0 0 0 I] (`MotionState::transition_jacobian`) applied by its blocks to
        // every column of P, then from the right to every row: F P Fᵀ, and F P on the clocks' cross-covariances
        // (the clocks do not move), in place.
        let f = self.state.transition_jacobian(dt_s);
        let e = f.fixed_view::<3, 3>(3, 3).into_owned();
        let b = f.fixed_view::<3, 3>(3, 9).into_owned();
        let apply = |v: &mut [f64]| {
            let (p, w, dv, dw) = (
                Vector3::new(v[0], v[1], v[2]),
                Vector3::new(v[3], v[4], v[5]),
                Vector3::new(v[6], v[7], v[8]),
                Vector3::new(v[9], v[10], v[11]),
            );
            let p = p + dv * dt_s;
            let w = e * w + b * dw;
            v[..3].copy_from_slice(p.as_slice());
            v[3..6].copy_from_slice(w.as_slice());
        };
        let n = self.p.nrows();
        for mut column in self.p.column_iter_mut() {
            apply(&mut column.as_mut_slice()[..12]);
        }
        let mut row = [0.0; 12];
        for r in 0..n {
            for (k, entry) in row.iter_mut().enumerate() {
                *entry = self.p[(r, k)];
            }
            apply(&mut row);
            for (k, entry) in row.iter().enumerate() {
                self.p[(r, k)] = *entry;
            }
        }
        let dt = dt_s.abs();
        let scale = self.process_log_scale.map(f64::exp);
        for (pos, vel, psd) in [
            (0, 6, tuning.linear_accel_psd * scale[0]),
            (3, 9, tuning.angular_accel_psd * scale[1]),
        ] {
            let (qpp, qpv, qvv) = (psd * dt * dt * dt / 3.0, psd * dt * dt / 2.0, psd * dt);
            for i in 0..3 {
                self.p[(pos + i, pos + i)] += qpp;
                self.p[(pos + i, vel + i)] += qpv;
                self.p[(vel + i, pos + i)] += qpv;
                self.p[(vel + i, vel + i)] += qvv;
            }
        }
        self.state = self.state.predicted(dt_s);
        self.t_s += dt_s;
    }

    /// The trend's weight per update (translational, rotational): as the single-camera filter's, the step over the
    /// filter's own time constant, at most [`Self::trend_rate`].
    fn trend_rates(&self) -> [f64; 2] {
        [0, 3].map(|first| {
            let pose: f64 = (first..first + 3).map(|i| self.p[(i, i)]).sum();
            let twist: f64 = (first + 6..first + 9).map(|i| self.p[(i, i)]).sum();
            let rate = self.last_dt_s / (pose / twist).sqrt();
            if rate.is_finite() && rate > 0.0 {
                rate.min(self.trend_rate)
            } else {
                self.trend_rate
            }
        })
    }
}
