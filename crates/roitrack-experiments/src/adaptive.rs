//! The measurement harness of the adaptive-estimation study: the default Kalman filter, which is not told the noise
//! of the centroids nor the motion, against hand-tuned filters searched over a grid on the same data
//! (`roitrack compare --sweep`, the table of `docs/results.md`).
//!
//! Each [`Case`] is a scenario seen by a camera carrying a target, sampled at a ROI rate with a centroid noise
//! ([`cases`]). Every case is simulated once per seed and tracked
//!
//! - by the **default** filter: `TrackerConfig::default()` (0.1 px assumed, the default acceleration densities,
//!   `adapt_noise` and `adapt_motion` on): the user does not know the noise;
//! - by **hand-tuned** filters (`adapt_noise` and `adapt_motion` off: the filter takes its settings as the truth) over
//!   the [`Grid`] of centroid noise (a factor of the true noise) and linear and angular acceleration densities. The
//!   **told-the-truth** filter is the grid's default point: the true noise and the default densities.
//!
//! The grid is searched in two stages ([`Grid`]): a coarse grid (the true noise, every other density of each axis,
//! and the told-the-truth point), then a pattern search on the full grid from the best point so far (each round runs
//! the unvisited neighbours, one step along each axis, and moves to the best, until none improves). The best
//! hand-tuned run's position RMSE is the case's **nominal** error.
//!
//! The targets ([`Goal`]), per case:
//!
//! - [`Goal::Rmse`]: the default filter's position RMSE at most [`RMSE_RATIO_LIMIT`] times the best hand-tuned one;
//! - [`Goal::Clean`]: no `disputed` or `lost` estimate (the data are clean);
//! - [`Goal::Calibrated`]: the covariance is calibrated ([`Consistency::is_calibrated`]: mean NEES of position and
//!   velocity within 0.5-2 times their dimension, at least 95 % of the estimates inside the 99 % chi-square bound);
//! - [`Goal::Lag`]: the velocity lag at most [`MAX_LAG_SAMPLES`] sample, on the moving built-in scenes (orthoglide);
//! - [`Goal::Bounded`]: no estimate marked tracking or converging more than [`BOUND_FACTOR`] times the nominal error
//!   away from the truth.
//!
//! The accuracy cases ([`Purpose::Accuracy`]) are checked against every target (the lag on the built-in scenes only); the
//! calibration set ([`Case::in_calibration_set`]: every built-in scenario, static, orthoglide, spin, random, at 0.03, 0.1,
//! 0.3 and 1 px) against [`Goal::Calibrated`]; its orthoglide rows are accuracy cases too. A calibration-only case
//! ([`Purpose::Calibration`]) runs the default and the told-the-truth filters, no grid.
//!
//! ```
//! use roitrack_experiments::adaptive::{SweepOptions, sweep};
//!
//! // One tiny case: a smoke run (the sweep proper runs every case of `cases()` on the whole grid).
//! let mut options = SweepOptions::quick();
//! options.cases.truncate(1);
//! options.max_duration_s = Some(0.4);
//! let result = sweep(&options, None).unwrap();
//! let case = &result.cases[0];
//! assert_eq!(case.case.name, "4 kHz, 0.1 px");
//! let best = case.best.as_ref().unwrap();
//! // The best hand-tuned run is at most the told-the-truth one: the grid's default point is searched.
//! assert!(best.summary.position_rmse_mm <= case.told_truth.summary.position_rmse_mm);
//! assert!(result.markdown().contains("| case |"));
//! assert!(!result.checks().is_empty());
//! ```

use std::collections::HashSet;
use std::fmt::Write as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use nalgebra::Vector3;
use roitrack_core::{CameraModel, MotionState, PinholeIntrinsics, PlumbBob, Target, TargetPoint};
use roitrack_estimators::{EstimatorConfig, KalmanTuning, StatusCounts, TrackerConfig, track_all};
use roitrack_eval::{Consistency, EvalOptions, PooledErrors, consistency_of};
use roitrack_sim::{Scenario, ScenarioKind, SimulatedRun, SimulationOptions, simulate};
use serde::Serialize;

use crate::ExperimentError;
use roitrack_demo::scoring::{Scored, score};

/// [`Goal::Rmse`]: the default filter's position RMSE may be at most this many times the best hand-tuned one.
///
/// ```
/// assert_eq!(roitrack_experiments::adaptive::RMSE_RATIO_LIMIT, 1.2);
/// ```
pub const RMSE_RATIO_LIMIT: f64 = 1.2;

/// [`Goal::Bounded`]: no vouched estimate may be more than this many times the nominal error off.
///
/// ```
/// assert_eq!(roitrack_experiments::adaptive::BOUND_FACTOR, 10.0);
/// ```
pub const BOUND_FACTOR: f64 = 10.0;

/// [`Goal::Lag`]: the largest velocity lag (estimator samples) on the built-in scenes.
///
/// ```
/// assert_eq!(roitrack_experiments::adaptive::MAX_LAG_SAMPLES, 1);
/// ```
pub const MAX_LAG_SAMPLES: i64 = 1;

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
    fn scenario(&self, seed: u64) -> Scenario {
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

/// What a case is for.
///
/// ```
/// use roitrack_experiments::adaptive::{Purpose, cases};
/// assert_eq!(cases().iter().filter(|c| c.purpose == Purpose::Accuracy).count(), 10);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Purpose {
    /// Every target of the study; the hand-tuned grid is searched.
    Accuracy,
    /// The calibration of the covariance only: the default and the told-the-truth filters, no grid.
    Calibration,
}

/// One case of the sweep: a scene seen by a camera carrying a target, sampled at `rate_hz` with `noise_px` of
/// centroid noise, once per seed.
///
/// ```
/// use roitrack_experiments::adaptive::cases;
///
/// let case = cases().into_iter().find(|c| c.name == "still 1.6 m").unwrap();
/// assert_eq!((case.rate_hz, case.noise_px), (4000.0, 0.15));
/// let scenario = case.scenario(case.seeds[0]);
/// assert_eq!(scenario.state_at(0.5).cam_t_obj_m.z, 1.6);
/// assert!(scenario.min_image_margin_px() > 0.0);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Case {
    /// The case's name in tables and on the command line.
    pub name: &'static str,
    /// The motion.
    pub scene: Scene,
    /// The camera that sees it.
    pub camera: CameraChoice,
    /// The target it carries.
    pub target: TargetChoice,
    /// ROI rate (Hz): one centroid every 1 / rate s.
    pub rate_hz: f64,
    /// Standard deviation of the centroid noise, per axis (px).
    pub noise_px: f64,
    /// Each seed is a simulation (the noise, and the motion of a random scene); figures are pooled over seeds.
    pub seeds: Vec<u64>,
    /// What the case is for: every accuracy target, or the covariance's calibration only.
    pub purpose: Purpose,
    /// One of the calibration set: a built-in scenario at 4 kHz, canonical camera and target, 0.03 to 1 px.
    pub in_calibration_set: bool,
}

