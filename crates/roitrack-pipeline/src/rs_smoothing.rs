//! Offline rolling-shutter smoothing: each frame's estimate is held until the four frames after it are tracked, and its
//! pose is fitted again from its own blobs at their row times with the twist of a difference of the poses of the
//! frames around it (two on each side; near a track's start, the frames after it) ([`roitrack_estimators::rolling_refit`]).
//!
//! Why: a rolling-shutter frame's blobs are read milliseconds apart, and the depth of its pose follows the twist
//! assumed over the readout; the causal filter's twist lags by the angular acceleration and jerk, which left the
//! position error of rolling-shutter frames about 5 times that of global-shutter frames of the same motion (docs/
//! frames.md, "Rolling shutter: offline smoothing"). Only for offline sources ([`crate::track_frame_stream`]): the
//! estimates come four frames late, which a live loop does not take.

use std::collections::VecDeque;

use nalgebra::Matrix6;
use roitrack_core::stats::chi2_upper_0_1_percent;
use roitrack_core::{CameraModel, Measurement, SpatioTemporalModel, Target};
use roitrack_estimators::{
    Estimate, MAX_STENCIL_POSES, Matrix12, Observation, PoseRefit, StencilMotion, TimedPose,
    TrackStatus, pose_residuals, refit_pose, stencil_motion, stencil_motion_at_start,
};

use crate::frames::{FrameOutcome, observation_of};

/// Frames on either side of the one refitted: a 5-point stencil, whose error (of order the fifth derivative times
/// T⁴) is far below the centroid noise at 30 Hz, where a ±1 frame difference leaves jerk·T²/6.
const REACH: usize = 2;
/// Frames held after the one given back: a frame near a track's start, with fewer than [`REACH`] poses before it,
/// takes its stencil's other poses after it (5 poses in all, as centred as the track allows), since a one-sided
/// 3-pose difference leaves jerk·T²/3 in the twist, and over a rolling shutter's readout that twist error is a
/// millimetre of depth on fast motions; 5 poses leave a term of order T⁴.
const HELD_AFTER: usize = MAX_STENCIL_POSES - 1;
/// Passes over the held frames per new frame: the neighbours' poses move with their own refits, and three passes bring
/// the refits close enough to their fixed point (measured in docs/results.md, "Design measurements behind the code").
const PASSES: usize = 3;
/// Gauss-Newton steps per refit, from the last refit (or the filter's pose): the pose moves by tenths of a millimetre.
const REFIT_ITERATIONS: usize = 4;
/// A refit moving the pose farther than this (m, rad) from the filter's is not taken, unless the filter's own pose
/// covariance allows it ([`within_the_filters_uncertainty`]): the stencil's poses are then not one smooth motion (a
/// relabelled or restarted track the filter has not flagged), and the filter's estimate is the safer one. The refits
/// move poses by tenths of a millimetre and milliradians; a young track's depth, by millimetres.
const MAX_SHIFT_M: f64 = 0.005;
const MAX_SHIFT_RAD: f64 = 0.05;

/// One frame held: what the sink is given once it is refined.
struct Held<I> {
    info: I,
    outcome: FrameOutcome,
    measurements: Vec<Measurement>,
    observations: Vec<Observation>,
    /// The pose in use (the filter's, then the last refit's) with its covariance; `None` if the frame has no estimate
    /// the filter vouches for (it is then neither refitted nor a neighbour).
    pose: Option<(TimedPose, Matrix6<f64>)>,
    refined: Option<Estimate>,
}

/// A frame's pose and covariance after it left the buffer: the past side of the next frames' stencils.
type PastPose = Option<(TimedPose, Matrix6<f64>)>;

/// A held frame's neighbours and the motion they give at its time ([`RollingSmoother::stencil`]).
struct Stencil {
    /// The neighbours' poses and covariances in time order, the frame's own among them.
    neighbours: Vec<(TimedPose, Matrix6<f64>)>,
    motion: StencilMotion,
    /// The frame has no pose before it: it starts a track.
    starts: bool,
}

