//! Tests of the filter's transition, readout Jacobians and refinement.

use super::*;

type Matrix18 = SMatrix<f64, 18, 18>;
type Vector18 = SMatrix<f64, 18, 1>;

fn moving() -> (MotionState, Acceleration) {
    (
        MotionState {
            cam_r_obj: Rotation3::from_euler_angles(0.1, -0.2, 0.3),
            cam_t_obj_m: Vector3::new(0.02, -0.01, 0.6),
            velocity_mps: Vector3::new(0.5, -0.3, 0.1),
            angular_velocity_radps: Vector3::new(2.0, -6.0, 1.0),
        },
        Acceleration {
            linear_mps2: Vector3::new(3.0, -12.0, 5.0),
            angular_radps2: Vector3::new(-40.0, 25.0, 60.0),
        },
    )
}

/// F, column by column: F applied to the unit vectors.
fn dense<const N: usize>(transition: &Transition) -> SMatrix<f64, N, N> {
    let mut f = SMatrix::<f64, N, N>::identity();
    for column in f.as_mut_slice().chunks_exact_mut(N) {
        transition.apply::<N>(column);
    }
    f
}

/// The 18-vector error between two (state, acceleration) pairs: `MotionState::difference`, then the
/// accelerations' difference.
fn difference(a: &(MotionState, Acceleration), b: &(MotionState, Acceleration)) -> Vector18 {
    let mut delta = Vector18::zeros();
    delta
        .fixed_rows_mut::<12>(0)
        .copy_from(&MotionState::difference(&a.0, &b.0));
    delta
        .fixed_rows_mut::<3>(12)
        .copy_from(&(b.1.linear_mps2 - a.1.linear_mps2));
    delta
        .fixed_rows_mut::<3>(15)
        .copy_from(&(b.1.angular_radps2 - a.1.angular_radps2));
    delta
}

fn corrected(
    (state, acceleration): &(MotionState, Acceleration),
    delta: &Vector18,
) -> (MotionState, Acceleration) {
    (
        state.corrected(&delta.fixed_rows::<12>(0).into_owned()),
        Acceleration {
            linear_mps2: acceleration.linear_mps2 + delta.fixed_rows::<3>(12),
            angular_radps2: acceleration.angular_radps2 + delta.fixed_rows::<3>(15),
        },
    )
}

#[test]
fn the_constant_acceleration_transition_matches_central_differences() {
    let start = moving();
    let predicted = |(state, acceleration): &(MotionState, Acceleration), dt_s: f64| {
        (acceleration.predicted(state, dt_s), *acceleration)
    };
    for dt_s in [0.015, -0.02, 1e-4] {
        let nominal = predicted(&start, dt_s);
        roitrack_testkit::jacobian::check_at(
            &format!("transition over {dt_s} s"),
            &start,
            &Vector18::repeat(1.0),
            |at, delta| difference(&nominal, &predicted(&corrected(at, delta), dt_s)),
            &dense::<18>(&Transition::new(&start.0, &start.1, dt_s)),
        );
    }
}

#[test]
fn without_accelerations_the_transition_is_the_states_own() {
    let (state, _) = moving();
    let still = Acceleration {
        linear_mps2: Vector3::zeros(),
        angular_radps2: Vector3::zeros(),
    };
    for dt_s in [0.015, -0.02] {
        let f = dense::<12>(&Transition::new(&state, &still, dt_s));
        assert!((f - state.transition_jacobian(dt_s)).amax() < 1e-15);
    }
}

#[test]
fn the_covariance_moves_as_f_p_f_transposed() {
    let (state, acceleration) = moving();
    let a = Matrix18::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 * 0.1 - 0.4);
    let p = a * a.transpose() + Matrix18::identity();
    for dt_s in [0.015, -0.02] {
        let transition = Transition::new(&state, &acceleration, dt_s);
        let f = dense::<18>(&transition);
        let mut moved = p;
        for column in moved.as_mut_slice().chunks_exact_mut(18) {
            transition.apply::<18>(column);
        }
        transition.apply_from_the_right::<18>(moved.as_mut_slice());
        let expected = f * p * f.transpose();
        assert!((moved - expected).amax() < 1e-12 * expected.amax());
    }
}

#[test]
fn the_filter_predicts_its_state_as_the_acceleration_does() {
    let (state, acceleration) = moving();
    let tuning = KalmanTuning {
        motion_model: MotionModel::constant_acceleration(),
        ..KalmanTuning::default()
    };
    let mut filter = ErrorStateKalman::<18>::new(Matrix12::identity(), tuning, 0.0);
    filter.acceleration = acceleration;
    let mut moved = state;
    filter.predict(&mut moved, 0.01, [1.0, 1.0]);
    let expected = acceleration.predicted(&state, 0.01);
    assert!(MotionState::difference(&moved, &expected).amax() < 1e-14);
}

