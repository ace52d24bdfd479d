//! Alignment, clock offset and relative pose error on a real tracking run: estimates moved into another frame (a
//! rotation, a translation, a scale) and onto another clock are brought back by `--align sim3 --time-offset auto` to
//! the figures of the untouched run; the relative pose error does not see the frame at all.

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};
use roitrack_core::{PoseSample, TwistSample};
use roitrack_estimators::{TrackerConfig, track_all};
use roitrack_eval::{
    Alignment, EvalError, EvalOptions, Metrics, SimilarityTransform, TimeOffset, evaluate,
    samples_of,
};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};

struct Run {
    truth: (Vec<PoseSample>, Vec<TwistSample>),
    estimates: (Vec<PoseSample>, Vec<TwistSample>),
}

fn tracked(kind: ScenarioKind) -> Run {
    let run = simulate(&Scenario::new(kind, 1), &SimulationOptions::default()).unwrap();
    let (estimates, _) = track_all(
        &run.camera,
        &run.target,
        TrackerConfig::default(),
        &run.measurements,
    )
    .unwrap();
    Run {
        truth: (run.truth_poses, run.truth_twists),
        estimates: samples_of(&estimates),
    }
}

fn metrics(
    run: &Run,
    estimates: &(Vec<PoseSample>, Vec<TwistSample>),
    opts: &EvalOptions,
) -> Result<Metrics, EvalError> {
    evaluate(
        &run.truth.0,
        Some(&run.truth.1),
        &estimates.0,
        Some(&estimates.1),
        opts,
    )
}

/// The estimates in another frame (`p -> s R p + t`) and on a clock `offset_s` behind.
fn moved(
    estimates: &(Vec<PoseSample>, Vec<TwistSample>),
    transform: &SimilarityTransform,
    offset_s: f64,
) -> (Vec<PoseSample>, Vec<TwistSample>) {
    (
        estimates
            .0
            .iter()
            .map(|p| {
                let mut q = transform.pose(p);
                q.t_s -= offset_s;
                q
            })
            .collect(),
        estimates
            .1
            .iter()
            .map(|t| {
                let mut q = transform.twist(t);
                q.t_s -= offset_s;
                q
            })
            .collect(),
    )
}

#[test]
fn sim3_and_auto_offset_undo_another_frame_and_clock() {
    let run = tracked(ScenarioKind::Orthoglide);
    let plain = metrics(&run, &run.estimates, &EvalOptions::default()).unwrap();
    let elsewhere = SimilarityTransform {
        rotation: Rotation3::from_euler_angles(0.4, -1.1, 2.0),
        translation_m: Vector3::new(1.2, -0.4, 2.5),
        scale: 1.02,
    };
    let offset_s = 0.0371;
    let far = moved(&run.estimates, &elsewhere, offset_s);
    // As they are, the moved estimates are metres off (and partly outside the truth's span).
    let skip = EvalOptions {
        skip_outside_truth: true,
        ..EvalOptions::default()
    };
    assert!(metrics(&run, &far, &skip).unwrap().position_rmse_mm > 1000.0);
    let opts = EvalOptions {
        alignment: Alignment::Sim3,
        time_offset: TimeOffset::Auto,
        skip_outside_truth: true,
        ..EvalOptions::default()
    };
    let back = metrics(&run, &far, &opts).unwrap();
    assert!(
        (back.time_offset_s - offset_s).abs() < 0.5e-3,
        "offset {} s against {offset_s} s",
        back.time_offset_s
    );
    assert!((back.alignment_scale - 1.0 / 1.02).abs() < 1e-3, "{back:?}");
    assert!(
        back.position_rmse_mm < 1.2 * plain.position_rmse_mm + 0.02,
        "{} mm against {} mm untouched",
        back.position_rmse_mm,
        plain.position_rmse_mm
    );
    // The alignment is fitted to positions only (as evo's is): its rotation carries their noise over the
    // trajectory's extent, a few hundredths of a degree here (0.079 against 0.047 deg).
    assert!(
        back.rotation_rmse_deg < plain.rotation_rmse_deg + 0.05,
        "{back:?} {plain:?}"
    );
    let (v, v_plain) = (
        back.velocity_rmse_mm_s.unwrap(),
        plain.velocity_rmse_mm_s.unwrap(),
    );
    assert!(v < 1.3 * v_plain + 2.0, "{v} mm/s against {v_plain} mm/s");
    // A rigid alignment cannot absorb the scale: 2 % of a 0.6 m distance is left.
    let rigid = metrics(
        &run,
        &far,
        &EvalOptions {
            alignment: Alignment::Se3,
            ..opts
        },
    )
    .unwrap();
    assert!(
        rigid.position_rmse_mm > 3.0 * back.position_rmse_mm,
        "{rigid:?}"
    );
}

