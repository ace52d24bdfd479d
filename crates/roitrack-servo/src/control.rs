//! Controllers behind one trait ([`Controller`]), fed by what the camera gives: the newest estimate of the platform's
//! position (and velocity, where the scheme uses it) with the time it refers to. Pure math: no I/O, no threads.
//!
//! - [`ComputedTorque`] with [`VelocitySource::Estimate`]: computed-torque control with velocity feed-forward, the
//!   tracker's position and velocity each predicted to the actuation instant (`p + v (t_act - t_ref)`, `v`).
//! - [`ComputedTorque`] with [`VelocitySource::PoseDifferences`]: the same law with the velocity taken from the
//!   differences of consecutive estimated positions (pose-only feedback), predicted the same way.
//! - [`KinematicServo`]: the classic kinematic visual servo: a velocity command `v_ref + λ (p_ref - p)` from the newest
//!   position, turned into joint velocities and tracked by the drives' own joint-velocity loop (PI on the encoders'
//!   joint velocities, which never see the camera).
//! - The `true-state` floor is [`ComputedTorque`] fed the true state at the actuation instant (the closed loop does
//!   that, [`crate::closed_loop`]).
//!
//! The computed-torque law (docs/servo.md), with the controller's own model of the robot (masses 20 % off):
//!
//! ```text
//! F = M̂_x(p̂) (a_ref + K_d (v_ref - v̂) + K_p (p_ref - p̂)) + ĥ(p̂, v̂) + ∇V̂(p̂)     (task space)
//! τ = Ĵ⁻ᵀ F - τ̂_f(Ĵ v̂)                                                       (joint forces)
//! ```

use nalgebra::Vector3;

use crate::reference::ReferencePoint;
use crate::robot::{Geometry, RobotParams, acceleration, joint_friction};

/// What the camera side knows of the platform: its position and velocity (robot frame) at `t_s`, the time the
/// estimate refers to (for roitrack, the newest measurement's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The time the estimate refers to (s).
    pub t_s: f64,
    /// The platform's position (m, robot frame).
    pub position_m: Vector3<f64>,
    /// The platform's velocity (m/s, robot frame).
    pub velocity_mps: Vector3<f64>,
    /// The acceleration, when the estimator has it in its state (the Kalman filter's constant-acceleration model).
    pub acceleration_mps2: Option<Vector3<f64>>,
}

/// What a controller is given at each control instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlInput {
    /// When the command will act on the robot (s): now plus the actuation delay.
    pub t_act_s: f64,
    /// Time since the previous command (s).
    pub dt_s: f64,
    /// The path at `t_act_s`.
    pub reference: ReferencePoint,
    /// The newest estimate available now, if any yet.
    pub observation: Option<Observation>,
    /// The drives' own joint velocities (encoders): only the inner loop of [`KinematicServo`] reads them.
    pub drive_joint_velocity_mps: Vector3<f64>,
}

/// A control law: joint forces (N) from what it is given.
pub trait Controller {
    /// The name in tables and files.
    fn name(&self) -> &'static str;
    /// The actuator forces (N) to apply at `input.t_act_s`.
    fn command(&mut self, input: &ControlInput) -> Vector3<f64>;

    /// The platform's acceleration (m/s², robot frame) that this controller's own model of the robot gives for the
    /// joint forces `joint_force_n` (its newest command as it will act, clipped to the actuators' limit), at the
    /// state it believed when it made that command; `None` before its first command. What the controller knows of
    /// the acceleration it commands: its model (the masses and friction 20 % off in the loop), not the robot.
    /// The closed loop tells the tracker (`roitrack_estimators::Estimator::set_known_acceleration`).
    fn believed_acceleration(&self, _joint_force_n: &Vector3<f64>) -> Option<Vector3<f64>> {
        None
    }
}

/// The platform's acceleration (m/s²) that `model` gives for the joint forces `joint_force_n` at `position_m`
/// (or, outside the workspace, at `fallback_m`) moving at `velocity_mps`: the model's forward dynamics
/// ([`acceleration`]).
fn model_acceleration(
    model: &RobotParams,
    position_m: &Vector3<f64>,
    fallback_m: &Vector3<f64>,
    velocity_mps: &Vector3<f64>,
    joint_force_n: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let geometry = Geometry::at(model, position_m)
        .or_else(|_| Geometry::at(model, fallback_m))
        .ok()?;
    let a = acceleration(model, &geometry, velocity_mps, joint_force_n);
    a.iter().all(|x| x.is_finite()).then_some(a)
}

