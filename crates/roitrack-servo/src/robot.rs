//! The robot: a 3-dof translational parallel robot in the spirit of the Orthoglide, its kinematics and its dynamics
//! (docs/servo.md derives every equation here). Pure math: no I/O, no threads.
//!
//! Three prismatic actuators slide along the axes x, y and z of the robot frame; each carries a leg of length `L`
//! (a parallelogram of two bars, so the platform only translates) whose other end holds the platform at `p`. Leg `i`
//! ties its slider `B_i = (q_i - L) e_i` to the platform by `|p - B_i| = L`, hence the inverse kinematics
//!
//! ```text
//! w_i = (I - e_i e_iᵀ) p,   s_i = sqrt(L² - |w_i|²),   q_i = e_iᵀ p - s_i + L
//! ```
//!
//! (`q = 0` at `p = 0`, the isotropic configuration, where the legs lie along their actuators and `dq/dp = I`). The
//! robot frame's axes are the camera's (x right, y down, z forward) and its origin is the platform's home, so the
//! target's origin on the platform is at `cam_t_obj = home + p`.
//!
//! The dynamics are those of the Lagrangian with the platform position `p` as generalised coordinate (the forward
//! kinematics needs no iteration that way): `M_x(p) p̈ + h(p, ṗ) + ∇V(p) = Jᵀ (τ + τ_f(q̇))`, with `J = dq/dp`, the
//! actuator forces `τ` and the joint friction `τ_f`. In joint space the same equations read
//! `M(q) q̈ + c(q, q̇) + g(q) = τ + τ_f` with `M(q) = J⁻ᵀ M_x J⁻¹` ([`joint_inertia`]).

use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// The actuator axis of leg `i` (0, 1, 2: x, y, z of the robot frame).
fn axis(i: usize) -> Vector3<f64> {
    Vector3::ith(i, 1.0)
}

/// The robot's geometry, masses, friction and actuators.
///
/// ```
/// use roitrack_servo::robot::RobotParams;
/// let robot = RobotParams::orthoglide();
/// // The controller's model of a robot carrying a payload it does not know: every mass 20 % low.
/// let model = robot.with_mass_factor(0.8);
/// assert!((model.platform_mass_kg - 0.8 * robot.platform_mass_kg).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotParams {
    /// Length of each leg (m).
    pub leg_length_m: f64,
    /// Platform with the target it carries (kg).
    pub platform_mass_kg: f64,
    /// Each actuated slider with the moving part of its drive (kg).
    pub slider_mass_kg: f64,
    /// Each leg (both bars of its parallelogram), a uniform thin rod between slider and platform (kg).
    pub leg_mass_kg: f64,
    /// Gravity in the robot frame (m/s²): down is +y, the camera's image down.
    pub gravity_mps2: Vector3<f64>,
    /// Viscous friction of each actuated joint (N per m/s).
    pub viscous_n_per_mps: f64,
    /// Coulomb friction of each actuated joint (N).
    pub coulomb_n: f64,
    /// Speed (m/s) over which the Coulomb friction rises (`tanh(q̇ / this)`): a smooth law that a fixed-step
    /// integrator can follow.
    pub coulomb_smoothing_mps: f64,
    /// Largest force of each actuator (N); commands beyond are clipped.
    pub force_limit_n: f64,
    /// The workspace: a leg may tilt from its actuator axis until `|w_i| = this * L` (0.8: 53 degrees), where the
    /// Jacobian is still well conditioned.
    pub max_tilt: f64,
}

impl RobotParams {
    /// An Orthoglide-sized robot: 0.31 m legs (the prototype's), masses of a light machine of that size, friction of
    /// preloaded linear guides, 400 N actuators (above what the path at 2 m/s asks for: docs/results.md, "Design
    /// measurements behind the code").
    pub fn orthoglide() -> Self {
        Self {
            leg_length_m: 0.31,
            platform_mass_kg: 0.8,
            slider_mass_kg: 1.5,
            leg_mass_kg: 0.4,
            gravity_mps2: Vector3::new(0.0, 9.81, 0.0),
            viscous_n_per_mps: 15.0,
            coulomb_n: 4.0,
            coulomb_smoothing_mps: 1e-3,
            force_limit_n: 400.0,
            max_tilt: 0.8,
        }
    }

