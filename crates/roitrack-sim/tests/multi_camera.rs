//! Many asynchronous cameras, one pose and velocity: the rig tracker on random seeded rigs of 2 to 4 cameras around
//! the built-in scene, each camera's clock offset and drift unknown to it.

use nalgebra::Vector3;
use roitrack_core::{Measurement, MotionState};
use roitrack_estimators::rig::{
    ClockEstimate, Rig, RigCamera, RigEstimate, RigTracker, RigTrackerConfig,
};
use roitrack_estimators::{Estimator, TrackStatus, Tracker, TrackerConfig};
use roitrack_sim::multi_camera::{CameraRigScene, RigRun, simulate_rig};
use roitrack_sim::{Scenario, ScenarioKind};

/// Every measurement of `run` pushed to `tracker`, merged by the cameras' own clocks, and the estimates to the end.
fn push_all(tracker: &mut RigTracker, run: &RigRun) -> Vec<RigEstimate> {
    let mut estimates = Vec::new();
    for m in run.merged_by_own_clocks() {
        estimates.extend(tracker.push(&m).unwrap());
    }
    estimates.extend(tracker.finish());
    estimates
}

/// The fused estimates and the final clocks.
fn track_rig(rig: Rig, run: &RigRun) -> (Vec<RigEstimate>, Vec<ClockEstimate>) {
    let mut tracker = RigTracker::new(
        rig,
        roitrack_core::Target::grid4x4(),
        RigTrackerConfig::default(),
    )
    .unwrap();
    let estimates = push_all(&mut tracker, run);
    let clocks = tracker.clocks();
    (estimates, clocks)
}

/// A camera's own single-camera tracker of the grid, default settings.
fn own_tracker(camera: &RigCamera) -> Tracker {
    Tracker::new(
        camera.camera.clone(),
        roitrack_core::Target::grid4x4(),
        TrackerConfig::default(),
    )
    .unwrap()
}

/// One camera alone: its estimates in the rig's frame and on the rig's clock (the true clock).
fn track_single(scene: &CameraRigScene, run: &RigRun, c: usize) -> Vec<(f64, MotionState)> {
    let camera = &scene.rig.cameras()[c];
    let mut tracker = own_tracker(camera);
    run.measurements[c]
        .iter()
        .filter_map(|m: &Measurement| tracker.push(m).unwrap())
        .filter(|e| e.status.is_vouched_for())
        .map(|e| {
            (
                camera.clock.rig_time_s(e.t_ref_s),
                camera.mount.rig_state(&e.state),
            )
        })
        .collect()
}

/// RMS of the position error along a camera's optical axis (depth) and across it (lateral), over estimates after
/// `after_s` (m).
fn depth_lateral_rms_m(
    scene: &CameraRigScene,
    estimates: &[(f64, MotionState)],
    axis: &Vector3<f64>,
    after_s: f64,
) -> (f64, f64, usize) {
    let (mut depth2, mut lateral2, mut n) = (0.0, 0.0, 0);
    for (t, state) in estimates.iter().filter(|(t, _)| *t >= after_s) {
        let error = state.cam_t_obj_m - scene.scenario.state_at(*t).cam_t_obj_m;
        let depth = error.dot(axis);
        depth2 += depth * depth;
        lateral2 += (error - axis * depth).norm_squared();
        n += 1;
    }
    let n_f = n.max(1) as f64;
    ((depth2 / n_f).sqrt(), (lateral2 / n_f / 2.0).sqrt(), n)
}

/// The `estimates` within half an estimate interval (the median of `times_s`' steps) of one of `times_s` (in time
/// order): those made at the instants another tracker has estimates for.
fn at_the_same_instants(
    estimates: &[(f64, MotionState)],
    times_s: &[f64],
) -> Vec<(f64, MotionState)> {
    let mut steps: Vec<f64> = times_s.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let half_step_s = steps.get(steps.len() / 2).copied().unwrap_or(0.0) / 2.0;
    estimates
        .iter()
        .filter(|(t, _)| {
            let k = times_s.partition_point(|s| s < t);
            [k.checked_sub(1), Some(k)]
                .into_iter()
                .flatten()
                .filter_map(|i| times_s.get(i))
                .any(|s| (s - t).abs() <= half_step_s)
        })
        .copied()
        .collect()
}

