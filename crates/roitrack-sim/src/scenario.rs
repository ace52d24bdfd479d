//! Scenario trajectories: the true pose and twist of the target at any time.
//!
//! Each scenario gives, at time `t`, a [`MotionState`] whose pose is the true pose at `t` and whose twist is the true
//! instantaneous twist at `t` (V = d t/dt, and W with dR/dt = \[W\]× R, both in the camera frame; docs/model.md).

use std::f64::consts::PI;

use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target, so3};

use crate::{RoiRenderer, SensorError, SensorModel, SimulatedCamera};

/// The scenarios the simulator offers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScenarioKind {
    /// The bench pose of the built-in scene (docs/model.md), at rest, 1 s.
    Static,
    /// The paper's Orthoglide experiment (docs/model.md; translations in the image plane, peak 1 m/s, 4.914 s).
    Orthoglide,
    /// Fast rotation: 3 rev/s about an axis tilted 20 deg from the optical axis while translating slowly, 3 s.
    Spin,
    /// Smooth random 6-dof motion (sums of sinusoids), peak 1.5 m/s and 4 rad/s, depth 0.45-0.8 m, 4 s.
    Random,
    /// A part swept in front of a video camera: smooth random 6-dof motion, peak 0.5 m/s and 1.5 rad/s at 0.5-1.2 Hz
    /// (accelerations of a few m/s², which a frame camera at 30 Hz can follow), depth 0.45-0.8 m, 6 s.
    Sweep,
}

impl ScenarioKind {
    /// Every scenario, in the order they are listed to the user.
    pub const ALL: [ScenarioKind; 5] = [
        Self::Static,
        Self::Orthoglide,
        Self::Spin,
        Self::Random,
        Self::Sweep,
    ];

    /// The scenario's name on the command line and in file names.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Static => "static",
            Self::Orthoglide => "orthoglide",
            Self::Spin => "spin",
            Self::Random => "random",
            Self::Sweep => "sweep",
        }
    }

    /// The scenario of that [`Self::name`], if there is one.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// The quintic time scaling s(u) = 10u³ - 15u⁴ + 6u⁵ and its derivative ds/du, for u clamped to [0, 1].
fn quintic(u: f64) -> (f64, f64) {
    let u = u.clamp(0.0, 1.0);
    let u2 = u * u;
    (
        u2 * u * (10.0 - 15.0 * u + 6.0 * u2),
        30.0 * u2 * (1.0 - 2.0 * u + u2),
    )
}

/// Sum of sinusoids per axis: value and time derivative.
#[derive(Debug, Clone)]
struct SinusoidSum {
    /// (amplitude, angular frequency rad/s, phase rad) per axis.
    terms: [Vec<(f64, f64, f64)>; 3],
}

impl SinusoidSum {
    fn random(
        rng: &mut ChaCha8Rng,
        per_axis: usize,
        freq_hz: (f64, f64),
        amplitude: [f64; 3],
    ) -> Self {
        let terms = std::array::from_fn(|axis| {
            (0..per_axis)
                .map(|_| {
                    (
                        amplitude[axis] * rng.random_range(0.3..1.0),
                        2.0 * PI * rng.random_range(freq_hz.0..freq_hz.1),
                        rng.random_range(0.0..2.0 * PI),
                    )
                })
                .collect()
        });
        Self { terms }
    }

    fn eval(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let mut value = Vector3::zeros();
        let mut rate = Vector3::zeros();
        for (axis, terms) in self.terms.iter().enumerate() {
            for &(a, w, phase) in terms {
                let (s, c) = (w * t + phase).sin_cos();
                value[axis] += a * s;
                rate[axis] += a * w * c;
            }
        }
        (value, rate)
    }

    fn scale(&mut self, factor: f64) {
        for terms in &mut self.terms {
            for term in terms.iter_mut() {
                term.0 *= factor;
            }
        }
    }
}

#[derive(Debug, Clone)]
enum Motion {
    /// At rest at this state (its twist zero).
    Static(MotionState),
    Orthoglide,
    Spin,
    Random {
        position: SinusoidSum,
        rotation: SinusoidSum,
        centre_m: Vector3<f64>,
    },
}

