//! The paths the robot is asked to follow, in the robot frame (axes of the camera, origin at the platform's home).
//!
//! - [`ReferencePath::orthoglide`]: the simulator's orthoglide scenario (docs/model.md: a line, two laps of a circle
//!   at 1 m/s peak, the line back), played `speed_scale` times faster; the one motion, defined once in roitrack-sim.
//! - [`ReferencePath::random`]: a smooth random path for tests, a seeded sum of sinusoids per axis, faded in and out
//!   so that it starts and ends at rest at home.

use std::f64::consts::TAU;

use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::MotionState;
use roitrack_sim::{Scenario, ScenarioKind};

/// Where the path is at one instant (robot frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ReferencePoint {
    /// Position (m).
    pub position_m: Vector3<f64>,
    /// Velocity (m/s).
    pub velocity_mps: Vector3<f64>,
    /// Acceleration (m/s²).
    pub acceleration_mps2: Vector3<f64>,
}

/// A reference path.
///
/// ```
/// use roitrack_servo::reference::ReferencePath;
/// let path = ReferencePath::orthoglide(1.0);
/// assert!((path.duration_s() - 4.914).abs() < 1e-3);
/// let peak = (0..5000).map(|k| path.at(k as f64 * 1e-3).velocity_mps.norm()).fold(0.0, f64::max);
/// assert!((peak - 1.0).abs() < 1e-3, "{peak}");
/// ```
#[derive(Debug, Clone)]
pub struct ReferencePath {
    motion: Motion,
    /// The target's orientation and the platform's home in the camera frame.
    cam_r_obj: Rotation3<f64>,
    home_cam_m: Vector3<f64>,
}

#[derive(Debug, Clone)]
enum Motion {
    /// The orthoglide scenario of roitrack-sim, played faster or slower.
    Orthoglide(Box<Scenario>),
    Random(Box<RandomPath>),
}

/// A seeded random path: per axis three sinusoids (0.4-1.6 Hz, random phases), times a window that rises from 0 to
/// 1 over the first 0.4 s and falls back over the last 0.4 s (quintic, so position, velocity and acceleration start
/// and end at zero), scaled so that the peak speed is the one asked for unless that would take the platform more than
/// [`RandomPath::MAX_EXCURSION_M`] from home.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomPath {
    /// The seed it was drawn from.
    pub seed: u64,
    /// Its length (s).
    pub duration_s: f64,
    /// (amplitude m, frequency Hz, phase rad) of each sinusoid of each axis.
    terms: [[(f64, f64, f64); 3]; 3],
}

const FADE_S: f64 = 0.4;

/// Quintic rise `10u³ - 15u⁴ + 6u⁵` on [0, 1], 0 before, 1 after.
fn quintic(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
}

impl RandomPath {
    /// The farthest a random path takes the platform from home, per axis (m): well inside the workspace and the
    /// camera's image.
    pub const MAX_EXCURSION_M: f64 = 0.06;

    /// The path of `seed` with peak speed about `peak_speed_mps`, lasting `duration_s` (at least 1 s).
    pub fn new(seed: u64, peak_speed_mps: f64, duration_s: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ RANDOM_SALT);
        let duration_s = duration_s.max(1.0);
        let mut terms = [[(0.0, 0.0, 0.0); 3]; 3];
        for axis in &mut terms {
            for term in axis.iter_mut() {
                *term = (
                    rng.random_range(0.2..1.0),
                    rng.random_range(0.4..1.6),
                    rng.random_range(0.0..TAU),
                );
            }
        }
        // The depth axis moves a third as much: the camera sees depth worst.
        for term in &mut terms[2] {
            term.0 /= 3.0;
        }
        let mut path = Self {
            seed,
            duration_s,
            terms,
        };
        let (speed, excursion) = path.peaks();
        let scale = (peak_speed_mps / speed).min(Self::MAX_EXCURSION_M / excursion);
        for axis in &mut path.terms {
            for term in axis.iter_mut() {
                term.0 *= scale;
            }
        }
        path
    }

    fn position(&self, t_s: f64) -> Vector3<f64> {
        let window = quintic(t_s / FADE_S) * quintic((self.duration_s - t_s) / FADE_S);
        Vector3::from_fn(|i, _| {
            self.terms[i]
                .iter()
                .map(|(a, f, phi)| a * ((TAU * f * t_s + phi).sin() - phi.sin()))
                .sum::<f64>()
                * window
        })
    }

    /// Peak speed and peak excursion per axis, sampled at 1 kHz.
    fn peaks(&self) -> (f64, f64) {
        let steps = (self.duration_s * 1000.0) as usize;
        let (mut speed, mut excursion) = (0.0_f64, 0.0_f64);
        for k in 0..=steps {
            let t = k as f64 / 1000.0;
            speed = speed.max(differentiate(|t| self.position(t), t).1.norm());
            excursion = excursion.max(self.position(t).amax());
        }
        (speed, excursion)
    }
}

