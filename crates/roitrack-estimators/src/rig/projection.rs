//! A centroid of a rig camera as a function of the rig's state and of the camera's clock, with its Jacobians.

use nalgebra::{Vector2, Vector3};

use super::{CameraMount, ClockModel};
use roitrack_core::{JacobianKind, Matrix2x12, MotionState, SpatioTemporalModel};

/// Where a rig camera sees a model point, with the derivatives a filter of the rig's state and the camera's clock
/// needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigProjection {
    /// The ideal pixel (u, v) in the camera.
    pub pixel: Vector2<f64>,
    /// `d(u, v) / dδ` for a correction `δ` of the rig's state (rig frame).
    pub jacobian: Matrix2x12,
    /// `d(u, v) / dt` (px/s): the image velocity of the point, which is also `d(u, v) / d clock_offset_s`.
    pub image_velocity_pxps: Vector2<f64>,
    /// `d(u, v) / d clock_drift_ppm` (px/ppm).
    pub per_drift_px: Vector2<f64>,
}

/// The ideal pixel of `point_in_obj_m` measured by a camera of `model` mounted at `mount` at the time `t_camera_s`
/// of its clock `clock`, for the rig's state `rig_state` at the rig time `t_ref_s`; with its Jacobians w.r.t. a
/// correction of the rig's state, the clock's offset and its drift. `None` if the point is behind the camera.
///
/// The point is seen `d = clock.rig_time_s(t_camera_s) - t_ref_s` after the reference time. The state's Jacobian is
/// the camera's ([`SpatioTemporalModel::project_with_jacobian`], exact) times `diag(R, R, R, R)`
/// ([`CameraMount::jacobian_to_rig`]); the offset's column is the image velocity `dm/dP (V_c + W_c × OP)` (camera frame,
/// `OP` the rotated model point at its time) and the drift's that times `d t_rig / d drift`.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_estimators::rig::{CameraMount, ClockModel, rig_projection};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let mut state = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6));
/// state.velocity_mps = Vector3::new(0.1, 0.0, 0.0);
/// let p = rig_projection(&model, &CameraMount::IDENTITY, &ClockModel::REFERENCE, &state, &Vector3::zeros(), 0.0, 0.0)
///     .unwrap();
/// // 0.1 m/s across at 0.6 m with a 1,500 px focal length: 250 px/s.
/// assert!((p.image_velocity_pxps.x - 250.0).abs() < 1e-9);
/// ```
#[inline]
pub fn rig_projection(
    model: &SpatioTemporalModel,
    mount: &CameraMount,
    clock: &ClockModel,
    rig_state: &MotionState,
    point_in_obj_m: &Vector3<f64>,
    t_camera_s: f64,
    t_ref_s: f64,
) -> Option<RigProjection> {
    let camera_state = mount.camera_state(rig_state);
    let d_s = clock.rig_time_s(t_camera_s) - t_ref_s;
    let projected =
        model.project_with_jacobian(JacobianKind::Exact, &camera_state, point_in_obj_m, d_s)?;
    let p = projected.point_in_cam_m;
    let op = p - camera_state.cam_t_obj_m - camera_state.velocity_mps * d_s;
    let point_velocity = camera_state.velocity_mps + camera_state.angular_velocity_radps.cross(&op);
    let image_velocity_pxps = model.intrinsics.pixel_jacobian_wrt_cam(&p) * point_velocity;
    Some(RigProjection {
        pixel: projected.pixel,
        jacobian: mount.jacobian_to_rig(&projected.jacobian),
        image_velocity_pxps,
        per_drift_px: image_velocity_pxps * clock.rig_time_per_drift_ppm(t_camera_s),
    })
}