/// A scenario: a camera, a target (the canonical ones unless replaced), and the true motion of the target's origin
/// over `[0, duration_s]`.
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_sim::{Scenario, ScenarioKind};
///
/// // The orthoglide motion seen through a distorting wide-angle lens.
/// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1).with_camera(CameraModel::wide_angle_example());
/// assert!(scenario.min_image_margin_px() > 0.0);
/// assert_eq!(scenario.target, Target::grid4x4());
/// ```
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Which motion this is.
    pub kind: ScenarioKind,
    /// The camera that sees it.
    pub camera: CameraModel,
    /// The target that moves.
    pub target: Target,
    /// Length of the motion (s), from time 0.
    pub duration_s: f64,
    motion: Motion,
    /// The motion played this many times faster ([`Self::with_speed_scale`]).
    time_scale: f64,
    /// The motion shifted by this in the camera frame ([`Self::with_distance_m`]).
    offset_m: Vector3<f64>,
}

// Orthoglide phases (docs/model.md).
const HOME_M: [f64; 3] = [0.0, 0.0, 0.60];
const LINE_M: f64 = 0.080;
const RADIUS_M: f64 = 0.060;
const LINE_DURATION_S: f64 = 0.5;
fn circle_duration_s() -> f64 {
    1.875 * 4.0 * PI * RADIUS_M
}
/// Start times of the seven phases and the end.
fn orthoglide_breaks_s() -> [f64; 8] {
    let durations = [
        0.25,
        LINE_DURATION_S,
        1.0,
        circle_duration_s(),
        0.25,
        LINE_DURATION_S,
        1.0,
    ];
    let mut breaks = [0.0; 8];
    for (i, d) in durations.iter().enumerate() {
        breaks[i + 1] = breaks[i] + d;
    }
    breaks
}

const SPIN_RATE_REV_S: f64 = 3.0;
const SPIN_AXIS_TILT_DEG: f64 = 20.0;

/// The parameters of a smooth random motion.
struct RandomMotion {
    peak_speed_mps: f64,
    peak_angular_radps: f64,
    duration_s: f64,
    /// Frequency ranges (Hz) of the translation's and the rotation's sinusoids.
    position_hz: (f64, f64),
    rotation_hz: (f64, f64),
    /// Salt of the seed, so that two kinds with one seed do not share their draws.
    salt: u64,
}

const RANDOM: RandomMotion = RandomMotion {
    peak_speed_mps: 1.5,
    peak_angular_radps: 4.0,
    duration_s: 4.0,
    position_hz: (0.4, 2.5),
    rotation_hz: (0.3, 1.5),
    salt: 0x5eed_0f7a_4d0e,
};

const SWEEP: RandomMotion = RandomMotion {
    peak_speed_mps: 0.5,
    peak_angular_radps: 1.5,
    duration_s: 6.0,
    position_hz: (0.5, 1.2),
    rotation_hz: (0.3, 1.0),
    salt: 0x5eed_5eed_0f7a,
};

impl Scenario {
    /// The scenario of this kind. `seed` only matters for [`ScenarioKind::Random`].
    pub fn new(kind: ScenarioKind, seed: u64) -> Self {
        let (duration_s, motion) = match kind {
            ScenarioKind::Static => (1.0, Motion::Static(MotionState::bench())),
            ScenarioKind::Orthoglide => (orthoglide_breaks_s()[7], Motion::Orthoglide),
            ScenarioKind::Spin => (3.0, Motion::Spin),
            ScenarioKind::Random => (RANDOM.duration_s, random_motion(seed, &RANDOM)),
            ScenarioKind::Sweep => (SWEEP.duration_s, random_motion(seed, &SWEEP)),
        };
        Self {
            kind,
            camera: CameraModel::canonical(),
            target: Target::grid4x4(),
            duration_s,
            motion,
            time_scale: 1.0,
            offset_m: Vector3::zeros(),
        }
    }