impl Case {
    /// The scenario of `seed`: the scene with the case's camera and target.
    pub fn scenario(&self, seed: u64) -> Scenario {
        self.scene
            .scenario(seed)
            .with_camera(self.camera.camera())
            .with_target(self.target.target())
    }

    /// The targets this case is checked against (see the [module docs](self)).
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{Goal, cases};
    ///
    /// let all = cases();
    /// let find = |name| all.iter().find(|c| c.name == name).unwrap();
    /// assert_eq!(find("4 kHz, 0.1 px").goals().len(), 5);
    /// assert!(!find("still 1.6 m").goals().contains(&Goal::Lag));
    /// assert_eq!(find("spin, 0.3 px").goals(), vec![Goal::Calibrated]);
    /// ```
    pub fn goals(&self) -> Vec<Goal> {
        match self.purpose {
            Purpose::Calibration => vec![Goal::Calibrated],
            Purpose::Accuracy => Goal::ALL
                .into_iter()
                .filter(|g| *g != Goal::Lag || self.scene.is_moving_spec_scene())
                .collect(),
        }
    }
}

/// Every case of the study, accuracy cases first, then the rest of the calibration set.
///
/// - 4 kHz at 0.03, 0.1, 0.3 and 1 px, and 10 kHz at 0.2 px, on orthoglide (the built-in scene);
/// - the grid at rest 1.6 m away at 0.15 px, 2 s;
/// - random 6-dof motion at 2.5 m/s and 7 rad/s (peaks), 4 s, 0.1 px;
/// - orthoglide through [`wide_angle_1280x1024`], with [`non_planar_11`], with [`grid2x3`], each at 0.1 px;
/// - the calibration set: static, spin and random at 0.03, 0.1, 0.3 and 1 px (orthoglide's are the first four).
///
/// ```
/// use roitrack_experiments::adaptive::cases;
///
/// let all = cases();
/// assert_eq!(all.len(), 22);
/// assert_eq!(all.iter().filter(|c| c.in_calibration_set).count(), 16);
/// // Every case keeps every blob inside its camera's image.
/// for case in &all {
///     for &seed in &case.seeds {
///         assert!(case.scenario(seed).min_image_margin_px() > 0.0, "{}", case.name);
///     }
/// }
/// ```
pub fn cases() -> Vec<Case> {
    let case = |name, scene, camera, target, rate_hz, noise_px, purpose, in_calibration_set| Case {
        name,
        scene,
        camera,
        target,
        rate_hz,
        noise_px,
        seeds: vec![1],
        purpose,
        in_calibration_set,
    };
    let ortho = Scene::Spec(ScenarioKind::Orthoglide);
    let (canonical, grid) = (CameraChoice::Canonical, TargetChoice::Grid4x4);
    let accuracy = |name, scene, camera, target, rate_hz, noise_px| {
        case(
            name,
            scene,
            camera,
            target,
            rate_hz,
            noise_px,
            Purpose::Accuracy,
            false,
        )
    };
    let mut all = vec![];
    for (name, noise_px) in [
        ("4 kHz, 0.03 px", 0.03),
        ("4 kHz, 0.1 px", 0.1),
        ("4 kHz, 0.3 px", 0.3),
        ("4 kHz, 1 px", 1.0),
    ] {
        all.push(Case {
            in_calibration_set: true,
            ..accuracy(name, ortho, canonical, grid, 4000.0, noise_px)
        });
    }
    all.push(accuracy(
        "10 kHz, 0.2 px",
        ortho,
        canonical,
        grid,
        10_000.0,
        0.2,
    ));
    all.push(accuracy(
        "still 1.6 m",
        Scene::Still {
            distance_m: 1.6,
            duration_s: 2.0,
        },
        canonical,
        grid,
        4000.0,
        0.15,
    ));
    all.push(accuracy(
        "random 2.5 m/s, 7 rad/s",
        Scene::Random {
            peak_speed_mps: 2.5,
            peak_angular_radps: 7.0,
            duration_s: 4.0,
        },
        canonical,
        grid,
        4000.0,
        0.1,
    ));
    all.push(accuracy(
        "wide-angle 1280x1024",
        ortho,
        CameraChoice::WideAngle,
        grid,
        4000.0,
        0.1,
    ));
    all.push(accuracy(
        "11-point 3-D target",
        ortho,
        canonical,
        TargetChoice::NonPlanar11,
        4000.0,
        0.1,
    ));
    all.push(accuracy(
        "2x3 target",
        ortho,
        canonical,
        TargetChoice::Grid2x3,
        4000.0,
        0.1,
    ));
    for (kind, names) in [
        (
            ScenarioKind::Static,
            [
                "static, 0.03 px",
                "static, 0.1 px",
                "static, 0.3 px",
                "static, 1 px",
            ],
        ),
        (
            ScenarioKind::Spin,
            [
                "spin, 0.03 px",
                "spin, 0.1 px",
                "spin, 0.3 px",
                "spin, 1 px",
            ],
        ),
        (
            ScenarioKind::Random,
            [
                "random, 0.03 px",
                "random, 0.1 px",
                "random, 0.3 px",
                "random, 1 px",
            ],
        ),
    ] {
        for (name, noise_px) in names.into_iter().zip([0.03, 0.1, 0.3, 1.0]) {
            all.push(case(
                name,
                Scene::Spec(kind),
                canonical,
                grid,
                4000.0,
                noise_px,
                Purpose::Calibration,
                true,
            ));
        }
    }
    all
}

/// The hand-tuned filters searched: centroid noise (a factor of the true noise) by linear acceleration density
/// ((m/s²)²/Hz) by angular acceleration density ((rad/s²)²/Hz), and how the search goes (see the
/// [module docs](self)). Every axis must hold the told-the-truth value: a noise factor of 1 and the default densities
/// of [`KalmanTuning`].
///
/// ```
/// use roitrack_experiments::adaptive::Grid;
///
/// let grid = Grid::full();
/// assert_eq!(grid.noise_factors, vec![0.5, 0.7, 1.0, 1.4, 2.0]);
/// assert_eq!(grid.linear_accel_psd.len(), 8);
/// assert_eq!(grid.points(), 5 * 8 * 9);
/// assert!(grid.validate().is_ok());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Grid {
    /// The assumed noise as a factor of the true noise.
    pub noise_factors: Vec<f64>,
    /// Linear acceleration densities, increasing.
    pub linear_accel_psd: Vec<f64>,
    /// Angular acceleration densities, increasing.
    pub angular_accel_psd: Vec<f64>,
    /// The coarse stage takes every `coarse_stride`-th density of each axis and the last (and the told-the-truth
    /// point), at the true noise.
    pub coarse_stride: usize,
    /// At most this many rounds of pattern search after the coarse stage (0: the coarse grid alone).
    pub max_rounds: usize,
}

