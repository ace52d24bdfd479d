//! Each camera's track of poses over the recording, to read its pose at any instant from.

use nalgebra::Matrix6;

use roitrack_core::{MotionState, so3};

/// The most estimates kept per camera: beyond, every other one is dropped (and from then on only every second,
/// fourth, ... is kept), so that memory stays bounded on long recordings while the whole of them is covered.
const MAX_TRACK_SAMPLES: usize = 1 << 18;

/// One vouched-for estimate of a camera's track.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sample {
    /// Its time on the camera's clock (s).
    pub(super) t_s: f64,
    pub(super) state: MotionState,
    /// The covariance of its pose error (translation, rotation on the left; camera frame).
    pub(super) pose_covariance: Matrix6<f64>,
}

/// The pose covariance assumed for an estimate that states none: 1 mm and 1 mrad, so that such estimates still
/// weigh in, below any estimate of a target seen well.
pub(super) const UNSTATED_POSE_VARIANCE: f64 = 1e-6;

/// A camera's track: its vouched-for estimates, thinned to a bounded number.
#[derive(Debug, Default)]
pub(super) struct Track {
    pub(super) samples: Vec<Sample>,
    pub(super) stride: usize,
    pub(super) seen: usize,
}

impl Track {
    pub(super) fn push(&mut self, sample: Sample) {
        self.stride = self.stride.max(1);
        if self.seen.is_multiple_of(self.stride) {
            self.samples.push(sample);
            if self.samples.len() >= MAX_TRACK_SAMPLES {
                let mut keep = false;
                self.samples.retain(|_| {
                    keep = !keep;
                    keep
                });
                self.stride *= 2;
            }
        }
        self.seen += 1;
    }

    /// The state at camera time `t_s`, between the estimates around it (at most `max_gap_s` apart): both carried
    /// to `t_s` by their twists and blended by their distances in time; the pose covariance of the nearer.
    pub(super) fn state_at(&self, t_s: f64, max_gap_s: f64) -> Option<(MotionState, Matrix6<f64>)> {
        let after = self.samples.partition_point(|s| s.t_s < t_s);
        let b = *self.samples.get(after)?;
        if b.t_s == t_s {
            return Some((b.state, b.pose_covariance));
        }
        let a = *self.samples.get(after.checked_sub(1)?)?;
        let (t_a, t_b) = (a.t_s, b.t_s);
        if t_b - t_a > max_gap_s {
            return None;
        }
        let alpha = (t_s - t_a) / (t_b - t_a);
        let covariance = if alpha < 0.5 {
            a.pose_covariance
        } else {
            b.pose_covariance
        };
        let (a, b) = (a.state.predicted(t_s - t_a), b.state.predicted(t_s - t_b));
        let turn = so3::log(&(b.cam_r_obj * a.cam_r_obj.inverse()));
        let state = MotionState {
            cam_r_obj: so3::exp(&(turn * alpha)) * a.cam_r_obj,
            cam_t_obj_m: a.cam_t_obj_m.lerp(&b.cam_t_obj_m, alpha),
            velocity_mps: a.velocity_mps.lerp(&b.velocity_mps, alpha),
            angular_velocity_radps: a
                .angular_velocity_radps
                .lerp(&b.angular_velocity_radps, alpha),
        };
        Some((state, covariance))
    }

    pub(super) fn span_s(&self) -> Option<(f64, f64)> {
        Some((self.samples.first()?.t_s, self.samples.last()?.t_s))
    }
}
