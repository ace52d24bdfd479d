//! The default Kalman filter learns the centroid noise and the process noise it was not told: checked on simulated
//! runs against their ground truth.

use nalgebra::Vector3;
use roitrack_core::{Measurement, MotionState, Target, TargetPoint};
use roitrack_demo::scoring::{Scored, track_and_score};
use roitrack_estimators::{
    Emit, Estimate, Estimator, EstimatorConfig, KalmanTuning, TrackStatus, Tracker, TrackerConfig,
};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};

fn scored(kind: ScenarioKind, noise_px: f64, config: TrackerConfig) -> (Scenario, Scored) {
    let scenario = Scenario::new(kind, 1);
    let options = SimulationOptions {
        seed: 7,
        noise_px,
        ..SimulationOptions::default()
    };
    let run = simulate(&scenario, &options).unwrap();
    (scenario, track_and_score(&run, config).unwrap())
}

fn hand_tuned(noise_px: f64) -> TrackerConfig {
    TrackerConfig {
        estimator: EstimatorConfig::Kalman(KalmanTuning {
            adapt_noise: false,
            adapt_motion: false,
            ..KalmanTuning::default()
        }),
        noise_px,
        ..TrackerConfig::default()
    }
}

fn unvouched(estimates: &[Estimate]) -> usize {
    estimates
        .iter()
        .filter(|e| matches!(e.status, TrackStatus::Disputed | TrackStatus::Lost))
        .count()
}

fn rms_position_error_mm(scenario: &Scenario, estimates: &[Estimate]) -> f64 {
    let sum: f64 = estimates
        .iter()
        .map(|e| {
            MotionState::difference(&e.state, &scenario.state_at(e.t_ref_s))
                .fixed_rows::<3>(0)
                .norm_squared()
        })
        .sum();
    1e3 * (sum / estimates.len() as f64).sqrt()
}

#[test]
fn learns_a_noise_three_times_the_assumed_one_and_beats_the_filter_told_the_truth() {
    let (_, adaptive) = scored(ScenarioKind::Orthoglide, 0.3, TrackerConfig::default());
    let learnt_px = adaptive.estimates.last().unwrap().noise_px;
    assert!((learnt_px - 0.3).abs() < 0.03, "learnt {learnt_px} px");
    assert_eq!(unvouched(&adaptive.estimates), 0);
    let (_, told) = scored(ScenarioKind::Orthoglide, 0.3, hand_tuned(0.3));
    assert!(told.estimates.iter().all(|e| e.noise_px == 0.3));
    assert!(
        adaptive.metrics.position_rmse_mm < 0.8 * told.metrics.position_rmse_mm,
        "adaptive {} mm, told the noise {} mm",
        adaptive.metrics.position_rmse_mm,
        told.metrics.position_rmse_mm
    );
    assert!(adaptive.metrics.velocity_lag_samples.unwrap() <= 1);
}

#[test]
fn initialises_and_tracks_at_one_pixel_of_noise() {
    let (_, adaptive) = scored(ScenarioKind::Orthoglide, 1.0, TrackerConfig::default());
    let first = adaptive.estimates.first().expect("initialised");
    assert!(
        first.t_ref_s < 0.05,
        "first estimate at {} s",
        first.t_ref_s
    );
    assert!(
        adaptive.metrics.position_rmse_mm < 1.2,
        "{} mm",
        adaptive.metrics.position_rmse_mm
    );
    assert_eq!(unvouched(&adaptive.estimates), 0);
}

#[test]
fn a_still_target_is_averaged_down() {
    let (scenario, adaptive) = scored(ScenarioKind::Static, 0.1, TrackerConfig::default());
    let estimates = &adaptive.estimates;
    let early = rms_position_error_mm(&scenario, &estimates[5..85]);
    let late = rms_position_error_mm(&scenario, &estimates[estimates.len() - 80..]);
    let (_, fixed) = scored(ScenarioKind::Static, 0.1, hand_tuned(0.1));
    let fixed_late =
        rms_position_error_mm(&scenario, &fixed.estimates[fixed.estimates.len() - 80..]);
    assert!(late < 0.7 * early, "early {early} mm, late {late} mm");
    assert!(
        late < 0.5 * fixed_late,
        "adaptive {late} mm, fixed {fixed_late} mm"
    );
}

#[test]
fn the_velocity_of_the_spec_scene_does_not_lag() {
    let (_, adaptive) = scored(ScenarioKind::Orthoglide, 0.1, TrackerConfig::default());
    let (_, fixed) = scored(ScenarioKind::Orthoglide, 0.1, hand_tuned(0.1));
    assert_eq!(adaptive.metrics.velocity_lag_samples, Some(0));
    assert!(adaptive.metrics.position_rmse_mm < fixed.metrics.position_rmse_mm);
    assert!(
        adaptive.metrics.velocity_rmse_mm_s.unwrap() < fixed.metrics.velocity_rmse_mm_s.unwrap()
    );
}

