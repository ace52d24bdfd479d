//! A new track from a frame found whole: its pose the frame's static pose, its twist and its labelling of a
//! symmetric target the ones that carry the last trusted pose to it.

use roitrack_core::target::{Symmetry, TargetAmbiguity};
use roitrack_core::{Acceleration, MotionState, Target};
use roitrack_estimators::Estimator;
use roitrack_estimators::Matrix12;

use super::{FrameError, FrameTracker};
use crate::realtime::full_frame_covariance;
use crate::scheduler::Predictor;

/// The oldest last trusted pose a new track takes its twist from (s): three frames at 30 Hz.
pub(super) const RESTART_TWIST_MAX_GAP_S: f64 = 0.1;
/// The standard deviations of that twist (m/s, rad/s).
pub(super) const RESTART_TWIST_SIGMAS: [f64; 2] = [0.3, 1.0];

/// What the track carries from one frame to the next.
#[derive(Debug, Default)]
pub(super) struct TrackMemory {
    /// The last estimate, from which the next frame's windows are placed, and its accelerations if the estimator
    /// has them.
    pub(super) predictor: Option<Predictor>,
    pub(super) acceleration: Option<Acceleration>,
    /// The latest time of the last frame's measurements (or of its row 0).
    pub(super) last_time_s: Option<f64>,
    /// The time of the last estimate given.
    pub(super) last_estimate_s: Option<f64>,
    /// The newest pose to trust, and its time: a frame found whole (the static pose of its identified blobs) or an
    /// estimate vouched for. A new track takes its twist from it ([`FrameTracker::restart_state`]).
    pub(super) last_pose: Option<(f64, MotionState)>,
    /// The centroid noise of the last estimate (px): the estimator's, learnt or given.
    pub(super) noise_px: Option<f64>,
    /// Whether the last estimate was `tracking`: its covariance, from which the windows are sized, has been borne out
    /// by the frames (a new track's states a twist differenced from two poses, and may be far too sure of it).
    pub(super) tracking: bool,
}

impl FrameTracker {
    /// Of the poses a symmetric target's detection `found` at `t_s` could be (its labelling and its twins'), the one
    /// nearest the last trusted pose carried on by its twist to `t_s`, and which twin it is (`None`: the detection's
    /// own). Identification labels a symmetric grid one fixed way; a track that has turned the grid past half its
    /// symmetry follows another labelling, and a new track on the detection's would turn the pose by the symmetry's
    /// angle and write the twist of that turn, tens of m/s and rad/s (measured in docs/results.md, "Design measurements
    /// behind the code").
    pub(super) fn nearest_twin(
        &self,
        t_s: f64,
        found: MotionState,
    ) -> (MotionState, Option<usize>) {
        let Some((t_last_s, last)) = self.memory.last_pose else {
            return (found, None);
        };
        let dt_s = t_s - t_last_s;
        if self.search.twins.is_empty() || !(0.0..=RESTART_TWIST_MAX_GAP_S).contains(&dt_s) {
            return (found, None);
        }
        let predicted = last.predicted(dt_s);
        let distance = |s: &MotionState| predicted.pose_distance(s);
        let mut best = (found, None, distance(&found));
        for (k, (symmetry, _)) in self.search.twins.iter().enumerate() {
            let twin = twin_state(&found, symmetry);
            let d = distance(&twin);
            if d < best.2 {
                best = (twin, Some(k), d);
            }
        }
        (best.0, best.1)
    }

    /// A new track from the static pose `found` of the frame whose row 0 is read at `t_s`; the frame's measurements
    /// (`self.measurements`, those the pose was found from) follow at their own times. The pose is that of their mean
    /// time (a rolling shutter reads them over the rows the target spans); the track starts at `t_s`, carried back by
    /// its twist. With a rolling shutter and the frames before it kept, the track starts from them and this frame
    /// fitted together instead ([`Self::joint_start`]), when that fit agrees with their blobs.
    pub(super) fn restart(&mut self, t_s: f64, found: MotionState) -> Result<(), FrameError> {
        let count = self.measurements.len();
        let found_s = if count == 0 {
            t_s
        } else {
            self.measurements.iter().map(|m| m.t_s).sum::<f64>() / count as f64
        };
        let (state, covariance) = self.restart_state(found_s, found);
        if !self.recent.is_empty() && self.joint_start(t_s, &[state])? {
            return Ok(());
        }
        self.recent.track_frames = 0;
        self.tracker.reset();
        self.tracker
            .start_from(t_s, state.predicted(t_s - found_s), Some(covariance));
        Ok(())
    }

