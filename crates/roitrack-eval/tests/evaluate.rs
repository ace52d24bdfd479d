//! End-to-end checks of `evaluate` on synthetic trajectories with known errors.

use std::f64::consts::TAU;

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};
use roitrack_core::{PoseSample, TwistSample};
use roitrack_eval::{EvalError, EvalOptions, Metrics, evaluate};

/// Ground-truth rate (Hz) and the estimator's decimation of it (400 Hz estimates, as in the paper).
const TRUTH_RATE_HZ: f64 = 4000.0;
const DECIMATION: usize = 10;
const DURATION_S: f64 = 3.0;

/// A smooth motion whose velocity varies in amplitude and frequency, so the velocity cross-correlation has one
/// clear peak: a chirped circle of radius 5 cm at 0.6 m depth, bobbing in depth, rocking about a fixed axis.
fn motion(t: f64) -> (PoseSample, TwistSample) {
    let radius = 0.05;
    let phase = TAU * (0.5 * t + 0.3 * t * t);
    let phase_rate = TAU * (0.5 + 0.6 * t);
    let (bob, bob_rate) = (TAU * 0.7, 0.02);
    let position = Vector3::new(
        radius * phase.cos(),
        radius * phase.sin(),
        0.6 + bob_rate * (bob * t).sin(),
    );
    let velocity = Vector3::new(
        -radius * phase.sin() * phase_rate,
        radius * phase.cos() * phase_rate,
        bob_rate * bob * (bob * t).cos(),
    );
    let axis = Vector3::new(1.0, 2.0, 3.0).normalize();
    let (rock, amplitude) = (TAU * 0.4, 0.3);
    let angle = amplitude * (rock * t).sin();
    let angle_rate = amplitude * rock * (rock * t).cos();
    let base = Rotation3::from_euler_angles(0.1, -0.2, 0.3);
    // R(t) = Exp(angle u) R0 about a fixed camera-frame axis u: W = angle' u.
    let rotation = Rotation3::new(axis * angle) * base;
    (
        pose(t, UnitQuaternion::from_rotation_matrix(&rotation), position),
        TwistSample {
            t_s: t,
            velocity_mps: velocity,
            angular_velocity_radps: axis * angle_rate,
        },
    )
}

fn pose(t_s: f64, rotation: UnitQuaternion<f64>, position: Vector3<f64>) -> PoseSample {
    PoseSample {
        t_s,
        cam_from_obj: Isometry3::from_parts(Translation3::from(position), rotation),
    }
}

/// The truth at 4 kHz over a few seconds.
fn truth() -> (Vec<PoseSample>, Vec<TwistSample>) {
    let n = (DURATION_S * TRUTH_RATE_HZ) as usize + 1;
    (0..n).map(|i| motion(i as f64 / TRUTH_RATE_HZ)).unzip()
}

/// The estimated twists at the times of `twists[delay..]`, each reporting the value `delay` samples earlier.
fn delayed(twists: &[TwistSample], delay: usize) -> Vec<TwistSample> {
    (delay..twists.len())
        .map(|k| TwistSample {
            t_s: twists[k].t_s,
            ..twists[k - delay]
        })
        .collect()
}

/// Every `DECIMATION`-th element.
fn decimate<T: Copy>(samples: &[T]) -> Vec<T> {
    samples.iter().step_by(DECIMATION).copied().collect()
}

fn run(
    truth: &(Vec<PoseSample>, Vec<TwistSample>),
    est_poses: &[PoseSample],
    est_twists: Option<&[TwistSample]>,
) -> Result<Metrics, EvalError> {
    evaluate(
        &truth.0,
        Some(&truth.1),
        est_poses,
        est_twists,
        &EvalOptions::default(),
    )
}

fn assert_close(actual: f64, expected: f64, tolerance: f64, what: &str) {
    assert!(
        (actual - expected).abs() <= tolerance,
        "{what}: {actual} != {expected} (± {tolerance})"
    );
}

#[test]
fn truth_against_itself_has_no_error_and_no_lag() {
    let truth = truth();
    for (poses, twists) in [
        (truth.0.clone(), truth.1.clone()),
        (decimate(&truth.0), decimate(&truth.1)),
    ] {
        let m = run(&truth, &poses, Some(&twists)).unwrap();
        assert_eq!(m.count, poses.len());
        assert_close(m.duration_s, DURATION_S, 1e-9, "duration");
        assert_eq!(m.position_rmse_mm, 0.0);
        assert_eq!(m.position_rmse_xyz_mm, [0.0; 3]);
        assert_eq!(m.max_position_error_mm, 0.0);
        assert_close(m.rotation_rmse_deg, 0.0, 1e-12, "rotation");
        assert_eq!(m.velocity_rmse_mm_s, Some(0.0));
        assert_eq!(m.velocity_rmse_xyz_mm_s, Some([0.0; 3]));
        assert_eq!(m.angular_velocity_rmse_deg_s, Some(0.0));
        assert_eq!(m.velocity_lag_samples, Some(0));
        assert_close(
            m.velocity_lag_subsample.unwrap(),
            0.0,
            1e-3,
            "subsample lag",
        );
        assert_eq!(m.velocity_lag_ms, Some(0.0));
    }
}