/// Holds the last frames of an offline rolling-shutter run and gives each back refined four frames later.
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_pipeline::frames::{FrameMethod, FrameOutcome};
/// use roitrack_pipeline::rs_smoothing::RollingSmoother;
///
/// let mut smoother = RollingSmoother::new(CameraModel::canonical(), Target::grid4x4());
/// let nothing = || FrameOutcome { estimate: None, method: FrameMethod::NotFound, measured: 0 };
/// // Four frames of latency: the first frame comes back with the fifth.
/// for k in 0..4 {
///     assert!(smoother.push(k, nothing(), &[]).is_none());
/// }
/// assert_eq!(smoother.push(4, nothing(), &[]).map(|(k, _, _)| k), Some(0));
/// let rest: Vec<usize> = smoother.finish().map(|(k, _, _)| k).collect();
/// assert_eq!(rest, [1, 2, 3, 4]);
/// ```
pub struct RollingSmoother<I> {
    camera: CameraModel,
    target: Target,
    model: SpatioTemporalModel,
    past: VecDeque<PastPose>,
    pending: VecDeque<Held<I>>,
}

impl<I> RollingSmoother<I> {
    /// A smoother for frames of `camera` (its rolling-shutter time model gave the measurements their times) seeing
    /// `target`.
    pub fn new(camera: CameraModel, target: Target) -> Self {
        Self {
            model: SpatioTemporalModel::new(camera.intrinsics),
            camera,
            target,
            past: VecDeque::with_capacity(REACH),
            pending: VecDeque::with_capacity(HELD_AFTER + 1),
        }
    }

    /// Takes the next frame's outcome and its measurements (raw pixels, at their row times), and gives back the frame
    /// four before it, refined, once there is one.
    pub fn push(
        &mut self,
        info: I,
        outcome: FrameOutcome,
        measurements: &[Measurement],
    ) -> Option<(I, FrameOutcome, Vec<Measurement>)> {
        let held = self.held(info, outcome, measurements);
        self.pending.push_back(held);
        if self.pending.len() <= HELD_AFTER {
            return None;
        }
        // Every held frame but the newest has a frame after it.
        self.refine(self.pending.len() - 1);
        self.pop()
    }