    /// The state and covariance a new track starts from at `t_s`, given the static pose `found` there: with the twist
    /// that carried the last trusted pose ([`TrackMemory::last_pose`]) to it, if that is at most
    /// [`RESTART_TWIST_MAX_GAP_S`] old, else at rest with a broad twist prior. A frame shows the pose, not the motion:
    /// at rest, a target that moves 50 mm between frames (1.5 m/s at 30 Hz) is far from the next frame's windows and
    /// from the blobs they would be matched with, and every frame would start a new track at rest again, far less
    /// accurate than the poses found frame by frame (measured in docs/results.md, "Design measurements behind the
    /// code").
    pub(super) fn restart_state(&self, t_s: f64, found: MotionState) -> (MotionState, Matrix12) {
        // (For a rolling shutter, `t_s` is the mean time of the blobs the pose was found from.)
        let mut covariance = full_frame_covariance();
        let Some((t_last_s, last)) = self.memory.last_pose else {
            return (found, covariance);
        };
        let dt_s = t_s - t_last_s;
        if !(dt_s > 0.0 && dt_s <= RESTART_TWIST_MAX_GAP_S) {
            return (found, covariance);
        }
        // The pose's change over the gap, in the error state's terms (translation, rotation vector on the left).
        let moved = MotionState::difference(&last, &found) / dt_s;
        let state = MotionState {
            velocity_mps: moved.fixed_rows::<3>(0).into_owned(),
            angular_velocity_radps: moved.fixed_rows::<3>(3).into_owned(),
            ..found
        };
        if !state.is_finite() {
            return (found, covariance);
        }
        // The mean twist between the two frames is the twist at their middle: at the newer one it is off by the
        // acceleration times half the gap (10 m/s² and 30 rad/s² over 17 ms: 0.17 m/s and 0.5 rad/s).
        for (i, sigma) in RESTART_TWIST_SIGMAS.iter().enumerate() {
            for axis in 0..3 {
                let k = 6 + 3 * i + axis;
                covariance[(k, k)] = sigma * sigma;
            }
        }
        (state, covariance)
    }
}

/// The symmetries of `target` that identification cannot tell apart ([`Target::ambiguity`]), each with the index of
/// the point it takes each point to.
pub(super) fn symmetric_twins(target: &Target) -> Vec<(Symmetry, Vec<usize>)> {
    let Some(TargetAmbiguity::Symmetric { motions }) = target.ambiguity() else {
        return Vec::new();
    };
    let points = target.points();
    motions
        .into_iter()
        .filter_map(|symmetry| {
            let image: Option<Vec<usize>> = points
                .iter()
                .map(|p| {
                    let moved = symmetry.obj_r * p.point_in_obj_m + symmetry.obj_t_m;
                    (0..points.len()).min_by(|&a, &b| {
                        (points[a].point_in_obj_m - moved)
                            .norm()
                            .total_cmp(&(points[b].point_in_obj_m - moved).norm())
                    })
                })
                .collect();
            image.map(|image| (symmetry, image))
        })
        .collect()
}

/// The pose under which the target's points, relabelled by `symmetry` (point `p` named as `S p`), project where
/// they do under `state`: `cam_T_obj S⁻¹`.
fn twin_state(state: &MotionState, symmetry: &Symmetry) -> MotionState {
    let cam_r_obj = state.cam_r_obj * symmetry.obj_r.inverse();
    MotionState {
        cam_r_obj,
        cam_t_obj_m: state.cam_t_obj_m - cam_r_obj * symmetry.obj_t_m,
        ..*state
    }
}