    /// The same robot with every mass times `factor` (what a model that misses a payload believes).
    pub fn with_mass_factor(self, factor: f64) -> Self {
        Self {
            platform_mass_kg: self.platform_mass_kg * factor,
            slider_mass_kg: self.slider_mass_kg * factor,
            leg_mass_kg: self.leg_mass_kg * factor,
            ..self
        }
    }

    /// The same robot with both friction coefficients times `factor`.
    pub fn with_friction_factor(self, factor: f64) -> Self {
        Self {
            viscous_n_per_mps: self.viscous_n_per_mps * factor,
            coulomb_n: self.coulomb_n * factor,
            ..self
        }
    }

    /// The same robot without friction (for the energy check).
    pub fn frictionless(self) -> Self {
        self.with_friction_factor(0.0)
    }

    /// Inertia coefficients of `M_x = a I + Σ b J_iᵀ J_i + c (J_iᵀ e_iᵀ + e_i J_i)` (docs/servo.md).
    fn inertia_coefficients(&self) -> (f64, f64, f64) {
        let (mp, ms, ml) = (self.platform_mass_kg, self.slider_mass_kg, self.leg_mass_kg);
        (mp + ml, ms + ml / 3.0, ml / 6.0)
    }
}

/// A platform position outside the workspace (a leg tilted beyond [`RobotParams::max_tilt`], or not finite).
#[derive(Debug, Clone, Copy, PartialEq, Error)]
#[error(
    "the platform at ({:.4}, {:.4}, {:.4}) m is outside the workspace: leg {leg} tilts {tilt:.3} of its length",
    position_m[0], position_m[1], position_m[2]
)]
pub struct WorkspaceError {
    /// The platform's position (m, robot frame).
    pub position_m: [f64; 3],
    /// The leg that cannot reach it.
    pub leg: usize,
    /// That leg's tilt as a fraction of its length (1 or more: out of reach).
    pub tilt: f64,
}

/// The legs' geometry at a platform position: what every dynamic term needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Platform position (m, robot frame).
    pub position_m: Vector3<f64>,
    /// Joint positions `q` (m).
    pub joints_m: Vector3<f64>,
    /// `J = dq/dp`, row `i` that of leg `i`.
    pub jacobian: Matrix3<f64>,
    /// `H_i = d²q_i/dp²` of each leg.
    pub hessians: [Matrix3<f64>; 3],
}

impl Geometry {
    /// The geometry at `position_m`, or why it is outside the workspace.
    ///
    /// ```
    /// use nalgebra::{Matrix3, Vector3};
    /// use roitrack_servo::robot::{Geometry, RobotParams};
    /// let home = Geometry::at(&RobotParams::orthoglide(), &Vector3::zeros()).unwrap();
    /// // Isotropic at home: the legs lie along their actuators.
    /// assert!((home.jacobian - Matrix3::identity()).norm() < 1e-12);
    /// assert!(Geometry::at(&RobotParams::orthoglide(), &Vector3::new(0.0, 0.3, 0.0)).is_err());
    /// ```
    pub fn at(params: &RobotParams, position_m: &Vector3<f64>) -> Result<Self, WorkspaceError> {
        let l = params.leg_length_m;
        let mut joints_m = Vector3::zeros();
        let mut jacobian = Matrix3::zeros();
        let mut hessians = [Matrix3::zeros(); 3];
        for i in 0..3 {
            let e = axis(i);
            let projector = Matrix3::identity() - e * e.transpose();
            let w = projector * position_m;
            let tilt = w.norm() / l;
            if !tilt.is_finite()
                || tilt > params.max_tilt
                || !position_m.iter().all(|x| x.is_finite())
            {
                return Err(WorkspaceError {
                    position_m: [position_m[0], position_m[1], position_m[2]],
                    leg: i,
                    tilt,
                });
            }
            let s = (l * l - w.norm_squared()).sqrt();
            joints_m[i] = e.dot(position_m) - s + l;
            jacobian.set_row(i, &(e + w / s).transpose());
            hessians[i] = projector / s + w * w.transpose() / (s * s * s);
        }
        Ok(Self {
            position_m: *position_m,
            joints_m,
            jacobian,
            hessians,
        })
    }