/// A point of the grid: indices into the noise factors, linear and angular densities.
type GridIndex = [usize; 3];

impl Grid {
    /// The sweep's grid: noise 0.5, 0.7, 1, 1.4, 2 x the truth; q_a from 1e-4 to 1e3 and q_α from 1e-4 to 1e4, by
    /// factors of 10; coarse stage every other density and the last of each axis (25 points at the true noise, and
    /// the told-the-truth point), then up to 20 rounds of pattern search.
    pub fn full() -> Self {
        Self {
            noise_factors: vec![0.5, 0.7, 1.0, 1.4, 2.0],
            linear_accel_psd: (-4..=3).map(|e| 10f64.powi(e)).collect(),
            angular_accel_psd: (-4..=4).map(|e| 10f64.powi(e)).collect(),
            coarse_stride: 2,
            max_rounds: 20,
        }
    }

    /// A small grid for tests: noise 0.7, 1, 1.4 x the truth; q_a 0.1, 1, 10; q_α 1, 10, 100; one round of pattern
    /// search.
    ///
    /// ```
    /// assert_eq!(roitrack_experiments::adaptive::Grid::quick().points(), 27);
    /// ```
    pub fn quick() -> Self {
        Self {
            noise_factors: vec![0.7, 1.0, 1.4],
            linear_accel_psd: vec![0.1, 1.0, 10.0],
            angular_accel_psd: vec![1.0, 10.0, 100.0],
            coarse_stride: 2,
            max_rounds: 1,
        }
    }

    /// Points in the full grid.
    pub fn points(&self) -> usize {
        self.noise_factors.len() * self.linear_accel_psd.len() * self.angular_accel_psd.len()
    }

    /// Checks that every axis is positive, finite, increasing, and holds its told-the-truth value, and that the
    /// stride is at least 1.
    ///
    /// ```
    /// use roitrack_experiments::adaptive::Grid;
    /// let grid = Grid { linear_accel_psd: vec![0.1, 10.0], ..Grid::quick() };
    /// assert!(grid.validate().unwrap_err().contains("1"));
    /// ```
    pub fn validate(&self) -> Result<(), String> {
        let defaults = KalmanTuning::default();
        for (name, axis, truth) in [
            ("noise_factors", &self.noise_factors, 1.0),
            (
                "linear_accel_psd",
                &self.linear_accel_psd,
                defaults.linear_accel_psd,
            ),
            (
                "angular_accel_psd",
                &self.angular_accel_psd,
                defaults.angular_accel_psd,
            ),
        ] {
            if axis.iter().any(|x| !x.is_finite() || *x <= 0.0)
                || axis.windows(2).any(|w| w[0] >= w[1])
            {
                return Err(format!(
                    "grid axis {name} must be positive, finite and increasing, got {axis:?}"
                ));
            }
            if !axis.contains(&truth) {
                return Err(format!(
                    "grid axis {name} must hold the told-the-truth value {truth}, got {axis:?}"
                ));
            }
        }
        if self.coarse_stride == 0 {
            return Err("the coarse stride must be at least 1".to_string());
        }
        Ok(())
    }

    /// The told-the-truth point: noise factor 1, the default densities.
    fn truth_index(&self) -> GridIndex {
        let defaults = KalmanTuning::default();
        let at = |axis: &[f64], x: f64| axis.iter().position(|&a| a == x).unwrap_or(0);
        [
            at(&self.noise_factors, 1.0),
            at(&self.linear_accel_psd, defaults.linear_accel_psd),
            at(&self.angular_accel_psd, defaults.angular_accel_psd),
        ]
    }

    /// The coarse stage: the true noise, every `coarse_stride`-th density and the last, and the told-the-truth point.
    fn coarse(&self) -> Vec<GridIndex> {
        let truth = self.truth_index();
        let strided = |len: usize| {
            let mut indices: Vec<usize> = (0..len).step_by(self.coarse_stride).collect();
            if indices.last() != Some(&(len - 1)) {
                indices.push(len - 1);
            }
            indices
        };
        let mut out = vec![truth];
        for l in strided(self.linear_accel_psd.len()) {
            for a in strided(self.angular_accel_psd.len()) {
                if [truth[0], l, a] != truth {
                    out.push([truth[0], l, a]);
                }
            }
        }
        out
    }

    /// The points one step from `at` along each axis.
    fn neighbours(&self, at: GridIndex) -> Vec<GridIndex> {
        let lens = [
            self.noise_factors.len(),
            self.linear_accel_psd.len(),
            self.angular_accel_psd.len(),
        ];
        let mut out = Vec::new();
        for axis in 0..3 {
            if at[axis] > 0 {
                let mut p = at;
                p[axis] -= 1;
                out.push(p);
            }
            if at[axis] + 1 < lens[axis] {
                let mut p = at;
                p[axis] += 1;
                out.push(p);
            }
        }
        out
    }

    /// Whether `at` lies on the boundary of the grid along some axis: the best there may lie beyond the grid.
    fn on_edge(&self, at: GridIndex) -> bool {
        let lens = [
            self.noise_factors.len(),
            self.linear_accel_psd.len(),
            self.angular_accel_psd.len(),
        ];
        (0..3).any(|axis| at[axis] == 0 || at[axis] + 1 == lens[axis])
    }

    /// The hand-tuned settings at `at` for a true noise of `noise_px`.
    fn tuning(&self, at: GridIndex, noise_px: f64) -> HandTuning {
        HandTuning {
            noise_factor: self.noise_factors[at[0]],
            noise_px: noise_px * self.noise_factors[at[0]],
            linear_accel_psd: self.linear_accel_psd[at[1]],
            angular_accel_psd: self.angular_accel_psd[at[2]],
        }
    }
}

/// The settings of a hand-tuned filter: `adapt_noise` and `adapt_motion` off, the rest of [`KalmanTuning`] and
/// [`TrackerConfig`] at their defaults.
///
/// ```
/// use roitrack_estimators::EstimatorConfig;
/// use roitrack_experiments::adaptive::HandTuning;
///
/// let tuning = HandTuning { noise_factor: 1.4, noise_px: 0.14, linear_accel_psd: 10.0, angular_accel_psd: 100.0 };
/// let config = tuning.config();
/// assert_eq!(config.noise_px, 0.14);
/// let EstimatorConfig::Kalman(kalman) = config.estimator else { unreachable!() };
/// assert!(!kalman.adapt_noise && !kalman.adapt_motion);
/// assert_eq!((kalman.linear_accel_psd, kalman.angular_accel_psd), (10.0, 100.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HandTuning {
    /// `noise_px` over the true noise.
    pub noise_factor: f64,
    /// The assumed centroid noise (px).
    pub noise_px: f64,
    /// q_a ((m/s²)²/Hz).
    pub linear_accel_psd: f64,
    /// q_α ((rad/s²)²/Hz).
    pub angular_accel_psd: f64,
}