#[test]
fn delayed_velocity_gives_its_lag() {
    let truth = truth();
    let (poses, twists) = (decimate(&truth.0), decimate(&truth.1));
    for delay in [3_usize, 1, 7] {
        // The estimate reports at time t_k the truth's twist of t_(k - delay).
        let m = run(&truth, &poses[delay..], Some(&delayed(&twists, delay))).unwrap();
        assert_eq!(m.velocity_lag_samples, Some(delay as i64));
        assert_close(
            m.velocity_lag_subsample.unwrap(),
            delay as f64,
            0.2,
            "subsample lag",
        );
        assert_close(m.estimator_period_ms, 2.5, 1e-9, "period");
        assert_close(
            m.velocity_lag_ms.unwrap(),
            2.5 * delay as f64,
            1e-9,
            "lag ms",
        );
        assert!(m.velocity_rmse_mm_s.unwrap() > 0.0);
        assert_eq!(m.position_rmse_mm, 0.0);
    }
}

#[test]
fn leading_velocity_gives_a_negative_lag() {
    let truth = truth();
    let (poses, twists) = (decimate(&truth.0), decimate(&truth.1));
    let lead = 2;
    let n = twists.len() - lead;
    let est_twists: Vec<TwistSample> = (0..n)
        .map(|k| TwistSample {
            t_s: twists[k].t_s,
            ..twists[k + lead]
        })
        .collect();
    let m = run(&truth, &poses[..n], Some(&est_twists)).unwrap();
    assert_eq!(m.velocity_lag_samples, Some(-(lead as i64)));
    assert_close(
        m.velocity_lag_subsample.unwrap(),
        -2.0,
        0.2,
        "subsample lag",
    );
}

#[test]
fn constant_position_offset() {
    let truth = truth();
    let offset = Vector3::new(1.0, 2.0, 2.0) * 1e-3;
    let est: Vec<PoseSample> = decimate(&truth.0)
        .into_iter()
        .map(|mut p| {
            p.cam_from_obj.translation.vector += offset;
            p
        })
        .collect();
    let m = run(&truth, &est, None).unwrap();
    assert_close(m.position_rmse_mm, 3.0, 1e-9, "position RMSE");
    for (axis, expected) in m.position_rmse_xyz_mm.iter().zip([1.0, 2.0, 2.0]) {
        assert_close(*axis, expected, 1e-9, "per-axis position RMSE");
    }
    assert_close(m.max_position_error_mm, 3.0, 1e-9, "max position error");
    assert_close(m.rotation_rmse_deg, 0.0, 1e-12, "rotation");
    assert_eq!(m.velocity_rmse_mm_s, None);
    assert_eq!(m.velocity_lag_samples, None);
}

#[test]
fn constant_rotation_offset() {
    let truth = truth();
    let offset = UnitQuaternion::from_scaled_axis(
        Vector3::new(-0.3, 0.5, 0.8).normalize() * 2f64.to_radians(),
    );
    // The offset's side does not matter: camera frame (left) or object frame (right).
    for on_the_left in [true, false] {
        let est: Vec<PoseSample> = decimate(&truth.0)
            .into_iter()
            .map(|mut p| {
                let r = p.cam_from_obj.rotation;
                p.cam_from_obj.rotation = if on_the_left { offset * r } else { r * offset };
                p
            })
            .collect();
        let m = run(&truth, &est, None).unwrap();
        assert_close(m.rotation_rmse_deg, 2.0, 1e-9, "rotation RMSE");
        assert_close(m.position_rmse_mm, 0.0, 1e-12, "position");
    }
}

#[test]
fn twist_errors_are_in_mm_s_and_deg_s() {
    let truth = truth();
    let (poses, mut twists) = (decimate(&truth.0), decimate(&truth.1));
    for twist in &mut twists {
        twist.velocity_mps += Vector3::new(0.0, 0.003, -0.004);
        twist.angular_velocity_radps += Vector3::new(1.5f64.to_radians(), 0.0, 0.0);
    }
    let m = run(&truth, &poses, Some(&twists)).unwrap();
    assert_close(m.velocity_rmse_mm_s.unwrap(), 5.0, 1e-9, "velocity RMSE");
    let xyz = m.velocity_rmse_xyz_mm_s.unwrap();
    for (axis, expected) in xyz.iter().zip([0.0, 3.0, 4.0]) {
        assert_close(*axis, expected, 1e-9, "per-axis velocity RMSE");
    }
    assert_close(
        m.angular_velocity_rmse_deg_s.unwrap(),
        1.5,
        1e-9,
        "angular velocity RMSE",
    );
    // A constant bias does not shift the correlation peak.
    assert_eq!(m.velocity_lag_samples, Some(0));
}