    /// Joint velocities `q̇ = J ṗ` (m/s).
    pub fn joint_velocity(&self, velocity_mps: &Vector3<f64>) -> Vector3<f64> {
        self.jacobian * velocity_mps
    }

    /// The task-space inertia `M_x(p)` (kg) of the robot `params` (docs/servo.md).
    pub fn task_inertia(&self, params: &RobotParams) -> Matrix3<f64> {
        let (a, b, c) = params.inertia_coefficients();
        let mut m = Matrix3::identity() * a;
        for i in 0..3 {
            let row = self.jacobian.row(i).transpose();
            let e = axis(i);
            m += row * row.transpose() * b + (row * e.transpose() + e * row.transpose()) * c;
        }
        m
    }

    /// The velocity-product forces `h(p, ṗ) = Σ (b J_iᵀ + c e_i) ṗᵀ H_i ṗ` (N): the Coriolis and centrifugal
    /// terms of the Lagrangian in task space.
    pub fn velocity_forces(
        &self,
        params: &RobotParams,
        velocity_mps: &Vector3<f64>,
    ) -> Vector3<f64> {
        let (_, b, c) = params.inertia_coefficients();
        (0..3)
            .map(|i| {
                let curvature = velocity_mps.dot(&(self.hessians[i] * velocity_mps));
                (self.jacobian.row(i).transpose() * b + axis(i) * c) * curvature
            })
            .sum()
    }

    /// The gravity forces `∇V(p)` (N) in task space.
    pub fn gravity_forces(&self, params: &RobotParams) -> Vector3<f64> {
        let g = params.gravity_mps2;
        let on_platform = params.platform_mass_kg + 1.5 * params.leg_mass_kg;
        let on_slider = params.slider_mass_kg + 0.5 * params.leg_mass_kg;
        -g * on_platform
            - (0..3)
                .map(|i| self.jacobian.row(i).transpose() * (on_slider * g[i]))
                .sum::<Vector3<f64>>()
    }

    /// Kinetic energy `½ ṗᵀ M_x ṗ` (J).
    pub fn kinetic_energy(&self, params: &RobotParams, velocity_mps: &Vector3<f64>) -> f64 {
        0.5 * velocity_mps.dot(&(self.task_inertia(params) * velocity_mps))
    }

    /// Potential energy `V(p)` (J), zero at home: `-gᵀ ((m_p + 3 m_l/2) p + (m_s + m_l/2) Σ q_i e_i)`.
    pub fn potential_energy(&self, params: &RobotParams) -> f64 {
        let g = params.gravity_mps2;
        let on_platform = params.platform_mass_kg + 1.5 * params.leg_mass_kg;
        let on_slider = params.slider_mass_kg + 0.5 * params.leg_mass_kg;
        -(g.dot(&self.position_m) * on_platform + g.dot(&self.joints_m) * on_slider)
    }

    /// The joint-space inertia `M(q) = J⁻ᵀ M_x J⁻¹` (kg); `None` at a singular configuration.
    pub fn joint_inertia(&self, params: &RobotParams) -> Option<Matrix3<f64>> {
        let inverse = self.jacobian.try_inverse()?;
        Some(inverse.transpose() * self.task_inertia(params) * inverse)
    }
}

/// The joint-space inertia `M(q)` at the platform position `position_m` (see [`Geometry::joint_inertia`]).
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_servo::robot::{RobotParams, joint_inertia};
/// let robot = RobotParams::orthoglide();
/// let home = joint_inertia(&robot, &Vector3::zeros()).unwrap();
/// let away = joint_inertia(&robot, &Vector3::new(0.05, -0.05, 0.0)).unwrap();
/// // It depends on the configuration.
/// assert!((home - away).norm() > 0.01);
/// ```
pub fn joint_inertia(params: &RobotParams, position_m: &Vector3<f64>) -> Option<Matrix3<f64>> {
    Geometry::at(params, position_m).ok()?.joint_inertia(params)
}