/// The error-state correction (translation, rotation, velocity, angular velocity).
fn error_state(parts: [[f64; 3]; 4]) -> Vector12 {
    Vector12::from_iterator(parts.into_iter().flatten())
}

fn readout_blob(point_in_obj_m: Vector3<f64>, dt_s: f64) -> ReadoutMeasurement {
    ReadoutMeasurement {
        point_index: 0,
        point_in_obj_m,
        ideal_px: Vector2::zeros(),
        dt_s,
        variance_px2: 0.01,
        gated: false,
        used: true,
    }
}

#[test]
fn a_readout_blobs_jacobian_matches_central_differences() {
    // H F: the pixel at the blob's own time against the error state at the readout's first time.
    let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
    let start = moving();
    let point = Vector3::new(0.03, -0.02, 0.01);
    for dt_s in [0.0, 0.004, 0.03] {
        let m = readout_blob(point, dt_s);
        let (_, jacobian) = readout_projection::<18>(&model, &start.0, &start.1, &m).unwrap();
        let pixel = |at: &(MotionState, Acceleration)| {
            readout_projection::<18>(&model, &at.0, &at.1, &m)
                .unwrap()
                .0
        };
        roitrack_testkit::jacobian::check_at(
            &format!("readout blob {dt_s} s after the readout's start"),
            &start,
            &Vector18::repeat(1.0),
            |at, delta| pixel(&corrected(at, delta)),
            &jacobian,
        );
        // Without accelerations (the constant-velocity filter), the projection's own Jacobian at the blob's time
        // times the state's transition to it.
        let still = Acceleration {
            linear_mps2: Vector3::zeros(),
            angular_radps2: Vector3::zeros(),
        };
        let (_, twelve) = readout_projection::<12>(&model, &start.0, &still, &m).unwrap();
        let at_blob = start.0.predicted(dt_s);
        let h = model
            .project_with_jacobian(JacobianKind::Exact, &at_blob, &point, 0.0)
            .unwrap()
            .jacobian;
        let expected = h * start.0.transition_jacobian(dt_s);
        assert!(
            (twelve - expected).amax() < 1e-9 * expected.amax(),
            "dt {dt_s}"
        );
    }
}

#[test]
fn a_readout_far_from_a_wide_prior_is_refined_to_the_pose_its_blobs_show() {
    // Six blobs seen exactly, 15 mm and 0.1 rad from a prior of 1 m and 1 rad: the refinement finds the blobs'
    // pose (the prior's pull is a millionth of it), where the sequential updates stop short of it and reject
    // some of the blobs.
    let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
    let (truth, _) = moving();
    let truth = MotionState {
        velocity_mps: Vector3::zeros(),
        angular_velocity_radps: Vector3::zeros(),
        ..truth
    };
    let prior_state = truth.corrected(&error_state([
        [0.004, -0.003, 0.015],
        [0.06, 0.05, -0.06],
        [0.0; 3],
        [0.0; 3],
    ]));
    let mut pose_twist = Matrix12::identity();
    for i in 6..12 {
        pose_twist[(i, i)] = 1e-4;
    }
    let tuning = KalmanTuning {
        adapt_noise: false,
        adapt_motion: false,
        ..KalmanTuning::default()
    };
    let prior = ErrorStateKalman::<12>::new(pose_twist, tuning, 0.0);
    let points = [
        Vector3::new(-0.05, -0.04, 0.0),
        Vector3::new(0.05, -0.04, 0.0),
        Vector3::new(0.05, 0.04, 0.0),
        Vector3::new(-0.05, 0.04, 0.0),
        Vector3::new(0.0, 0.02, 0.0),
        Vector3::new(0.01, -0.01, 0.0),
    ];
    let mut readout: Vec<_> = points
        .iter()
        .map(|p| ReadoutMeasurement {
            ideal_px: model.project(&truth, p, 0.0).unwrap(),
            ..readout_blob(*p, 0.0)
        })
        .collect();
    let mut sequential = prior;
    let mut state = prior_state;
    for m in &mut readout {
        let outcome = sequential.update(
            &model,
            &mut state,
            &m.point_in_obj_m,
            &m.ideal_px,
            CentroidNoise::white(0.1),
            None,
        );
        m.gated = matches!(outcome, UpdateOutcome::Gated { .. });
        m.used = !m.gated;
    }
    // Linearised where the blobs before them left the state, later blobs look like outliers.
    let gated = readout.iter().filter(|m| m.gated).count();
    assert!(gated > 0);
    let sequential_error = MotionState::difference(&truth, &state)
        .fixed_rows::<6>(0)
        .amax();
    let mut refined = sequential;
    assert!(refined.refine(
        &prior,
        &prior_state,
        &mut state,
        0.0,
        &model,
        &mut readout,
        CentroidNoise::white(0.1),
        [1.0, 1.0],
    ));
    let error = MotionState::difference(&truth, &state)
        .fixed_rows::<6>(0)
        .amax();
    assert!(
        error < 1e-6,
        "refined {error:e}, sequential {sequential_error:e}, {gated} gated"
    );
    // The fit of all of them puts the blobs rejected one by one inside the gate.
    assert!(readout.iter().all(|m| m.used), "{gated} gated");
    assert!(
        sequential_error > 100.0 * error,
        "sequential {sequential_error:e}"
    );
    // The covariance is the fit's: the pose's variances far below the prior's, still symmetric.
    let c = refined.covariance;
    assert!((c - c.transpose()).amax() < 1e-12 * c.amax());
    assert!(
        (0..6).all(|i| c[(i, i)] < 1e-4),
        "{:?}",
        c.diagonal().as_slice()
    );
}

