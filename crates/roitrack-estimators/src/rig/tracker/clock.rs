//! The cameras' clocks as the rig tracker learns them: the coarse offset searched by laying a camera's own track
//! over the first camera's, taken only if the tracks agree within their errors, and searched again when the fused
//! filter keeps rejecting the camera.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

use nalgebra::{Matrix3, Vector3};
use roitrack_core::stats::chi2_upper_0_1_percent;

use super::{RigError, RigTracker};
use crate::rig::{offset_chi2, search_offset_s};

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

/// Grid step (s) of the coarse offset search.
const SEARCH_STEP_S: f64 = 0.5e-3;

impl RigTracker {
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

    /// The coarse offset of camera `c` against the first camera, once both tracks span the stretch and the target has
    /// moved over it.
    pub(super) fn try_sync(&mut self, c: usize) -> Result<(), RigError> {
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
    pub(super) fn resync(&mut self, c: usize) {
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
}

/// The step (s) of the offset's chi² on either side of the offset found, for its curvature: a fraction of the
/// interval of 30 Hz frames, many of a 4 kHz stream's.
const SYNC_CURVATURE_STEP_S: f64 = 1e-3;

/// One vouched estimate of a camera's own track: its time (the camera's clock), its position in the rig frame and
/// that position's covariance (m²).
pub(super) type TrackSample = (f64, Vector3<f64>, Matrix3<f64>);