struct Case {
    seed: u64,
    cameras: usize,
    best_depth_m: f64,
    best_lateral_m: f64,
    fused_depth_m: f64,
    fused_lateral_m: f64,
    offset_errors_s: Vec<f64>,
    drift_errors_ppm: Vec<f64>,
    offset_sigmas_s: Vec<f64>,
    drift_sigmas_ppm: Vec<f64>,
}

/// A random rig of `cameras` around the random scene of `seed` (its first `duration_s` seconds), tracked with the
/// clocks unknown (or `known`); the best single camera and the fused estimate scored after the first second.
fn run_case(seed: u64, cameras: usize, known: bool, duration_s: f64) -> Case {
    let scenario = Scenario::new(ScenarioKind::Random, seed).with_duration_s(duration_s);
    let scene = CameraRigScene::random(scenario, cameras, seed);
    let run = simulate_rig(&scene, 4000.0, 0.1, seed).unwrap();
    let told = if known {
        scene.rig.clone()
    } else {
        scene.rig_with_clocks_unknown()
    };
    let (fused, clocks) = track_rig(told, &run);
    let fused: Vec<(f64, MotionState)> = fused
        .iter()
        .filter(|e| e.estimate.status.is_vouched_for())
        .map(|e| (e.estimate.t_ref_s, e.estimate.state))
        .collect();
    let after_s = 1.0;
    // The best single camera: the smallest depth RMSE along its own axis.
    let mut best: Option<(f64, f64, Vector3<f64>, Vec<f64>)> = None;
    for c in 0..cameras {
        let axis = scene.rig.cameras()[c].mount.camera_r_rig.inverse() * Vector3::z();
        let single = track_single(&scene, &run, c);
        let (depth, lateral, n) = depth_lateral_rms_m(&scene, &single, &axis, after_s);
        assert!(n > 100, "seed {seed} camera {c}: {n} estimates");
        if best.as_ref().is_none_or(|(d, ..)| depth < *d) {
            best = Some((
                depth,
                lateral,
                axis,
                single.iter().map(|(t, _)| *t).collect(),
            ));
        }
    }
    let (best_depth_m, best_lateral_m, axis, best_times_s) = best.unwrap();
    // Scored where the best camera has estimates: where the target leaves its view (seen edge-on or past the image's
    // edge) it gives none, and the fused estimates there rest on the other cameras alone.
    let fused = at_the_same_instants(&fused, &best_times_s);
    let (fused_depth_m, fused_lateral_m, n) = depth_lateral_rms_m(&scene, &fused, &axis, after_s);
    assert!(n > 100, "seed {seed}: {n} fused estimates");
    let truth: Vec<_> = scene.rig.cameras().iter().map(|c| c.clock).collect();
    let case = Case {
        seed,
        cameras,
        best_depth_m,
        best_lateral_m,
        fused_depth_m,
        fused_lateral_m,
        offset_errors_s: (1..cameras)
            .map(|c| clocks[c].offset_s - truth[c].offset_s)
            .collect(),
        drift_errors_ppm: (1..cameras)
            .map(|c| clocks[c].drift_ppm - truth[c].drift_ppm)
            .collect(),
        offset_sigmas_s: (1..cameras).map(|c| clocks[c].offset_sigma_s).collect(),
        drift_sigmas_ppm: (1..cameras).map(|c| clocks[c].drift_sigma_ppm).collect(),
    };
    println!(
        "seed {seed}, {} cameras, clocks {}: best camera depth {:.4} mm, lateral {:.4} mm; fused depth {:.4} mm, \
         lateral {:.4} mm; offset errors {:?} us (sigmas {:?}); drift errors {:?} ppm (sigmas {:?})",
        case.cameras,
        if known { "known" } else { "unknown" },
        case.best_depth_m * 1e3,
        case.best_lateral_m * 1e3,
        case.fused_depth_m * 1e3,
        case.fused_lateral_m * 1e3,
        case.offset_errors_s
            .iter()
            .map(|e| (e * 1e7).round() / 10.0)
            .collect::<Vec<_>>(),
        case.offset_sigmas_s
            .iter()
            .map(|e| (e * 1e7).round() / 10.0)
            .collect::<Vec<_>>(),
        case.drift_errors_ppm
            .iter()
            .map(|e| (e * 10.0).round() / 10.0)
            .collect::<Vec<_>>(),
        case.drift_sigmas_ppm
            .iter()
            .map(|e| (e * 10.0).round() / 10.0)
            .collect::<Vec<_>>(),
    );
    case
}

