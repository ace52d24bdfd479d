//! A rolling-shutter track started from its first frames fitted together: pose and twist under one constant twist,
//! every blob of the frames at its own row's time.
//!
//! Why: a rolling-shutter frame's blobs are read over the rows the target spans (4 ms for 130 rows at 30 µs), and the
//! static pose of one frame takes them as simultaneous: the target's motion over the readout is read as a change of the
//! pose, millimetres of depth at the speeds of the renderer outside the project (docs/results.md, "Rolling shutter from
//! a renderer outside the project"). A track started there, at rest or with the twist of two such poses, predicts the
//! next frames tens of millimetres off; their estimates are disputed and every new track starts the same way while the
//! target stays fast. One frame does not show the twist; two or three consecutive frames do, and their blobs fitted
//! with it give the pose too.

use std::collections::VecDeque;

use roitrack_core::solver::{SolverOptions, solve};
use roitrack_core::stats::chi2_upper_0_1_percent;
use roitrack_core::{Measurement, MotionState, SpatioTemporalModel};
use roitrack_estimators::{Emit, Estimator, Observation, WindowProblem};

use super::restart::{RESTART_TWIST_MAX_GAP_S, RESTART_TWIST_SIGMAS};
use super::{FrameError, FrameTracker, RESTART_RESIDUAL_PX, observation_of};
use crate::realtime::full_frame_covariance;

/// Frames a rolling-shutter track's start is fitted from (the newest included): three frames pin the twist over two
/// frame intervals, and the filter takes the acceleration from there.
pub(super) const JOINT_START_FRAMES: usize = 3;
/// Levenberg-Marquardt iterations of the joint fit: it starts centimetres and a metre per second off.
const JOINT_FIT_ITERATIONS: usize = 50;

/// The last frames' measurements on a rolling shutter (at most [`JOINT_START_FRAMES`] - 1, consecutive, each with
/// its target found), and how many frames the current track rests on.
#[derive(Debug, Default)]
pub(super) struct RecentFrames {
    /// Each frame's row-0 time and its measurements (time order), oldest first.
    frames: VecDeque<(f64, Vec<Measurement>)>,
    /// Buffers of frames that left, reused.
    spare: Vec<Vec<Measurement>>,
    /// Frames of the current track before the frame being processed: 0 at a start from one frame's static pose,
    /// the frames fitted before the newest at a joint start.
    pub(super) track_frames: usize,
}

impl RecentFrames {
    /// Keeps the frame whose row 0 was read at `t_s` and its `measurements`; a frame without any breaks the run.
    pub(super) fn remember(&mut self, t_s: f64, measurements: &[Measurement]) {
        if measurements.is_empty() {
            self.forget();
            return;
        }
        if self.frames.len() + 1 >= JOINT_START_FRAMES
            && let Some((_, buffer)) = self.frames.pop_front()
        {
            self.spare.push(buffer);
        }
        let mut buffer = self.spare.pop().unwrap_or_default();
        buffer.clear();
        buffer.extend_from_slice(measurements);
        self.frames.push_back((t_s, buffer));
    }