/// A salt that keeps the random paths' draws apart from other users of the same seed.
const RANDOM_SALT: u64 = 0x5e7_0a7d_f00d;

/// Position, velocity and acceleration of `position(t)` at `t_s` by central differences with a 10 µs step: the
/// error, `h² x'''/6` for the velocity, is below 1e-8 m/s for the paths' jerks (under 1000 m/s³).
fn differentiate(
    position: impl Fn(f64) -> Vector3<f64>,
    t_s: f64,
) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let h = 1e-5;
    let (before, now, after) = (position(t_s - h), position(t_s), position(t_s + h));
    (
        now,
        (after - before) / (2.0 * h),
        (after - now * 2.0 + before) / (h * h),
    )
}

impl ReferencePath {
    /// The orthoglide path at `speed_scale` times its speed (1: 1 m/s peak).
    ///
    /// # Panics
    ///
    /// If `speed_scale` is not finite and positive.
    pub fn orthoglide(speed_scale: f64) -> Self {
        let scenario = Scenario::new(ScenarioKind::Orthoglide, 0).with_speed_scale(speed_scale);
        Self::with_motion(Motion::Orthoglide(Box::new(scenario)))
    }

    /// A random path ([`RandomPath::new`]).
    pub fn random(seed: u64, peak_speed_mps: f64, duration_s: f64) -> Self {
        Self::with_motion(Motion::Random(Box::new(RandomPath::new(
            seed,
            peak_speed_mps,
            duration_s,
        ))))
    }

    fn with_motion(motion: Motion) -> Self {
        // Home and orientation: those of the orthoglide scenario's start (the bench rotation, 0.6 m away).
        let start = Scenario::new(ScenarioKind::Orthoglide, 0).state_at(0.0);
        Self {
            motion,
            cam_r_obj: start.cam_r_obj,
            home_cam_m: start.cam_t_obj_m,
        }
    }

    /// A short name: `orthoglide` or `random`.
    pub fn name(&self) -> &'static str {
        match self.motion {
            Motion::Orthoglide(_) => "orthoglide",
            Motion::Random(_) => "random",
        }
    }

    /// The path's length (s).
    pub fn duration_s(&self) -> f64 {
        match &self.motion {
            Motion::Orthoglide(scenario) => scenario.duration_s,
            Motion::Random(path) => path.duration_s,
        }
    }

    /// The target's constant orientation and the platform's home in the camera frame (the robot only translates).
    pub fn home_in_camera(&self) -> (Rotation3<f64>, Vector3<f64>) {
        (self.cam_r_obj, self.home_cam_m)
    }

    /// The path at `t_s` (held at its ends outside `[0, duration]`).
    pub fn at(&self, t_s: f64) -> ReferencePoint {
        let t_s = t_s.clamp(0.0, self.duration_s());
        match &self.motion {
            Motion::Orthoglide(scenario) => {
                let home = self.home_cam_m;
                let state = |t: f64| scenario.state_at(t.clamp(0.0, scenario.duration_s));
                let h = 1e-5;
                let now = state(t_s);
                ReferencePoint {
                    position_m: now.cam_t_obj_m - home,
                    velocity_mps: now.velocity_mps,
                    acceleration_mps2: (state(t_s + h).velocity_mps - state(t_s - h).velocity_mps)
                        / (2.0 * h),
                }
            }
            Motion::Random(path) => {
                let (p, v, a) = differentiate(|t| path.position(t), t_s);
                ReferencePoint {
                    position_m: p,
                    velocity_mps: v,
                    acceleration_mps2: a,
                }
            }
        }
    }

    /// The camera-frame state of the target when the platform is at `position_m` moving at `velocity_mps`.
    pub fn camera_state(
        &self,
        position_m: &Vector3<f64>,
        velocity_mps: &Vector3<f64>,
    ) -> MotionState {
        MotionState {
            cam_r_obj: self.cam_r_obj,
            cam_t_obj_m: self.home_cam_m + position_m,
            velocity_mps: *velocity_mps,
            angular_velocity_radps: Vector3::zeros(),
        }
    }
}
