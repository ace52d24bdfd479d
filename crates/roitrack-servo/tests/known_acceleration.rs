//! The loop tells the tracker the acceleration the controller commands (its own model's, from the instant the force
//! acts): with the built-in scenes' 0.1 px of centroid noise, computed torque on the ROI camera stays within the
//! error its model error and the tracker's own uncertainty imply (docs/servo.md, "Pose and velocity against pose
//! only"). Without it, the filter's velocity lags the commanded accelerations by milliseconds and the same runs
//! diverge within the first second.

use roitrack_servo::robot::{Geometry, joint_friction};
use roitrack_servo::{CameraKind, ControllerKind, ServoConfig, ServoReport, run_servo};

/// The bound of a run's RMS error: per axis, the error obeys `ë + K_d ė + K_p e = d + K_p n_p + K_d n_v`, with `d`
/// the model's error (as in the floor's test, `tests/closed_loop.rs`) and `n_p`, `n_v` the errors of the position and
/// velocity fed back. A critically damped loop's response `1 / (s + ω)²` has an L2 gain of `1/ω²` and `ω² / (s +
/// ω)²` one of 1 (`|jΩ + ω|² ≥ ω²`), so the model's part has an RMS of at most `RMS(d) / ω²` and the noise's part
/// at most `σ_p + 2 σ_v / ω`, with `σ_p`, `σ_v` the tracker's own standard deviations (the median over the run of its
/// covariance's). The axes' bounds add in quadrature, and the sum is taken 1.5 times for the delay and the
/// linearisation, as the floor's test does.
fn error_bound_mm(config: &ServoConfig, report: &ServoReport) -> f64 {
    let robot = config.robot;
    let model = robot
        .with_mass_factor(config.model_mass_factor)
        .with_friction_factor(config.model_friction_factor);
    let mut d_squares = nalgebra::Vector3::zeros();
    for s in &report.samples {
        let g = Geometry::at(&robot, &s.achieved_m).unwrap();
        let (v, a) = (s.achieved_velocity_mps, s.reference.acceleration_mps2);
        let qd = g.joint_velocity(&v);
        let error_force = (g.task_inertia(&robot) - g.task_inertia(&model)) * a
            + g.velocity_forces(&robot, &v)
            - g.velocity_forces(&model, &v)
            + g.gravity_forces(&robot)
            - g.gravity_forces(&model)
            - g.jacobian.transpose() * (joint_friction(&robot, &qd) - joint_friction(&model, &qd));
        let d = g.task_inertia(&model).try_inverse().unwrap() * error_force;
        d_squares += d.component_mul(&d);
    }
    let d_rms = (d_squares / report.samples.len() as f64).map(f64::sqrt);
    let omega = report.gains.frequencies_radps();
    let median_sigma = |i: usize| {
        let sigmas: Vec<f64> = report
            .estimates
            .iter()
            .filter_map(|e| e.covariance.map(|p| p[(i, i)].sqrt()))
            .collect();
        roitrack_core::stats::median(&sigmas)
    };
    let bound_m = (0..3)
        .map(|axis| {
            let w = omega[axis];
            (d_rms[axis] / (w * w) + median_sigma(axis) + 2.0 * median_sigma(6 + axis) / w).powi(2)
        })
        .sum::<f64>()
        .sqrt();
    1.5 * bound_m * 1e3
}

/// `ctc` on the ROI camera at 1 m/s with 0.1 px of noise added to each centroid, seeds 1-3: stable, and within the
/// bound of [`error_bound_mm`].
#[test]
fn computed_torque_told_its_acceleration_holds_the_path_at_a_tenth_of_a_pixel() {
    for seed in 1..=3 {
        let mut config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
        config.extra_centroid_noise_px = 0.1;
        config.seed = seed;
        assert!(config.known_acceleration, "on by default");
        let report = run_servo(&config).unwrap();
        assert!(report.stable, "seed {seed}: {:?}", report.stop_reason);
        let bound_mm = error_bound_mm(&config, &report);
        eprintln!(
            "seed {seed}: {:.4} mm RMS, {:.4} max, bound {bound_mm:.4}",
            report.rms_error_mm, report.max_error_mm
        );
        assert!(
            report.rms_error_mm <= bound_mm,
            "seed {seed}: {:.4} mm RMS against a bound of {bound_mm:.4}",
            report.rms_error_mm
        );
    }
}

/// What the computed-torque law tells the tracker is the acceleration it asked of its model: its model's forward
/// dynamics at the state it believed, for the forces it commanded (not clipped here), equal `a_ref + K_d (v_ref -
/// v̂) + K_p (p_ref - p̂)`; and the true robot, 25 % heavier than the model, accelerates otherwise.
#[test]
fn the_believed_acceleration_is_the_one_the_law_asked_of_its_model() {
    use nalgebra::Vector3;
    use roitrack_servo::control::{
        ComputedTorque, ControlInput, Controller, Gains, Observation, VelocitySource,
    };
    use roitrack_servo::reference::ReferencePoint;
    use roitrack_servo::robot::{RobotParams, acceleration};
    let robot = RobotParams::orthoglide();
    let model = robot.with_mass_factor(0.8).with_friction_factor(0.8);
    let gains = Gains::critically_damped(200.0).with_depth_factor(0.5);
    let mut ctc = ComputedTorque::new("ctc", model, gains, VelocitySource::Estimate);
    assert_eq!(ctc.believed_acceleration(&Vector3::zeros()), None);
    let (p, v) = (
        Vector3::new(0.02, -0.01, 0.03),
        Vector3::new(0.4, -0.3, 0.2),
    );
    let reference = ReferencePoint {
        position_m: Vector3::new(0.021, -0.0105, 0.0302),
        velocity_mps: Vector3::new(0.45, -0.28, 0.21),
        acceleration_mps2: Vector3::new(12.0, -7.0, 20.0),
    };
    let input = ControlInput {
        t_act_s: 0.5,
        dt_s: 2.5e-4,
        reference,
        observation: Some(Observation {
            t_s: 0.5,
            position_m: p,
            velocity_mps: v,
            acceleration_mps2: None,
        }),
        drive_joint_velocity_mps: Vector3::zeros(),
    };
    let force = ctc.command(&input);
    let asked = reference.acceleration_mps2
        + (reference.velocity_mps - v).component_mul(&gains.kd())
        + (reference.position_m - p).component_mul(&gains.kp());
    let believed = ctc.believed_acceleration(&force).unwrap();
    assert!(
        (believed - asked).amax() < 1e-9 * asked.amax(),
        "{believed} {asked}"
    );
    let true_acceleration = acceleration(&robot, &Geometry::at(&robot, &p).unwrap(), &v, &force);
    assert!((true_acceleration - believed).norm() > 0.1 * asked.norm());
}
