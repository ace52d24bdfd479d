//! Timestamped data exchanged with the outside world: measured centroids, poses and twists.

use nalgebra::{Isometry3, Vector3};

/// One measured blob centroid: time of its exposure midpoint (s), point id, raw (distorted) pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Mid-exposure time of this blob (s): for a rolling shutter, of the blob's own row
    /// ([`crate::TimeModel::blob_time_s`]).
    pub t_s: f64,
    /// The id of the target point ([`crate::TargetPoint::id`]) the blob is the image of.
    pub id: u32,
    /// Raw (distorted) centroid column (px; pixel centres at integers).
    pub u_px: f64,
    /// Raw (distorted) centroid row (px).
    pub v_px: f64,
}

/// A pose camera_T_object at a time (one line of a TUM trajectory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// The time of the pose (s).
    pub t_s: f64,
    /// The object's pose in the camera frame (camera_T_object): maps object-frame points (m) to camera-frame ones.
    pub cam_from_obj: Isometry3<f64>,
}

/// A twist at a time (one row of a twists CSV): V of the object origin and W, camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwistSample {
    /// The time of the twist (s).
    pub t_s: f64,
    /// Velocity of the object's origin (m/s), camera frame.
    pub velocity_mps: Vector3<f64>,
    /// Angular velocity of the object (rad/s), camera frame.
    pub angular_velocity_radps: Vector3<f64>,
}

impl PoseSample {
    /// The pose of `state` (at its reference time), stamped `t_s`.
    pub fn from_state(t_s: f64, state: &crate::MotionState) -> Self {
        Self {
            t_s,
            cam_from_obj: state.cam_from_obj(),
        }
    }
}

impl TwistSample {
    /// The twist of `state` (constant over its window), stamped `t_s`.
    pub fn from_state(t_s: f64, state: &crate::MotionState) -> Self {
        Self {
            t_s,
            velocity_mps: state.velocity_mps,
            angular_velocity_radps: state.angular_velocity_radps,
        }
    }
}
