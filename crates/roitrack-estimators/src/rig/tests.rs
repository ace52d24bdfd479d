use nalgebra::{Rotation3, SMatrix, SVector, Vector3};
use rand::Rng;

use super::*;
use crate::{Estimator, Tracker, TrackerConfig};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::{SpatioTemporalModel, Target};

fn model() -> SpatioTemporalModel {
    let mut k = CameraModel::canonical().intrinsics;
    k.skew_px = 2.5;
    SpatioTemporalModel::new(k)
}

/// A mount `spread` from the identity (1: turned up to 0.8 rad, moved up to 0.4 m).
fn drawn_mount(rng: &mut rand_chacha::ChaCha8Rng, spread: f64) -> CameraMount {
    let mut v3 = |m: f64| {
        spread
            * Vector3::new(
                rng.random_range(-m..m),
                rng.random_range(-m..m),
                rng.random_range(-m..m),
            )
    };
    CameraMount::new(Rotation3::new(v3(0.8)), v3(0.4))
}

/// A rig state and a mount that puts the target in front of the camera: the state is drawn in the camera's frame
/// ([`roitrack_core::test_support::drawn_state`]) and carried into the rig's.
fn drawn_case(
    rng: &mut rand_chacha::ChaCha8Rng,
    spread: f64,
) -> (MotionState, CameraMount, ClockModel, usize, f64) {
    let camera_state = roitrack_core::test_support::drawn_state(rng, spread);
    let mount = drawn_mount(rng, spread);
    let clock = ClockModel {
        offset_s: rng.random_range(-0.05..0.05) * spread,
        drift_ppm: rng.random_range(-100.0..100.0) * spread,
    };
    let point = rng.random_range(0..16);
    let t_camera_s = rng.random_range(0.0..3.0);
    (
        mount.rig_state(&camera_state),
        mount,
        clock,
        point,
        t_camera_s,
    )
}

#[test]
fn a_mount_carries_states_and_corrections() {
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(3);
    for _ in 0..20 {
        let (rig_state, mount, ..) = drawn_case(&mut rng, 1.0);
        let back = mount.rig_state(&mount.camera_state(&rig_state));
        assert!(MotionState::difference(&rig_state, &back).norm() < 1e-12);
        // A correction of the rig's state is the rotated correction of the camera's.
        let delta = Vector12::from_fn(|i, _| 1e-3 * (i as f64 - 5.5));
        let via_rig = mount.camera_state(&rig_state.corrected(&delta));
        let via_camera = mount
            .camera_state(&rig_state)
            .corrected(&(mount.error_rotation() * delta));
        assert!(MotionState::difference(&via_rig, &via_camera).norm() < 1e-12);
    }
}

/// The rig projection's Jacobian w.r.t. the rig's state, the clock offset and the drift against central differences,
/// at mounts, clocks, points and camera times drawn around the identity and far from it.
#[test]
fn rig_jacobian_matches_central_differences() {
    let m = model();
    let points: Vec<Vector3<f64>> = Target::grid4x4()
        .points()
        .iter()
        .map(|p| p.point_in_obj_m)
        .collect();
    let mut scale = SVector::<f64, 14>::repeat(1.0);
    scale.fixed_rows_mut::<6>(6).fill(100.0);
    scale[12] = 1e-3;
    scale[13] = 100.0;
    // The reference time a few ms before the measurement's rig time, so that the twist's columns act too.
    let t_ref = |clock: &ClockModel, t_camera_s: f64| clock.rig_time_s(t_camera_s) - 4e-3;
    let pixel = |(state, mount, clock, point, t_camera_s): &(
        MotionState,
        CameraMount,
        ClockModel,
        usize,
        f64,
    ),
                 delta: &SVector<f64, 14>| {
        let moved = ClockModel {
            offset_s: clock.offset_s + delta[12],
            drift_ppm: clock.drift_ppm + delta[13],
        };
        let corrected = state.corrected(&delta.fixed_rows::<12>(0).into_owned());
        rig_projection(
            &m,
            mount,
            &moved,
            &corrected,
            &points[*point],
            *t_camera_s,
            t_ref(clock, *t_camera_s),
        )
        .unwrap()
        .pixel
    };
    roitrack_testkit::check_jacobian(
        "rig projection Jacobian",
        (
            MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6)),
            CameraMount::IDENTITY,
            ClockModel::REFERENCE,
            0,
            1.0,
        ),
        drawn_case,
        &scale,
        pixel,
        |(state, mount, clock, point, t_camera_s)| {
            let p = rig_projection(
                &m,
                mount,
                clock,
                state,
                &points[*point],
                *t_camera_s,
                t_ref(clock, *t_camera_s),
            )
            .unwrap();
            let mut j = SMatrix::<f64, 2, 14>::zeros();
            j.fixed_columns_mut::<12>(0).copy_from(&p.jacobian);
            j.set_column(12, &p.image_velocity_pxps);
            j.set_column(13, &p.per_drift_px);
            j
        },
    );
}