impl HandTuning {
    /// The tracker configuration.
    pub fn config(&self) -> TrackerConfig {
        TrackerConfig {
            estimator: EstimatorConfig::Kalman(KalmanTuning {
                linear_accel_psd: self.linear_accel_psd,
                angular_accel_psd: self.angular_accel_psd,
                adapt_noise: false,
                adapt_motion: false,
                ..KalmanTuning::default()
            }),
            noise_px: self.noise_px,
            ..TrackerConfig::default()
        }
    }
}

/// One filter's figures on a case, pooled over its seeds.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Estimates, of every status.
    pub estimates: usize,
    /// Seeds on which the filter gave no estimate at all (it never initialised): every figure then comes from the
    /// other seeds (NaN when none is left), and every target fails.
    pub runs_without_estimates: usize,
    /// RMSE of the position error over every estimate (mm), pooled over the seeds.
    pub position_rmse_mm: f64,
    /// RMSE of the velocity error over every estimate (mm/s).
    pub velocity_rmse_mm_s: f64,
    /// The largest position error of an estimate marked tracking or converging (mm); NaN without one.
    pub max_vouched_error_mm: f64,
    /// The velocity lag (estimator samples), the largest in magnitude over the seeds.
    pub velocity_lag_samples: Option<i64>,
    /// Estimates whose status was converging.
    pub converging: usize,
    /// Estimates whose status was tracking.
    pub tracking: usize,
    /// Estimates whose status was degenerate (the update not applied, the state only predicted).
    pub degenerate: usize,
    /// Estimates whose status was disputed (the newest measurement at odds with the earlier ones).
    pub disputed: usize,
    /// Estimates whose status was lost.
    pub lost: usize,
    /// NEES of position and velocity of the vouched estimates with a covariance.
    pub consistency: Consistency,
    /// The mean of [`Estimate::noise_px`](roitrack_estimators::Estimate::noise_px) over the vouched estimates:
    /// the noise the filter worked with (px).
    pub mean_noise_px: f64,
}

impl RunSummary {
    /// The figures of a filter's runs, one per seed (`None`: the run gave no estimate at all).
    fn of(runs: &[SimulatedRun], scored: &[Option<Scored>]) -> Result<Self, ExperimentError> {
        let mut metrics = Vec::with_capacity(scored.len());
        let mut max_vouched_error_mm: f64 = 0.0;
        let mut lag: Option<i64> = None;
        let mut statuses = StatusCounts::default();
        let mut consistencies = Vec::with_capacity(scored.len());
        let (mut noise_sum, mut vouched) = (0.0, 0usize);
        let mut runs_without_estimates = 0;
        for (run, s) in runs.iter().zip(scored) {
            let Some(s) = s else {
                runs_without_estimates += 1;
                continue;
            };
            let m = &s.metrics;
            metrics.push(m);
            if let Some(l) = m.velocity_lag_samples
                && lag.is_none_or(|worst| l.abs() > worst.abs())
            {
                lag = Some(l);
            }
            statuses.converging += s.statuses.converging;
            statuses.tracking += s.statuses.tracking;
            statuses.degenerate += s.statuses.degenerate;
            statuses.disputed += s.statuses.disputed;
            statuses.lost += s.statuses.lost;
            for (e, error) in s.estimates.iter().zip(&s.errors.position_m) {
                if e.status.is_vouched_for() {
                    max_vouched_error_mm = max_vouched_error_mm.max(error.norm() * 1e3);
                    noise_sum += e.noise_px;
                    vouched += 1;
                }
            }
            consistencies.push(consistency_of(
                &run.truth_poses,
                &run.truth_twists,
                &s.estimates,
                &EvalOptions::default(),
            )?);
        }
        let pooled = PooledErrors::of(metrics);
        Ok(Self {
            estimates: pooled.count,
            runs_without_estimates,
            position_rmse_mm: pooled.position_rmse_mm,
            velocity_rmse_mm_s: pooled.velocity_rmse_mm_s,
            max_vouched_error_mm: if vouched == 0 {
                f64::NAN
            } else {
                max_vouched_error_mm
            },
            velocity_lag_samples: lag,
            converging: statuses.converging,
            tracking: statuses.tracking,
            degenerate: statuses.degenerate,
            disputed: statuses.disputed,
            lost: statuses.lost,
            consistency: Consistency::pooled(&consistencies),
            mean_noise_px: noise_sum / vouched as f64,
        })
    }
}

/// A hand-tuned filter and its figures.
#[derive(Debug, Clone, Serialize)]
pub struct HandTuned {
    /// The filter's settings.
    pub tuning: HandTuning,
    /// Whether the settings lie on the grid's boundary along some axis (for the best: a better one may lie beyond).
    pub on_edge: bool,
    /// Its figures over the case's seeds.
    pub summary: RunSummary,
}

/// One grid point visited by the search, and its pooled position RMSE (mm).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Visited {
    /// The grid point's settings.
    pub tuning: HandTuning,
    /// Position RMSE over the runs that gave estimates.
    pub position_rmse_mm: f64,
    /// Runs (seeds) in which the filter never started: such a setting is no candidate for the best.
    pub runs_without_estimates: usize,
}

/// A case's figures.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    /// The case.
    pub case: Case,
    /// Measurements simulated, over every seed.
    pub measurements: usize,
    /// The default filter (`TrackerConfig::default()`).
    pub default: RunSummary,
    /// The told-the-truth hand-tuned filter: the true noise, the default densities, adaptation off.
    pub told_truth: HandTuned,
    /// The best hand-tuned filter of the grid search (accuracy cases).
    pub best: Option<HandTuned>,
    /// Every grid point the search ran, in the order run.
    pub visited: Vec<Visited>,
    /// The nominal error (mm): the best hand-tuned position RMSE (accuracy cases).
    pub nominal_mm: Option<f64>,
    /// The default filter's vouched estimates more than [`BOUND_FACTOR`] times the nominal error off.
    pub beyond_bound: Option<usize>,
    /// Wall time of the case (s).
    pub seconds: f64,
}

impl CaseResult {
    /// The default filter's position RMSE over the best hand-tuned one (NaN without a search).
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{SweepOptions, sweep};
    /// let mut options = SweepOptions::quick();
    /// options.cases.truncate(1);
    /// (options.max_duration_s, options.grid.max_rounds) = (Some(0.3), 0);
    /// let case = &sweep(&options, None).unwrap().cases[0];
    /// assert!(case.rmse_ratio() > 0.5);
    /// ```
    pub fn rmse_ratio(&self) -> f64 {
        self.best.as_ref().map_or(f64::NAN, |b| {
            self.default.position_rmse_mm / b.summary.position_rmse_mm
        })
    }