    /// The frames still held, refined with the neighbours there are (a frame without one on each side keeps the
    /// filter's estimate), in order.
    pub fn finish(&mut self) -> impl Iterator<Item = (I, FrameOutcome, Vec<Measurement>)> + '_ {
        self.refine(self.pending.len().saturating_sub(1));
        std::iter::from_fn(move || self.pop())
    }

    fn held(&self, info: I, outcome: FrameOutcome, measurements: &[Measurement]) -> Held<I> {
        let observations: Vec<Observation> = measurements
            .iter()
            .filter_map(|m| observation_of(&self.target, &self.camera, m))
            .collect();
        // Only estimates the filter vouches for are refitted or lent to a neighbour's stencil, and a track's first
        // estimate when it is flagged degenerate (a static pose of a rolling frame: one frame does not show the
        // twist) or disputed (a start fitted with a twist its frames refute), which the frames after it can set
        // right. The refit changes such an estimate's pose and twist, never its flag.
        let previous_has_pose = match self.pending.back() {
            Some(previous) => previous.pose.is_some(),
            None => self.past.back().is_some_and(Option::is_some),
        };
        let pose = outcome.estimate.as_ref().and_then(|e| {
            let starts_a_track =
                matches!(e.status, TrackStatus::Degenerate | TrackStatus::Disputed)
                    && !previous_has_pose;
            (e.status.is_vouched_for() || starts_a_track).then(|| {
                (
                    TimedPose {
                        t_s: e.t_ref_s,
                        cam_r_obj: e.state.cam_r_obj,
                        cam_t_obj_m: e.state.cam_t_obj_m,
                    },
                    pose_block(e.covariance.as_ref(), e.noise_px),
                )
            })
        });
        Held {
            info,
            outcome,
            measurements: measurements.to_vec(),
            observations,
            pose,
            refined: None,
        }
    }

    /// [`PASSES`] passes of refits over the first `count` held frames.
    fn refine(&mut self, count: usize) {
        for _ in 0..PASSES {
            for p in 0..count {
                self.refit(p);
            }
        }
    }

    /// Refits held frame `p` from the poses of its neighbours (contiguous, vouched for: up to [`REACH`] before it,
    /// and after it as many as make [`MAX_STENCIL_POSES`] in all); leaves it as it is without one after it, or
    /// without one before it and two after it.
    fn refit(&mut self, p: usize) {
        let Some(Stencil {
            neighbours,
            motion,
            starts,
        }) = self.stencil(p)
        else {
            return;
        };
        let held = &self.pending[p];
        let (Some(filter), Some((current, _))) = (held.outcome.estimate.as_ref(), held.pose) else {
            return;
        };
        let start = roitrack_core::MotionState {
            cam_r_obj: current.cam_r_obj,
            cam_t_obj_m: current.cam_t_obj_m,
            velocity_mps: motion.velocity_mps,
            angular_velocity_radps: motion.angular_velocity_radps,
        };
        let Some(fit) = refit_pose(
            &self.model,
            &self.target,
            &held.observations,
            current.t_s,
            &start,
            Some(&motion.acceleration),
            filter.noise_px,
            REFIT_ITERATIONS,
        ) else {
            return;
        };
        if !self.takes(p, filter, &fit, &motion.acceleration, starts) {
            return;
        }
        let mut estimate = *filter;
        estimate.state = fit.state;
        estimate.residual_rms_px = fit.residual_rms_px;
        if estimate.acceleration.is_some() {
            estimate.acceleration = Some(motion.acceleration);
        }
        estimate.covariance = filter.covariance.map(|_| {
            // The pose's from the fit; the twist's from the stencil over independent pose errors (Σ w² P); no
            // correlation between them is claimed.
            let mut covariance = Matrix12::zeros();
            covariance
                .fixed_view_mut::<6, 6>(0, 0)
                .copy_from(&fit.pose_covariance);
            let mut twist = Matrix6::zeros();
            for ((_, pose_covariance), w) in neighbours.iter().zip(motion.velocity_weights_per_s) {
                twist += pose_covariance * (w * w);
            }
            covariance.fixed_view_mut::<6, 6>(6, 6).copy_from(&twist);
            covariance
        });
        let held = &mut self.pending[p];
        held.pose = Some((
            TimedPose {
                t_s: current.t_s,
                cam_r_obj: fit.state.cam_r_obj,
                cam_t_obj_m: fit.state.cam_t_obj_m,
            },
            fit.pose_covariance,
        ));
        held.refined = Some(estimate);
    }

    /// The stencil of held frame `p`: its neighbours' poses and covariances (itself among them), the motion they
    /// give at its time, and whether it starts a track (no pose before it); `None` if it has no pose or too few
    /// neighbours.
    fn stencil(&self, p: usize) -> Option<Stencil> {
        let position = self.past.len() + p;
        let pose_at = |i: usize| -> PastPose {
            if i < self.past.len() {
                self.past[i]
            } else {
                self.pending[i - self.past.len()].pose
            }
        };
        let total = self.past.len() + self.pending.len();
        pose_at(position)?;
        let mut first = position;
        while first > 0 && position - first < REACH && pose_at(first - 1).is_some() {
            first -= 1;
        }
        let after = MAX_STENCIL_POSES - 1 - (position - first);
        let mut last = position;
        while last + 1 < total && last - position < after && pose_at(last + 1).is_some() {
            last += 1;
        }
        let neighbours: Vec<(TimedPose, Matrix6<f64>)> =
            (first..=last).filter_map(pose_at).collect();
        let poses: Vec<TimedPose> = neighbours.iter().map(|(pose, _)| *pose).collect();
        // A frame with no pose before it starts a track: its twist from the poses after it.
        let starts = position == first;
        let motion = if starts {
            stencil_motion_at_start(&poses)
        } else {
            stencil_motion(&poses, position - first)
        }?;
        Some(Stencil {
            neighbours,
            motion,
            starts,
        })
    }

    /// Whether held frame `p`'s refit `fit` replaces the filter's estimate `filter`: within the shifts allowed (or
    /// the filter's own uncertainty), or, for a frame that `starts` a track, when it explains the frame's blobs
    /// better.
    fn takes(
        &self,
        p: usize,
        filter: &Estimate,
        fit: &PoseRefit,
        acceleration: &roitrack_core::Acceleration,
        starts: bool,
    ) -> bool {
        let shift_m = (fit.state.cam_t_obj_m - filter.state.cam_t_obj_m).norm();
        let shift_rad =
            roitrack_core::so3::angle_between(&fit.state.cam_r_obj, &filter.state.cam_r_obj);
        // A track's first pose was fitted with no twist, or with one the frames after it have not pinned yet: it may
        // be off by more than the shifts allowed (a rolling frame's, by millimetres and degrees), and the refit is
        // taken when it explains the frame's blobs better: a start the filter does not vouch for (degenerate or
        // disputed) by the filter's residual, any start when its own blobs refute the filter's pose
        // ([`refutes_the_filter`]).
        let within_shifts = (shift_m <= MAX_SHIFT_M && shift_rad <= MAX_SHIFT_RAD)
            || within_the_filters_uncertainty(filter, &fit.state, &fit.pose_covariance);
        let explains_a_start_better = starts
            && ((!filter.status.is_vouched_for() && fit.residual_rms_px <= filter.residual_rms_px)
                || refutes_the_filter(
                    &self.model,
                    &self.target,
                    &self.pending[p].observations,
                    filter,
                    &fit.state,
                    acceleration,
                ));
        fit.state.is_finite() && (within_shifts || explains_a_start_better)
    }

    /// Gives back the oldest held frame, its estimate the last refit's if there was one.
    fn pop(&mut self) -> Option<(I, FrameOutcome, Vec<Measurement>)> {
        let mut held = self.pending.pop_front()?;
        if self.past.len() == REACH {
            self.past.pop_front();
        }
        self.past.push_back(held.pose);
        if let Some(refined) = held.refined {
            held.outcome.estimate = Some(refined);
        }
        Some((held.info, held.outcome, held.measurements))
    }
}