/// Seeds of the random rigs: 2, 3 or 4 cameras in turn.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=9;

fn cameras_of(seed: u64) -> usize {
    2 + (seed as usize % 3)
}

/// The mean of `values` and its standard error.
fn mean_and_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Depth: the fused estimate's error along the best single camera's axis is at most a third of that camera's own, on
/// every seed. Lateral: the ratio of the fused lateral RMSE to the best camera's, averaged over the seeds, is not
/// above 1 by more than twice its standard error (the seeds' spread), and no seed's is above 1.5.
fn check_accuracy(cases: &[Case]) {
    for case in cases {
        assert!(
            case.fused_depth_m <= case.best_depth_m / 3.0,
            "seed {}: fused depth {} m against the best camera's {} m",
            case.seed,
            case.fused_depth_m,
            case.best_depth_m
        );
    }
    let ratios: Vec<f64> = cases
        .iter()
        .map(|c| c.fused_lateral_m / c.best_lateral_m)
        .collect();
    let (mean, error) = mean_and_error(&ratios);
    assert!(mean - 2.0 * error <= 1.0, "lateral ratios {ratios:?}");
    assert!(
        ratios.iter().all(|&r| r <= 1.5),
        "lateral ratios {ratios:?}"
    );
}

#[test]
fn fused_depth_is_a_third_of_the_best_cameras_with_clocks_unknown() {
    let cases: Vec<Case> = SEEDS
        .map(|seed| run_case(seed, cameras_of(seed), false, 4.0))
        .collect();
    check_accuracy(&cases);
}

#[test]
fn fused_depth_is_a_third_of_the_best_cameras_with_clocks_known() {
    let cases: Vec<Case> = SEEDS
        .map(|seed| run_case(seed, cameras_of(seed), true, 4.0))
        .collect();
    check_accuracy(&cases);
}

/// Every unknown clock offset is learnt within 20 µs over the 4 s of the random scene, and every drift to within a
/// fifth of the ±100 ppm it starts from; the share of offsets within 20 µs and of drifts within 5 ppm after 2 s and
/// after 4 s is printed (docs/results.md).
#[test]
fn clocks_are_learnt_from_the_measurements() {
    for duration_s in [2.0, 4.0] {
        let (mut offsets, mut drifts) = (Vec::new(), Vec::new());
        for seed in SEEDS {
            let case = run_case(seed, cameras_of(seed), false, duration_s);
            offsets.extend(case.offset_errors_s);
            drifts.extend(case.drift_errors_ppm);
        }
        let within = |v: &[f64], target: f64| v.iter().filter(|e| e.abs() <= target).count();
        println!(
            "after {duration_s} s: offsets within 20 us: {} of {}; drifts within 5 ppm: {} of {}",
            within(&offsets, 20e-6),
            offsets.len(),
            within(&drifts, 5.0),
            drifts.len()
        );
        if duration_s == 4.0 {
            assert!(offsets.iter().all(|e| e.abs() <= 20e-6), "{offsets:?}");
            assert!(drifts.iter().all(|e| e.abs() <= 20.0), "{drifts:?}");
        }
    }
}

