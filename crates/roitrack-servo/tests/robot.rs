//! The robot's model against the physics it claims: the Jacobian against central differences of the inverse
//! kinematics, the velocity forces against the Lagrangian differentiated numerically, and energy conservation of the
//! integrated motion without friction or actuator force.

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_servo::robot::{
    Geometry, RobotParams, RobotState, acceleration, energy, joint_friction, step_rk4,
};
use roitrack_testkit::check_jacobian;

fn robot() -> RobotParams {
    RobotParams::orthoglide()
}

/// A platform position drawn over the part of the workspace the paths use (a 0.2 m cube about home) times `spread`.
fn draw_position(rng: &mut ChaCha8Rng, spread: f64) -> Vector3<f64> {
    Vector3::from_fn(|_, _| rng.random_range(-0.1..0.1) * spread)
}

#[test]
fn the_jacobian_is_the_derivative_of_the_inverse_kinematics() {
    let params = robot();
    check_jacobian(
        "dq/dp",
        Vector3::zeros(),
        draw_position,
        &Vector3::repeat(0.1),
        |p: &Vector3<f64>, d: &Vector3<f64>| Geometry::at(&params, &(p + d)).unwrap().joints_m,
        |p: &Vector3<f64>| Geometry::at(&params, p).unwrap().jacobian,
    );
}

#[test]
fn each_hessian_is_the_derivative_of_its_jacobian_row() {
    let params = robot();
    for leg in 0..3 {
        check_jacobian(
            "d²q_i/dp²",
            Vector3::zeros(),
            draw_position,
            &Vector3::repeat(0.1),
            |p: &Vector3<f64>, d: &Vector3<f64>| {
                Geometry::at(&params, &(p + d))
                    .unwrap()
                    .jacobian
                    .row(leg)
                    .transpose()
            },
            |p: &Vector3<f64>| Geometry::at(&params, p).unwrap().hessians[leg],
        );
    }
}

/// `h = Ṁ ṗ - ∂T/∂p`, each term by central differences of the kinetic energy `T(p, ṗ) = ½ ṗᵀ M_x(p) ṗ`.
#[test]
fn the_velocity_forces_are_those_of_the_lagrangian() {
    let params = robot();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..50 {
        let p = draw_position(&mut rng, 1.0);
        let v = Vector3::from_fn(|_, _| rng.random_range(-2.0..2.0));
        let inertia = |p: &Vector3<f64>| Geometry::at(&params, p).unwrap().task_inertia(&params);
        let h = 1e-6;
        // Ṁ ṗ = (dM/dt) ṗ = (Σ_k ∂M/∂p_k v_k) v.
        let m_dot = (0..3)
            .map(|k| {
                let dp = Vector3::ith(k, h);
                (inertia(&(p + dp)) - inertia(&(p - dp))) / (2.0 * h) * v[k]
            })
            .sum::<Matrix3<f64>>();
        let dt_dp = Vector3::from_fn(|k, _| {
            let dp = Vector3::ith(k, h);
            0.5 * (v.dot(&(inertia(&(p + dp)) * v)) - v.dot(&(inertia(&(p - dp)) * v))) / (2.0 * h)
        });
        let numeric = m_dot * v - dt_dp;
        let analytic = Geometry::at(&params, &p)
            .unwrap()
            .velocity_forces(&params, &v);
        assert!(
            (numeric - analytic).norm() <= 1e-6 * (1.0 + analytic.norm()),
            "at p = {p:?}, v = {v:?}: {numeric:?} against {analytic:?}"
        );
    }
}

#[test]
fn the_gravity_forces_are_the_gradient_of_the_potential() {
    let params = robot();
    check_jacobian(
        "∇V",
        Vector3::zeros(),
        draw_position,
        &Vector3::repeat(0.1),
        |p: &Vector3<f64>, d: &Vector3<f64>| {
            nalgebra::Vector1::new(
                Geometry::at(&params, &(p + d))
                    .unwrap()
                    .potential_energy(&params),
            )
        },
        |p: &Vector3<f64>| {
            Geometry::at(&params, p)
                .unwrap()
                .gravity_forces(&params)
                .transpose()
        },
    );
}

