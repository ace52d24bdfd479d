//! From roitrack's estimates to ROS's conventions: stamps, quaternions and the covariances of each message, in ROS's
//! order (x, y, z, rotation about x, y, z) and in each message's frame (docs/ros2.md derives them).

use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};
use roitrack_core::MotionState;
use roitrack_core::camera::Distortion;
use roitrack_estimators::Matrix12;

use crate::msg::{Pose, Quaternion, Time, Vector3 as RosVector3};

/// A time (s) as a ROS stamp: whole seconds and nanoseconds, rounded to the nearest nanosecond. `None` for a time
/// a stamp cannot hold (negative, from 2^31 s on, or not finite).
///
/// ```
/// let stamp = roitrack_ros::convert::stamp(1.25).unwrap();
/// assert_eq!((stamp.sec, stamp.nanosec), (1, 250_000_000));
/// assert!(roitrack_ros::convert::stamp(-1.0).is_none());
/// ```
pub fn stamp(t_s: f64) -> Option<Time> {
    let ns = nanoseconds(t_s)?;
    Some(Time {
        sec: i32::try_from(ns / 1_000_000_000).ok()?,
        nanosec: (ns % 1_000_000_000) as u32,
    })
}

/// A time (s) in nanoseconds (the bag's log time), as [`stamp`] rounds it.
pub fn nanoseconds(t_s: f64) -> Option<u64> {
    let ns = (t_s * 1e9).round();
    (t_s.is_finite() && (0.0..2_147_483_648e9).contains(&ns)).then_some(ns as u64)
}

/// A camera's lens distortion as `sensor_msgs/msg/CameraInfo` names it: the model's own name (`plumb_bob`,
/// `rational_polynomial`, `equidistant`) and its coefficients in ROS's order; a camera without distortion as
/// `plumb_bob` with five zeros, what ROS's camera drivers write for an undistorted camera (ROS has no `none`). The
/// way back is [`Distortion::from_model`].
///
/// ```
/// use roitrack_core::camera::{Distortion, Equidistant};
/// use roitrack_ros::convert::camera_info_distortion;
///
/// let fisheye = Distortion::from(Equidistant::from_coefficients([0.1, -0.02, 0.003, 0.0]));
/// assert_eq!(camera_info_distortion(&fisheye), ("equidistant", vec![0.1, -0.02, 0.003, 0.0]));
/// assert_eq!(camera_info_distortion(&Distortion::None), ("plumb_bob", vec![0.0; 5]));
/// ```
pub fn camera_info_distortion(distortion: &Distortion) -> (&'static str, Vec<f64>) {
    match distortion {
        Distortion::None => (PLUMB_BOB, vec![0.0; 5]),
        other => (other.model_name(), other.coefficients()),
    }
}

const PLUMB_BOB: &str = "plumb_bob";

