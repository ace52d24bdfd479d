//! A camera's restarts by a live loop as the fused filter meets them: which of its centroids come from a track that
//! has not yet shown a whole cycle of agreement with the fused one.

use std::collections::VecDeque;

/// The most restarts of one camera kept ahead of the fused filter (a bound on memory: a camera that restarts on
/// every full frame while its clock is still unknown fuses nothing, so nothing passes them).
const MAX_PENDING_RESTARTS: usize = 8;

/// One camera's restarts ([`super::RigTracker::restart_camera`]) and how far its centroids since the one in effect
/// agree with the fused track.
///
/// A live loop restarts a camera when its own side finds the target in a full frame, and tells the tracker at once,
/// while the fused filter, behind by its reorder buffer, has still to take the centroids of the camera's previous
/// track: each centroid is judged by the restart before it, not by the newest one.
#[derive(Debug, Clone, Default)]
pub(super) struct Restarts {
    /// Restart times (the camera's clock) in order: the first is the one in effect for the camera's newest centroid
    /// fused, the later ones are still ahead of the fused filter.
    times_s: VecDeque<f64>,
    /// The camera's centroids the fused filter accepted in a row since the restart in effect.
    agreeing_in_a_row: usize,
    /// A whole cycle was accepted in a row since the restart in effect: the track has settled, and stays settled
    /// until the next restart whatever the gate says of its later centroids (they count as any camera's).
    settled: bool,
}

impl Restarts {
    /// A restart at `t_s` of the camera's clock.
    pub(super) fn push(&mut self, t_s: f64) {
        if self.times_s.len() == MAX_PENDING_RESTARTS {
            self.times_s.pop_front();
        }
        self.times_s.push_back(t_s);
    }

    /// Whether the camera's centroid at `t_s` (its clock; centroids of a camera come in time order) is from a track
    /// that is settling: restarted before it, and never `cycle` of its centroids accepted in a row since. Settled
    /// once, a track does not settle again before its next restart: a settled camera's rejections (the fused track
    /// gone wrong at a hard turn, say) must count against the fused track, or the other cameras, whose clock states
    /// can absorb its error, would outvote the first camera for good.
    pub(super) fn settling(&mut self, t_s: f64, cycle: usize) -> bool {
        while self.times_s.len() >= 2 && self.times_s[1] <= t_s {
            self.times_s.pop_front();
            self.agreeing_in_a_row = 0;
            self.settled = false;
        }
        self.settled |= self.agreeing_in_a_row >= cycle;
        self.times_s.front().is_some_and(|&r| t_s >= r) && !self.settled
    }

    /// The camera's centroid just judged by [`Self::settling`] was accepted (`true`) or rejected by the gate.
    pub(super) fn judged(&mut self, accepted: bool) {
        self.agreeing_in_a_row = if accepted {
            self.agreeing_in_a_row.saturating_add(1)
        } else {
            0
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_centroid_is_judged_by_the_restart_before_it() {
        let mut r = Restarts::default();
        assert!(!r.settling(0.1, 2), "never restarted: settled");
        r.push(1.0);
        r.push(2.0);
        assert!(!r.settling(0.9, 2), "the track before the first restart");
        assert!(r.settling(1.1, 2));
        r.judged(true);
        r.judged(true);
        assert!(!r.settling(1.2, 2), "a whole cycle in a row agreed");
        assert!(
            r.settling(2.0, 2),
            "the second restart starts its own count"
        );
        r.judged(true);
        r.judged(false);
        r.judged(true);
        assert!(r.settling(2.1, 2), "a rejection starts the run again");
        r.judged(true);
        assert!(!r.settling(2.2, 2), "settled");
        r.judged(false);
        assert!(
            !r.settling(2.3, 2),
            "a settled track's rejection does not make it settle again"
        );
    }

    #[test]
    fn restarts_ahead_of_the_filter_are_bounded() {
        let mut r = Restarts::default();
        for k in 0..100 {
            r.push(k as f64);
        }
        assert_eq!(r.times_s.len(), MAX_PENDING_RESTARTS);
        assert!(r.settling(99.5, 1));
    }
}
