//! Each camera's own tracker: the instants of a frame camera held and given to it whole, and what the rig takes
//! from its vouched estimates (its noise, its track for the clock search, its estimates for the cross-check).

use super::estimate::{CROSS_CHECK_CAPACITY, CROSS_CHECK_SPAN_S};
use super::fused::broad_prior;
use super::{RigError, RigTracker};
use crate::{Emit, Estimate, Estimator, TrackError};

impl RigTracker {
    /// The held measurements of one instant to their camera's own tracker, and its estimate to the rig.
    pub(super) fn give_held(&mut self) -> Result<(), RigError> {
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
        let single = single.map_err(|source| self.measurement_error(c, source))?;
        self.note_own(c, single);
        if let Some(e) = single
            && e.status.is_vouched_for()
        {
            self.take_single(c, &e)?;
        }
        Ok(())
    }

    pub(super) fn measurement_error(&self, c: usize, source: TrackError) -> RigError {
        RigError::Measurement {
            camera: self.rig.cameras()[c].name.clone(),
            source,
        }
    }

    /// A vouched estimate of camera `c`'s own tracker: its noise, its track for the offset search, and the search
    /// when both tracks are long enough.
    pub(super) fn take_single(&mut self, c: usize, e: &Estimate) -> Result<(), RigError> {
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
}