#[test]
fn the_identity_mount_projects_as_the_camera() {
    let m = model();
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(5);
    for _ in 0..20 {
        let state = roitrack_core::test_support::drawn_state(&mut rng, 1.0);
        let p = Vector3::new(0.03, -0.02, 0.0);
        let camera = m
            .project_with_jacobian(roitrack_core::JacobianKind::Exact, &state, &p, 0.0)
            .unwrap();
        let rig = rig_projection(
            &m,
            &CameraMount::IDENTITY,
            &ClockModel::REFERENCE,
            &state,
            &p,
            2.0,
            2.0,
        )
        .unwrap();
        assert_eq!(rig.pixel, camera.pixel);
        assert_eq!(rig.jacobian, camera.jacobian);
    }
}

#[test]
fn clocks_invert() {
    let clock = ClockModel {
        offset_s: -0.037,
        drift_ppm: -85.0,
    };
    for t in [0.0, 0.5, 1e3] {
        assert!((clock.camera_time_s(clock.rig_time_s(t)) - t).abs() < 1e-12);
    }
    assert!(ClockModel::REFERENCE.is_reference() && !clock.is_reference());
}

#[test]
fn bad_rigs_are_refused() {
    let cam = |name: &str| {
        RigCamera::known(
            name,
            CameraModel::canonical(),
            CameraMount::IDENTITY,
            ClockModel::REFERENCE,
        )
    };
    assert_eq!(Rig::new(vec![]), Err(RigDefinitionError::Empty));
    let mut unknown = cam("a");
    unknown.offset_known = false;
    assert!(matches!(
        Rig::new(vec![unknown.clone(), cam("b")]),
        Err(RigDefinitionError::ReferenceClockUnknown { .. })
    ));
    assert!(Rig::new(vec![cam("b"), unknown]).is_ok());
    let mut fast = cam("c");
    fast.clock.drift_ppm = 5000.0;
    assert!(
        Rig::new(vec![cam("b"), fast])
            .unwrap_err()
            .to_string()
            .contains("'c'")
    );
}

/// Noise-free measurements of the built-in scene, one point every 250 µs, moving at 0.1 m/s.
fn stream(n: usize) -> Vec<Measurement> {
    let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
    let mut truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
    truth.velocity_mps = Vector3::new(0.1, 0.0, 0.0);
    let order = bit_reversed_indices(16);
    (0..n)
        .map(|k| {
            let t_s = k as f64 * 250e-6;
            let point = &target.points()[order[k % 16]];
            let px = camera
                .raw_pixel_from_cam(&truth.point_in_cam_at(&point.point_in_obj_m, t_s))
                .unwrap();
            let noise = 0.1 * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
            Measurement {
                t_s,
                id: point.id,
                u_px: px.x + noise,
                v_px: px.y - noise,
            }
        })
        .collect()
}

#[test]
fn a_one_camera_rig_is_the_single_camera_tracker() {
    let config = RigTrackerConfig::default();
    let mut single = Tracker::new(
        CameraModel::canonical(),
        Target::grid4x4(),
        TrackerConfig::default(),
    )
    .unwrap();
    let mut rig = RigTracker::new(
        Rig::single("cam", CameraModel::canonical()),
        Target::grid4x4(),
        config,
    )
    .unwrap();
    let mut compared = 0;
    for m in stream(2000) {
        let a = single.push(&m).unwrap();
        let b = rig
            .push(&RigMeasurement {
                camera: 0,
                measurement: m,
            })
            .unwrap();
        assert_eq!(a, b.into_iter().next().map(|e| e.estimate));
        compared += usize::from(a.is_some());
    }
    assert!(compared > 150);
}