    /// A target at rest at the pose (`cam_r_obj`, `cam_t_obj_m`) for `duration_s` seconds: a [`ScenarioKind::Static`]
    /// scenario at any pose (the canonical static scenario is the bench pose 0.6 m away, 1 s), with the canonical
    /// camera and target unless replaced.
    ///
    /// # Panics
    ///
    /// If `duration_s` is not finite and positive or the translation is not finite.
    ///
    /// ```
    /// use nalgebra::Vector3;
    /// use roitrack_core::MotionState;
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// // The grid 1.6 m away, at rest for 2 s.
    /// let far = Scenario::still(MotionState::bench_rotation(), Vector3::new(0.02, -0.01, 1.6), 2.0);
    /// assert_eq!((far.kind, far.duration_s), (ScenarioKind::Static, 2.0));
    /// assert_eq!(far.state_at(1.3).cam_t_obj_m.z, 1.6);
    /// assert_eq!(far.state_at(1.3).velocity_mps, Vector3::zeros());
    /// assert!(far.min_image_margin_px() > 0.0);
    /// ```
    pub fn still(cam_r_obj: Rotation3<f64>, cam_t_obj_m: Vector3<f64>, duration_s: f64) -> Self {
        assert!(
            duration_s.is_finite() && duration_s > 0.0,
            "Scenario::still: duration_s must be finite and positive, got {duration_s}"
        );
        assert!(
            cam_t_obj_m.iter().all(|x| x.is_finite()),
            "Scenario::still: the translation must be finite, got {cam_t_obj_m:?}"
        );
        Self {
            kind: ScenarioKind::Static,
            camera: CameraModel::canonical(),
            target: Target::grid4x4(),
            duration_s,
            motion: Motion::Static(MotionState::at_rest(cam_r_obj, cam_t_obj_m)),
            time_scale: 1.0,
            offset_m: Vector3::zeros(),
        }
    }

    /// Smooth random 6-dof motion as [`ScenarioKind::Random`] (the same draws for a seed), scaled to the peak speed
    /// `peak_speed_mps` and peak angular rate `peak_angular_radps` over `duration_s` seconds. Faster than the
    /// canonical random motion (1.5 m/s, 4 rad/s), the frequencies of the sinusoids are raised in proportion, so that
    /// the excursions stay those of the canonical scene (depth 0.45-0.8 m, every blob of the canonical target at least
    /// 20 px inside the canonical image, the target facing the camera within 60 deg) and the accelerations grow with
    /// the square of the speed; slower, only the amplitudes shrink. `random_with(seed, 1.5, 4.0, 4.0)` is
    /// `Scenario::new(ScenarioKind::Random, seed)`.
    ///
    /// # Panics
    ///
    /// If a peak or the duration is not finite and positive.
    ///
    /// ```
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// // Fast: 2.5 m/s and 7 rad/s at their peaks, 4 s.
    /// let fast = Scenario::random_with(1, 2.5, 7.0, 4.0);
    /// assert_eq!((fast.kind, fast.duration_s), (ScenarioKind::Random, 4.0));
    /// let peak_speed = (0..=4000)
    ///     .map(|k| fast.state_at(k as f64 / 1000.0).velocity_mps.norm())
    ///     .fold(0.0, f64::max);
    /// assert!((peak_speed - 2.5).abs() < 0.05, "{peak_speed}");
    /// assert!(fast.min_image_margin_px() > 0.0);
    /// ```
    pub fn random_with(
        seed: u64,
        peak_speed_mps: f64,
        peak_angular_radps: f64,
        duration_s: f64,
    ) -> Self {
        for (name, value) in [
            ("peak_speed_mps", peak_speed_mps),
            ("peak_angular_radps", peak_angular_radps),
            ("duration_s", duration_s),
        ] {
            assert!(
                value.is_finite() && value > 0.0,
                "Scenario::random_with: {name} must be finite and positive, got {value}"
            );
        }
        let faster = |peak: f64, canonical: f64| (peak / canonical).max(1.0);
        let (fp, fr) = (
            faster(peak_speed_mps, RANDOM.peak_speed_mps),
            faster(peak_angular_radps, RANDOM.peak_angular_radps),
        );
        let spec = RandomMotion {
            peak_speed_mps,
            peak_angular_radps,
            duration_s,
            position_hz: (RANDOM.position_hz.0 * fp, RANDOM.position_hz.1 * fp),
            rotation_hz: (RANDOM.rotation_hz.0 * fr, RANDOM.rotation_hz.1 * fr),
            salt: RANDOM.salt,
        };
        Self {
            kind: ScenarioKind::Random,
            camera: CameraModel::canonical(),
            target: Target::grid4x4(),
            duration_s,
            motion: random_motion(seed, &spec),
            time_scale: 1.0,
            offset_m: Vector3::zeros(),
        }
    }