/// Three of the sixteen blobs measured four times more noisily than the others (0.4 against 0.1 px, as smaller or
/// shadowed blobs are): the default filter learns each point's share of the noise and weighs them down, where the same
/// filter without the shares (`learn_point_noise: false`: one learnt noise for every point) cannot; on equally noisy
/// points the shares change little. Measured: docs/estimation.md, "Each point's share of the noise".
#[test]
fn noisier_blobs_are_weighted_down() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let simulated = |seed, noise_px| {
        let options = SimulationOptions {
            seed,
            noise_px,
            ..SimulationOptions::default()
        };
        simulate(&scenario, &options).unwrap()
    };
    let equal = simulated(7, 0.1);
    let mut run = equal.clone();
    let noisy = simulated(8, 0.4);
    let noisy_ids = [3, 7, 12];
    for (m, n) in run.measurements.iter_mut().zip(&noisy.measurements) {
        assert_eq!((m.t_s, m.id), (n.t_s, n.id), "the same ROIs in both runs");
        if noisy_ids.contains(&m.id) {
            *m = *n;
        }
    }
    let one_noise = TrackerConfig {
        estimator: EstimatorConfig::Kalman(KalmanTuning {
            learn_point_noise: false,
            ..KalmanTuning::default()
        }),
        ..TrackerConfig::default()
    };
    for (name, run, at_most) in [("three noisier", &run, 0.9), ("equal", &equal, 1.02)] {
        let shares = track_and_score(run, TrackerConfig::default()).unwrap();
        let one = track_and_score(run, one_noise).unwrap();
        let (s, o) = (
            shares.metrics.position_rmse_mm,
            one.metrics.position_rmse_mm,
        );
        println!(
            "{name}: shares learnt {s:.4} mm, {} disputed or lost; one noise for all {o:.4} mm, {} disputed or lost",
            unvouched(&shares.estimates),
            unvouched(&one.estimates)
        );
        assert!(
            s < at_most * o,
            "{name}: shares learnt {s} mm, one noise {o} mm"
        );
        assert_eq!(unvouched(&shares.estimates), 0, "{name}");
    }
}

/// Centroids as a frame camera gives them: every point of a frame at the frame's time, 30 frames a second, raw
/// pixels with Gaussian noise of `noise_px` per axis (Box-Muller on a fixed linear congruential sequence).
fn frame_batches(scenario: &Scenario, noise_px: f64, frames: usize) -> Vec<Vec<Measurement>> {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut gaussian = move || {
        let (a, b) = (uniform(), uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    };
    (0..frames)
        .map(|k| {
            let t_s = k as f64 / 30.0;
            let truth = scenario.state_at(t_s);
            scenario
                .target
                .points()
                .iter()
                .map(|p| {
                    let raw = scenario
                        .camera
                        .raw_pixel_from_cam(&truth.point_in_cam_at(&p.point_in_obj_m, 0.0))
                        .unwrap();
                    Measurement {
                        t_s,
                        id: p.id,
                        u_px: raw.x + noise_px * gaussian(),
                        v_px: raw.y + noise_px * gaussian(),
                    }
                })
                .collect()
        })
        .collect()
}

/// The frames' estimates: one per frame with [`Emit::EachBatch`], or as `track --measurements` gives them with
/// [`Emit::Every`] (after the frame that holds every 10th measurement: every third frame of four dots).
fn track_frames(
    scenario: &Scenario,
    batches: &[Vec<Measurement>],
    config: TrackerConfig,
    emit: Emit,
) -> Vec<Estimate> {
    let mut tracker =
        Tracker::new(scenario.camera.clone(), scenario.target.clone(), config).unwrap();
    batches
        .iter()
        .filter_map(|batch| tracker.push_batch(batch, emit).unwrap())
        .collect()
}

#[test]
fn centroids_that_come_a_frame_at_a_time_are_tracked_as_well_as_by_the_filter_told_the_noise() {
    // The blobs of a frame share one instant: the filter samples the noise from each frame's own blobs (a window of
    // two cycles of points would span several frames, under one constant twist) and leaves the process noise as it
    // is (the innovations' persistence means nothing within one instant). Before, the default filter was 1.5 times
    // the told one on four dots at 0.3 px, and 10 times on 16 points at 0.03 px.
    let four_dots = Target::new(
        [(-0.04, -0.03), (0.04, -0.03), (0.04, 0.03), (-0.03, 0.03)]
            .iter()
            .enumerate()
            .map(|(id, &(x, y))| TargetPoint {
                id: id as u32,
                point_in_obj_m: Vector3::new(x, y, 0.0),
                diameter_m: None,
            })
            .collect(),
    )
    .unwrap();
    for (target, noise_px, emit) in [
        (four_dots.clone(), 0.3, Emit::EachBatch),
        (four_dots, 0.3, Emit::Every),
        (Target::grid4x4(), 0.03, Emit::EachBatch),
    ] {
        let scenario = Scenario::new(ScenarioKind::Sweep, 2).with_target(target);
        let batches = frame_batches(&scenario, noise_px, 150);
        let adaptive = track_frames(&scenario, &batches, TrackerConfig::default(), emit);
        let told = track_frames(&scenario, &batches, hand_tuned(noise_px), emit);
        if emit == Emit::EachBatch {
            // The first estimate comes with the second frame: the initial fit takes two cycles of points.
            assert_eq!(adaptive.len(), batches.len() - 1);
        }
        assert_eq!(unvouched(&adaptive), 0);
        let learnt_px = adaptive.last().unwrap().noise_px;
        assert!(
            (learnt_px / noise_px - 1.0).abs() < 0.15,
            "learnt {learnt_px} px of {noise_px}"
        );
        let (adaptive_mm, told_mm) = (
            rms_position_error_mm(&scenario, &adaptive[5..]),
            rms_position_error_mm(&scenario, &told[5..]),
        );
        eprintln!(
            "{noise_px} px, {emit:?}: default {adaptive_mm:.4} mm, told the noise {told_mm:.4} mm, learnt {learnt_px:.4} px"
        );
        assert!(adaptive_mm < 1.1 * told_mm, "{adaptive_mm} vs {told_mm} mm");
    }
}

/// The mean and the standard error of the mean of `values`.
fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (variance / n).sqrt())
}

