//! Several cameras, no shared clock: a rig of cameras, each with its pose in the rig and its clock, and the one
//! estimate of the target's pose and twist in the rig's frame and on the rig's clock that their measurements give
//! together ([`RigTracker`]).
//!
//! - A camera's pose in the rig is `camera_T_rig` ([`CameraMount`]): `x_camera = R x_rig + t`.
//! - A camera's clock ([`ClockModel`]): `t_rig = clock_offset_s + t_camera / (1 + clock_drift_ppm * 1e-6)` (a positive
//!   drift: the camera's clock runs fast). The first camera's clock is the rig's unless told otherwise.
//! - The state is `rig_T_object` with its twist in the rig frame, a [`MotionState`] whose "camera" is the rig. A
//!   correction `δ` of it acts in the rig frame (rotations on the left, as [`MotionState::corrected`]); seen from a
//!   camera mounted with rotation `R`, the same correction is `diag(R, R, R, R) δ` ([`CameraMount::error_rotation`]),
//!   so the Jacobian of a centroid w.r.t. the rig's error state is the camera's Jacobian times that block rotation.
//! - The derivative of a centroid w.r.t. its own time is its image velocity, `H_pose (V, W)`: the column of a clock
//!   offset, and, times `dt_rig / d drift`, of a drift ([`rig_projection`]).
//!
//! A one-camera rig whose camera is the rig (identity mount, reference clock) is exactly the single-camera tracker.
//!
//! ```
//! use nalgebra::{Rotation3, Vector3};
//! use roitrack_estimators::rig::{CameraMount, ClockModel};
//!
//! // A camera 0.3 m to the right of the rig's origin, turned 15° about y, whose clock is 12.3 ms ahead and 40 ppm fast.
//! let mount = CameraMount::new(Rotation3::from_euler_angles(0.0, 15f64.to_radians(), 0.0), Vector3::new(-0.3, 0.0, 0.05));
//! let clock = ClockModel { offset_s: 0.0123, drift_ppm: 40.0 };
//! assert!((clock.camera_time_s(clock.rig_time_s(2.5)) - 2.5).abs() < 1e-15);
//! let p_rig = Vector3::new(0.0, 0.0, 0.6);
//! assert!((mount.rig_from_camera(&mount.camera_from_rig(&p_rig)) - p_rig).norm() < 1e-15);
//! ```

mod calibrate;
mod projection;
mod sync;
#[cfg(test)]
mod tests;
mod tracker;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use thiserror::Error;

pub use calibrate::{
    CameraCalibration, RigCalibration, RigCalibrationConfig, RigCalibrationError, RigCalibrator,
};
pub use projection::{RigProjection, rig_projection};
use roitrack_core::{CameraModel, Matrix2x12, Measurement, MotionState, Vector12};
pub use sync::{OffsetSearch, offset_chi2, search_offset_s};
pub use tracker::{
    CameraCounts, ClockEstimate, RigError, RigEstimate, RigTracker, RigTrackerConfig,
    RigTrackerReport,
};

/// A camera's clock against the rig's: `t_rig = offset_s + t_camera / (1 + drift_ppm * 1e-6)`.
///
/// ```
/// use roitrack_estimators::rig::ClockModel;
/// let fast = ClockModel { offset_s: 0.01, drift_ppm: 100.0 };
/// // 1 s of a clock 100 ppm fast is 0.9999 s of the rig's.
/// assert!((fast.rig_time_s(1.0) - (0.01 + 1.0 / 1.0001)).abs() < 1e-15);
/// assert_eq!(ClockModel::REFERENCE.rig_time_s(3.0), 3.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockModel {
    /// The rig's time when the camera's clock reads 0 (s).
    pub offset_s: f64,
    /// How fast the camera's clock runs against the rig's (parts per million; positive: fast).
    pub drift_ppm: f64,
}

impl Default for ClockModel {
    fn default() -> Self {
        Self::REFERENCE
    }
}

impl ClockModel {
    /// The rig's own clock: no offset, no drift.
    pub const REFERENCE: Self = Self {
        offset_s: 0.0,
        drift_ppm: 0.0,
    };