/// The force each joint's friction exerts (N, opposing its velocity): `-B q̇ - F_c tanh(q̇ / v_s)`.
pub fn joint_friction(params: &RobotParams, joint_velocity_mps: &Vector3<f64>) -> Vector3<f64> {
    joint_velocity_mps.map(|qd| {
        let coulomb = if params.coulomb_n == 0.0 {
            0.0
        } else {
            params.coulomb_n * (qd / params.coulomb_smoothing_mps).tanh()
        };
        -params.viscous_n_per_mps * qd - coulomb
    })
}

/// The platform's acceleration (m/s²) under the actuator forces `joint_force_n` (applied as given: clip them first
/// with [`RobotParams::force_limit_n`]), from `M_x p̈ = Jᵀ (τ + τ_f) - h - ∇V`.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_servo::robot::{Geometry, RobotParams, acceleration};
/// let robot = RobotParams::orthoglide();
/// let home = Geometry::at(&robot, &Vector3::zeros()).unwrap();
/// // Holding the robot still at home takes exactly the gravity forces (J = I there).
/// let hold = home.gravity_forces(&robot);
/// assert!(acceleration(&robot, &home, &Vector3::zeros(), &hold).norm() < 1e-12);
/// ```
pub fn acceleration(
    params: &RobotParams,
    geometry: &Geometry,
    velocity_mps: &Vector3<f64>,
    joint_force_n: &Vector3<f64>,
) -> Vector3<f64> {
    let joint_velocity = geometry.joint_velocity(velocity_mps);
    let generalised = geometry.jacobian.transpose()
        * (joint_force_n + joint_friction(params, &joint_velocity))
        - geometry.velocity_forces(params, velocity_mps)
        - geometry.gravity_forces(params);
    let inertia = geometry.task_inertia(params);
    // M_x is symmetric positive definite in the workspace (a sum of masses times Gram matrices).
    inertia
        .cholesky()
        .map_or(Vector3::repeat(f64::NAN), |c| c.solve(&generalised))
}

/// The simulated robot's state: platform position and velocity (robot frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RobotState {
    /// Platform position (m).
    pub position_m: Vector3<f64>,
    /// Platform velocity (m/s).
    pub velocity_mps: Vector3<f64>,
}

/// One classical Runge-Kutta (RK4) step of `dt_s` under the constant actuator forces `joint_force_n` (already
/// clipped), or why a stage left the workspace.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_servo::robot::{Geometry, RobotParams, RobotState, step_rk4};
/// let robot = RobotParams::orthoglide();
/// let hold = Geometry::at(&robot, &Vector3::zeros()).unwrap().gravity_forces(&robot);
/// let next = step_rk4(&robot, &RobotState::default(), &hold, 1e-4).unwrap();
/// assert!(next.position_m.norm() < 1e-15);
/// ```
pub fn step_rk4(
    params: &RobotParams,
    state: &RobotState,
    joint_force_n: &Vector3<f64>,
    dt_s: f64,
) -> Result<RobotState, WorkspaceError> {
    let derivative = |p: &Vector3<f64>,
                      v: &Vector3<f64>|
     -> Result<(Vector3<f64>, Vector3<f64>), WorkspaceError> {
        let geometry = Geometry::at(params, p)?;
        Ok((*v, acceleration(params, &geometry, v, joint_force_n)))
    };
    let (p, v) = (state.position_m, state.velocity_mps);
    let (k1p, k1v) = derivative(&p, &v)?;
    let (k2p, k2v) = derivative(&(p + k1p * (dt_s / 2.0)), &(v + k1v * (dt_s / 2.0)))?;
    let (k3p, k3v) = derivative(&(p + k2p * (dt_s / 2.0)), &(v + k2v * (dt_s / 2.0)))?;
    let (k4p, k4v) = derivative(&(p + k3p * dt_s), &(v + k3v * dt_s))?;
    Ok(RobotState {
        position_m: p + (k1p + k2p * 2.0 + k3p * 2.0 + k4p) * (dt_s / 6.0),
        velocity_mps: v + (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (dt_s / 6.0),
    })
}

/// Total mechanical energy `T + V` (J) of `state`, or why it is outside the workspace.
pub fn energy(params: &RobotParams, state: &RobotState) -> Result<f64, WorkspaceError> {
    let geometry = Geometry::at(params, &state.position_m)?;
    Ok(geometry.kinetic_energy(params, &state.velocity_mps) + geometry.potential_energy(params))
}