/// Without friction or actuator force the mechanical energy is constant: RK4's error per unit time is O(dt⁴), so
/// halving the step must shrink the drift about 16-fold, and at 62.5 µs (the loop's step) it stays far below the
/// energy exchanged.
#[test]
fn energy_is_conserved_without_friction_or_force() {
    let params = robot().frictionless();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for case in 0..12 {
        let start = RobotState {
            position_m: draw_position(&mut rng, 0.5),
            velocity_mps: Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)),
        };
        let drift = |dt_s: f64| {
            let e0 = energy(&params, &start).unwrap();
            let mut state = start;
            let mut worst: f64 = 0.0;
            let steps = (0.1 / dt_s).round() as usize;
            for _ in 0..steps {
                state = step_rk4(&params, &state, &Vector3::zeros(), dt_s).unwrap();
                worst = worst.max((energy(&params, &state).unwrap() - e0).abs());
            }
            (worst, e0)
        };
        let (coarse, e0) = drift(62.5e-6);
        let (fine, _) = drift(31.25e-6);
        let kinetic = Geometry::at(&params, &start.position_m)
            .unwrap()
            .kinetic_energy(&params, &start.velocity_mps);
        assert!(
            coarse < 1e-7 * (kinetic + 1.0),
            "case {case}: drift {coarse} J of {e0} J"
        );
        // Fourth order: the drift falls at least 8-fold when the step halves (16 in theory; round-off floor aside).
        assert!(
            fine < coarse / 8.0 || coarse < 1e-12,
            "case {case}: {coarse} then {fine}"
        );
    }
}

/// The power the actuators put in plus the power friction takes out is the rate of change of the energy:
/// `dE/dt = q̇ᵀ (τ + τ_f)`. Checked by integrating both over random forces held for a millisecond each.
#[test]
fn energy_balance_with_friction_and_forces() {
    let params = robot();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let dt_s = 31.25e-6;
    let mut state = RobotState::default();
    let e0 = energy(&params, &state).unwrap();
    let mut work = 0.0;
    let mut peak_speed: f64 = 0.0;
    for _ in 0..100 {
        let geometry = Geometry::at(&params, &state.position_m).unwrap();
        let force = geometry.gravity_forces(&params)
            + Vector3::from_fn(|_, _| rng.random_range(-60.0..60.0));
        for _ in 0..32 {
            // Trapezoidal rule of the power over the step.
            let power = |s: &RobotState| {
                let g = Geometry::at(&params, &s.position_m).unwrap();
                let qd = g.joint_velocity(&s.velocity_mps);
                qd.dot(&(force + joint_friction(&params, &qd)))
            };
            let next = step_rk4(&params, &state, &force, dt_s).unwrap();
            work += 0.5 * (power(&state) + power(&next)) * dt_s;
            state = next;
            peak_speed = peak_speed.max(state.velocity_mps.norm());
        }
    }
    let e1 = energy(&params, &state).unwrap();
    assert!(peak_speed > 0.02, "the robot must move: {peak_speed} m/s");
    // The trapezoidal rule of the power is second order: at 31 µs steps, within 1e-4 of the work's scale.
    let scale = work.abs().max(0.01);
    assert!(
        ((e1 - e0) - work).abs() < 1e-4 * scale,
        "{} against {work}",
        e1 - e0
    );
}

/// In joint space: `M(q) = J⁻ᵀ M_x J⁻¹` gives the same kinetic energy from the joint velocities.
#[test]
fn joint_and_task_inertia_agree() {
    let params = robot();
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    for _ in 0..50 {
        let p = draw_position(&mut rng, 1.0);
        let v = Vector3::from_fn(|_, _| rng.random_range(-2.0..2.0));
        let g = Geometry::at(&params, &p).unwrap();
        let qd = g.joint_velocity(&v);
        let joint = 0.5 * qd.dot(&(g.joint_inertia(&params).unwrap() * qd));
        assert!((joint - g.kinetic_energy(&params, &v)).abs() < 1e-9);
        // And a finite acceleration everywhere in the workspace.
        assert!(
            acceleration(&params, &g, &v, &Vector3::zeros())
                .iter()
                .all(|a| a.is_finite())
        );
    }
}