    /// The rig's time (s) of the camera's time `t_camera_s`.
    #[inline]
    pub fn rig_time_s(&self, t_camera_s: f64) -> f64 {
        if self.drift_ppm == 0.0 {
            // Exactly the camera's time for the reference clock.
            return self.offset_s + t_camera_s;
        }
        self.offset_s + t_camera_s / (1.0 + self.drift_ppm * 1e-6)
    }

    /// The camera's time (s) of the rig's time `t_rig_s` (inverse of [`Self::rig_time_s`]).
    #[inline]
    pub fn camera_time_s(&self, t_rig_s: f64) -> f64 {
        (t_rig_s - self.offset_s) * (1.0 + self.drift_ppm * 1e-6)
    }

    /// `d t_rig / d drift_ppm` at the camera's time `t_camera_s` (s per ppm).
    #[inline]
    pub fn rig_time_per_drift_ppm(&self, t_camera_s: f64) -> f64 {
        let scale = 1.0 + self.drift_ppm * 1e-6;
        -t_camera_s * 1e-6 / (scale * scale)
    }

    /// Whether this is the rig's own clock.
    pub fn is_reference(&self) -> bool {
        self.offset_s == 0.0 && self.drift_ppm == 0.0
    }
}

/// Where a camera is in the rig: `camera_T_rig`, `x_camera = camera_r_rig x_rig + camera_t_rig_m`.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::MotionState;
/// use roitrack_estimators::rig::CameraMount;
///
/// // A camera 0.2 m to the rig's left, looking the same way: the target 0.6 m ahead of the rig is 0.2 m to its right.
/// let mount = CameraMount::new(Rotation3::identity(), Vector3::new(0.2, 0.0, 0.0));
/// let rig_state = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6));
/// assert_eq!(mount.camera_state(&rig_state).cam_t_obj_m, Vector3::new(0.2, 0.0, 0.6));
/// assert!(!mount.is_identity() && CameraMount::IDENTITY.is_identity());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    /// The rotation taking a direction in the rig frame to the camera frame.
    pub camera_r_rig: Rotation3<f64>,
    /// The rig's origin in the camera frame (m).
    pub camera_t_rig_m: Vector3<f64>,
}

impl Default for CameraMount {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl CameraMount {
    /// The camera is the rig.
    pub const IDENTITY: Self = Self {
        camera_r_rig: Rotation3::from_matrix_unchecked(Matrix3::new(
            1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0,
        )),
        camera_t_rig_m: Vector3::new(0.0, 0.0, 0.0),
    };

    /// The mount `camera_T_rig` from its rotation and the rig's origin in the camera frame (m).
    pub fn new(camera_r_rig: Rotation3<f64>, camera_t_rig_m: Vector3<f64>) -> Self {
        Self {
            camera_r_rig,
            camera_t_rig_m,
        }
    }

    /// The mount of an isometry `camera_T_rig`.
    pub fn from_isometry(camera_from_rig: &Isometry3<f64>) -> Self {
        Self::new(
            camera_from_rig.rotation.to_rotation_matrix(),
            camera_from_rig.translation.vector,
        )
    }