/// Proportional-derivative gains as a natural frequency and a damping ratio: `K_p = ω²`, `K_d = 2 ζ ω` (per unit
/// mass: the computed-torque law multiplies them by the model's inertia).
///
/// ```
/// use roitrack_servo::control::Gains;
/// let gains = Gains::critically_damped(100.0).with_depth_factor(0.5);
/// assert_eq!((gains.kp().x, gains.kd().x), (10_000.0, 200.0));
/// assert_eq!((gains.kp().z, gains.kd().z), (2_500.0, 100.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// The natural frequency ω of the image-plane axes (rad/s).
    pub natural_frequency_radps: f64,
    /// The damping ratio ζ (1: critically damped).
    pub damping: f64,
    /// The natural frequency along the camera's optical axis (the robot frame's z) is this times the others': a
    /// camera sees depth an order of magnitude worse than the image-plane directions, and its tracker follows depth
    /// with more lag; a loop faster than its feedback along an axis oscillates along it.
    pub depth_factor: f64,
}

impl Gains {
    /// Phase (rad) a loop may lose to its delay at the natural frequency: `ω τ` rad are lost, and 0.35 rad
    /// (20 degrees) leaves a critically damped loop about 55 degrees of margin.
    pub const DELAY_PHASE_RAD: f64 = 0.35;
    /// The highest natural frequency used whatever the latency (rad/s): 2π × 40 Hz, a quarter of the robot's
    /// first structural modes' typical 150-200 Hz (not simulated, so not to be excited).
    pub const MAX_NATURAL_FREQUENCY_RADPS: f64 = 2.0 * std::f64::consts::PI * 40.0;

    /// Critically damped gains of natural frequency `natural_frequency_radps`, the same on every axis.
    pub fn critically_damped(natural_frequency_radps: f64) -> Self {
        Self {
            natural_frequency_radps,
            damping: 1.0,
            depth_factor: 1.0,
        }
    }

    /// The same gains with [`Self::depth_factor`] set.
    pub fn with_depth_factor(self, depth_factor: f64) -> Self {
        Self {
            depth_factor,
            ..self
        }
    }

    /// The gains for a loop whose feedback is `latency_s` old on average when it acts: `ω = 0.35 / latency`, at most
    /// [`Self::MAX_NATURAL_FREQUENCY_RADPS`] (docs/servo.md, "Tuning").
    pub fn for_latency(latency_s: f64) -> Self {
        Self::critically_damped(
            (Self::DELAY_PHASE_RAD / latency_s.max(1e-9)).min(Self::MAX_NATURAL_FREQUENCY_RADPS),
        )
    }

    /// The natural frequency of each axis (rad/s).
    pub fn frequencies_radps(&self) -> Vector3<f64> {
        let w = self.natural_frequency_radps;
        Vector3::new(w, w, w * self.depth_factor)
    }

    /// `K_p = ω²` of each axis (1/s²).
    pub fn kp(&self) -> Vector3<f64> {
        self.frequencies_radps().map(|w| w * w)
    }

    /// `K_d = 2 ζ ω` of each axis (1/s).
    pub fn kd(&self) -> Vector3<f64> {
        self.frequencies_radps() * (2.0 * self.damping)
    }

    /// The same gains with the natural frequency times `factor`.
    pub fn scaled(self, factor: f64) -> Self {
        Self {
            natural_frequency_radps: self.natural_frequency_radps * factor,
            ..self
        }
    }
}

/// Where [`ComputedTorque`] takes the platform's velocity from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VelocitySource {
    /// The estimate's own velocity (roitrack's, or the truth's).
    Estimate,
    /// Differences of consecutive estimated positions (pose-only feedback).
    PoseDifferences,
}