    /// Whether the default filter meets `goal` on this case (see [`Goal`]). No target holds when the default filter
    /// gave no estimate on some seed.
    pub fn holds(&self, goal: Goal) -> bool {
        let d = &self.default;
        if d.runs_without_estimates > 0 {
            return false;
        }
        match goal {
            Goal::Rmse => self.rmse_ratio() <= RMSE_RATIO_LIMIT,
            Goal::Clean => d.disputed == 0 && d.lost == 0,
            Goal::Calibrated => d.consistency.is_calibrated(),
            Goal::Lag => d
                .velocity_lag_samples
                .is_some_and(|l| l.abs() <= MAX_LAG_SAMPLES),
            Goal::Bounded => self.beyond_bound == Some(0),
        }
    }

    /// The figure `goal` is judged on, as text.
    fn figure(&self, goal: Goal) -> String {
        let d = &self.default;
        if d.runs_without_estimates > 0 {
            return format!("no estimate on {} seed(s)", d.runs_without_estimates);
        }
        match goal {
            Goal::Rmse => format!("{:.3}", self.rmse_ratio()),
            Goal::Clean => format!("{} disputed, {} lost", d.disputed, d.lost),
            Goal::Calibrated => format!(
                "NEES/3 {:.2} / {:.2}, inside {:.1} % / {:.1} %",
                d.consistency.position_nees_per_dof,
                d.consistency.velocity_nees_per_dof,
                100.0 * d.consistency.position_inside_99,
                100.0 * d.consistency.velocity_inside_99
            ),
            Goal::Lag => d
                .velocity_lag_samples
                .map_or("none".to_string(), |l| l.to_string()),
            Goal::Bounded => format!(
                "{} beyond {:.3} mm",
                self.beyond_bound.unwrap_or(0),
                BOUND_FACTOR * self.nominal_mm.unwrap_or(f64::NAN)
            ),
        }
    }
}

/// The targets of the study (see the [module docs](self)).
///
/// ```
/// use roitrack_experiments::adaptive::Goal;
/// assert_eq!(Goal::ALL.len(), 5);
/// assert_eq!(Goal::Rmse.name(), "rmse");
/// assert!(Goal::Calibrated.description().contains("NEES"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Goal {
    /// Position RMSE at most [`RMSE_RATIO_LIMIT`] times the best hand-tuned.
    Rmse,
    /// No disputed or lost estimate.
    Clean,
    /// Calibrated covariance.
    Calibrated,
    /// Velocity lag at most [`MAX_LAG_SAMPLES`].
    Lag,
    /// No vouched estimate beyond [`BOUND_FACTOR`] times the nominal error.
    Bounded,
}

impl Goal {
    /// Every target, in the tables' order.
    pub const ALL: [Self; 5] = [
        Self::Rmse,
        Self::Clean,
        Self::Calibrated,
        Self::Lag,
        Self::Bounded,
    ];

    /// A short name: `rmse`, `clean`, `calibrated`, `lag`, `bounded`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Rmse => "rmse",
            Self::Clean => "clean",
            Self::Calibrated => "calibrated",
            Self::Lag => "lag",
            Self::Bounded => "bounded",
        }
    }

    /// What the target asks.
    pub fn description(&self) -> &'static str {
        match self {
            Self::Rmse => "position RMSE at most 1.2 x the best hand-tuned",
            Self::Clean => "no disputed or lost estimate",
            Self::Calibrated => {
                "mean NEES of position and velocity within 0.5-2 x 3, at least 95 % inside the 99 % bound"
            }
            Self::Lag => "velocity lag at most 1 sample (moving built-in scenes)",
            Self::Bounded => "no vouched estimate beyond 10 x the nominal error",
        }
    }
}

/// One target checked on one case.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// The case's name.
    pub case: &'static str,
    /// The target checked.
    pub goal: Goal,
    /// The figure judged, as text.
    pub figure: String,
    /// Whether the case meets the target.
    pub holds: bool,
}

/// What the sweep runs.
///
/// ```
/// use roitrack_experiments::adaptive::SweepOptions;
///
/// let full = SweepOptions::full();
/// assert_eq!((full.cases.len(), full.max_duration_s), (22, None));
/// let quick = SweepOptions::quick();
/// assert!(quick.cases.len() < full.cases.len() && quick.max_duration_s.is_some());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepOptions {
    /// The cases run, in order.
    pub cases: Vec<Case>,
    /// The hand-tuned filter's grid, searched on the accuracy cases.
    pub grid: Grid,
    /// Scenarios cut to at most this long (s); `None`: whole.
    pub max_duration_s: Option<f64>,
    /// Cases run at once. Default: the machine's cores.
    pub threads: usize,
    /// Whether this is the quick mode (for the description).
    pub quick: bool,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self::full()
    }
}

impl SweepOptions {
    /// Every case of [`cases`], whole, on [`Grid::full`].
    pub fn full() -> Self {
        Self {
            cases: cases(),
            grid: Grid::full(),
            max_duration_s: None,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            quick: false,
        }
    }

    /// For tests: 5 accuracy cases (4 kHz at 0.1 px, still, random, wide-angle, 2x3) and 2 calibration cases (static
    /// at 0.3 px, spin at 1 px), cut to 0.6 s, on [`Grid::quick`].
    pub fn quick() -> Self {
        const QUICK: [&str; 7] = [
            "4 kHz, 0.1 px",
            "still 1.6 m",
            "random 2.5 m/s, 7 rad/s",
            "wide-angle 1280x1024",
            "2x3 target",
            "static, 0.3 px",
            "spin, 1 px",
        ];
        Self {
            cases: cases()
                .into_iter()
                .filter(|c| QUICK.contains(&c.name))
                .collect(),
            grid: Grid::quick(),
            max_duration_s: Some(0.6),
            quick: true,
            ..Self::full()
        }
    }

    /// Every case simulated with these seeds instead of its own, its figures pooled over them (the lag: the largest
    /// over the seeds).
    ///
    /// ```
    /// use roitrack_experiments::adaptive::SweepOptions;
    ///
    /// let options = SweepOptions::full().with_seeds(&[2, 3]);
    /// assert!(options.cases.iter().all(|c| c.seeds == [2, 3]));
    /// ```
    pub fn with_seeds(mut self, seeds: &[u64]) -> Self {
        for case in &mut self.cases {
            case.seeds = seeds.to_vec();
        }
        self
    }
}

/// Why the sweep could not run.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The grid is invalid: what is wrong with which axis.
    #[error("invalid grid: {0}")]
    Grid(String),
    /// Zero threads asked for.
    #[error("the sweep needs at least one thread")]
    NoThreads,
    /// A case has no seed.
    #[error("case {case} has no seed to simulate")]
    NoSeeds {
        /// The case's name.
        case: &'static str,
    },
    /// A case's simulation or tracking failed.
    #[error("case {case}: {source}")]
    Case {
        /// The case's name.
        case: &'static str,
        /// What failed.
        #[source]
        source: ExperimentError,
    },
}