    /// `camera_T_rig` as an isometry.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.camera_t_rig_m),
            UnitQuaternion::from_rotation_matrix(&self.camera_r_rig),
        )
    }

    /// Whether the camera is the rig (exactly).
    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// A point of the rig frame in the camera frame.
    pub fn camera_from_rig(&self, p_rig: &Vector3<f64>) -> Vector3<f64> {
        self.camera_r_rig * p_rig + self.camera_t_rig_m
    }

    /// A point of the camera frame in the rig frame.
    pub fn rig_from_camera(&self, p_camera: &Vector3<f64>) -> Vector3<f64> {
        self.camera_r_rig.inverse() * (p_camera - self.camera_t_rig_m)
    }

    /// The motion of the rig frame's state (`rig_T_object` and its twist in the rig frame) as this camera sees it
    /// (`camera_T_object`, twist in the camera frame). The identity mount returns the state as it is.
    #[inline]
    pub fn camera_state(&self, rig_state: &MotionState) -> MotionState {
        if self.is_identity() {
            return *rig_state;
        }
        let r = &self.camera_r_rig;
        MotionState {
            cam_r_obj: r * rig_state.cam_r_obj,
            cam_t_obj_m: r * rig_state.cam_t_obj_m + self.camera_t_rig_m,
            velocity_mps: r * rig_state.velocity_mps,
            angular_velocity_radps: r * rig_state.angular_velocity_radps,
        }
    }

    /// The rig frame's state of a camera's state (inverse of [`Self::camera_state`]).
    pub fn rig_state(&self, camera_state: &MotionState) -> MotionState {
        if self.is_identity() {
            return *camera_state;
        }
        let r_inv = self.camera_r_rig.inverse();
        MotionState {
            cam_r_obj: r_inv * camera_state.cam_r_obj,
            cam_t_obj_m: r_inv * (camera_state.cam_t_obj_m - self.camera_t_rig_m),
            velocity_mps: r_inv * camera_state.velocity_mps,
            angular_velocity_radps: r_inv * camera_state.angular_velocity_radps,
        }
    }

    /// `diag(R, R, R, R)`: a correction `δ` of the rig's state is the correction `diag(R, R, R, R) δ` of the camera's
    /// ([`Self::camera_state`]); a camera's 2 x 12 Jacobian times this is the rig's.
    pub fn error_rotation(&self) -> nalgebra::SMatrix<f64, 12, 12> {
        let mut m = nalgebra::SMatrix::<f64, 12, 12>::zeros();
        for k in 0..4 {
            m.fixed_view_mut::<3, 3>(3 * k, 3 * k)
                .copy_from(self.camera_r_rig.matrix());
        }
        m
    }

    /// A camera's 2 x 12 Jacobian (w.r.t. its own error state) as the rig's: `J diag(R, R, R, R)`, by 2 x 3 blocks.
    #[inline]
    pub fn jacobian_to_rig(&self, camera_jacobian: &Matrix2x12) -> Matrix2x12 {
        if self.is_identity() {
            return *camera_jacobian;
        }
        let r = self.camera_r_rig.matrix();
        let mut out = Matrix2x12::zeros();
        for k in 0..4 {
            let block = camera_jacobian.fixed_view::<2, 3>(0, 3 * k) * r;
            out.fixed_view_mut::<2, 3>(0, 3 * k).copy_from(&block);
        }
        out
    }

    /// A covariance of the camera's error state as the rig's: `Aᵀ P A` with `A = diag(R, R, R, R)`.
    pub fn covariance_to_rig(&self, camera_covariance: &crate::Matrix12) -> crate::Matrix12 {
        if self.is_identity() {
            return *camera_covariance;
        }
        let a = self.error_rotation();
        a.transpose() * camera_covariance * a
    }

    /// A correction of the camera's error state as the rig's (`Aᵀ δ`).
    pub fn correction_to_rig(&self, camera_delta: &Vector12) -> Vector12 {
        self.error_rotation().transpose() * camera_delta
    }
}

/// One camera of a rig.
///
/// ```
/// use roitrack_estimators::rig::{CameraMount, ClockModel, RigCamera};
/// use roitrack_core::CameraModel;
///
/// // Pose known, clock offset and drift to be learnt from the measurements.
/// let right = RigCamera {
///     offset_known: false,
///     drift_known: false,
///     ..RigCamera::known("right", CameraModel::canonical(), CameraMount::IDENTITY, ClockModel::REFERENCE)
/// };
/// assert!(!right.clock_known());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct RigCamera {
    /// Its name (unique in the rig), as files and measurement streams name it.
    pub name: String,
    /// Its calibration.
    pub camera: CameraModel,
    /// Where it is in the rig.
    pub mount: CameraMount,
    /// Whether `mount` is known; else it is a placeholder (the identity) that [`RigCalibrator`] finds from the
    /// target, and a [`RigTracker`] refuses the rig.
    pub mount_known: bool,
    /// Its clock: its offset and drift, known or (with `offset_known` / `drift_known` false) a starting value to be
    /// estimated.
    pub clock: ClockModel,
    /// Whether the offset is known (else estimated from the measurements).
    pub offset_known: bool,
    /// Whether the drift is known (else estimated from the measurements).
    pub drift_known: bool,
}

