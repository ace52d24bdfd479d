//! The 12-dof state: pose and constant twist of the object at a reference time.

use nalgebra::{Isometry3, Matrix3, Rotation3, SMatrix, Translation3, UnitQuaternion, Vector3};

use crate::{Vector12, so3};

/// Pose and twist of the object in the camera frame at the reference time `t_ref` (docs/model.md).
///
/// - `cam_r_obj` = c_R_o, `cam_t_obj_m` = c_t_o: the object's pose in the camera;
/// - `velocity_mps` = V: velocity of the object's origin, camera frame;
/// - `angular_velocity_radps` = W: angular velocity of the object, camera frame (a constant body rate ω_o is the same
///   motion as W = R ω_o).
///
/// With the twist held constant, the pose `d` seconds after `t_ref` is `R(d) = Exp(W d) R`, `t(d) = t + V d`, and a
/// model point `p` is at `R(d) p + t(d)`. A correction `δ = (v, w, dV, dW)` (tangent order: translation, rotation,
/// velocity, angular velocity) acts as `R <- Exp(w) R`, `t <- t + v`, `V <- V + dV`, `W <- W + dW`: rotation
/// perturbations are on the left, about the object's origin, in the camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionState {
    /// c_R_o: the object's orientation in the camera frame (maps object-frame directions to camera-frame ones).
    pub cam_r_obj: Rotation3<f64>,
    /// c_t_o: the object's origin in the camera frame (m).
    pub cam_t_obj_m: Vector3<f64>,
    /// V: velocity of the object's origin (m/s), camera frame.
    pub velocity_mps: Vector3<f64>,
    /// W: angular velocity of the object (rad/s), camera frame.
    pub angular_velocity_radps: Vector3<f64>,
}

impl MotionState {
    /// A pose at rest.
    pub fn at_rest(cam_r_obj: Rotation3<f64>, cam_t_obj_m: Vector3<f64>) -> Self {
        Self {
            cam_r_obj,
            cam_t_obj_m,
            velocity_mps: Vector3::zeros(),
            angular_velocity_radps: Vector3::zeros(),
        }
    }

    /// The bench pose of the built-in scene (docs/model.md), at rest: the origin at (0.02, -0.01, 0.60) m, the rotation
    /// [`Self::bench_rotation`]. With [`crate::CameraModel::canonical`] and [`crate::Target::grid4x4`], the scene of
    /// the benchmarks, the accuracy studies and the `static` scenario.
    pub fn bench() -> Self {
        Self::at_rest(Self::bench_rotation(), Vector3::new(0.02, -0.01, 0.60))
    }