    /// The same motion seen by another camera. The motions are those of the canonical scene (the target about 0.6 m in
    /// front of the camera): check [`Self::min_image_margin_px`] that the blobs stay in the new camera's image.
    pub fn with_camera(self, camera: CameraModel) -> Self {
        Self { camera, ..self }
    }

    /// The same motion carrying another target (its origin follows the motion).
    pub fn with_target(self, target: Target) -> Self {
        Self { target, ..self }
    }

    /// The same path played `factor` times faster (velocities and angular velocities times `factor`, the duration
    /// divided by it): a slower or faster rig with the same excursions.
    ///
    /// # Panics
    ///
    /// If `factor` is not finite and positive.
    ///
    /// ```
    /// use roitrack_sim::{Scenario, ScenarioKind};
    /// let spin = Scenario::new(ScenarioKind::Spin, 1);
    /// let slow = spin.clone().with_speed_scale(0.5);
    /// assert_eq!(slow.duration_s, 2.0 * spin.duration_s);
    /// let (a, b) = (spin.state_at(0.7), slow.state_at(1.4));
    /// assert!((a.cam_t_obj_m - b.cam_t_obj_m).norm() < 1e-12);
    /// assert!((0.5 * a.angular_velocity_radps - b.angular_velocity_radps).norm() < 1e-12);
    /// ```
    pub fn with_speed_scale(self, factor: f64) -> Self {
        assert!(
            factor.is_finite() && factor > 0.0,
            "Scenario::with_speed_scale: the factor must be finite and positive, got {factor}"
        );
        Self {
            time_scale: self.time_scale * factor,
            duration_s: self.duration_s / factor,
            ..self
        }
    }

    /// The same motion moved along the optical axis so that the target's origin is on average `distance_m` from the
    /// camera (the canonical motions are about 0.6 m away): for a rig whose target is nearer or farther. Check
    /// [`Self::min_image_margin_px`] that the target stays in the image.
    ///
    /// # Panics
    ///
    /// If `distance_m` is not finite and positive.
    ///
    /// ```
    /// use roitrack_sim::{Scenario, ScenarioKind};
    /// let far = Scenario::new(ScenarioKind::Orthoglide, 1).with_distance_m(1.5);
    /// let mean_z = (0..=100).map(|k| far.state_at(far.duration_s * k as f64 / 100.0).cam_t_obj_m.z).sum::<f64>() / 101.0;
    /// assert!((mean_z - 1.5).abs() < 1e-3, "{mean_z}");
    /// ```
    pub fn with_distance_m(self, distance_m: f64) -> Self {
        assert!(
            distance_m.is_finite() && distance_m > 0.0,
            "Scenario::with_distance_m: the distance must be finite and positive, got {distance_m}"
        );
        let samples = 101;
        let mean_z = (0..samples)
            .map(|k| {
                let t = self.duration_s * k as f64 / (samples - 1) as f64;
                self.state_at(t).cam_t_obj_m.z - self.offset_m.z
            })
            .sum::<f64>()
            / samples as f64;
        Self {
            offset_m: Vector3::new(self.offset_m.x, self.offset_m.y, distance_m - mean_z),
            ..self
        }
    }

    /// The motion over `duration_s` seconds instead of its own duration: shorter, it stops early; longer, the
    /// periodic and random motions go on and the orthoglide's rests at its end.
    ///
    /// # Panics
    ///
    /// If `duration_s` is not finite and positive.
    pub fn with_duration_s(self, duration_s: f64) -> Self {
        assert!(
            duration_s.is_finite() && duration_s > 0.0,
            "Scenario::with_duration_s: the duration must be finite and positive, got {duration_s}"
        );
        Self { duration_s, ..self }
    }

    /// A renderer of the scenario's camera and target with the default sensor ([`SensorModel::default`]): what its
    /// simulated ROI camera ([`Self::simulated_camera`]) draws. Refuses a camera whose time model is invalid.
    pub fn roi_renderer(&self) -> Result<RoiRenderer, SensorError> {
        RoiRenderer::new(
            self.camera.clone(),
            self.target.clone(),
            SensorModel::default(),
        )
    }