impl RigCamera {
    /// A camera whose pose in the rig and whose clock are known.
    pub fn known(
        name: impl Into<String>,
        camera: CameraModel,
        mount: CameraMount,
        clock: ClockModel,
    ) -> Self {
        Self {
            name: name.into(),
            camera,
            mount,
            mount_known: true,
            clock,
            offset_known: true,
            drift_known: true,
        }
    }

    /// Whether its clock is known in full.
    pub fn clock_known(&self) -> bool {
        self.offset_known && self.drift_known
    }
}

/// Why a rig is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RigDefinitionError {
    /// The rig lists no camera.
    #[error("a rig needs at least one camera")]
    Empty,
    /// Two cameras share a name.
    #[error("camera '{name}' is listed twice")]
    DuplicateCamera {
        /// The name given twice.
        name: String,
    },
    /// A mount or clock value is NaN or infinite.
    #[error("camera '{name}': {what} is not finite")]
    NotFinite {
        /// The camera.
        name: String,
        /// Which value.
        what: &'static str,
    },
    /// A clock drift beyond [`MAX_DRIFT_PPM`].
    #[error("camera '{name}': the clock drift must be within ±{max} ppm, got {value} ppm")]
    Drift {
        /// The camera.
        name: String,
        /// The drift given (ppm).
        value: f64,
        /// The largest drift allowed (ppm).
        max: f64,
    },
    /// The first camera, whose clock is the rig's, has an unknown offset or drift.
    #[error(
        "the first camera '{name}' is the rig's clock: its clock offset and drift must be known (give both, or neither)"
    )]
    ReferenceClockUnknown {
        /// The first camera.
        name: String,
    },
}

/// The largest clock drift a rig may state (ppm): a tenth of a percent, ten times a cheap crystal's.
pub const MAX_DRIFT_PPM: f64 = 1000.0;

/// Cameras, each with its calibration, its pose in the rig and its clock (see the [module documentation](self)).
///
/// ```
/// use roitrack_estimators::rig::{CameraMount, ClockModel, Rig, RigCamera};
/// use roitrack_core::CameraModel;
///
/// let cam = |name: &str| RigCamera::known(name, CameraModel::canonical(), CameraMount::IDENTITY, ClockModel::REFERENCE);
/// let rig = Rig::new(vec![cam("left"), cam("right")]).unwrap();
/// assert_eq!(rig.index_of("right"), Some(1));
/// assert!(Rig::new(vec![cam("left"), cam("left")]).unwrap_err().to_string().contains("'left' is listed twice"));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    cameras: Vec<RigCamera>,
}

impl Rig {
    /// A rig of these cameras: at least one, names unique, mounts and clocks finite, the first camera's clock known.
    pub fn new(cameras: Vec<RigCamera>) -> Result<Self, RigDefinitionError> {
        let first = cameras.first().ok_or(RigDefinitionError::Empty)?;
        if !first.clock_known() {
            return Err(RigDefinitionError::ReferenceClockUnknown {
                name: first.name.clone(),
            });
        }
        for (i, c) in cameras.iter().enumerate() {
            if cameras[..i].iter().any(|o| o.name == c.name) {
                return Err(RigDefinitionError::DuplicateCamera {
                    name: c.name.clone(),
                });
            }
            let not_finite = |what| RigDefinitionError::NotFinite {
                name: c.name.clone(),
                what,
            };
            if !c.mount.camera_r_rig.matrix().iter().all(|x| x.is_finite()) {
                return Err(not_finite("camera_T_rig's rotation"));
            }
            if !c.mount.camera_t_rig_m.iter().all(|x| x.is_finite()) {
                return Err(not_finite("camera_T_rig's translation"));
            }
            if !c.clock.offset_s.is_finite() {
                return Err(not_finite("clock_offset_s"));
            }
            if c.clock.drift_ppm.is_nan() || c.clock.drift_ppm.abs() > MAX_DRIFT_PPM {
                return Err(RigDefinitionError::Drift {
                    name: c.name.clone(),
                    value: c.clock.drift_ppm,
                    max: MAX_DRIFT_PPM,
                });
            }
        }
        Ok(Self { cameras })
    }

    /// A rig of one camera that is the rig: the single-camera tracker's setting.
    pub fn single(name: impl Into<String>, camera: CameraModel) -> Self {
        Self {
            cameras: vec![RigCamera::known(
                name,
                camera,
                CameraMount::IDENTITY,
                ClockModel::REFERENCE,
            )],
        }
    }

