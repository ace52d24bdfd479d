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

/// The sequential update of the readout's measurement `m` (0.1 px of white noise), marked gated or used as
/// [`ErrorStateKalman::refine`] takes it.
fn update_and_mark<const N: usize>(
    filter: &mut ErrorStateKalman<N>,
    model: &SpatioTemporalModel,
    state: &mut MotionState,
    m: &mut ReadoutMeasurement,
) {
    let outcome = filter.update(
        model,
        state,
        &m.point_in_obj_m,
        &m.ideal_px,
        CentroidNoise::white(0.1),
        None,
    );
    m.gated = matches!(outcome, UpdateOutcome::Gated { .. });
    m.used = !m.gated;
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
        update_and_mark(&mut sequential, &model, &mut state, m);
    }
    // Linearised where the blobs before them left the state, later blobs look like outliers.
    let gated = readout.iter().filter(|m| m.gated).count();
    assert!(gated > 0);
    let sequential_error = MotionState::difference(&truth, &state)
        .fixed_rows::<6>(0)
        .amax();
    let mut refined = sequential;
    let fit = ReadoutFit {
        prior_state: &prior_state,
        span_s: 0.0,
        model: &model,
        noise: CentroidNoise::white(0.1),
        process_scale: [1.0, 1.0],
    };
    assert!(refined.refine(&prior, &fit, &mut state, &mut readout));
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
        update_and_mark(&mut sequential, &model, &mut state, m);
    }
    let span_s = t_s;
    let sequential_px = residual_px(&readout, &state, &sequential.acceleration, span_s);
    let mut refined = sequential;
    let fit = ReadoutFit {
        prior_state: &prior_state,
        span_s,
        model: &model,
        noise: CentroidNoise::white(0.1),
        process_scale: [1.0, 1.0],
    };
    assert!(refined.refine(&prior, &fit, &mut state, &mut readout));
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

/// Bench pose, moving: the known input's tests start from it.
fn known_input(linear: [f64; 3], angular: [f64; 3]) -> Acceleration {
    Acceleration {
        linear_mps2: Vector3::from(linear),
        angular_radps2: Vector3::from(angular),
    }
}

/// A known linear acceleration moves the state as the acceleration does and leaves the covariance's propagation as
/// it was: bit for bit when one input is in force over the whole step, to round-off when the step is cut where the
/// input changes (the pieces' `F` compose to the whole step's, and so do their `Q`).
#[test]
fn a_known_linear_acceleration_moves_the_state_and_leaves_the_covariance() {
    let (state, _) = moving();
    let u = known_input([30.0, -12.0, 45.0], [0.0; 3]);
    let a = Matrix12::from_fn(|i, j| ((i * 7 + j * 3) % 11) as f64 * 0.1 - 0.4);
    let p = a * a.transpose() * 1e-4 + Matrix12::identity() * 1e-6;
    let dt_s = 2.5e-4;
    let plain = {
        let mut f = ErrorStateKalman::<12>::new(p, KalmanTuning::default(), 0.1);
        let mut s = state;
        f.predict(&mut s, dt_s, [1.0, 1.0]);
        (f, s)
    };
    // One input, in force before the step: the same covariance, bit for bit; the state moved by the input.
    let mut known = KnownAcceleration::default();
    known.set(-1.0, u).unwrap();
    let mut f = ErrorStateKalman::<12>::new(p, KalmanTuning::default(), 0.1);
    let mut s = state;
    f.predict_known(&mut s, 0.3, dt_s, [1.0, 1.0], &known);
    assert_eq!(f.covariance, plain.0.covariance);
    assert_eq!(f.last_dt_s, plain.0.last_dt_s);
    let expected = u.predicted(&state, dt_s);
    assert!((s.cam_t_obj_m - expected.cam_t_obj_m).amax() < 1e-15);
    assert!((s.velocity_mps - expected.velocity_mps).amax() < 1e-15);
    assert_eq!(s.cam_r_obj, plain.1.cam_r_obj);
    // The input changing twice within the step: cut in three, each piece with its own input. Without rotation
    // (with it, the process noise of the rotation, whose model takes the rotation increment as small, differs
    // between one step and three by a fraction of the order of |W dt|).
    let v = known_input([-20.0, 5.0, 0.0], [0.0; 3]);
    let mut changing = KnownAcceleration::default();
    for (t, input) in [(0.0, u), (0.3001, v), (0.3002, u)] {
        changing.set(t, input).unwrap();
    }
    let still = MotionState {
        angular_velocity_radps: Vector3::zeros(),
        ..state
    };
    let mut whole = ErrorStateKalman::<12>::new(p, KalmanTuning::default(), 0.1);
    whole.predict(&mut still.clone(), dt_s, [1.0, 1.0]);
    let mut f = ErrorStateKalman::<12>::new(p, KalmanTuning::default(), 0.1);
    let mut s = still;
    f.predict_known(&mut s, 0.3, dt_s, [1.0, 1.0], &changing);
    assert!((f.covariance - whole.covariance).amax() < 1e-12 * p.amax());
    assert_eq!(f.last_dt_s, dt_s);
    let by_pieces = [(1e-4, u), (1e-4, v), (0.5e-4, u)]
        .iter()
        .fold(still, |at, (d, input)| input.predicted(&at, *d));
    assert!((s.cam_t_obj_m - by_pieces.cam_t_obj_m).amax() < 1e-15);
    assert!((s.velocity_mps - by_pieces.velocity_mps).amax() < 1e-14);
    // And a constant-acceleration filter adds the input to its own acceleration, which the prediction leaves.
    let tuning = KalmanTuning {
        motion_model: MotionModel::constant_acceleration(),
        ..KalmanTuning::default()
    };
    let own = known_input([1.0, 2.0, -3.0], [0.0; 3]);
    let mut f = ErrorStateKalman::<18>::new(p, tuning, 0.1);
    f.acceleration = own;
    let mut g = f;
    let mut s = state;
    f.predict_known(&mut s, 0.3, dt_s, [1.0, 1.0], &known);
    let mut s_plain = state;
    g.predict(&mut s_plain, dt_s, [1.0, 1.0]);
    assert_eq!(f.covariance, g.covariance);
    assert_eq!(f.acceleration, own);
    let total = known::sum(&own, &u);
    assert!((s.velocity_mps - total.predicted(&state, dt_s).velocity_mps).amax() < 1e-15);
}

