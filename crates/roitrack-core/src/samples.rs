//! Timestamped data exchanged with the outside world: measured centroids, poses and twists.

use nalgebra::{Isometry3, Vector3};

/// One measured blob centroid: time of its exposure midpoint (s), point id, raw (distorted) pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    pub t_s: f64,
    pub id: u32,
    pub u_px: f64,
    pub v_px: f64,
}

/// A pose camera_T_object at a time (one line of a TUM trajectory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    pub t_s: f64,
    pub cam_from_obj: Isometry3<f64>,
}

/// A twist at a time (one row of a twists CSV): V of the object origin and W, camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwistSample {
    pub t_s: f64,
    pub velocity_mps: Vector3<f64>,
    pub angular_velocity_radps: Vector3<f64>,
}

impl PoseSample {
    pub fn from_state(t_s: f64, state: &crate::MotionState) -> Self {
        Self {
            t_s,
            cam_from_obj: state.cam_from_obj(),
        }
    }
}

impl TwistSample {
    pub fn from_state(t_s: f64, state: &crate::MotionState) -> Self {
        Self {
            t_s,
            velocity_mps: state.velocity_mps,
            angular_velocity_radps: state.angular_velocity_radps,
        }
    }
}