/// Computed-torque control with velocity feed-forward in task space (see the [module docs](self)).
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_servo::control::{ComputedTorque, ControlInput, Controller, Gains, Observation, VelocitySource};
/// use roitrack_servo::reference::ReferencePoint;
/// use roitrack_servo::robot::{Geometry, RobotParams};
///
/// let model = RobotParams::orthoglide();
/// let mut ctc = ComputedTorque::new("ctc", model, Gains::critically_damped(150.0), VelocitySource::Estimate);
/// let at_home = Observation {
///     t_s: 0.0,
///     position_m: Vector3::zeros(),
///     velocity_mps: Vector3::zeros(),
///     acceleration_mps2: None,
/// };
/// let input = ControlInput {
///     t_act_s: 0.0,
///     dt_s: 2.5e-4,
///     reference: ReferencePoint::default(),
///     observation: Some(at_home),
///     drive_joint_velocity_mps: Vector3::zeros(),
/// };
/// // On the path at rest: the forces that hold the robot against gravity.
/// let hold = Geometry::at(&model, &Vector3::zeros()).unwrap().gravity_forces(&model);
/// assert!((ctc.command(&input) - hold).norm() < 1e-9);
/// ```
#[derive(Debug, Clone)]
pub struct ComputedTorque {
    name: &'static str,
    model: RobotParams,
    gains: Gains,
    velocity: VelocitySource,
    /// The last observation seen, and the velocity of the differences.
    previous: Option<Observation>,
    differenced_mps: Vector3<f64>,
    /// The newest command's believed position and velocity, and the path's position then (where the model is
    /// evaluated when the belief is outside the workspace).
    believed: Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
}

impl ComputedTorque {
    /// The law with the robot model `model` (what the controller believes), `gains`, and the velocity from
    /// `velocity`.
    pub fn new(
        name: &'static str,
        model: RobotParams,
        gains: Gains,
        velocity: VelocitySource,
    ) -> Self {
        Self {
            name,
            model,
            gains,
            velocity,
            previous: None,
            differenced_mps: Vector3::zeros(),
            believed: None,
        }
    }

    /// The platform's position and velocity as this controller believes them at `t_act_s`.
    fn believed_state(
        &mut self,
        observation: &Observation,
        t_act_s: f64,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let dt_s = t_act_s - observation.t_s;
        let velocity = match self.velocity {
            VelocitySource::Estimate => {
                // As the estimator predicts its own state (`Estimate::state_at`): with its acceleration if it has one.
                if let Some(a) = observation.acceleration_mps2 {
                    let predicted = observation.position_m
                        + observation.velocity_mps * dt_s
                        + a * (0.5 * dt_s * dt_s);
                    return (predicted, observation.velocity_mps + a * dt_s);
                }
                observation.velocity_mps
            }
            VelocitySource::PoseDifferences => {
                if let Some(previous) = self.previous
                    && observation.t_s > previous.t_s
                {
                    self.differenced_mps = (observation.position_m - previous.position_m)
                        / (observation.t_s - previous.t_s);
                }
                if self.previous.is_none_or(|p| observation.t_s > p.t_s) {
                    self.previous = Some(*observation);
                }
                self.differenced_mps
            }
        };
        (
            observation.position_m + velocity * (t_act_s - observation.t_s),
            velocity,
        )
    }
}

impl Controller for ComputedTorque {
    fn name(&self) -> &'static str {
        self.name
    }

    fn command(&mut self, input: &ControlInput) -> Vector3<f64> {
        let reference = &input.reference;
        // Before the first estimate: the feed-forward of the path alone.
        let (position, velocity) = match &input.observation {
            Some(observation) => self.believed_state(observation, input.t_act_s),
            None => (reference.position_m, reference.velocity_mps),
        };
        // The model is evaluated where the controller believes the platform is; outside the workspace (a wild
        // estimate), where the path is.
        let geometry = Geometry::at(&self.model, &position)
            .or_else(|_| Geometry::at(&self.model, &reference.position_m))
            .expect("the reference path stays inside the workspace");
        self.believed = Some((position, velocity, reference.position_m));
        let wanted = reference.acceleration_mps2
            + (reference.velocity_mps - velocity).component_mul(&self.gains.kd())
            + (reference.position_m - position).component_mul(&self.gains.kp());
        let task_force = geometry.task_inertia(&self.model) * wanted
            + geometry.velocity_forces(&self.model, &velocity)
            + geometry.gravity_forces(&self.model);
        let joint_force = geometry
            .jacobian
            .transpose()
            .try_inverse()
            .map_or(Vector3::zeros(), |inverse| inverse * task_force);
        joint_force - joint_friction(&self.model, &geometry.joint_velocity(&velocity))
    }

    /// The model's forward dynamics at the believed state of the newest command: for forces that the actuators'
    /// limit left as commanded, exactly the acceleration the law asked for (`a_ref + K_d (v_ref - v̂) + K_p (p_ref
    /// - p̂)`), since the law inverts the same model.
    fn believed_acceleration(&self, joint_force_n: &Vector3<f64>) -> Option<Vector3<f64>> {
        let (position, velocity, reference) = self.believed?;
        model_acceleration(&self.model, &position, &reference, &velocity, joint_force_n)
    }
}