    /// The cameras, the first one the rig's reference.
    pub fn cameras(&self) -> &[RigCamera] {
        &self.cameras
    }

    /// How many cameras.
    pub fn len(&self) -> usize {
        self.cameras.len()
    }

    /// Never: a rig has at least one camera.
    pub fn is_empty(&self) -> bool {
        self.cameras.is_empty()
    }

    /// The index of the camera named `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.cameras.iter().position(|c| c.name == name)
    }
}

/// A centroid tagged with the rig camera that measured it; its time is on that camera's own clock.
///
/// ```
/// use roitrack_estimators::rig::RigMeasurement;
/// use roitrack_core::Measurement;
/// let m = RigMeasurement { camera: 1, measurement: Measurement { t_s: 0.5, id: 3, u_px: 510.0, v_px: 498.0 } };
/// assert_eq!(m.camera, 1);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigMeasurement {
    /// The index of the camera in the rig.
    pub camera: usize,
    /// The centroid, its time `t_s` on the camera's clock.
    pub measurement: Measurement,
}

/// Several cameras' streams of centroids (each in its own camera's time order) merged into one, in the order of their
/// rig times by `clocks` (a camera's clock as the rig file gives it; its own time for one left unknown, which the
/// tracker's reorder buffer then puts right). Each item is the position of its stream in the list and the
/// measurement tagged with its camera, or the stream's error (which comes first, as soon as its stream is looked at).
///
/// ```
/// use roitrack_estimators::rig::{ClockModel, RigMeasurement, merge_streams};
/// use roitrack_core::Measurement;
///
/// let m = |t_s| Ok::<_, ()>(Measurement { t_s, id: 0, u_px: 1.0, v_px: 1.0 });
/// let clocks = [ClockModel::REFERENCE, ClockModel { offset_s: 0.5, drift_ppm: 0.0 }];
/// // Camera 1's 0.1 s is the rig's 0.6 s.
/// let merged: Vec<f64> = merge_streams(vec![(0, vec![m(0.2), m(0.7)].into_iter()), (1, vec![m(0.1)].into_iter())], &clocks)
///     .map(|(_, r)| r.unwrap().measurement.t_s)
///     .collect();
/// assert_eq!(merged, [0.2, 0.1, 0.7]);
/// ```
pub fn merge_streams<I, E>(streams: Vec<(usize, I)>, clocks: &[ClockModel]) -> MergedStreams<I>
where
    I: Iterator<Item = Result<Measurement, E>>,
{
    MergedStreams {
        streams: streams
            .into_iter()
            .map(|(camera, stream)| (camera, stream.peekable()))
            .collect(),
        clocks: clocks.to_vec(),
    }
}

/// The iterator of [`merge_streams`].
pub struct MergedStreams<I: Iterator> {
    streams: Vec<(usize, std::iter::Peekable<I>)>,
    clocks: Vec<ClockModel>,
}

impl<I: Iterator> std::fmt::Debug for MergedStreams<I> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MergedStreams")
            .field("streams", &self.streams.len())
            .field("clocks", &self.clocks)
            .finish()
    }
}

impl<I, E> Iterator for MergedStreams<I>
where
    I: Iterator<Item = Result<Measurement, E>>,
{
    type Item = (usize, Result<RigMeasurement, E>);

    fn next(&mut self) -> Option<Self::Item> {
        let mut next: Option<(f64, usize)> = None;
        for (k, (camera, stream)) in self.streams.iter_mut().enumerate() {
            match stream.peek() {
                Some(Ok(m)) => {
                    let clock = self.clocks.get(*camera).copied().unwrap_or_default();
                    let t = clock.rig_time_s(m.t_s);
                    if next.is_none_or(|(best, _)| t < best) {
                        next = Some((t, k));
                    }
                }
                Some(Err(_)) => {
                    next = Some((f64::NEG_INFINITY, k));
                    break;
                }
                None => {}
            }
        }
        let (_, k) = next?;
        let (camera, stream) = &mut self.streams[k];
        let item = stream.next()?.map(|measurement| RigMeasurement {
            camera: *camera,
            measurement,
        });
        Some((k, item))
    }
}