#[test]
fn a_rolling_readout_is_refined_to_fit_its_blobs() {
    // Sixteen blobs in four row bands read 1.5 ms apart (a rolling shutter) from a target moving at 0.4 m/s and
    // 3 rad/s, accelerating; the prior 10 mm and 0.05 rad off with a wide pose covariance, its twist near the
    // truth. The constant-acceleration filter's sequential updates stop short of the blobs; its refinement fits
    // them, each at its own time.
    let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
    let (truth, acceleration) = moving();
    let acceleration = Acceleration {
        linear_mps2: acceleration.linear_mps2 * 0.1,
        angular_radps2: acceleration.angular_radps2 * 0.1,
    };
    let truth = MotionState {
        velocity_mps: Vector3::new(0.4, -0.1, 0.05),
        angular_velocity_radps: Vector3::new(1.0, -2.5, 1.0),
        ..truth
    };
    let prior_state = truth.corrected(&error_state([
        [0.003, 0.002, 0.01],
        [-0.03, 0.04, 0.02],
        [0.03, -0.02, 0.02],
        [0.1, 0.1, -0.1],
    ]));
    let mut pose_twist = Matrix12::identity();
    for i in 6..12 {
        pose_twist[(i, i)] = if i < 9 { 0.05 * 0.05 } else { 0.2 * 0.2 };
    }
    let tuning = KalmanTuning {
        motion_model: MotionModel::constant_acceleration(),
        adapt_noise: false,
        adapt_motion: false,
        ..KalmanTuning::default()
    };
    let prior = ErrorStateKalman::<18>::new(pose_twist, tuning, 0.0);
    let mut readout: Vec<_> = (0..16)
        .map(|k| {
            let point = Vector3::new(
                0.05 * ((k % 4) as f64 - 1.5),
                0.04 * ((k / 4) as f64 - 1.5),
                0.0,
            );
            let dt_s = 0.0015 * (k / 4) as f64;
            ReadoutMeasurement {
                ideal_px: model
                    .project(&acceleration.predicted(&truth, dt_s), &point, 0.0)
                    .unwrap(),
                ..readout_blob(point, dt_s)
            }
        })
        .collect();
    // The residual (RMS, px) of a state at the readout's last time with its accelerations.
    let residual_px =
        |readout: &[ReadoutMeasurement], state: &MotionState, accel: &Acceleration, span_s: f64| {
            let at_first = accel.predicted(state, -span_s);
            let sum: f64 = readout
                .iter()
                .map(|m| {
                    let pixel = model
                        .project(&accel.predicted(&at_first, m.dt_s), &m.point_in_obj_m, 0.0)
                        .unwrap();
                    (m.ideal_px - pixel).norm_squared()
                })
                .sum();
            (sum / readout.len() as f64).sqrt()
        };
    // The sequential updates first, each blob at its own time.
    let (mut sequential, mut state, mut t_s) = (prior, prior_state, 0.0);
    for m in &mut readout {
        sequential.predict(&mut state, m.dt_s - t_s, [1.0, 1.0]);
        t_s = m.dt_s;
        let outcome = sequential.update(
            &model,
            &mut state,
            &m.point_in_obj_m,
            &m.ideal_px,
            CentroidNoise::white(0.1),
            None,
        );
        m.gated = matches!(outcome, UpdateOutcome::Gated { .. });
        m.used = !m.gated;
    }
    let span_s = t_s;
    let sequential_px = residual_px(&readout, &state, &sequential.acceleration, span_s);
    let mut refined = sequential;
    assert!(refined.refine(
        &prior,
        &prior_state,
        &mut state,
        span_s,
        &model,
        &mut readout,
        CentroidNoise::white(0.1),
        [1.0, 1.0],
    ));
    let refined_px = residual_px(&readout, &state, &refined.acceleration, span_s);
    assert!(
        // (0.0075 against 0.023 px: the prior's twist pulls the fit a little.)
        refined_px < 0.01 && sequential_px > 2.0 * refined_px,
        "refined {refined_px} px, sequential {sequential_px} px"
    );
    assert!(readout.iter().all(|m| m.used));
}

