//! The default Kalman filter learns the centroid noise and the process noise it was not told: checked on simulated
//! runs against their ground truth.

use roitrack_core::MotionState;
use roitrack_core::estimator::{
    Estimate, EstimatorConfig, KalmanTuning, TrackStatus, TrackerConfig,
};
use roitrack_experiments::scoring::{Scored, track_and_score};
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
