//! What a case looks at: its motion ([`Scene`]), the camera that sees it ([`CameraChoice`]) and the target it
//! carries ([`TargetChoice`]), with the study's own camera and targets.

use nalgebra::Vector3;
use roitrack_core::{CameraModel, MotionState, PinholeIntrinsics, PlumbBob, Target, TargetPoint};
use roitrack_sim::{Scenario, ScenarioKind};
use serde::Serialize;

/// The motion of a case.
///
/// ```
/// use roitrack_experiments::adaptive::Scene;
/// use roitrack_sim::ScenarioKind;
///
/// assert_eq!(Scene::Spec(ScenarioKind::Orthoglide).name(), "orthoglide");
/// assert_eq!(Scene::Still { distance_m: 1.6, duration_s: 2.0 }.name(), "still 1.6 m");
/// assert!(Scene::Spec(ScenarioKind::Spin).is_moving_spec_scene());
/// assert!(!Scene::Spec(ScenarioKind::Static).is_moving_spec_scene());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scene {
    /// A built-in scenario, `Scenario::new(kind, seed)`.
    Spec(ScenarioKind),
    /// The target at rest `distance_m` in front of the camera, [`Scenario::still`] at the bench rotation and
    /// t = (0.02, -0.01, distance) m.
    Still {
        /// Depth of the target's origin in front of the camera (m).
        distance_m: f64,
        /// Length of the scenario (s).
        duration_s: f64,
    },
    /// Smooth random 6-dof motion at these peaks, [`Scenario::random_with`].
    Random {
        /// Peak speed of the target's origin (m/s).
        peak_speed_mps: f64,
        /// Peak angular speed (rad/s).
        peak_angular_radps: f64,
        /// Length of the scenario (s).
        duration_s: f64,
    },
}

impl Scene {
    /// A short name: the built-in scenario's, `still 1.6 m`, `random 2.5 m/s, 7 rad/s`.
    pub fn name(&self) -> String {
        match self {
            Self::Spec(kind) => kind.name().to_string(),
            Self::Still { distance_m, .. } => format!("still {distance_m} m"),
            Self::Random {
                peak_speed_mps,
                peak_angular_radps,
                ..
            } => format!("random {peak_speed_mps} m/s, {peak_angular_radps} rad/s"),
        }
    }

    /// Whether this is a built-in scene in motion (orthoglide, spin, random): where the velocity lag means something.
    pub fn is_moving_spec_scene(&self) -> bool {
        matches!(self, Self::Spec(kind) if *kind != ScenarioKind::Static)
    }

    /// The scenario of `seed` (canonical camera and target).
    pub(super) fn scenario(&self, seed: u64) -> Scenario {
        match *self {
            Self::Spec(kind) => Scenario::new(kind, seed),
            Self::Still {
                distance_m,
                duration_s,
            } => Scenario::still(
                MotionState::bench_rotation(),
                Vector3::new(0.02, -0.01, distance_m),
                duration_s,
            ),
            Self::Random {
                peak_speed_mps,
                peak_angular_radps,
                duration_s,
            } => Scenario::random_with(seed, peak_speed_mps, peak_angular_radps, duration_s),
        }
    }
}

/// A [`Scene`] as serialised: tagged by `kind`, a built-in scenario by its name.
#[derive(Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum SceneRecord {
    Spec {
        scenario: &'static str,
    },
    Still {
        distance_m: f64,
        duration_s: f64,
    },
    Random {
        peak_speed_mps: f64,
        peak_angular_radps: f64,
        duration_s: f64,
    },
}

impl Serialize for Scene {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match *self {
            Self::Spec(kind) => SceneRecord::Spec {
                scenario: kind.name(),
            },
            Self::Still {
                distance_m,
                duration_s,
            } => SceneRecord::Still {
                distance_m,
                duration_s,
            },
            Self::Random {
                peak_speed_mps,
                peak_angular_radps,
                duration_s,
            } => SceneRecord::Random {
                peak_speed_mps,
                peak_angular_radps,
                duration_s,
            },
        }
        .serialize(serializer)
    }
}

/// The camera of a case.
///
/// ```
/// use roitrack_experiments::adaptive::CameraChoice;
///
/// let wide = CameraChoice::WideAngle.camera();
/// assert_eq!((wide.width_px, wide.height_px), (1280, 1024));
/// assert!(!wide.distortion.is_identity());
/// assert_eq!(CameraChoice::Canonical.camera(), roitrack_core::CameraModel::canonical());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraChoice {
    /// [`CameraModel::canonical`]: 1024 x 1024 px, f = 1500 px, no distortion.
    Canonical,
    /// [`wide_angle_1280x1024`]: 1280 x 1024 px, f = 760 px (80 deg across), strong plumb_bob distortion.
    WideAngle,
}

impl CameraChoice {
    /// The camera model.
    pub fn camera(&self) -> CameraModel {
        match self {
            Self::Canonical => CameraModel::canonical(),
            Self::WideAngle => wide_angle_1280x1024(),
        }
    }

    /// `canonical` or `wide 1280x1024`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Canonical => "canonical",
            Self::WideAngle => "wide 1280x1024",
        }
    }
}