/// Small rigid bodies (4 points not on a plane, 5 points on three levels) carried through the paper's motion: their
/// velocity lags no more than the built-in 16-point grid's. Judged on six seeds each, by the difference of the mean
/// sub-sample lags against twice its standard error (the seeds' own spread). Before the trend's span had a floor, the
/// small bodies lagged 0.07 samples more, about three standard errors.
#[test]
fn small_rigid_bodies_lag_no_more_than_the_built_in_grid() {
    let body = |points: &[[f64; 3]]| {
        let points = points
            .iter()
            .enumerate()
            .map(|(id, p)| TargetPoint {
                id: id as u32,
                point_in_obj_m: Vector3::from(*p),
                diameter_m: Some(0.006),
            })
            .collect();
        Target::new(points).unwrap()
    };
    let lags = |target: &Target| -> Vec<f64> {
        (1..=6)
            .map(|seed| {
                let scenario =
                    Scenario::new(ScenarioKind::Orthoglide, 1).with_target(target.clone());
                let options = SimulationOptions {
                    seed,
                    noise_px: 0.1,
                    ..SimulationOptions::default()
                };
                let run = simulate(&scenario, &options).unwrap();
                let scored = track_and_score(&run, TrackerConfig::default()).unwrap();
                scored.metrics.velocity_lag_subsample.unwrap()
            })
            .collect()
    };
    let (grid_lag, grid_error) = mean_and_standard_error(&lags(&Target::grid4x4()));
    let tetrahedron = body(&[
        [-0.03, -0.025, 0.0],
        [0.035, -0.02, 0.0],
        [0.0, 0.03, 0.0],
        [0.005, 0.0, -0.025],
    ]);
    let three_levels = body(&[
        [-0.03, -0.025, 0.0],
        [0.035, -0.02, 0.005],
        [0.0, 0.03, 0.0],
        [0.005, 0.0, -0.025],
        [-0.02, 0.02, -0.012],
    ]);
    for (name, target) in [("4 points", tetrahedron), ("5 points", three_levels)] {
        let (lag, error) = mean_and_standard_error(&lags(&target));
        let bound = 2.0 * (error * error + grid_error * grid_error).sqrt();
        println!(
            "{name}: lag {lag:.3} samples, the grid's {grid_lag:.3}, allowed above it {bound:.3}"
        );
        assert!(
            lag <= grid_lag + bound,
            "{name}: lag {lag:.3} samples, the grid's {grid_lag:.3} (+{bound:.3} allowed)"
        );
    }
}

/// A small target tracked on clean measurements is not disputed by chance. On 6 points, one point refused twice in a
/// row (1.2e-4 a point and cycle for good measurements) disputed the 2 x 3 grid on the orthoglide at 4 kHz 8 times
/// over seeds 1-6, three estimates each, with nothing wrong; three in a row (1.3e-6) expect 0.16 over the six runs,
/// so at most one is allowed (a chance of about 1 % to see two).
#[test]
fn a_small_target_on_clean_measurements_is_not_disputed_by_chance() {
    let target = roitrack_experiments::adaptive::grid2x3();
    let mut disputes = Vec::new();
    for seed in 1..=6u64 {
        let scenario = Scenario::new(ScenarioKind::Orthoglide, seed).with_target(target.clone());
        let options = SimulationOptions {
            seed,
            ..SimulationOptions::default()
        };
        let run = simulate(&scenario, &options).unwrap();
        let scored = track_and_score(&run, TrackerConfig::default()).unwrap();
        let disputed: Vec<f64> = scored
            .estimates
            .iter()
            .filter(|e| e.status == TrackStatus::Disputed)
            .map(|e| e.t_ref_s)
            .collect();
        eprintln!("seed {seed}: disputed at {disputed:?}");
        disputes.extend(disputed);
    }
    assert!(
        disputes.len() <= 3,
        "disputed estimates over six clean runs at {disputes:?} s"
    );
}