    /// The scenario's simulated ROI camera: the target rendered by [`Self::roi_renderer`] at the scenario's true
    /// motion, at the time of each ROI's exposure, its noise drawn from `seed`.
    ///
    /// ```
    /// use roitrack_image::{Frame, RoiCamera};
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// let mut camera = Scenario::new(ScenarioKind::Orthoglide, 1).simulated_camera(7).unwrap();
    /// let mut frame = Frame::default();
    /// camera.grab_full_frame(0.3, &mut frame).unwrap();
    /// assert_eq!((frame.width, frame.height), (1024, 1024));
    /// ```
    pub fn simulated_camera(
        &self,
        seed: u64,
    ) -> Result<SimulatedCamera<impl Fn(f64) -> MotionState + Send + 'static>, SensorError> {
        let scenario = self.clone();
        Ok(SimulatedCamera::new(
            self.roi_renderer()?,
            move |t_s| scenario.state_at(t_s),
            seed,
        ))
    }

    /// True pose and instantaneous twist at time `t_s`.
    pub fn state_at(&self, t_s: f64) -> MotionState {
        let t = t_s * self.time_scale;
        let mut state = match &self.motion {
            Motion::Static(state) => *state,
            Motion::Orthoglide => orthoglide_state(t),
            Motion::Spin => spin_state(t),
            Motion::Random {
                position,
                rotation,
                centre_m,
            } => random_state(t, position, rotation, centre_m),
        };
        state.cam_t_obj_m += self.offset_m;
        state.velocity_mps *= self.time_scale;
        state.angular_velocity_radps *= self.time_scale;
        state
    }

    /// The instant (s, to the millisecond) at which the target moves fastest, among those followed by at least
    /// `after_s` of the scenario: where a track started is hardest to start.
    ///
    /// ```
    /// use roitrack_sim::Scenario;
    ///
    /// let fast = Scenario::random_with(1, 1.5, 5.0, 4.0);
    /// let t_s = fast.fastest_instant_s(1.0);
    /// assert!(t_s <= 3.0);
    /// assert!(fast.state_at(t_s).velocity_mps.norm() > 1.45);
    /// ```
    pub fn fastest_instant_s(&self, after_s: f64) -> f64 {
        let speed = |t_s: f64| self.state_at(t_s).velocity_mps.norm();
        (0..)
            .map(|k| f64::from(k) * 1e-3)
            .take_while(|t_s| *t_s <= self.duration_s - after_s)
            .max_by(|a, b| speed(*a).total_cmp(&speed(*b)))
            .unwrap_or(0.0)
    }

    /// The smallest margin (px) between any blob centre and the image border over the whole scenario, sampled at
    /// 1 kHz; negative if a blob leaves the image or goes behind the camera.
    pub fn min_image_margin_px(&self) -> f64 {
        min_image_margin_px(&self.camera, &self.target, self.duration_s, |t| {
            self.state_at(t)
        })
    }
}

fn min_image_margin_px(
    camera: &CameraModel,
    target: &Target,
    duration_s: f64,
    state_at: impl Fn(f64) -> MotionState,
) -> f64 {
    let steps = (duration_s * 1000.0).ceil() as usize;
    let (w, h) = (camera.width_px as f64, camera.height_px as f64);
    let mut margin = f64::INFINITY;
    for k in 0..=steps {
        let state = state_at((k as f64 / 1000.0).min(duration_s));
        for p in target.points() {
            match camera.raw_pixel_from_cam(&state.point_in_cam_at(&p.point_in_obj_m, 0.0)) {
                Some(px) => {
                    margin = margin
                        .min(px.x)
                        .min(px.y)
                        .min(w - 1.0 - px.x)
                        .min(h - 1.0 - px.y)
                }
                None => return f64::NEG_INFINITY,
            }
        }
    }
    margin
}