#[test]
fn estimates_between_truth_samples_are_compared_with_the_interpolated_truth() {
    // Constant twist: linear translation and rotation about a fixed axis at a constant rate, which linear
    // interpolation and slerp reproduce exactly.
    let velocity = Vector3::new(0.2, -0.1, 0.05);
    let angular_velocity = Vector3::new(0.4, 1.0, -0.7);
    let base = UnitQuaternion::from_euler_angles(0.5, 0.1, -0.4);
    let sample = |t: f64| {
        (
            pose(
                t,
                UnitQuaternion::from_scaled_axis(angular_velocity * t) * base,
                Vector3::new(0.01, 0.02, 0.6) + velocity * t,
            ),
            TwistSample {
                t_s: t,
                velocity_mps: velocity,
                angular_velocity_radps: angular_velocity,
            },
        )
    };
    let (truth_poses, truth_twists): (Vec<_>, Vec<_>) =
        (0..=100).map(|i| sample(i as f64 * 0.01)).unzip();
    let (est_poses, est_twists): (Vec<_>, Vec<_>) =
        (0..100).map(|i| sample((i as f64 + 0.5) * 0.01)).unzip();
    let m = evaluate(
        &truth_poses,
        Some(&truth_twists),
        &est_poses,
        Some(&est_twists),
        &EvalOptions::default(),
    )
    .unwrap();
    assert_eq!(m.count, 100);
    assert_close(m.max_position_error_mm, 0.0, 1e-9, "max position error");
    assert_close(m.rotation_rmse_deg, 0.0, 1e-9, "rotation RMSE");
    assert_close(m.velocity_rmse_mm_s.unwrap(), 0.0, 1e-9, "velocity RMSE");
    assert_close(
        m.angular_velocity_rmse_deg_s.unwrap(),
        0.0,
        1e-9,
        "angular velocity RMSE",
    );

    // Interpolation really happens: the same estimates without it (a nearest-sample lookup) would be 1 mm off.
    assert!(velocity.norm() * 0.005 * 1e3 > 1.0);
}

#[test]
fn empty_inputs_are_errors() {
    let truth = truth();
    let opts = EvalOptions::default();
    assert_eq!(
        evaluate(&[], None, &truth.0, None, &opts),
        Err(EvalError::Empty {
            what: "truth poses"
        })
    );
    let err = evaluate(&truth.0, None, &[], None, &opts).unwrap_err();
    assert_eq!(
        err,
        EvalError::Empty {
            what: "estimated poses"
        }
    );
    assert_eq!(err.to_string(), "no estimated poses: nothing to evaluate");
}

#[test]
fn an_estimate_outside_the_truth_span_is_an_error() {
    let truth = truth();
    let mut est = decimate(&truth.0);
    let last = *est.last().unwrap();
    est.push(PoseSample {
        t_s: last.t_s + 0.01,
        ..last
    });
    let err = run(&truth, &est, None).unwrap_err();
    let EvalError::OutsideTruthSpan {
        index,
        t_s,
        start_s,
        end_s,
    } = err
    else {
        panic!("unexpected error {err:?}");
    };
    assert_eq!(index, est.len() - 1);
    assert_close(t_s, DURATION_S + 0.01, 1e-12, "time");
    assert_eq!(start_s, 0.0);
    assert_close(end_s, DURATION_S, 1e-12, "span end");
    let message = err.to_string();
    assert!(
        message.contains("3.01") && message.contains("[0, 3]"),
        "{message}"
    );
}

#[test]
fn unordered_times_are_errors() {
    let truth = truth();
    let mut est = decimate(&truth.0);
    est.swap(4, 5);
    let err = run(&truth, &est, None).unwrap_err();
    assert!(
        matches!(
            err,
            EvalError::NonIncreasingTime {
                what: "estimated poses",
                index: 5,
                ..
            }
        ),
        "{err:?}"
    );

    let mut bad_truth = truth.0.clone();
    bad_truth[10].t_s = bad_truth[9].t_s;
    let err = evaluate(&bad_truth, None, &est, None, &EvalOptions::default()).unwrap_err();
    assert!(
        matches!(
            err,
            EvalError::NonIncreasingTime {
                what: "truth poses",
                index: 10,
                ..
            }
        ),
        "{err:?}"
    );

    let mut nan = decimate(&truth.0);
    nan[0].t_s = f64::NAN;
    let err = run(&truth, &nan, None).unwrap_err();
    assert!(
        matches!(err, EvalError::NonFiniteTime { index: 0, .. }),
        "{err:?}"
    );
}

