//! The cases of the study ([`cases`]): each a scene, a camera, a target, a rate and a noise, and what it is for.

use roitrack_sim::{Scenario, ScenarioKind};
use serde::Serialize;

use super::goal::Goal;
use super::scene::{CameraChoice, Scene, TargetChoice};

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

    /// The targets this case is checked against (see the [module docs](super)).
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
///
/// [`wide_angle_1280x1024`]: super::wide_angle_1280x1024
/// [`non_planar_11`]: super::non_planar_11
/// [`grid2x3`]: super::grid2x3
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