fn orthoglide_state(t_s: f64) -> MotionState {
    let b = orthoglide_breaks_s();
    let home = Vector3::from(HOME_M);
    let side = home + Vector3::new(LINE_M, 0.0, 0.0);
    let line = |from: Vector3<f64>, to: Vector3<f64>, t0: f64| {
        let (s, ds) = quintic((t_s - t0) / LINE_DURATION_S);
        (from + (to - from) * s, (to - from) * (ds / LINE_DURATION_S))
    };
    let (position, velocity) = if t_s < b[1] {
        (home, Vector3::zeros())
    } else if t_s < b[2] {
        line(home, side, b[1])
    } else if t_s < b[3] {
        (side, Vector3::zeros())
    } else if t_s < b[4] {
        let duration = circle_duration_s();
        let (s, ds) = quintic((t_s - b[3]) / duration);
        let total_angle = 4.0 * PI;
        let phi = total_angle * s;
        let phi_rate = total_angle * ds / duration;
        let centre = side - Vector3::new(RADIUS_M, 0.0, 0.0);
        let (sin, cos) = phi.sin_cos();
        // Starts at `side` and first moves towards -y: counter-clockwise as displayed (y down).
        (
            centre + Vector3::new(RADIUS_M * cos, -RADIUS_M * sin, 0.0),
            Vector3::new(-RADIUS_M * sin, -RADIUS_M * cos, 0.0) * phi_rate,
        )
    } else if t_s < b[5] {
        (side, Vector3::zeros())
    } else if t_s < b[6] {
        line(side, home, b[5])
    } else {
        (home, Vector3::zeros())
    };
    MotionState {
        cam_r_obj: MotionState::bench_rotation(),
        cam_t_obj_m: position,
        velocity_mps: velocity,
        angular_velocity_radps: Vector3::zeros(),
    }
}

fn spin_state(t_s: f64) -> MotionState {
    let axis = Rotation3::from_axis_angle(&Vector3::x_axis(), SPIN_AXIS_TILT_DEG.to_radians())
        * Vector3::z();
    let w = axis * (2.0 * PI * SPIN_RATE_REV_S);
    // Slow translation: a few centimetres at well under 1 Hz.
    let (a, f) = (
        Vector3::new(0.03, 0.02, 0.05),
        Vector3::new(0.5, 0.7, 0.3) * (2.0 * PI),
    );
    let position =
        MotionState::bench().cam_t_obj_m + a.component_mul(&f.map(|x| x * t_s).map(f64::sin));
    let velocity = a
        .component_mul(&f)
        .component_mul(&f.map(|x| x * t_s).map(f64::cos));
    MotionState {
        cam_r_obj: so3::exp(&(w * t_s)) * MotionState::bench_rotation(),
        cam_t_obj_m: position,
        velocity_mps: velocity,
        angular_velocity_radps: w,
    }
}

fn random_state(
    t_s: f64,
    position: &SinusoidSum,
    rotation: &SinusoidSum,
    centre_m: &Vector3<f64>,
) -> MotionState {
    let (p, v) = position.eval(t_s);
    let (phi, phi_rate) = rotation.eval(t_s);
    // R(t) = Exp(φ(t)) R0, so dR/dt = [J_l(φ) φ']× R.
    MotionState {
        cam_r_obj: so3::exp(&phi) * MotionState::bench_rotation(),
        cam_t_obj_m: centre_m + p,
        velocity_mps: v,
        angular_velocity_radps: so3::left_jacobian(&phi) * phi_rate,
    }
}