#[test]
fn twists_must_match_their_poses() {
    let truth = truth();
    let (poses, twists) = (decimate(&truth.0), decimate(&truth.1));

    let err = run(&truth, &poses, Some(&twists[1..])).unwrap_err();
    assert_eq!(
        err,
        EvalError::TwistCountMismatch {
            what: "estimated twists",
            poses: poses.len(),
            twists: poses.len() - 1
        }
    );

    let mut shifted = twists.clone();
    shifted[7].t_s += 1e-3;
    let err = run(&truth, &poses, Some(&shifted)).unwrap_err();
    assert_eq!(
        err,
        EvalError::TwistTimeMismatch {
            what: "estimated twists",
            index: 7,
            pose_t_s: poses[7].t_s,
            twist_t_s: shifted[7].t_s
        }
    );
    assert!(err.to_string().contains("twist 7"), "{err}");

    let err = evaluate(
        &truth.0,
        Some(&twists),
        &poses,
        None,
        &EvalOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            EvalError::TwistCountMismatch {
                what: "truth twists",
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn velocity_metrics_need_twists_on_both_sides() {
    let truth = truth();
    let (poses, twists) = (decimate(&truth.0), decimate(&truth.1));
    let m = evaluate(
        &truth.0,
        None,
        &poses,
        Some(&twists),
        &EvalOptions::default(),
    )
    .unwrap();
    assert_eq!(m.velocity_rmse_mm_s, None);
    assert_eq!(m.velocity_lag_samples, None);
    assert_close(m.estimator_period_ms, 2.5, 1e-9, "period");
}

#[test]
fn invalid_time_gap_is_an_error() {
    let truth = truth();
    let opts = EvalOptions {
        max_time_gap_s: -1.0,
        ..EvalOptions::default()
    };
    let err = evaluate(&truth.0, None, &truth.0, None, &opts).unwrap_err();
    assert!(matches!(
        err,
        EvalError::InvalidOption {
            name: "max_time_gap_s",
            ..
        }
    ));
}

#[test]
fn table_and_json_show_every_metric() {
    let truth = truth();
    let (poses, twists) = (decimate(&truth.0), decimate(&truth.1));
    let m = run(&truth, &poses[3..], Some(&delayed(&twists, 3))).unwrap();

    let json: serde_json::Value = serde_json::from_str(&m.to_json()).unwrap();
    let object = json.as_object().unwrap();
    for key in [
        "count",
        "duration_s",
        "estimator_period_ms",
        "position_rmse_mm",
        "position_rmse_xyz_mm",
        "max_position_error_mm",
        "rotation_rmse_deg",
        "velocity_rmse_mm_s",
        "velocity_rmse_xyz_mm_s",
        "angular_velocity_rmse_deg_s",
        "velocity_lag_samples",
        "velocity_lag_subsample",
        "velocity_lag_ms",
        "time_offset_s",
        "alignment",
        "alignment_scale",
        "alignment_rotation_deg",
        "alignment_translation_mm",
        "skipped_outside_truth",
        "rpe_interval_s",
        "rpe_pairs",
        "rpe_translation_rmse_mm",
        "rpe_rotation_rmse_deg",
    ] {
        assert!(object.contains_key(key), "missing {key} in {json}");
    }
    assert_eq!(object.len(), 23);
    assert_eq!(json["alignment"], "none");
    assert_eq!(json["velocity_lag_samples"], 3);
    assert!(!m.to_json().contains('\n'));
    let back: Metrics = serde_json::from_str(&m.to_json()).unwrap();
    assert_eq!(back, m);

    let table = m.to_table();
    let lines: Vec<&str> = table.lines().collect();
    assert!(lines[0].starts_with("metric"));
    assert!(table.contains("velocity lag") && table.contains("samples") && table.contains("deg/s"));
    // The value column is right-aligned: every row's value ends at the same column.
    let value_end = |line: &str| {
        line.trim_end_matches(|c: char| c.is_alphabetic() || c == '/')
            .trim_end()
            .len()
    };
    let end = value_end(lines[1]);
    assert!(lines.iter().skip(1).all(|l| value_end(l) == end), "{table}");

    let without = run(&truth, &poses, None).unwrap();
    assert!(!without.to_table().contains("velocity"));
    let json: serde_json::Value = serde_json::from_str(&without.to_json()).unwrap();
    assert!(json["velocity_lag_ms"].is_null());
}