#[test]
fn relative_pose_error_is_the_same_in_any_frame() {
    let run = tracked(ScenarioKind::Spin);
    let opts = EvalOptions {
        rpe_interval_s: Some(0.1),
        ..EvalOptions::default()
    };
    let plain = metrics(&run, &run.estimates, &opts).unwrap();
    let frame = SimilarityTransform {
        rotation: Rotation3::from_euler_angles(-0.3, 0.2, 0.9),
        translation_m: Vector3::new(-0.5, 0.1, 0.3),
        scale: 1.0,
    };
    // A change of the camera frame: camera_T_object becomes other_T_camera * camera_T_object.
    let other = Isometry3::from_parts(
        Translation3::from(frame.translation_m),
        UnitQuaternion::from_rotation_matrix(&frame.rotation),
    );
    let seen_elsewhere = (
        run.estimates
            .0
            .iter()
            .map(|p| PoseSample {
                t_s: p.t_s,
                cam_from_obj: other * p.cam_from_obj,
            })
            .collect::<Vec<_>>(),
        run.estimates.1.clone(),
    );
    let elsewhere = metrics(&run, &seen_elsewhere, &opts).unwrap();
    assert!(elsewhere.position_rmse_mm > 100.0);
    let (a, b) = (
        plain.rpe_translation_rmse_mm.unwrap(),
        elsewhere.rpe_translation_rmse_mm.unwrap(),
    );
    assert!((a - b).abs() < 1e-9 * a.max(1.0), "{a} against {b}");
    assert!(
        (plain.rpe_rotation_rmse_deg.unwrap() - elsewhere.rpe_rotation_rmse_deg.unwrap()).abs()
            < 1e-6
    );
    assert!(plain.rpe_pairs.unwrap() > 100);
    // The estimates' own error over 0.1 s is a fraction of a millimetre and of a degree.
    assert!(
        a < 2.0 && plain.rpe_rotation_rmse_deg.unwrap() < 0.5,
        "{plain:?}"
    );
}

#[test]
fn a_still_target_cannot_be_aligned() {
    let run = tracked(ScenarioKind::Static);
    let err = metrics(
        &run,
        &run.estimates,
        &EvalOptions {
            alignment: Alignment::Se3,
            ..EvalOptions::default()
        },
    );
    // A still target's estimates scatter by noise: the fit is either refused as degenerate or harmless, never a
    // wrong answer with a large rotation.
    match err {
        Err(EvalError::DegenerateAlignment { .. }) => {}
        Ok(m) => assert!(m.position_rmse_mm < 1.0, "{m:?}"),
        Err(other) => panic!("{other}"),
    }
    let offset = metrics(
        &run,
        &run.estimates,
        &EvalOptions {
            time_offset: TimeOffset::Auto,
            ..EvalOptions::default()
        },
    );
    assert!(
        matches!(offset, Err(EvalError::TimeOffsetNotFound { .. })) || offset.is_ok(),
        "{offset:?}"
    );
}