/// The sweep's results.
#[derive(Debug, Clone, Serialize)]
pub struct Sweep {
    /// What was run.
    pub options: SweepOptions,
    /// One per case, in the options' order.
    pub cases: Vec<CaseResult>,
    /// Wall time of the sweep (s).
    pub seconds: f64,
}

/// Runs every case of `options` (see the [module docs](self)), cases in parallel on `options.threads` threads.
/// `progress`, when given, counts the cases done.
///
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use roitrack_experiments::adaptive::{Purpose, SweepOptions, sweep};
///
/// let mut options = SweepOptions::quick();
/// options.cases.retain(|c| c.purpose == Purpose::Calibration);
/// options.max_duration_s = Some(0.3);
/// let done = AtomicUsize::new(0);
/// let result = sweep(&options, Some(&done)).unwrap();
/// assert_eq!(done.load(Ordering::Relaxed), 2);
/// // Calibration cases search no grid: the default and the told-the-truth filters only.
/// assert!(result.cases.iter().all(|c| c.best.is_none() && c.visited.len() == 1));
/// ```
pub fn sweep(options: &SweepOptions, progress: Option<&AtomicUsize>) -> Result<Sweep, SweepError> {
    options.grid.validate().map_err(SweepError::Grid)?;
    if options.threads == 0 {
        return Err(SweepError::NoThreads);
    }
    if let Some(case) = options.cases.iter().find(|c| c.seeds.is_empty()) {
        return Err(SweepError::NoSeeds { case: case.name });
    }
    let start = Instant::now();
    // The longest cases first, so that the last to finish is a short one.
    let cost = |c: &Case| {
        let duration = c.scenario(c.seeds[0]).duration_s;
        let duration = options.max_duration_s.map_or(duration, |m| duration.min(m));
        let runs = match c.purpose {
            Purpose::Accuracy => 30.0,
            Purpose::Calibration => 2.0,
        };
        duration * c.rate_hz * c.seeds.len() as f64 * runs
    };
    let mut order: Vec<usize> = (0..options.cases.len()).collect();
    order.sort_by(|&a, &b| cost(&options.cases[b]).total_cmp(&cost(&options.cases[a])));
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Result<CaseResult, SweepError>)>> = Mutex::new(Vec::new());
    let workers = options.threads.min(order.len());
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&index) = order.get(k) else {
                        break;
                    };
                    let case = &options.cases[index];
                    let result = run_case(case, options).map_err(|source| SweepError::Case {
                        case: case.name,
                        source,
                    });
                    let failed = result.is_err();
                    results
                        .lock()
                        .expect("no worker panics holding the lock")
                        .push((index, result));
                    if let Some(done) = progress {
                        done.fetch_add(1, Ordering::Relaxed);
                    }
                    if failed {
                        next.store(order.len(), Ordering::Relaxed);
                        break;
                    }
                }
            });
        }
    });
    let mut results = results.into_inner().expect("the workers have ended");
    results.sort_by_key(|(index, _)| *index);
    let cases = results
        .into_iter()
        .map(|(_, r)| r)
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Sweep {
        options: options.clone(),
        cases,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// What the search minimises: the pooled position RMSE, infinite when some seed gave no estimate.
fn objective(summary: &RunSummary) -> f64 {
    if summary.runs_without_estimates == 0 && summary.position_rmse_mm.is_finite() {
        summary.position_rmse_mm
    } else {
        f64::INFINITY
    }
}

/// Simulates a case's seeds, searches the grid (accuracy cases), and runs the default filter.
fn run_case(case: &Case, options: &SweepOptions) -> Result<CaseResult, ExperimentError> {
    let start = Instant::now();
    let runs: Vec<SimulatedRun> = case
        .seeds
        .iter()
        .map(|&seed| {
            let mut scenario = case.scenario(seed);
            if let Some(max) = options.max_duration_s {
                scenario.duration_s = scenario.duration_s.min(max);
            }
            let sim = SimulationOptions {
                seed,
                noise_px: case.noise_px,
                rate_hz: case.rate_hz,
                ..SimulationOptions::default()
            };
            simulate(&scenario, &sim)
        })
        .collect::<Result<_, _>>()?;
    let track = |config: TrackerConfig| -> Result<Vec<Option<Scored>>, ExperimentError> {
        runs.iter()
            .map(|run| {
                let start = Instant::now();
                let (estimates, _) =
                    track_all(&run.camera, &run.target, config, &run.measurements)?;
                let seconds = start.elapsed().as_secs_f64();
                if estimates.is_empty() {
                    Ok(None)
                } else {
                    Ok(Some(score(run, estimates, seconds)?))
                }
            })
            .collect()
    };
    let grid = &options.grid;
    let run_at = |at: GridIndex| -> Result<RunSummary, ExperimentError> {
        RunSummary::of(&runs, &track(grid.tuning(at, case.noise_px).config())?)
    };
    let mut visited: Vec<Visited> = Vec::new();
    let mut note = |at: GridIndex, summary: &RunSummary| {
        visited.push(Visited {
            tuning: grid.tuning(at, case.noise_px),
            position_rmse_mm: summary.position_rmse_mm,
            runs_without_estimates: summary.runs_without_estimates,
        });
    };
    let truth_at = grid.truth_index();
    let truth_summary = run_at(truth_at)?;
    note(truth_at, &truth_summary);
    let told_truth = HandTuned {
        tuning: grid.tuning(truth_at, case.noise_px),
        on_edge: grid.on_edge(truth_at),
        summary: truth_summary.clone(),
    };
    let best = if case.purpose == Purpose::Accuracy {
        let mut best = (truth_at, truth_summary);
        for at in grid.coarse().into_iter().filter(|&p| p != truth_at) {
            let summary = run_at(at)?;
            note(at, &summary);
            if objective(&summary) < objective(&best.1) {
                best = (at, summary);
            }
        }
        let mut tried: HashSet<GridIndex> = grid.coarse().into_iter().collect();
        for _ in 0..grid.max_rounds {
            let mut moved = false;
            for at in grid.neighbours(best.0) {
                if !tried.insert(at) {
                    continue;
                }
                let summary = run_at(at)?;
                note(at, &summary);
                if objective(&summary) < objective(&best.1) {
                    best = (at, summary);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        Some(HandTuned {
            tuning: grid.tuning(best.0, case.noise_px),
            on_edge: grid.on_edge(best.0),
            summary: best.1,
        })
    } else {
        None
    };
    let default_scored = track(TrackerConfig::default())?;
    let default = RunSummary::of(&runs, &default_scored)?;
    let nominal_mm = best.as_ref().map(|b| b.summary.position_rmse_mm);
    let beyond_bound = nominal_mm.map(|nominal| {
        let bound_m = BOUND_FACTOR * nominal * 1e-3;
        default_scored
            .iter()
            .flatten()
            .flat_map(|s| s.estimates.iter().zip(&s.errors.position_m))
            .filter(|(e, error)| e.status.is_vouched_for() && error.norm() > bound_m)
            .count()
    });
    Ok(CaseResult {
        case: case.clone(),
        measurements: runs.iter().map(|r| r.measurements.len()).sum(),
        default,
        told_truth,
        best,
        visited,
        nominal_mm,
        beyond_bound,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// `yes` or a bold `no`.
fn mark(holds: bool) -> &'static str {
    if holds { "yes" } else { "**no**" }
}

/// A number in a short form: at most 3 significant digits without trailing zeros, or a power of ten far from 1.
fn short(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if (-3..4).contains(&magnitude) {
        let decimals = (2 - magnitude).max(0) as usize;
        let text = format!("{x:.decimals$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        }
    } else {
        format!("{x:.0e}")
    }
}

impl Sweep {
    /// Every target of every case, checked on the default filter.
    pub fn checks(&self) -> Vec<Check> {
        self.cases
            .iter()
            .flat_map(|r| {
                r.case.goals().into_iter().map(move |goal| Check {
                    case: r.case.name,
                    goal,
                    figure: r.figure(goal),
                    holds: r.holds(goal),
                })
            })
            .collect()
    }

    /// The checks that do not hold, as `case: target` lines.
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{SweepOptions, sweep};
    /// let mut options = SweepOptions::quick();
    /// options.cases.truncate(1);
    /// (options.max_duration_s, options.grid.max_rounds) = (Some(0.3), 0);
    /// let result = sweep(&options, None).unwrap();
    /// assert!(result.failures().iter().all(|line| line.starts_with("4 kHz, 0.1 px: ")));
    /// ```
    pub fn failures(&self) -> Vec<String> {
        self.checks()
            .into_iter()
            .filter(|c| !c.holds)
            .map(|c| {
                format!(
                    "{}: {} ({}; {})",
                    c.case,
                    c.goal.name(),
                    c.goal.description(),
                    c.figure
                )
            })
            .collect()
    }

    /// What was run, in a paragraph.
    pub fn description(&self) -> String {
        let o = &self.options;
        let g = &o.grid;
        let list = |axis: &[f64]| {
            axis.iter()
                .map(|&x| short(x))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let seeds: Vec<u64> = {
            let mut s: Vec<u64> = o.cases.iter().flat_map(|c| c.seeds.clone()).collect();
            s.sort_unstable();
            s.dedup();
            s
        };
        format!(
            "{}Each case simulated at the measurement level (ideal centroids with Gaussian noise, bit-reversed ROI \
             order; seed{} {}{}) and tracked by the default Kalman filter (`TrackerConfig::default()`: 0.1 px \
             assumed, q_a = {} (m/s²)²/Hz, q_α = {} (rad/s²)²/Hz, adapt_noise and adapt_motion on) and by \
             hand-tuned filters (adaptation off, the settings taken as the truth). Hand-tuned grid: noise {} x the \
             true noise, q_a {} and q_α {}; searched by a coarse stage (the true noise, {} of each axis, and the \
             told-the-truth point: the true noise, the default densities) then pattern search on the full grid \
             from the best point (each round the unvisited neighbours one step along each axis, up to {} round{}, \
             until none improves): about {} of the {} points run per case; (edge): the best lies on the grid's \
             boundary along some axis, and a better setting may lie beyond. Nominal error = the best \
             hand-tuned position RMSE. RMSEs over every estimate; NEES over the estimates marked tracking or \
             converging (mean NEES / 3 of position and of velocity, and the share inside the 99 % chi-square bound \
             11.34); lag = the shift of the velocity cross-correlation peak in estimator samples (400 Hz at 4 kHz); \
             noise = the mean noise the default filter worked with (`Estimate::noise_px`) against the truth.",
            if o.quick {
                "Quick mode (a smoke run, not the table of record): a few cases, each cut to at most \
                 0.6 s, on a small grid. "
            } else {
                ""
            },
            if seeds.len() == 1 { "" } else { "s" },
            seeds
                .iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join(", "),
            o.max_duration_s
                .map_or(String::new(), |m| format!(", at most {m} s")),
            short(KalmanTuning::default().linear_accel_psd),
            short(KalmanTuning::default().angular_accel_psd),
            list(&g.noise_factors),
            list(&g.linear_accel_psd),
            list(&g.angular_accel_psd),
            match g.coarse_stride {
                1 => "every density".to_string(),
                2 => "every other density and the last".to_string(),
                n => format!("every {n}th density and the last"),
            },
            g.max_rounds,
            if g.max_rounds == 1 { "" } else { "s" },
            self.mean_visited(),
            g.points(),
        )
    }

    /// The mean number of grid points run per accuracy case, rounded.
    fn mean_visited(&self) -> usize {
        let searched: Vec<usize> = self
            .cases
            .iter()
            .filter(|c| c.best.is_some())
            .map(|c| c.visited.len())
            .collect();
        (searched.iter().sum::<usize>() as f64 / searched.len().max(1) as f64).round() as usize
    }

    /// The cases as a markdown list: scene, camera, target, rate, noise.
    pub fn cases_list(&self) -> String {
        let mut out = String::new();
        for r in &self.cases {
            let c = &r.case;
            let _ = writeln!(
                out,
                "- **{}** ({}): {}, {} camera, {} target, {} kHz, {} px, {} measurements{}",
                c.name,
                match c.purpose {
                    Purpose::Accuracy => "accuracy",
                    Purpose::Calibration => "calibration",
                },
                c.scene.name(),
                c.camera.name(),
                c.target.name(),
                c.rate_hz / 1000.0,
                c.noise_px,
                r.measurements,
                if c.in_calibration_set && c.purpose == Purpose::Accuracy {
                    "; also in the calibration set"
                } else {
                    ""
                }
            );
        }
        out
    }

    /// The accuracy cases as a markdown table.
    pub fn accuracy_table(&self) -> String {
        let mut out = String::from(
            "| case | default mm | best hand-tuned mm | noise px, q_a, q_α | ratio | worst vouched mm | > 10x nominal | \
             disputed / lost / degenerate | NEES/3 pos, vel | inside 99 % pos, vel | lag default, hand-tuned | \
             noise est. / true px | fails |\n\
             |---|---:|---:|---|---:|---:|---:|---:|---|---|---|---|---|\n",
        );
        for r in self.cases.iter().filter(|r| r.best.is_some()) {
            let d = &r.default;
            let Some(best) = &r.best else { continue };
            let t = &best.tuning;
            let lag = |l: Option<i64>| l.map_or("-".to_string(), |l| l.to_string());
            let fails: Vec<&str> = r
                .case
                .goals()
                .into_iter()
                .filter(|&g| !r.holds(g))
                .map(|g| g.name())
                .collect();
            let _ = writeln!(
                out,
                "| {} | {:.4} | {:.4} | {}, {}, {}{} | {:.2} | {:.3} | {} | {} / {} / {} | {:.2}, {:.2} | {:.1} %, {:.1} % \
                 | {}, {} | {:.3} / {} | {} |",
                r.case.name,
                d.position_rmse_mm,
                best.summary.position_rmse_mm,
                short(t.noise_px),
                short(t.linear_accel_psd),
                short(t.angular_accel_psd),
                if best.on_edge { " (edge)" } else { "" },
                r.rmse_ratio(),
                d.max_vouched_error_mm,
                r.beyond_bound.unwrap_or(0),
                d.disputed,
                d.lost,
                d.degenerate,
                d.consistency.position_nees_per_dof,
                d.consistency.velocity_nees_per_dof,
                100.0 * d.consistency.position_inside_99,
                100.0 * d.consistency.velocity_inside_99,
                lag(d.velocity_lag_samples),
                lag(best.summary.velocity_lag_samples),
                d.mean_noise_px,
                r.case.noise_px,
                if d.runs_without_estimates > 0 {
                    format!("all (no estimate on {} seed(s))", d.runs_without_estimates)
                } else if fails.is_empty() {
                    "none".to_string()
                } else {
                    fails.join(", ")
                }
            );
        }
        out
    }

    /// The calibration set as a markdown table: the default filter's and the told-the-truth filter's NEES.
    pub fn calibration_table(&self) -> String {
        let mut out = String::from(
            "| scene | noise px | default NEES/3 pos, vel | inside 99 % pos, vel | disputed / lost | calibrated | \
             told-the-truth NEES/3 pos, vel | inside 99 % pos, vel |\n\
             |---|---:|---|---|---:|---|---|---|\n",
        );
        let mut rows: Vec<&CaseResult> = self
            .cases
            .iter()
            .filter(|r| r.case.in_calibration_set)
            .collect();
        let scene_order = |r: &CaseResult| match r.case.scene {
            Scene::Spec(kind) => ScenarioKind::ALL
                .iter()
                .position(|k| *k == kind)
                .unwrap_or(usize::MAX),
            _ => usize::MAX,
        };
        rows.sort_by(|a, b| {
            scene_order(a)
                .cmp(&scene_order(b))
                .then(a.case.noise_px.total_cmp(&b.case.noise_px))
        });
        for r in rows {
            let (d, t) = (&r.default.consistency, &r.told_truth.summary.consistency);
            let _ = writeln!(
                out,
                "| {} | {} | {:.2}, {:.2} | {:.1} %, {:.1} % | {} / {} | {} | {:.2}, {:.2} | {:.1} %, {:.1} % |",
                r.case.scene.name(),
                r.case.noise_px,
                d.position_nees_per_dof,
                d.velocity_nees_per_dof,
                100.0 * d.position_inside_99,
                100.0 * d.velocity_inside_99,
                r.default.disputed,
                r.default.lost,
                mark(d.is_calibrated()),
                t.position_nees_per_dof,
                t.velocity_nees_per_dof,
                100.0 * t.position_inside_99,
                100.0 * t.velocity_inside_99,
            );
        }
        out
    }

    /// Each target: on how many cases it is checked and holds, and where it fails, as a markdown table.
    pub fn goals_table(&self) -> String {
        let checks = self.checks();
        let mut out = String::from(
            "| target | what | checked | holds | fails on |\n|---|---|---:|---:|---|\n",
        );
        for goal in Goal::ALL {
            let of: Vec<&Check> = checks.iter().filter(|c| c.goal == goal).collect();
            let failing: Vec<&str> = of.iter().filter(|c| !c.holds).map(|c| c.case).collect();
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} |",
                goal.name(),
                goal.description(),
                of.len(),
                of.len() - failing.len(),
                if failing.is_empty() {
                    "-".to_string()
                } else {
                    failing.join("; ")
                }
            );
        }
        out
    }

    /// The description, the cases, the accuracy table, the calibration table and the targets, in markdown.
    pub fn markdown(&self) -> String {
        let checks = self.checks();
        let failing = checks.iter().filter(|c| !c.holds).count();
        format!(
            "{}\n\nCases:\n\n{}\nAccuracy cases (default filter against the best hand-tuned one):\n\n{}\n\
             Calibration set (every built-in scenario at 4 kHz):\n\n{}\nTargets:\n\n{}\n{}\n",
            self.description(),
            self.cases_list(),
            self.accuracy_table(),
            self.calibration_table(),
            self.goals_table(),
            if failing == 0 {
                format!("All {} checks hold.", checks.len())
            } else {
                format!("{failing} of {} checks do not hold.", checks.len())
            }
        )
    }

    /// Everything as one JSON object: `description`, `options`, `cases` (with every grid point visited), `checks`,
    /// `failures`, `holds` and `seconds`.
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{SweepOptions, sweep};
    /// let mut options = SweepOptions::quick();
    /// options.cases.truncate(1);
    /// (options.max_duration_s, options.grid.max_rounds) = (Some(0.3), 0);
    /// let json: serde_json::Value = serde_json::from_str(&sweep(&options, None).unwrap().json()).unwrap();
    /// assert_eq!(json["cases"][0]["case"]["name"], "4 kHz, 0.1 px");
    /// assert!(json["cases"][0]["default"]["position_rmse_mm"].as_f64().unwrap() > 0.0);
    /// ```
    pub fn json(&self) -> String {
        let failures = self.failures();
        serde_json::json!({
            "description": self.description(),
            "options": self.options,
            "cases": self.cases,
            "checks": self.checks(),
            "holds": failures.is_empty(),
            "failures": failures,
            "seconds": self.seconds,
        })
        .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_coarse_stage_and_the_neighbours_stay_on_the_grid() {
        let grid = Grid::full();
        let coarse = grid.coarse();
        assert_eq!(coarse.len(), 26);
        assert_eq!(coarse[0], grid.truth_index());
        let t = grid.tuning(grid.truth_index(), 0.3);
        assert_eq!(
            (t.noise_px, t.linear_accel_psd, t.angular_accel_psd),
            (0.3, 1.0, 10.0)
        );
        assert_eq!(grid.neighbours([0, 0, 0]).len(), 3);
        assert_eq!(grid.neighbours([2, 3, 3]).len(), 6);
        assert!(
            grid.neighbours([4, 7, 8])
                .iter()
                .all(|p| p[0] < 5 && p[1] < 8 && p[2] < 9)
        );
        assert!(grid.on_edge([4, 3, 3]) && grid.on_edge([2, 0, 3]) && !grid.on_edge([2, 3, 3]));
        assert_eq!(Grid::quick().coarse().len(), 5);
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short(0.001), "0.001");
        assert_eq!(short(1e-4), "1e-4");
        assert_eq!(short(10.0), "10");
        assert_eq!(short(1000.0), "1000");
        assert_eq!(short(1e4), "1e4");
        assert_eq!(short(0.14), "0.14");
        assert_eq!(short(0.0333333), "0.0333");
    }
}