/// Whether a frame's blobs (`observations`) refute the filter's estimate of it and `refit` (under `acceleration`)
/// explains them better: the filter's residual cost over the noise variance beyond the chi-square's upper 0.1 % point
/// (a pose off by more than its blobs' noise allows, as a rolling-shutter start fitted with a twist the frames had not
/// shown yet), and the refit's cost below it.
fn refutes_the_filter(
    model: &SpatioTemporalModel,
    target: &Target,
    observations: &[Observation],
    filter: &Estimate,
    refit: &roitrack_core::MotionState,
    acceleration: &roitrack_core::Acceleration,
) -> bool {
    let cost_px2 = |state: &roitrack_core::MotionState, acceleration| {
        pose_residuals(
            model,
            target,
            observations,
            filter.t_ref_s,
            state,
            acceleration,
        )
        .map_or(f64::INFINITY, |(residuals, _)| residuals.norm_squared())
    };
    let filter_px2 = cost_px2(&filter.state, filter.acceleration.as_ref());
    let refit_px2 = cost_px2(refit, Some(acceleration));
    // Six pose parameters fitted to two coordinates a blob.
    let dof = 2.0 * observations.len() as f64 - 6.0;
    let noise_px2 = filter.noise_px * filter.noise_px;
    dof > 0.0
        && noise_px2 > 0.0
        && filter_px2 > chi2_upper_0_1_percent(dof) * noise_px2
        && refit_px2 < filter_px2
}

/// Whether `refit`'s pose (with covariance `refit_covariance`) is where the filter's estimate allows its pose to be: the
/// squared Mahalanobis distance of their difference under the sum of both pose covariances within the chi-square's
/// upper 0.1 % point for 6 degrees of freedom. A young track's filter, unsure of its depth, allows the refit to move
/// the pose by more than [`MAX_SHIFT_M`]; a track the filter has settled does not, whatever the stencil says.
fn within_the_filters_uncertainty(
    filter: &Estimate,
    refit: &roitrack_core::MotionState,
    refit_covariance: &Matrix6<f64>,
) -> bool {
    let Some(covariance) = filter.covariance.as_ref() else {
        return false;
    };
    let difference = roitrack_core::MotionState::difference(&filter.state, refit)
        .fixed_rows::<6>(0)
        .into_owned();
    let sum = covariance.fixed_view::<6, 6>(0, 0) + refit_covariance;
    let Some(inverse) = sum.try_inverse() else {
        return false;
    };
    let d2 = (difference.transpose() * inverse * difference)[(0, 0)];
    d2.is_finite() && d2 <= chi2_upper_0_1_percent(6.0)
}

/// The pose block of an estimate's covariance; without one, the centroid noise's order of magnitude (used only to
/// weigh the neighbours in the twist's covariance, which an estimate without a covariance does not report).
fn pose_block(covariance: Option<&Matrix12>, noise_px: f64) -> Matrix6<f64> {
    match covariance {
        Some(c) => c.fixed_view::<6, 6>(0, 0).into_owned(),
        None => Matrix6::identity() * (noise_px * 1e-4).powi(2),
    }
}