/// A 4-dot plate 0.5 m away, turned, on the canonical camera: the pose-innovation test's scene.
fn plate_scene() -> (SpatioTemporalModel, Vec<Vector3<f64>>, MotionState) {
    let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
    let points = [(-0.07, -0.06), (0.07, -0.06), (0.07, 0.06), (-0.07, 0.06)]
        .iter()
        .map(|&(x, y)| Vector3::new(x, y, 0.0))
        .collect();
    let truth = MotionState {
        cam_r_obj: Rotation3::from_euler_angles(0.2, -0.15, 0.3),
        cam_t_obj_m: Vector3::new(0.01, -0.02, 0.5),
        velocity_mps: Vector3::zeros(),
        angular_velocity_radps: Vector3::zeros(),
    };
    (model, points, truth)
}

/// The frame's pose innovation widens the covariance on about one frame in a thousand when the filter is right (its
/// belief drawn from its own covariance, the blobs from their white noise): the chi-square gate is the test's, not a
/// number fitted to the examples. Binomial(2000, 0.001): 9 or more widened frames has a probability of about 1e-4.
#[test]
fn the_pose_innovation_widens_a_right_filter_about_once_in_a_thousand_frames() {
    use rand::{Rng, SeedableRng};
    let (model, points, truth) = plate_scene();
    let sigmas = [
        5e-4, 5e-4, 5e-4, 1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0,
    ];
    let covariance =
        Matrix12::from_diagonal(&Vector12::from_iterator(sigmas.iter().map(|s| s * s)));
    let white_px = 0.1;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    // Box-Muller: a standard normal from two uniforms.
    let mut normal = move || -> f64 {
        let (u, v): (f64, f64) = (rng.random_range(f64::EPSILON..1.0), rng.random());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let mut widened = 0;
    for _ in 0..2000 {
        let delta = Vector12::from_fn(|i, _| sigmas[i] * normal());
        let belief = truth.corrected(&delta);
        let blobs: Vec<_> = points
            .iter()
            .map(|p| {
                let pixel = model.project(&truth, p, 0.0).unwrap();
                (
                    *p,
                    pixel + Vector2::new(normal(), normal()) * white_px,
                    white_px * white_px,
                )
            })
            .collect();
        let mut filter = ErrorStateKalman::<12>::new(covariance, KalmanTuning::default(), 0.0);
        let alpha = filter.match_pose_innovation(
            &model,
            &belief,
            blobs.into_iter(),
            POSE_INNOVATION_GATE_CHI2,
        );
        if alpha > 1.0 {
            widened += 1;
        }
    }
    assert!(widened <= 8, "{widened} of 2000 frames widened");
}

/// A filter sure of a pose 1 mm and half a degree off its frame's blobs is widened until the frame's pose
/// innovation is what its degrees of freedom expect, and then left alone.
#[test]
fn the_pose_innovation_widens_a_filter_too_sure_of_a_wrong_pose_to_its_expected_value() {
    let (model, points, truth) = plate_scene();
    let white_px = 0.1;
    let belief = truth.corrected(&Vector12::from_column_slice(&[
        1e-3, -5e-4, 0.0, 0.008, 0.0, -0.004, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    ]));
    let blobs = || {
        points.iter().map(move |p| {
            (
                *p,
                model.project(&truth, p, 0.0).unwrap(),
                white_px * white_px,
            )
        })
    };
    let tight = Matrix12::identity() * 1e-10;
    let mut filter = ErrorStateKalman::<12>::new(tight, KalmanTuning::default(), 0.0);
    let alpha = filter.match_pose_innovation(&model, &belief, blobs(), POSE_INNOVATION_GATE_CHI2);
    assert!(alpha > 100.0, "{alpha}");
    assert!((filter.covariance[(0, 0)] - 1e-10 * alpha).abs() < 1e-12 * alpha);
    // Now the innovation is at its expected 6, inside the gate: no second widening.
    assert_eq!(
        filter.match_pose_innovation(&model, &belief, blobs(), POSE_INNOVATION_GATE_CHI2),
        1.0
    );
    // And a filter as sure of the right pose is left alone.
    let mut right = ErrorStateKalman::<12>::new(tight, KalmanTuning::default(), 0.0);
    assert_eq!(
        right.match_pose_innovation(&model, &truth, blobs(), POSE_INNOVATION_GATE_CHI2),
        1.0
    );
}