fn vector(v: &Vector3<f64>) -> RosVector3 {
    RosVector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

/// The pose camera_T_object as a ROS pose: the object's origin in the camera frame and the rotation from object to
/// camera as the quaternion the TUM writer writes (nalgebra's, from the rotation matrix).
pub fn pose(state: &MotionState) -> Pose {
    let q = UnitQuaternion::from_rotation_matrix(&state.cam_r_obj);
    Pose {
        position: vector(&state.cam_t_obj_m),
        orientation: Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// The twist in the camera frame (as the twists CSV): linear, the velocity of the object's origin; angular, the
/// angular velocity.
pub fn twist_in_camera(state: &MotionState) -> (RosVector3, RosVector3) {
    (
        vector(&state.velocity_mps),
        vector(&state.angular_velocity_radps),
    )
}

/// The twist in the object (child) frame, nav_msgs' convention for odometry: `Rᵀ V`, `Rᵀ W`.
pub fn twist_in_object(state: &MotionState) -> (RosVector3, RosVector3) {
    let r_t = state.cam_r_obj.matrix().transpose();
    (
        vector(&(r_t * state.velocity_mps)),
        vector(&(r_t * state.angular_velocity_radps)),
    )
}

type Matrix6 = SMatrix<f64, 6, 6>;

fn row_major(m: &Matrix6) -> [f64; 36] {
    let mut out = [0.0; 36];
    for i in 0..6 {
        for j in 0..6 {
            // Symmetrised so that the message is exactly symmetric whatever the rounding of the products.
            out[6 * i + j] = 0.5 * (m[(i, j)] + m[(j, i)]);
        }
    }
    out
}

fn usable(covariance: Option<&Matrix12>) -> Option<&Matrix12> {
    covariance.filter(|c| c.iter().all(|x| x.is_finite()))
}

/// The pose covariance, row-major 6 x 6 in ROS's order: position (m) in the camera frame, then the rotation error as
/// a rotation vector about the camera's x, y, z axes (rad; R_true = Exp(w) R). It is the estimator's covariance
/// block (0..6, 0..6) as it is, since roitrack's error state already has this order and frame. All zeros (ROS's
/// "unknown") when the estimate has no covariance.
pub fn pose_covariance(covariance: Option<&Matrix12>) -> [f64; 36] {
    usable(covariance).map_or([0.0; 36], |c| {
        row_major(&c.fixed_view::<6, 6>(0, 0).into_owned())
    })
}

/// The covariance of the twist in the camera frame: the block (6..12, 6..12), velocity then angular velocity.
pub fn twist_covariance_in_camera(covariance: Option<&Matrix12>) -> [f64; 36] {
    usable(covariance).map_or([0.0; 36], |c| {
        row_major(&c.fixed_view::<6, 6>(6, 6).into_owned())
    })
}

/// The Jacobian of the object-frame twist (`Rᵀ V`, `Rᵀ W`) with respect to the error state (position, rotation,
/// velocity, angular velocity): with `R_true = Exp(w) R`, `R_trueᵀ V_true ≈ Rᵀ V + Rᵀ dV + Rᵀ [V]x w`.
pub fn object_twist_jacobian(state: &MotionState) -> SMatrix<f64, 6, 12> {
    let r_t: Matrix3<f64> = state.cam_r_obj.matrix().transpose();
    let mut j = SMatrix::<f64, 6, 12>::zeros();
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(r_t * state.velocity_mps.cross_matrix()));
    j.fixed_view_mut::<3, 3>(0, 6).copy_from(&r_t);
    j.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(r_t * state.angular_velocity_radps.cross_matrix()));
    j.fixed_view_mut::<3, 3>(3, 9).copy_from(&r_t);
    j
}

/// The covariance of the twist in the object (child) frame, to first order: `J C Jᵀ` with
/// [`object_twist_jacobian`] (so the rotation's uncertainty is carried into the rotated velocities).
pub fn twist_covariance_in_object(covariance: Option<&Matrix12>, state: &MotionState) -> [f64; 36] {
    usable(covariance).map_or([0.0; 36], |c| {
        // The position's columns of the Jacobian are zero: only the rotation, velocity and angular velocity block
        // of the covariance enters.
        let j = object_twist_jacobian(state)
            .fixed_view::<6, 9>(0, 3)
            .into_owned();
        let block = c.fixed_view::<9, 9>(3, 3).into_owned();
        row_major(&(j * block * j.transpose()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;
    use roitrack_core::camera::{Equidistant, PlumbBob, RationalPolynomial};

    #[test]
    fn every_distortion_model_is_named_as_ros_names_it_and_reads_back() {
        let models = [
            Distortion::from(PlumbBob::from_coefficients([0.1, -0.2, 1e-3, -2e-3, 0.05])),
            Distortion::from(RationalPolynomial::from_coefficients([
                0.1, -0.2, 1e-3, -2e-3, 0.05, 0.3, -0.1, 0.02,
            ])),
            Distortion::from(Equidistant::from_coefficients([0.1, -0.02, 3e-3, -4e-4])),
        ];
        for (distortion, name) in
            models
                .iter()
                .zip(["plumb_bob", "rational_polynomial", "equidistant"])
        {
            let (model, d) = camera_info_distortion(distortion);
            assert_eq!(model, name);
            assert_eq!(&Distortion::from_model(model, &d).unwrap(), distortion);
        }
        // No distortion: plumb_bob with zeros, which reads back as an identity.
        let (model, d) = camera_info_distortion(&Distortion::None);
        assert!(Distortion::from_model(model, &d).unwrap().is_identity());
    }

    fn state() -> MotionState {
        MotionState {
            cam_r_obj: Rotation3::from_scaled_axis(Vector3::new(0.3, -0.5, 1.1)),
            cam_t_obj_m: Vector3::new(0.1, -0.05, 0.6),
            velocity_mps: Vector3::new(0.2, 0.1, -0.3),
            angular_velocity_radps: Vector3::new(-1.0, 0.4, 2.0),
        }
    }

    #[test]
    fn the_object_twist_jacobian_matches_central_differences() {
        use roitrack_testkit::rand::Rng;
        let twist = |s: &MotionState| {
            let (v, w) = twist_in_object(s);
            nalgebra::Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z)
        };
        roitrack_testkit::check_jacobian(
            "object_twist_jacobian",
            MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6)),
            |rng, spread| {
                let mut v3 = |m: f64| spread * Vector3::from_fn(|_, _| rng.random_range(-m..m));
                MotionState {
                    cam_r_obj: Rotation3::from_scaled_axis(v3(3.0)),
                    cam_t_obj_m: Vector3::new(0.0, 0.0, 0.6) + v3(0.2),
                    velocity_mps: v3(2.0),
                    angular_velocity_radps: v3(10.0),
                }
            },
            &nalgebra::SVector::<f64, 12>::repeat(1.0),
            |s, delta| twist(&s.corrected(delta)),
            object_twist_jacobian,
        );
    }

    #[test]
    fn covariances_keep_the_order_and_are_symmetric() {
        let mut c = Matrix12::zeros();
        for i in 0..12 {
            c[(i, i)] = (i + 1) as f64;
        }
        c[(0, 3)] = 0.5;
        c[(3, 0)] = 0.5;
        let pose = pose_covariance(Some(&c));
        assert_eq!(
            (pose[0], pose[7], pose[35], pose[3], pose[18]),
            (1.0, 2.0, 6.0, 0.5, 0.5)
        );
        let twist = twist_covariance_in_camera(Some(&c));
        assert_eq!((twist[0], twist[35]), (7.0, 12.0));
        let object = twist_covariance_in_object(Some(&c), &state());
        for i in 0..6 {
            for k in 0..6 {
                assert_eq!(object[6 * i + k], object[6 * k + i]);
            }
        }
        assert_eq!(pose_covariance(None), [0.0; 36]);
        c[(1, 1)] = f64::NAN;
        assert_eq!(twist_covariance_in_object(Some(&c), &state()), [0.0; 36]);
    }

    #[test]
    fn stamps_round_to_the_nanosecond() {
        let s = stamp(0.999_999_999_6).unwrap();
        assert_eq!((s.sec, s.nanosec), (1, 0));
        assert!(stamp(f64::NAN).is_none());
        assert!(stamp(3e9).is_none());
    }
}