/// The target hidden from every camera but one for 0.5 s (its measurements of [1.5, 2.0) s of rig time removed): the
/// fused track goes on over the one camera and takes the others back, with no new track and no disputed estimate;
/// during the stretch it is no worse than that camera's own track beyond the spread of its errors.
#[test]
fn a_target_hidden_from_all_but_one_camera_is_tracked_on() {
    for (seed, visible) in [(4, 0), (4, 1), (7, 2), (5, 3)] {
        let cameras = cameras_of(seed);
        let scenario = Scenario::new(ScenarioKind::Random, seed);
        let scene = CameraRigScene::random(scenario, cameras, seed);
        let mut run = simulate_rig(&scene, 4000.0, 0.1, seed).unwrap();
        let hidden = |t_rig: f64| (1.5..2.0).contains(&t_rig);
        for (c, list) in run.measurements.iter_mut().enumerate() {
            let clock = scene.rig.cameras()[c].clock;
            if c != visible {
                list.retain(|m| !hidden(clock.rig_time_s(m.t_s)));
            }
        }
        let mut tracker = RigTracker::new(
            scene.rig_with_clocks_unknown(),
            roitrack_core::Target::grid4x4(),
            RigTrackerConfig::default(),
        )
        .unwrap();
        let estimates = push_all(&mut tracker, &run);
        let report = tracker.report();
        let not_vouched: Vec<(f64, &str)> = estimates
            .iter()
            .filter(|e| e.estimate.t_ref_s > 1.0 && !e.estimate.status.is_vouched_for())
            .map(|e| (e.estimate.t_ref_s, e.estimate.status.name()))
            .collect();
        // The fused error in the stretch against the visible camera's own.
        let errors = |list: &[(f64, MotionState)]| -> Vec<f64> {
            list.iter()
                .filter(|(t, _)| hidden(*t))
                .map(|(t, s)| (s.cam_t_obj_m - scene.scenario.state_at(*t).cam_t_obj_m).norm())
                .collect()
        };
        let fused: Vec<(f64, MotionState)> = estimates
            .iter()
            .map(|e| (e.estimate.t_ref_s, e.estimate.state))
            .collect();
        let single = track_single(&scene, &run, visible);
        let rms = |v: &[f64]| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
        let (fused_m, single_m) = (rms(&errors(&fused)), rms(&errors(&single)));
        println!(
            "seed {seed}, {cameras} cameras, only camera {visible} sees 1.5-2.0 s: fused {:.4} mm, that camera alone {:.4} \
             mm; {} starts; not vouched after 1 s: {not_vouched:?}; camera counts {:?}",
            fused_m * 1e3,
            single_m * 1e3,
            report.starts,
            tracker.camera_counts()
        );
        assert_eq!(
            report.starts, 1,
            "seed {seed}: the fused track was started again"
        );
        assert!(not_vouched.is_empty(), "seed {seed}: {not_vouched:?}");
        assert!(
            fused_m <= 1.5 * single_m,
            "seed {seed}: {fused_m} against {single_m}"
        );
    }
}