/// Gains of [`KinematicServo`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinematicGains {
    /// Outer loop: velocity command per metre of position error (1/s).
    pub lambda_per_s: f64,
    /// Inner loop: bandwidth of the drives' joint-velocity loop (rad/s); the proportional gain is the model's joint
    /// inertia times it, the integral gain a quarter of its square.
    pub inner_bandwidth_radps: f64,
}

impl KinematicGains {
    /// The outer gain for a camera whose feedback is `latency_s` old: `λ = 0.35 / latency` (the phase rule of
    /// [`Gains::for_latency`] for a first-order loop), at most 2π × 20 Hz; the inner loop at 2π × 80 Hz, bounded by
    /// the actuation delay, not by the camera.
    pub fn for_latency(latency_s: f64) -> Self {
        Self {
            lambda_per_s: (Gains::DELAY_PHASE_RAD / latency_s.max(1e-9))
                .min(2.0 * std::f64::consts::PI * 20.0),
            inner_bandwidth_radps: 2.0 * std::f64::consts::PI * 80.0,
        }
    }
}

/// The classic kinematic visual servo (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct KinematicServo {
    model: RobotParams,
    gains: KinematicGains,
    integral_n: Vector3<f64>,
    /// The newest command's position (the camera's), velocity (the encoders', through the model's Jacobian) and
    /// the path's position then.
    believed: Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
}

impl KinematicServo {
    /// The servo with the robot model `model` (what the controller believes) and `gains`.
    pub fn new(model: RobotParams, gains: KinematicGains) -> Self {
        Self {
            model,
            gains,
            integral_n: Vector3::zeros(),
            believed: None,
        }
    }
}

impl Controller for KinematicServo {
    fn name(&self) -> &'static str {
        "kvs"
    }

    fn command(&mut self, input: &ControlInput) -> Vector3<f64> {
        let reference = &input.reference;
        let position = input
            .observation
            .map_or(reference.position_m, |o| o.position_m);
        let geometry = Geometry::at(&self.model, &position)
            .or_else(|_| Geometry::at(&self.model, &reference.position_m))
            .expect("the reference path stays inside the workspace");
        // The platform's velocity as the drives' encoders and the model's Jacobian give it.
        let encoder_velocity = geometry
            .jacobian
            .try_inverse()
            .map_or(reference.velocity_mps, |inverse| {
                inverse * input.drive_joint_velocity_mps
            });
        self.believed = Some((position, encoder_velocity, reference.position_m));
        let velocity_command =
            reference.velocity_mps + (reference.position_m - position) * self.gains.lambda_per_s;
        let joint_velocity_command = geometry.joint_velocity(&velocity_command);
        let error = joint_velocity_command - input.drive_joint_velocity_mps;
        // The drive's loop: proportional to the joint inertia it moves (the diagonal of the model's M(q)), with an
        // integral that takes up gravity and friction.
        let inertia = geometry
            .joint_inertia(&self.model)
            .map_or(Vector3::repeat(self.model.slider_mass_kg), |m| m.diagonal());
        let w = self.gains.inner_bandwidth_radps;
        let gravity = geometry
            .jacobian
            .transpose()
            .try_inverse()
            .map_or(Vector3::zeros(), |inverse| {
                inverse * geometry.gravity_forces(&self.model)
            });
        let proportional = gravity + inertia.component_mul(&error) * w;
        let increment = inertia.component_mul(&error) * (w * w / 4.0 * input.dt_s);
        // Anti-windup: an axis whose force is at the actuator's limit stops integrating (else the integral grows
        // while the drive cannot follow and throws the robot past the path when it can again).
        let limit = self.model.force_limit_n;
        for i in 0..3 {
            let candidate = self.integral_n[i] + increment[i];
            if (proportional[i] + candidate).abs() < limit
                || candidate.abs() < self.integral_n[i].abs()
            {
                self.integral_n[i] = candidate;
            }
        }
        proportional + self.integral_n
    }

    /// The model's forward dynamics at the camera's position and the encoders' velocity.
    fn believed_acceleration(&self, joint_force_n: &Vector3<f64>) -> Option<Vector3<f64>> {
        let (position, velocity, reference) = self.believed?;
        model_acceleration(&self.model, &position, &reference, &velocity, joint_force_n)
    }
}