    /// R = Rz(5°) Ry(-15°) Rx(10°), the rotation of the bench pose ([`Self::bench`]).
    pub fn bench_rotation() -> Rotation3<f64> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), 5f64.to_radians())
            * Rotation3::from_axis_angle(&Vector3::y_axis(), (-15f64).to_radians())
            * Rotation3::from_axis_angle(&Vector3::x_axis(), 10f64.to_radians())
    }

    /// The pose `d_s` seconds after the reference time, under the constant twist.
    #[inline]
    pub fn pose_at(&self, d_s: f64) -> (Rotation3<f64>, Vector3<f64>) {
        (
            so3::exp(&(self.angular_velocity_radps * d_s)) * self.cam_r_obj,
            self.cam_t_obj_m + self.velocity_mps * d_s,
        )
    }

    /// Where the model point `point_in_obj_m` is, in the camera frame, `d_s` seconds after the reference time.
    #[inline]
    pub fn point_in_cam_at(&self, point_in_obj_m: &Vector3<f64>, d_s: f64) -> Vector3<f64> {
        // Exp(W d) applied to the rotated point by cross products: no rotation matrix for every point and time.
        so3::RotationIncrement::new(&(self.angular_velocity_radps * d_s))
            .rotate(&(self.cam_r_obj * point_in_obj_m))
            + self.cam_t_obj_m
            + self.velocity_mps * d_s
    }

    /// The same motion with its reference time moved `dt_s` later (the paper's compensation term, eq. 12).
    #[inline]
    pub fn predicted(&self, dt_s: f64) -> Self {
        let (cam_r_obj, cam_t_obj_m) = self.pose_at(dt_s);
        Self {
            cam_r_obj,
            cam_t_obj_m,
            ..*self
        }
    }

    /// The Jacobian `F` of [`Self::predicted`]`(dt_s)` in error-state coordinates: a correction `δ` of this state
    /// becomes, to first order, the correction `F δ` of the predicted one. With `E = Exp(W dt)` and
    /// `B = J_l(W dt) dt` (the left Jacobian of SO(3)):
    ///
    /// ```text
    /// F = [ I  0  dt·I  0 ]
    ///     [ 0  E  0     B ]
    ///     [ 0  0  I     0 ]
    ///     [ 0  0  0     I ]
    /// ```
    ///
    /// A covariance `P` of this state's error is `F P Fᵀ` for the predicted state (without process noise); `dt_s`
    /// may be negative, to carry an estimate back in time.
    ///
    /// ```
    /// use roitrack_core::MotionState;
    /// use nalgebra::{Rotation3, Vector3};
    ///
    /// let state = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6));
    /// let f = state.transition_jacobian(0.01);
    /// // An error in the velocity becomes, 10 ms later, an error in the position too.
    /// assert_eq!(f[(0, 6)], 0.01);
    /// ```
    pub fn transition_jacobian(&self, dt_s: f64) -> SMatrix<f64, 12, 12> {
        let increment = self.angular_velocity_radps * dt_s;
        let mut f = SMatrix::<f64, 12, 12>::identity();
        f.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&(Matrix3::identity() * dt_s));
        f.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(so3::exp(&increment).matrix());
        f.fixed_view_mut::<3, 3>(3, 9)
            .copy_from(&(so3::left_jacobian(&increment) * dt_s));
        f
    }

    /// The state after a correction `δ = (v, w, dV, dW)`.
    #[inline]
    pub fn corrected(&self, delta: &Vector12) -> Self {
        let v = delta.fixed_rows::<3>(0).into_owned();
        let w = delta.fixed_rows::<3>(3).into_owned();
        let dv = delta.fixed_rows::<3>(6).into_owned();
        let dw = delta.fixed_rows::<3>(9).into_owned();
        Self {
            cam_r_obj: so3::orthonormalized(&(so3::exp(&w) * self.cam_r_obj)),
            cam_t_obj_m: self.cam_t_obj_m + v,
            velocity_mps: self.velocity_mps + dv,
            angular_velocity_radps: self.angular_velocity_radps + dw,
        }
    }

    /// How far apart two poses are, as one number: their rotation angle (rad) plus their distance over `self`'s
    /// distance from the camera. What tells a pose from a twin that fits the same image (a mirror tilt, a symmetric
    /// target's relabelling), which turns it by tens of degrees.
    ///
    /// ```
    /// use nalgebra::{Rotation3, Vector3};
    /// use roitrack_core::MotionState;
    ///
    /// let a = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.5));
    /// let b = MotionState::at_rest(Rotation3::from_euler_angles(0.0, 0.0, 0.1), Vector3::new(0.0, 0.005, 0.5));
    /// assert!((a.pose_distance(&b) - (0.1 + 0.01)).abs() < 1e-12);
    /// ```
    pub fn pose_distance(&self, other: &Self) -> f64 {
        so3::angle_between(&self.cam_r_obj, &other.cam_r_obj)
            + (self.cam_t_obj_m - other.cam_t_obj_m).norm() / self.cam_t_obj_m.norm().max(1e-9)
    }

    /// The 12-vector `δ` with `a.corrected(δ) == b` (inverse of [`Self::corrected`]).
    pub fn difference(a: &Self, b: &Self) -> Vector12 {
        let mut delta = Vector12::zeros();
        delta
            .fixed_rows_mut::<3>(0)
            .copy_from(&(b.cam_t_obj_m - a.cam_t_obj_m));
        delta
            .fixed_rows_mut::<3>(3)
            .copy_from(&so3::log(&(b.cam_r_obj * a.cam_r_obj.inverse())));
        delta
            .fixed_rows_mut::<3>(6)
            .copy_from(&(b.velocity_mps - a.velocity_mps));
        delta
            .fixed_rows_mut::<3>(9)
            .copy_from(&(b.angular_velocity_radps - a.angular_velocity_radps));
        delta
    }

    /// The pose as an isometry camera_T_object.
    pub fn cam_from_obj(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.cam_t_obj_m),
            UnitQuaternion::from_rotation_matrix(&self.cam_r_obj),
        )
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.cam_r_obj.matrix().iter().all(|x| x.is_finite())
            && self.cam_t_obj_m.iter().all(|x| x.is_finite())
            && self.velocity_mps.iter().all(|x| x.is_finite())
            && self.angular_velocity_radps.iter().all(|x| x.is_finite())
    }
}