/// Every camera of the random rigs loses the target for 0.5 s and finds it again: its own tracker, predicting over the
/// gap, vouches for no estimate more than 10 mm off (the acceptance bound a user holds a `tracking` pose to), and
/// takes the target back. (One came back 394 mm off, marked tracking, on the two measurements after the gap.)
#[test]
fn a_camera_back_from_a_gap_vouches_for_no_far_estimate() {
    for seed in SEEDS {
        let scene = CameraRigScene::random(
            Scenario::new(ScenarioKind::Random, seed),
            cameras_of(seed),
            seed,
        );
        let mut run = simulate_rig(&scene, 4000.0, 0.1, seed).unwrap();
        for (c, list) in run.measurements.iter_mut().enumerate() {
            let clock = scene.rig.cameras()[c].clock;
            list.retain(|m| !(1.5..2.0).contains(&clock.rig_time_s(m.t_s)));
        }
        for c in 0..scene.rig.len() {
            let camera = &scene.rig.cameras()[c];
            let mut tracker = own_tracker(camera);
            let (mut far, mut back) = (Vec::new(), false);
            for m in &run.measurements[c] {
                let Some(e) = tracker.push(m).unwrap() else {
                    continue;
                };
                let t_s = camera.clock.rig_time_s(e.t_ref_s);
                let error_m = (camera.mount.rig_state(&e.state).cam_t_obj_m
                    - scene.scenario.state_at(t_s).cam_t_obj_m)
                    .norm();
                if e.status.is_vouched_for() && error_m > 0.010 {
                    far.push((t_s, error_m, e.status.name()));
                }
                back |= t_s > 2.0 && e.status == TrackStatus::Tracking;
            }
            assert!(far.is_empty(), "seed {seed}, camera {c}: {far:?}");
            assert!(
                back,
                "seed {seed}, camera {c}: never tracking again after the gap"
            );
        }
    }
}

/// A camera whose clock is off by more than the search (0.3 s against ±0.1 s) is refused, naming it, instead of
/// being fused at a wrong offset.
#[test]
fn a_clock_beyond_the_search_is_refused_naming_the_camera() {
    for seed in [1, 2, 3] {
        let scenario = Scenario::new(ScenarioKind::Random, seed);
        let mut scene = CameraRigScene::random(scenario, 2, seed);
        let mut cameras = scene.rig.cameras().to_vec();
        cameras[1].clock.offset_s = 0.3;
        scene.rig = Rig::new(cameras).unwrap();
        let run = simulate_rig(&scene, 4000.0, 0.1, seed).unwrap();
        let mut tracker = RigTracker::new(
            scene.rig_with_clocks_unknown(),
            roitrack_core::Target::grid4x4(),
            RigTrackerConfig::default(),
        )
        .unwrap();
        let error = run
            .merged_by_own_clocks()
            .iter()
            .find_map(|m| tracker.push(m).err())
            .map(|e| e.to_string());
        println!("seed {seed}: {error:?}");
        let error = error.expect("refused");
        assert!(
            error.contains("camera 'cam1'") && error.contains("never matches"),
            "{error}"
        );
    }
}

/// The rig tracker tuned as `track --images` tunes it for frames (the process noise held, the noise learnt from the
/// frames, the cameras' own trackers on a constant acceleration).
fn frame_rig_config() -> RigTrackerConfig {
    use roitrack_estimators::{EstimatorConfig, MotionModel, NoiseSample};
    let mut tracker_config = TrackerConfig::default();
    let EstimatorConfig::Kalman(tuning) = &mut tracker_config.estimator else {
        unreachable!()
    };
    tuning.adapt_motion = false;
    tuning.calibrate_twist_covariance = false;
    tuning.noise_sample = NoiseSample::Frames;
    tuning.motion_model = MotionModel::constant_acceleration();
    RigTrackerConfig {
        tracker: tracker_config,
        ..RigTrackerConfig::default()
    }
}

/// The largest position (m) and rotation (rad) error of the estimates vouched for.
fn worst_vouched(scene: &CameraRigScene, estimates: &[&RigEstimate]) -> (f64, f64) {
    estimates
        .iter()
        .filter(|e| e.estimate.status.is_vouched_for())
        .map(|e| {
            let truth = scene.scenario.state_at(e.estimate.t_ref_s);
            (
                (e.estimate.state.cam_t_obj_m - truth.cam_t_obj_m).norm(),
                roitrack_core::so3::log(&(e.estimate.state.cam_r_obj * truth.cam_r_obj.inverse()))
                    .norm(),
            )
        })
        .fold((0.0, 0.0), |(m, r), (em, er)| {
            (f64::max(m, em), f64::max(r, er))
        })
}