/// A wide-angle 1280 x 1024 camera: fx = 760, fy = 770 px (80 deg across, 67 deg down), skew 0.5 px, principal point
/// (643, 508), and the strong radial distortion of [`CameraModel::wide_angle_example`] (k1 = -0.28, k2 = 0.12,
/// k3 = -0.03, tangential 1.2e-3 and -8e-4): the corners are drawn in by about a fifth. Seen through it, the
/// orthoglide motion keeps the blobs within about 0.25 of the optical axis (normalised), where the distortion moves
/// them by up to about 3 px.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_experiments::adaptive::wide_angle_1280x1024;
///
/// let camera = wide_angle_1280x1024();
/// let ideal = camera.intrinsics.pixel_from_cam(&Vector3::new(0.1, 0.0, 0.6)).unwrap();
/// let raw = camera.raw_pixel_from_cam(&Vector3::new(0.1, 0.0, 0.6)).unwrap();
/// assert!((ideal - raw).norm() > 0.5);
/// ```
pub fn wide_angle_1280x1024() -> CameraModel {
    CameraModel::new(
        "wide_1280x1024",
        1280,
        1024,
        PinholeIntrinsics {
            fx_px: 760.0,
            fy_px: 770.0,
            skew_px: 0.5,
            cx_px: 643.0,
            cy_px: 508.0,
        },
        // The wide-angle example's lens without its k3 (-0.03), whose radial map turned back 727 px from the
        // principal point, inside this image (its corners are 820 px away): a lens must be invertible over its image.
        PlumbBob::from_coefficients([-0.28, 0.12, 1.2e-3, -8e-4, 0.0]),
    )
    .expect("the wide-angle camera is valid")
}

/// The target of a case.
///
/// ```
/// use roitrack_experiments::adaptive::TargetChoice;
///
/// assert_eq!(TargetChoice::NonPlanar11.target().len(), 11);
/// assert!(!TargetChoice::NonPlanar11.target().is_planar());
/// assert_eq!(TargetChoice::Grid2x3.target().len(), 6);
/// assert_eq!(TargetChoice::Grid4x4.target(), roitrack_core::Target::grid4x4());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetChoice {
    /// [`Target::grid4x4`]: 16 points, 20 mm pitch.
    Grid4x4,
    /// [`non_planar_11`]: 11 points spread over 70 x 50 mm and ±15 mm in depth.
    NonPlanar11,
    /// [`grid2x3`]: 2 rows of 3 points, 20 mm pitch.
    Grid2x3,
}

impl TargetChoice {
    /// The target.
    pub fn target(&self) -> Target {
        match self {
            Self::Grid4x4 => Target::grid4x4(),
            Self::NonPlanar11 => non_planar_11(),
            Self::Grid2x3 => grid2x3(),
        }
    }

    /// `grid4x4`, `11-point 3-D`, `grid2x3`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Grid4x4 => "grid4x4",
            Self::NonPlanar11 => "11-point 3-D",
            Self::Grid2x3 => "grid2x3",
        }
    }
}

/// A non-planar target of 11 points (a tool carrying markers): spread over 70 x 50 mm around the origin, at depths
/// from -15 to +15 mm out of the plane z = 0; 6 mm blobs except the 9 mm key blob 0.
///
/// ```
/// let target = roitrack_experiments::adaptive::non_planar_11();
/// let depths: Vec<f64> = target.points().iter().map(|p| p.point_in_obj_m.z).collect();
/// assert_eq!(depths.iter().cloned().fold(f64::MIN, f64::max), 0.015);
/// assert_eq!(depths.iter().cloned().fold(f64::MAX, f64::min), -0.015);
/// assert_eq!(target.key_point().unwrap().id, 0);
/// ```
pub fn non_planar_11() -> Target {
    const POINTS_MM: [[f64; 3]; 11] = [
        [-30.0, -20.0, 0.0],
        [0.0, -25.0, 15.0],
        [30.0, -20.0, -8.0],
        [-35.0, 0.0, 8.0],
        [-10.0, 5.0, -15.0],
        [12.0, -5.0, 5.0],
        [35.0, 2.0, 12.0],
        [-28.0, 22.0, -10.0],
        [0.0, 25.0, 0.0],
        [25.0, 20.0, 15.0],
        [8.0, 12.0, -5.0],
    ];
    let points = POINTS_MM
        .iter()
        .enumerate()
        .map(|(id, p)| TargetPoint {
            id: id as u32,
            point_in_obj_m: Vector3::from(*p) * 1e-3,
            diameter_m: Some(if id == 0 { 0.009 } else { 0.006 }),
        })
        .collect();
    Target::new(points).expect("the 11-point target is valid")
}

/// A planar 2 x 3 grid of pitch 20 mm centred on the origin, as [`Target::grid4x4`]: id = 3 r + c at
/// ((c - 1) 0.02, (r - 0.5) 0.02, 0); 6 mm blobs except the 9 mm key blob 0.
///
/// ```
/// let target = roitrack_experiments::adaptive::grid2x3();
/// assert_eq!(target.points()[5].point_in_obj_m, nalgebra::Vector3::new(0.02, 0.01, 0.0));
/// assert!(target.is_planar());
/// ```
pub fn grid2x3() -> Target {
    let points = (0..6u32)
        .map(|id| {
            let (r, c) = ((id / 3) as f64, (id % 3) as f64);
            TargetPoint {
                id,
                point_in_obj_m: Vector3::new((c - 1.0) * 0.020, (r - 0.5) * 0.020, 0.0),
                diameter_m: Some(if id == 0 { 0.009 } else { 0.006 }),
            }
        })
        .collect();
    Target::new(points).expect("the 2x3 grid is valid")
}