/// With a known angular acceleration, `F` changes (its rotation blocks are those of the increment `W dt + ½ Α dt²`):
/// checked against central differences of the prediction, and against the `F` without the input.
#[test]
fn a_known_angular_acceleration_enters_the_transition_as_central_differences_say() {
    let (state, _) = moving();
    let u = known_input([3.0, -1.0, 2.0], [-400.0, 250.0, 600.0]);
    for dt_s in [0.015, -0.02, 2.5e-4] {
        let nominal = u.predicted(&state, dt_s);
        let analytic = dense::<12>(&Transition::new(&state, &u, dt_s));
        roitrack_testkit::jacobian::check_at(
            &format!("transition with a known angular acceleration over {dt_s} s"),
            &state,
            &Vector12::repeat(1.0),
            |at, delta| MotionState::difference(&nominal, &u.predicted(&at.corrected(delta), dt_s)),
            &analytic,
        );
        let without = state.transition_jacobian(dt_s);
        assert!((analytic - without).amax() > 1e-3 * dt_s.abs(), "{dt_s}");
    }
}

#[test]
fn known_accelerations_are_refused_out_of_order_or_not_finite_and_pieced_in_order() {
    let u = known_input([1.0, 0.0, 0.0], [0.0; 3]);
    let v = known_input([2.0, 0.0, 0.0], [0.0; 3]);
    let mut known = KnownAcceleration::default();
    known.set(1.0, u).unwrap();
    known.set(2.0, v).unwrap();
    assert!(matches!(
        known.set(1.5, u),
        Err(KnownAccelerationError::OutOfOrder { .. })
    ));
    assert!(matches!(
        known.set(3.0, known_input([f64::NAN, 0.0, 0.0], [0.0; 3])),
        Err(KnownAccelerationError::NotFinite { .. })
    ));
    // The same time replaces.
    known.set(2.0, u).unwrap();
    assert_eq!(known.at(2.5), u);
    assert_eq!(known.at(0.5), known::zero_acceleration());
    let mut pieces = Vec::new();
    known.for_each_piece(0.5, 2.0, |d, a| pieces.push((d, a.linear_mps2.x)));
    assert_eq!(pieces, vec![(0.5, 0.0), (1.0, 1.0), (0.5, 1.0)]);
    pieces.clear();
    known.for_each_piece(2.5, -2.0, |d, a| pieces.push((d, a.linear_mps2.x)));
    assert_eq!(pieces, vec![(-0.5, 1.0), (-1.0, 1.0), (-0.5, 0.0)]);
    known.forget_before(2.2);
    assert_eq!(known.at(2.2), u);
    let mut full = KnownAcceleration::default();
    for k in 0..KNOWN_ACCELERATION_CAPACITY {
        full.set(k as f64, u).unwrap();
    }
    assert!(matches!(
        full.set(1e9, u),
        Err(KnownAccelerationError::TooMany { .. })
    ));
}