/// 30 Hz global-shutter cameras of the random scene triggered together, seeds 1-4, every clock but the first to be
/// learnt: per seed, the
/// estimates after the first second, and the largest position (m) and rotation (rad) error of those vouched for.
fn frames_with_clocks_to_learn() -> Vec<(u64, usize, f64, f64)> {
    use roitrack_sim::multi_camera::simulate_rig_frames;
    let fps = 30.0;
    [(1, 3), (2, 3), (3, 2), (4, 3)]
        .into_iter()
        .map(|(seed, cameras)| {
            let scene =
                CameraRigScene::random(Scenario::new(ScenarioKind::Random, seed), cameras, seed);
            let mut run = simulate_rig_frames(&scene, fps, 0.05, seed).unwrap();
            // Cameras triggered together, as a user's frames read at --fps are: frame k of every camera at the
            // first camera's time of its frame k, on each camera's own clock (the clocks to learn then differ by the
            // phases too).
            let first_frames: Vec<f64> = run.measurements[0]
                .iter()
                .map(|m| m.t_s)
                .fold(Vec::new(), |mut times, t| {
                    if times.last() != Some(&t) {
                        times.push(t);
                    }
                    times
                });
            for list in run.measurements.iter_mut().skip(1) {
                let start_s = list[0].t_s;
                list.retain_mut(|m| {
                    let k = ((m.t_s - start_s) * fps).round() as usize;
                    first_frames.get(k).map(|&t| m.t_s = t).is_some()
                });
            }
            let mut tracker = RigTracker::new(
                scene.rig_with_clocks_unknown(),
                roitrack_core::Target::grid4x4(),
                frame_rig_config(),
            )
            .unwrap();
            let estimates = push_all(&mut tracker, &run);
            let after_start: Vec<&RigEstimate> = estimates
                .iter()
                .filter(|e| e.estimate.t_ref_s >= 1.0)
                .collect();
            let (worst_m, worst_rad) = worst_vouched(&scene, &after_start);
            let frames = ((scene.scenario.duration_s - 1.0) * fps) as usize;
            println!(
                "seed {seed}, {cameras} cameras: {} estimates after 1 s ({frames} frames of the first camera), {} \
                 vouched for, worst {:.3} mm, {:.3} deg; clocks synced {:?}",
                after_start.len(),
                after_start.iter().filter(|e| e.estimate.status.is_vouched_for()).count(),
                worst_m * 1e3,
                worst_rad.to_degrees(),
                tracker.clocks().iter().map(|c| c.synced).collect::<Vec<_>>()
            );
            (seed, after_start.len() * 100 / frames.max(1), worst_m, worst_rad)
        })
        .collect()
}

/// The first camera's frames are estimated on (at least 95 % of them after the first second) whether or not the
/// other clocks are found. (The frames of all cameras fall at one time on clocks still unknown, and every frame of
/// the first camera ended at another camera's blob, which is not fused: no estimate came from the first camera.)
#[test]
fn frames_with_clocks_to_learn_are_estimated_on() {
    for (seed, percent, _, _) in frames_with_clocks_to_learn() {
        assert!(
            percent >= 95,
            "seed {seed}: estimates on {percent} % of the frames"
        );
    }
}

/// No estimate 10 mm or 5 degrees off vouched for. Failed on seed 2 (17.6 mm) while each camera's own tracker took a
/// frame's blobs one after the other: the first camera's own track was disputed on most frames and had no estimate
/// vouched for near the fused one to refute it, and an offset learnt milliseconds off carried the fused track 5-18 mm
/// off, the camera with that clock agreeing with it. Each frame now goes to its camera's tracker whole.
#[test]
fn frames_with_clocks_to_learn_vouch_for_no_wrong_pose() {
    for (seed, _, worst_m, worst_rad) in frames_with_clocks_to_learn() {
        assert!(
            worst_m < 0.01 && worst_rad < 5f64.to_radians(),
            "seed {seed}: a vouched estimate {:.1} mm, {:.2} deg off",
            worst_m * 1e3,
            worst_rad.to_degrees()
        );
    }
}