/// Draws random smooth motions until one keeps every blob inside the image with a margin, the depth in
/// [0.45, 0.8] m and the target facing the camera, scaled to the peak speeds.
fn random_motion(seed: u64, spec: &RandomMotion) -> Motion {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ spec.salt);
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    let centre_m = Vector3::new(0.0, 0.0, 0.625);
    let duration_s = spec.duration_s;
    loop {
        let mut position = SinusoidSum::random(&mut rng, 3, spec.position_hz, [0.06, 0.06, 0.06]);
        let mut rotation = SinusoidSum::random(&mut rng, 3, spec.rotation_hz, [0.3, 0.3, 0.3]);
        let peak = |f: &dyn Fn(f64) -> f64| {
            (0..=(duration_s * 500.0) as usize)
                .map(|k| f(k as f64 / 500.0))
                .fold(0.0, f64::max)
        };
        let speed = peak(&|t| position.eval(t).1.norm());
        position.scale(spec.peak_speed_mps / speed);
        for _ in 0..3 {
            let angular = peak(&|t| {
                random_state(t, &position, &rotation, &centre_m)
                    .angular_velocity_radps
                    .norm()
            });
            rotation.scale(spec.peak_angular_radps / angular);
        }
        let state_at = |t| random_state(t, &position, &rotation, &centre_m);
        let steps = (duration_s * 500.0) as usize;
        let acceptable = (0..=steps).all(|k| {
            let s = state_at(k as f64 / 500.0);
            let facing = (s.cam_r_obj * Vector3::z()).z.abs() > 60f64.to_radians().cos();
            (0.45..=0.8).contains(&s.cam_t_obj_m.z) && facing
        }) && min_image_margin_px(&camera, &target, duration_s, state_at) > 20.0;
        if acceptable {
            return Motion::Random {
                position,
                rotation,
                centre_m,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of the pose reproduce the scenario's twist (pins the convention: V = dt/dt, dR/dt = [W]× R),
    /// from mid-run to anywhere within it.
    fn assert_twist_is_pose_derivative(s: &Scenario) {
        let mid_s = 0.5 * s.duration_s;
        roitrack_testkit::check_jacobian(
            &format!("{:?}: twist", s.kind),
            mid_s,
            |rng, spread| {
                mid_s
                    + spread
                        * roitrack_testkit::rand::Rng::random_range(rng, -0.49..0.49)
                        * s.duration_s
            },
            &nalgebra::Vector1::new(1.0),
            |&t, dt| {
                let (at, moved) = (s.state_at(t), s.state_at(t + dt[0]));
                let rotation = so3::log(&(moved.cam_r_obj * at.cam_r_obj.inverse()));
                nalgebra::Vector6::new(
                    moved.cam_t_obj_m.x,
                    moved.cam_t_obj_m.y,
                    moved.cam_t_obj_m.z,
                    rotation.x,
                    rotation.y,
                    rotation.z,
                )
            },
            |&t| {
                let state = s.state_at(t);
                let (v, w) = (state.velocity_mps, state.angular_velocity_radps);
                nalgebra::Matrix6x1::new(v.x, v.y, v.z, w.x, w.y, w.z)
            },
        );
    }

    #[test]
    fn every_scenario_twist_is_the_derivative_of_its_pose() {
        for kind in ScenarioKind::ALL {
            assert_twist_is_pose_derivative(&Scenario::new(kind, 1));
        }
        assert_twist_is_pose_derivative(&Scenario::new(ScenarioKind::Random, 7));
    }

    #[test]
    fn every_blob_stays_inside_the_image() {
        for kind in ScenarioKind::ALL {
            let s = Scenario::new(kind, 1);
            assert!(
                s.min_image_margin_px() > 10.0,
                "{kind:?}: margin {}",
                s.min_image_margin_px()
            );
        }
    }

    #[test]
    fn orthoglide_matches_the_spec() {
        let s = Scenario::new(ScenarioKind::Orthoglide, 0);
        assert!((s.duration_s - 4.91372).abs() < 1e-5);
        let b = orthoglide_breaks_s();
        let home = Vector3::new(0.0, 0.0, 0.6);
        let side = Vector3::new(0.08, 0.0, 0.6);
        assert!((s.state_at(0.1).cam_t_obj_m - home).norm() < 1e-15);
        assert!((s.state_at(b[2]).cam_t_obj_m - side).norm() < 1e-12);
        // The circle starts at `side` moving towards -y, peaks at 1.0 m/s, passes the far side at (-0.04, 0).
        let early = s.state_at(b[3] + 0.05);
        assert!(
            early.velocity_mps.y < 0.0 && early.velocity_mps.x.abs() < early.velocity_mps.y.abs()
        );
        let peak = (0..10_000)
            .map(|k| {
                s.state_at(b[3] + circle_duration_s() * k as f64 / 10_000.0)
                    .velocity_mps
                    .norm()
            })
            .fold(0.0, f64::max);
        assert!((peak - 1.0).abs() < 1e-6, "peak speed {peak}");
        let half = s.state_at(b[3] + circle_duration_s() / 2.0);
        assert!(
            (half.cam_t_obj_m - side).norm() < 1e-12,
            "two laps: back at the start halfway"
        );
        assert!((s.state_at(s.duration_s).cam_t_obj_m - home).norm() < 1e-15);
        assert_eq!(s.state_at(1.0).cam_r_obj, MotionState::bench_rotation());
    }

    #[test]
    fn random_scenario_meets_its_envelope_and_depends_on_the_seed() {
        for seed in [1, 2, 3] {
            let s = Scenario::new(ScenarioKind::Random, seed);
            let (mut speed, mut angular): (f64, f64) = (0.0, 0.0);
            for k in 0..=4000 {
                let st = s.state_at(k as f64 / 1000.0);
                speed = speed.max(st.velocity_mps.norm());
                angular = angular.max(st.angular_velocity_radps.norm());
                assert!((0.45..=0.8).contains(&st.cam_t_obj_m.z));
            }
            assert!(
                (speed - 1.5).abs() < 0.01,
                "seed {seed}: peak speed {speed}"
            );
            assert!(
                (angular - 4.0).abs() < 0.1,
                "seed {seed}: peak angular rate {angular}"
            );
        }
        let a = Scenario::new(ScenarioKind::Random, 1).state_at(1.0);
        let b = Scenario::new(ScenarioKind::Random, 2).state_at(1.0);
        assert_ne!(a.cam_t_obj_m, b.cam_t_obj_m);
    }

    /// Peak speed and angular rate of a scenario, sampled at 1 kHz.
    fn peaks(s: &Scenario) -> (f64, f64) {
        let (mut speed, mut angular): (f64, f64) = (0.0, 0.0);
        for k in 0..=(s.duration_s * 1000.0) as usize {
            let st = s.state_at(k as f64 / 1000.0);
            speed = speed.max(st.velocity_mps.norm());
            angular = angular.max(st.angular_velocity_radps.norm());
        }
        (speed, angular)
    }

    #[test]
    fn random_with_reaches_its_peaks_and_keeps_the_blobs_in_the_image() {
        for (seed, speed, angular, duration) in [
            (1, 2.5, 7.0, 4.0),
            (2, 2.5, 7.0, 4.0),
            (3, 0.5, 1.0, 2.0),
            (4, 3.0, 5.0, 3.0),
        ] {
            let s = Scenario::random_with(seed, speed, angular, duration);
            assert_eq!((s.kind, s.duration_s), (ScenarioKind::Random, duration));
            let (peak_speed, peak_angular) = peaks(&s);
            assert!(
                (peak_speed / speed - 1.0).abs() < 0.03,
                "seed {seed}: peak speed {peak_speed} for {speed}"
            );
            assert!(
                (peak_angular / angular - 1.0).abs() < 0.03,
                "seed {seed}: peak angular rate {peak_angular} for {angular}"
            );
            assert!(
                s.min_image_margin_px() > 10.0,
                "seed {seed}: margin {}",
                s.min_image_margin_px()
            );
            assert_twist_is_pose_derivative(&s);
        }
    }

    #[test]
    fn random_with_the_canonical_peaks_is_the_random_scenario() {
        for seed in [1, 5] {
            let a = Scenario::new(ScenarioKind::Random, seed);
            let b = Scenario::random_with(seed, 1.5, 4.0, 4.0);
            for t in [0.0, 0.7, 2.3, 4.0] {
                assert_eq!(a.state_at(t), b.state_at(t));
            }
        }
    }

    #[test]
    fn still_rests_at_its_pose() {
        let rotation = MotionState::bench_rotation();
        let s = Scenario::still(rotation, Vector3::new(0.02, -0.01, 1.6), 1.5);
        assert_eq!((s.kind, s.duration_s), (ScenarioKind::Static, 1.5));
        for t in [0.0, 0.4, 1.5] {
            let st = s.state_at(t);
            assert_eq!(st.cam_r_obj, rotation);
            assert_eq!(st.cam_t_obj_m, Vector3::new(0.02, -0.01, 1.6));
            assert_eq!(st.velocity_mps, Vector3::zeros());
            assert_eq!(st.angular_velocity_radps, Vector3::zeros());
        }
        assert_eq!(peaks(&s), (0.0, 0.0));
        assert!(s.min_image_margin_px() > 100.0);
        // The canonical static scenario is the bench pose 0.6 m away.
        let canonical = Scenario::new(ScenarioKind::Static, 1);
        let bench = Scenario::still(rotation, MotionState::bench().cam_t_obj_m, 1.0);
        assert_eq!(canonical.state_at(0.5), bench.state_at(0.5));
        // Too close: the grid fills more than the image.
        let close = Scenario::still(rotation, Vector3::new(0.0, 0.0, 0.05), 1.0);
        assert!(close.min_image_margin_px() < 0.0);
    }

    #[test]
    #[should_panic(expected = "duration_s must be finite and positive")]
    fn still_refuses_a_zero_duration() {
        let _ = Scenario::still(
            MotionState::bench_rotation(),
            Vector3::new(0.0, 0.0, 1.0),
            0.0,
        );
    }
}