/// Linear and angular acceleration of the object in the camera frame (the derivatives of [`MotionState`]'s
/// `velocity_mps` and `angular_velocity_radps`), as a constant-acceleration Kalman filter estimates them.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{Acceleration, MotionState};
///
/// let state = MotionState { velocity_mps: Vector3::new(1.0, 0.0, 0.0), ..MotionState::at_rest(Rotation3::identity(), Vector3::z()) };
/// let braking = Acceleration { linear_mps2: Vector3::new(-10.0, 0.0, 0.0), angular_radps2: Vector3::zeros() };
/// let later = braking.predicted(&state, 0.1);
/// assert!((later.velocity_mps.x - 0.0).abs() < 1e-12);
/// assert!((later.cam_t_obj_m.x - 0.05).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Acceleration {
    /// A: the rate of change of the velocity of the object's origin (m/s²), camera frame.
    pub linear_mps2: Vector3<f64>,
    /// Α: the rate of change of the angular velocity (rad/s²), camera frame.
    pub angular_radps2: Vector3<f64>,
}

impl Acceleration {
    /// `state` moved `dt_s` later (or earlier, when negative) under this constant acceleration: `t + V dt + ½ A dt²`,
    /// `Exp(W dt + ½ Α dt²) R`, `V + A dt`, `W + Α dt` (a rotation that is a first-order approximation when the
    /// angular velocity turns during `dt_s`).
    pub fn predicted(&self, state: &MotionState, dt_s: f64) -> MotionState {
        let half_dt2 = 0.5 * dt_s * dt_s;
        MotionState {
            cam_r_obj: so3::exp(
                &(state.angular_velocity_radps * dt_s + self.angular_radps2 * half_dt2),
            ) * state.cam_r_obj,
            cam_t_obj_m: state.cam_t_obj_m
                + state.velocity_mps * dt_s
                + self.linear_mps2 * half_dt2,
            velocity_mps: state.velocity_mps + self.linear_mps2 * dt_s,
            angular_velocity_radps: state.angular_velocity_radps + self.angular_radps2 * dt_s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_transition_jacobian_matches_central_differences() {
        for dt_s in [0.015, -0.02] {
            roitrack_testkit::check_jacobian(
                &format!("transition_jacobian({dt_s})"),
                MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6)),
                crate::test_support::drawn_state,
                &Vector12::repeat(1.0),
                |s, delta| {
                    MotionState::difference(&s.predicted(dt_s), &s.corrected(delta).predicted(dt_s))
                },
                |s| s.transition_jacobian(dt_s),
            );
        }
    }

    fn moving() -> MotionState {
        MotionState {
            cam_r_obj: Rotation3::from_euler_angles(0.1, -0.2, 0.3),
            cam_t_obj_m: Vector3::new(0.02, -0.01, 0.6),
            velocity_mps: Vector3::new(0.5, -0.3, 0.1),
            angular_velocity_radps: Vector3::new(2.0, -6.0, 1.0),
        }
    }

    #[test]
    fn prediction_composes() {
        let s = moving();
        let a = s.predicted(0.003).predicted(0.002);
        let b = s.predicted(0.005);
        assert!(MotionState::difference(&a, &b).norm() < 1e-14);
        let back = s.predicted(0.004).predicted(-0.004);
        assert!(MotionState::difference(&s, &back).norm() < 1e-14);
    }

    #[test]
    fn difference_inverts_correction() {
        let s = moving();
        let delta = Vector12::from_fn(|i, _| 0.01 * (i as f64 - 5.5));
        let back = MotionState::difference(&s, &s.corrected(&delta));
        assert!((back - delta).norm() < 1e-14);
    }

    #[test]
    fn constant_twist_point_motion() {
        // A point on the rotation axis through the origin only translates.
        let s = moving();
        let axis_in_obj = s.cam_r_obj.inverse() * s.angular_velocity_radps.normalize();
        let p = s.point_in_cam_at(&(axis_in_obj * 0.05), 0.01);
        let expected = s.cam_r_obj * (axis_in_obj * 0.05) + s.cam_t_obj_m + s.velocity_mps * 0.01;
        assert!((p - expected).norm() < 1e-15);
    }
}