/// Global-shutter cameras at 30 Hz on the random scene (up to 1.5 m/s and 4 rad/s: a constant-twist prediction is
/// millimetres off in one frame): the fused track follows every frame, where, taking each frame's blobs one by one
/// against such a prediction, its gate rejected them until the track was lost. Every camera's mount and clock known,
/// each camera's frames at its own phase; the trackers tuned as `track --images` tunes them (the process noise
/// held, the noise learnt from the frames).
#[test]
fn global_shutter_frames_of_a_fast_target_are_tracked_on_every_frame() {
    use roitrack_core::so3;
    use roitrack_sim::multi_camera::simulate_rig_frames;
    let fps = 30.0;
    for (seed, cameras) in [(1, 2), (2, 3), (3, 2), (4, 3)] {
        let scene =
            CameraRigScene::random(Scenario::new(ScenarioKind::Random, seed), cameras, seed);
        let run = simulate_rig_frames(&scene, fps, 0.05, seed).unwrap();
        let mut tracker = RigTracker::new(
            scene.rig.clone(),
            roitrack_core::Target::grid4x4(),
            frame_rig_config(),
        )
        .unwrap();
        let estimates = push_all(&mut tracker, &run);
        let report = tracker.report();
        let after_start: Vec<&RigEstimate> = estimates
            .iter()
            .filter(|e| e.estimate.t_ref_s >= 1.0)
            .collect();
        let vouched: Vec<&&RigEstimate> = after_start
            .iter()
            .filter(|e| e.estimate.status.is_vouched_for())
            .collect();
        let (mut sum_m2, mut worst_m, mut worst_rad) = (0.0, 0.0f64, 0.0f64);
        for e in &vouched {
            let truth = scene.scenario.state_at(e.estimate.t_ref_s);
            let error_m = (e.estimate.state.cam_t_obj_m - truth.cam_t_obj_m).norm();
            let error_rad =
                so3::log(&(e.estimate.state.cam_r_obj * truth.cam_r_obj.inverse())).norm();
            sum_m2 += error_m * error_m;
            worst_m = worst_m.max(error_m);
            worst_rad = worst_rad.max(error_rad);
        }
        let frames = ((scene.scenario.duration_s - 1.0) * fps * cameras as f64) as usize;
        let rmse_m = (sum_m2 / vouched.len().max(1) as f64).sqrt();
        println!(
            "seed {seed}, {cameras} cameras: {} estimates after 1 s of {frames} frames, {} vouched for; position RMSE \
             {:.4} mm, worst {:.3} mm, {:.3} deg; noise {:.4} px; {report:?}",
            after_start.len(),
            vouched.len(),
            rmse_m * 1e3,
            worst_m * 1e3,
            worst_rad.to_degrees(),
            estimates.last().map_or(0.0, |e| e.estimate.noise_px)
        );
        // Followed: an estimate vouched for on at least 95 % of the frames of the first camera after the first second
        // (one per instant of any camera, so several per frame of the first).
        assert!(
            vouched.len() as f64 >= 0.95 * (scene.scenario.duration_s - 1.0) * fps,
            "seed {seed}: {} estimates vouched for after the first second",
            vouched.len()
        );
        // Never a wrong pose vouched for: none 10 mm or 5 degrees off.
        assert!(
            worst_m < 0.01 && worst_rad < 5f64.to_radians(),
            "seed {seed}: a vouched estimate {:.1} mm, {:.2} deg off",
            worst_m * 1e3,
            worst_rad.to_degrees()
        );
    }
}