    /// Forgets every frame kept.
    pub(super) fn forget(&mut self) {
        while let Some((_, buffer)) = self.frames.pop_front() {
            self.spare.push(buffer);
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

impl FrameTracker {
    /// Whether the frame being processed, measured for a running track, starts it anew from the frames before it
    /// fitted with it ([`Self::joint_start`]): a rolling shutter, frames kept before it, and a track of fewer than
    /// [`JOINT_START_FRAMES`] frames before this one (its start rests on fewer frames than a joint start takes).
    pub(super) fn wants_joint_start(&self) -> bool {
        self.camera.time.is_rolling()
            && !self.recent.is_empty()
            && self.recent.track_frames < JOINT_START_FRAMES
    }

    /// The states a joint start is fitted from, at the mean time of this frame's measurements: the running track's
    /// prediction, and `found` (this frame's static pose, if it was identified whole) with the twist that carried
    /// the last trusted pose to it.
    pub(super) fn joint_guesses(&self, found: Option<MotionState>) -> Vec<MotionState> {
        let count = self.measurements.len().max(1);
        let mean_s = self.measurements.iter().map(|m| m.t_s).sum::<f64>() / count as f64;
        let predicted = self
            .memory
            .predictor
            .map(|p| p.state.predicted(mean_s - p.t_ref_s));
        let restarted = found.map(|pose| self.restart_state(mean_s, pose).0);
        predicted.into_iter().chain(restarted).collect()
    }

    /// Starts a new track from the kept frames and this one (row 0 read at `t_s`, its measurements in
    /// `self.measurements`) fitted together under one constant twist, from each of `guesses` (the state at the mean
    /// time of this frame's measurements) and keeping the fit of least residual. The filter starts at the oldest
    /// frame from that fit, with the broad prior of a pose from a full frame and the twist prior of a new track, and
    /// is given the kept frames again: the current frame's batch is the caller's to give. Fewer kept frames are
    /// fitted when more do not fit ([`Self::joint_fit`]); returns `false`, leaving the track as it was, when no fit
    /// explains the blobs.
    pub(super) fn joint_start(
        &mut self,
        t_s: f64,
        guesses: &[MotionState],
    ) -> Result<bool, FrameError> {
        let count = self.measurements.len();
        if count == 0 || !self.camera.time.is_rolling() {
            return Ok(false);
        }
        // The kept frames close enough to this one for one twist to carry the pose across them.
        let oldest = self
            .recent
            .frames
            .iter()
            .position(|(t_kept_s, _)| t_s - t_kept_s <= RESTART_TWIST_MAX_GAP_S)
            .unwrap_or(self.recent.frames.len());
        let t_ref_s = self.measurements.iter().map(|m| m.t_s).sum::<f64>() / count as f64;
        // From the most frames to the fewest: one twist may not carry the pose across three frames of a motion
        // whose twist turns within them (the random motion at 5 rad/s: 1.5-6.4 px of residual over three frames,
        // where two fitted to 0.03 px, and a start 9 mm and 7.7 degrees off marked converging).
        let Some((first, fitted)) = (oldest..self.recent.frames.len())
            .find_map(|first| Some((first, self.joint_fit(first, t_ref_s, guesses)?)))
        else {
            return Ok(false);
        };
        let kept = self.recent.frames.len() - first;
        // The filter goes over the kept frames again from the fit's state at the oldest one: the fit is its
        // linearisation point, and its own motion model (accelerations included) makes the estimates.
        let (t_first_s, _) = self.recent.frames[first];
        let mut covariance = full_frame_covariance();
        for (i, sigma) in RESTART_TWIST_SIGMAS.iter().enumerate() {
            for axis in 0..3 {
                let k = 6 + 3 * i + axis;
                covariance[(k, k)] = sigma * sigma;
            }
        }
        self.tracker.reset();
        self.tracker.start_from(
            t_first_s,
            fitted.predicted(t_first_s - t_ref_s),
            Some(covariance),
        );
        for (_, ms) in self.recent.frames.iter().skip(first) {
            self.tracker.push_batch(ms, Emit::EachBatch)?;
        }
        self.windows.scheduler.reset();
        // A start from fewer frames than were kept is final: a fit over more of them, longer still, would not fit
        // either, and starting again at every frame would keep the filter from ever settling.
        self.recent.track_frames = if first > oldest {
            JOINT_START_FRAMES
        } else {
            kept
        };
        Ok(true)
    }

    /// The fit of pose and twist (at `t_ref_s`) to the blobs of the kept frames from `first` on and of this frame,
    /// from each of `guesses`, the one of least residual; `None` when no fit explains the blobs as the centroid
    /// noise does: its residual beyond the upper 0.1 % point of the chi-square of its degrees of freedom at the
    /// tracker's noise, or beyond [`RESTART_RESIDUAL_PX`].
    fn joint_fit(
        &self,
        first: usize,
        t_ref_s: f64,
        guesses: &[MotionState],
    ) -> Option<MotionState> {
        let kept = self.recent.frames.len() - first;
        let observations: Vec<Observation> = self
            .recent
            .frames
            .iter()
            .skip(first)
            .flat_map(|(_, ms)| ms.iter())
            .chain(self.measurements.iter())
            .filter_map(|m| observation_of(&self.target, &self.camera, m))
            .collect();
        // Twelve unknowns: at least as many blobs as a frame's fit takes (4) per frame.
        if observations.len() < 4 * (kept + 1) {
            return None;
        }
        let dof = 2 * observations.len() - 12;
        let noise_px = self
            .memory
            .noise_px
            .unwrap_or(self.tracker.config().noise_px);
        let limit_px = (noise_px * (chi2_upper_0_1_percent(dof as f64) / dof as f64).sqrt())
            .min(RESTART_RESIDUAL_PX);
        let model = SpatioTemporalModel::new(self.camera.intrinsics);
        let options = SolverOptions::levenberg_marquardt(JOINT_FIT_ITERATIONS);
        let mut best: Option<(f64, MotionState)> = None;
        for guess in guesses {
            let mut problem =
                WindowProblem::new(&model, self.target.points(), &observations, t_ref_s);
            let fit = solve(&mut problem, *guess, &options);
            let rms_px = (fit.normal_equations.cost_px2() / dof as f64).sqrt();
            if fit.params.is_finite() && rms_px <= limit_px && best.is_none_or(|(b, _)| rms_px < b)
            {
                best = Some((rms_px, fit.params));
            }
        }
        best.map(|(_, fitted)| fitted)
    }
}
