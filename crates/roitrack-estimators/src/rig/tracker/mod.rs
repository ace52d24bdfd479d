//! The rig's tracker: one pose and twist of the target, in the rig's frame and on the rig's clock, from the
//! centroids of every camera as they come, and each camera's clock learnt from them.
//!
//! [`RigTracker`] takes the centroids here, and merges the cameras' streams by rig time in a reorder buffer. Each
//! camera's own tracker and what the rig takes from it are in `cameras`, the clocks' search in `clock`, the fused
//! filter in `fused` (the covariance matching of a frame's blobs in `instant`), the estimates and their cross-check
//! in `estimate`, the options and errors in `config`.

mod cameras;
mod clock;
mod config;
mod estimate;
mod fused;
mod instant;
mod restarts;

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

use roitrack_core::{Measurement, MotionState, SpatioTemporalModel, Target};

use super::{Rig, RigMeasurement};
use crate::{Estimate, Estimator, EstimatorConfig, KalmanTuning, Matrix12, Tracker};
use clock::TrackSample;
use fused::Fused;
use restarts::Restarts;

pub use clock::ClockEstimate;
pub use config::{RigError, RigTrackerConfig};
pub use estimate::RigEstimate;

#[cfg(doc)]
use super::{rig_projection, search_offset_s};
#[cfg(doc)]
use estimate::{CROSS_CHECK_CAPACITY, CROSS_CHECK_SPAN_S};

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
    /// Per camera: the newest estimate of its own tracker, whatever its status (its frame and clock), until a live
    /// loop takes it ([`Self::take_camera_estimate`]).
    untaken_single: Vec<Option<Estimate>>,
    /// Per camera: its restarts by a live loop ([`Self::restart_camera`]) as the fused filter meets them. While a
    /// restarted camera's centroids have not agreed with the fused track for a whole cycle in a row (as many as the
    /// target has points), those the gate rejects tell against that camera, not against the track, as long as
    /// another camera's centroids agree with the track (accepted within [`CROSS_CHECK_SPAN_S`]): they dispute the
    /// fused estimate neither by a run of rejections, nor by one far beyond the gate, nor in the share of rejected
    /// centroids. A track started from a still pose in one frame may lose a fast target for a few ROIs and read its
    /// neighbouring blobs (in a live rig, centroids 14-28 px off 2 ms after a camera's view came back, the fused
    /// track right all along). With no other camera agreeing, its rejections count as any camera's.
    restarts: Vec<Restarts>,
    /// Per camera: the rig time of its newest centroid the fused filter accepted while the camera was not settling
    /// (-inf: none).
    agreed_at_rig_s: Vec<f64>,
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
            untaken_single: vec![None; n],
            restarts: vec![Restarts::default(); n],
            agreed_at_rig_s: vec![f64::NEG_INFINITY; n],
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

    /// The newest estimate of camera `camera`'s own tracker (in its frame and on its clock, whatever its status) that
    /// came since the last call, taken: what a live loop places that camera's next ROIs from, as a single camera's
    /// loop does from its tracker's estimates (the fused ones come [`RigTrackerConfig::reorder_latency_s`] later).
    /// `None` if no new one came, or for a camera the rig does not have.
    ///
    /// ```
    /// use roitrack_estimators::rig::{Rig, RigMeasurement, RigTracker, RigTrackerConfig};
    /// use roitrack_core::{CameraModel, Measurement, Target};
    ///
    /// let mut tracker = RigTracker::new(Rig::single("cam", CameraModel::canonical()), Target::grid4x4(),
    ///     RigTrackerConfig::default()).unwrap();
    /// let m = Measurement { t_s: 0.0, id: 0, u_px: 480.0, v_px: 480.0 };
    /// tracker.push(&RigMeasurement { camera: 0, measurement: m }).unwrap();
    /// // One centroid starts no track: no estimate to place ROIs from.
    /// assert!(tracker.take_camera_estimate(0).is_none());
    /// ```
    pub fn take_camera_estimate(&mut self, camera: usize) -> Option<Estimate> {
        self.untaken_single.get_mut(camera)?.take()
    }

    /// Restarts camera `camera`'s own tracker from `state` at `t_s` of its clock with `covariance` (a live loop's
    /// full frame, where the target was found with no prior). Until the camera's centroids from `t_s` on have agreed
    /// with the fused track for a whole cycle in a row, those the fused filter's gate rejects do not dispute the fused
    /// estimate while another camera's agree with it. Nothing for a camera the rig does not have.
    ///
    /// ```
    /// use roitrack_estimators::rig::{Rig, RigTracker, RigTrackerConfig};
    /// use roitrack_estimators::Estimator;
    /// use roitrack_core::{CameraModel, MotionState, Target};
    ///
    /// let mut tracker = RigTracker::new(Rig::single("cam", CameraModel::canonical()), Target::grid4x4(),
    ///     RigTrackerConfig::default()).unwrap();
    /// let pose = MotionState::at_rest(Default::default(), [0.0, 0.0, 0.6].into());
    /// tracker.restart_camera(0, 0.5, pose, None);
    /// assert_eq!(tracker.camera_tracker(0).unwrap().state().unwrap().0, 0.5);
    /// ```
    pub fn restart_camera(
        &mut self,
        camera: usize,
        t_s: f64,
        state: MotionState,
        covariance: Option<Matrix12>,
    ) {
        if let Some(single) = self.singles.get_mut(camera) {
            single.start_from(t_s, state, covariance);
            self.restarts[camera].push(t_s);
        }
    }

    /// The newest estimate of camera `c`'s own tracker, if one came: kept for [`Self::take_camera_estimate`].
    fn note_own(&mut self, c: usize, single: Option<Estimate>) {
        if single.is_some() {
            self.untaken_single[c] = single;
        }
    }

    /// The time on the rig's clock of `t_camera_s` on camera `camera`'s clock, by that clock as known now (given,
    /// or learnt so far: before its offset is found, the camera's own time). What a live loop merges the cameras'
    /// streams by, as the reorder buffer orders them.
    ///
    /// # Panics
    ///
    /// If the rig has no camera `camera`.
    pub fn rig_time_s(&self, camera: usize, t_camera_s: f64) -> f64 {
        self.clocks[camera].rig_time_s(t_camera_s)
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
            self.note_own(c, single);
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
            self.note_own(c, single);
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
}