/// A target accelerating hard (up to 45 m/s², its acceleration a new value every 250 µs as a 4 kHz controller
/// commands it), seen one blob at a time at 4 kHz with 0.1 px of noise, tracked by the filter of the servo loop
/// (process noise fixed at 1 (m/s²)²/Hz), told the noise.
struct Accelerating {
    measurements: Vec<Measurement>,
    /// Per 250 µs tick: its start time, the state then and the acceleration over it.
    ticks: Vec<(f64, MotionState, Acceleration)>,
}

const TICK_S: f64 = 2.5e-4;

impl Accelerating {
    fn new(seed: u64, duration_s: f64) -> Self {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let target = Target::grid4x4();
        let camera = CameraModel::canonical();
        let mut state = MotionState::bench();
        let (mut measurements, mut ticks) = (Vec::new(), Vec::new());
        let n = (duration_s / TICK_S).round() as usize;
        let phase: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..std::f64::consts::TAU));
        for k in 0..n {
            let t = k as f64 * TICK_S;
            let w = [7.0, 5.0, 11.0].map(|f| std::f64::consts::TAU * f);
            let a = Vector3::new(
                20.0 * (w[0] * t + phase[0]).sin(),
                15.0 * (w[1] * t + phase[1]).sin(),
                45.0 * (w[2] * t + phase[2]).sin(),
            );
            let acceleration = known_input([a.x, a.y, a.z], [0.0; 3]);
            ticks.push((t, state, acceleration));
            // One blob a tick, at its mid-exposure 50 µs in, the points in turn.
            let t_blob = t + 5e-5;
            let at = acceleration.predicted(&state, 5e-5);
            let point = &target.points()[k % target.len()];
            let pixel = camera
                .raw_pixel_from_cam(&(at.cam_r_obj * point.point_in_obj_m + at.cam_t_obj_m))
                .unwrap();
            let mut gauss = || {
                // Box-Muller.
                let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
                (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
            };
            measurements.push(Measurement {
                t_s: t_blob,
                id: point.id,
                u_px: pixel.x + 0.1 * gauss(),
                v_px: pixel.y + 0.1 * gauss(),
            });
            state = acceleration.predicted(&state, TICK_S);
        }
        Self {
            measurements,
            ticks,
        }
    }

    /// The true state and acceleration at `t_s`.
    fn truth(&self, t_s: f64) -> (MotionState, Acceleration) {
        let k = ((t_s / TICK_S).floor() as usize).min(self.ticks.len() - 1);
        let (t0, state, acceleration) = self.ticks[k];
        (acceleration.predicted(&state, t_s - t0), acceleration)
    }
}

/// What a run of the filter gives: the velocity's lag behind the truth (s) by least squares, `-Σ e·a / Σ a·a` over
/// the estimates after the first 0.1 s, with its standard deviation from the filter's own velocity covariance (the
/// errors counted as independent over the filter's time constant only); the mean normalised innovation squared
/// (2 for a consistent filter) and the fraction of innovations beyond the gate.
struct LagAndInnovations {
    lag_s: f64,
    lag_sigma_s: f64,
    mean_nis: f64,
    innovations: usize,
    gated_fraction: f64,
}

fn run_accelerating(scene: &Accelerating, told: bool) -> LagAndInnovations {
    let tuning = KalmanTuning {
        adapt_motion: false,
        adapt_noise: false,
        ..KalmanTuning::default()
    };
    let config = TrackerConfig {
        noise_px: 0.1,
        ..TrackerConfig::default()
    };
    let mut kalman =
        KalmanEstimator::new(CameraModel::canonical(), Target::grid4x4(), config, tuning).unwrap();
    let (mut nis_sum, mut nis_count, mut beyond) = (0.0, 0usize, 0usize);
    let (mut ea, mut aa, mut var_aa) = (0.0, 0.0, 0.0);
    let mut time_constants = Vec::new();
    if told {
        let (t, _, a) = scene.ticks[0];
        kalman.set_known_acceleration(t, a).unwrap();
    }
    for (k, m) in scene.measurements.iter().enumerate() {
        if told && let Some((t, _, a)) = scene.ticks.get(k + 1) {
            // The acceleration of the tick after this one, told a tick ahead, as a controller's command.
            kalman.set_known_acceleration(*t, *a).unwrap();
        }
        let running = kalman.state().is_some();
        let estimate = kalman.push(m).unwrap();
        if running && m.t_s > 0.1 {
            let nis = kalman.0.law.newest_nis;
            nis_sum += nis;
            nis_count += 1;
            beyond += usize::from(nis > tuning.gate_sigma * tuning.gate_sigma);
        }
        let Some(e) = estimate.filter(|e| e.t_ref_s > 0.1) else {
            continue;
        };
        let (truth, a) = scene.truth(e.t_ref_s);
        let error = e.state.velocity_mps - truth.velocity_mps;
        let p = e.covariance.unwrap();
        ea += error.dot(&a.linear_mps2);
        aa += a.linear_mps2.norm_squared();
        var_aa += (0..3)
            .map(|i| p[(6 + i, 6 + i)] * a.linear_mps2[i].powi(2))
            .sum::<f64>();
        let pose: f64 = (0..3).map(|i| p[(i, i)]).sum();
        let twist: f64 = (6..9).map(|i| p[(i, i)]).sum();
        time_constants.push((pose / twist).sqrt());
    }
    // Errors a time constant apart are about independent: each counts as many estimates as fall in two of them.
    let time_constant_s = roitrack_core::stats::median(&time_constants);
    let every_s = 10.0 * TICK_S;
    let correlated = (2.0 * time_constant_s / every_s).max(1.0);
    LagAndInnovations {
        lag_s: -ea / aa,
        lag_sigma_s: (var_aa * correlated).sqrt() / aa,
        mean_nis: nis_sum / nis_count as f64,
        innovations: nis_count,
        gated_fraction: beyond as f64 / nis_count as f64,
    }
}

/// Told the target's acceleration (a new value every 250 µs, a tick ahead), the filter's velocity does not lag:
/// its least-squares lag is within 4 standard deviations of zero by its own covariance; without it, the same filter
/// lags by more than that. Its innovations are consistent: their mean normalised square within 4 standard errors of
/// 2 (χ² of 2 dof: standard error `2 / √n`; the filter assumes process noise the input leaves none of, so it may
/// sit below), and the fraction beyond the 3 σ gate within 4 standard errors of a χ²₂'s `e^-4.5` (1.1 %).
#[test]
fn a_filter_told_the_true_acceleration_does_not_lag_and_its_innovations_are_consistent() {
    for seed in [1, 2] {
        let scene = Accelerating::new(seed, 1.0);
        let told = run_accelerating(&scene, true);
        let blind = run_accelerating(&scene, false);
        eprintln!(
            "seed {seed}: told lag {:.3} ms (σ {:.3}), NIS {:.3}, gated {:.4}; blind lag {:.3} ms (σ {:.3}), NIS {:.3}, gated {:.4}",
            told.lag_s * 1e3,
            told.lag_sigma_s * 1e3,
            told.mean_nis,
            told.gated_fraction,
            blind.lag_s * 1e3,
            blind.lag_sigma_s * 1e3,
            blind.mean_nis,
            blind.gated_fraction
        );
        assert!(
            told.lag_s.abs() <= 4.0 * told.lag_sigma_s,
            "seed {seed}: told, the velocity lags {:.3} ms (σ {:.3} ms)",
            told.lag_s * 1e3,
            told.lag_sigma_s * 1e3
        );
        assert!(
            blind.lag_s > 4.0 * blind.lag_sigma_s,
            "seed {seed}: blind, the velocity lags only {:.3} ms (σ {:.3} ms)",
            blind.lag_s * 1e3,
            blind.lag_sigma_s * 1e3
        );
        let n = told.innovations as f64;
        assert!(
            told.mean_nis <= 2.0 + 4.0 * 2.0 / n.sqrt(),
            "seed {seed}: mean NIS {:.3} over {n}",
            told.mean_nis
        );
        let p_gate = (-4.5f64).exp();
        let gate_se = (p_gate * (1.0 - p_gate) / n).sqrt();
        assert!(
            told.gated_fraction <= p_gate + 4.0 * gate_se,
            "seed {seed}: {:.4} beyond the gate",
            told.gated_fraction
        );
    }
}
