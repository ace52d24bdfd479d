//! The real-time loop tells its tracker the commanded acceleration (the control thread to the live loop's
//! estimation thread, through its lock-free queue of known accelerations), as the simulated-time loop does: the
//! estimates' velocity no longer lags the robot's accelerations. One test, two live runs of the same configuration,
//! one with and one without; the figures are compared with each other and with the runs' own noise, never with
//! the wall clock.

use nalgebra::Vector3;
use roitrack_servo::live::{LiveOptions, LiveServoReport, run_live_servo_simulated};
use roitrack_servo::{CameraKind, CameraTiming, ControllerKind, ServoConfig};

/// A run that skipped more than this fraction of its ROI slots did not get the machine it needs (as `tests/live.rs`).
const MAX_SKIPPED_FRACTION: f64 = 0.4;

/// The accelerating phases: where the path's acceleration is above this fraction of its peak.
const ACCELERATING_FRACTION: f64 = 0.25;

/// The calm phases: where the path's acceleration is under this fraction of its peak.
const CALM_FRACTION: f64 = 0.05;

/// Told, the velocity error in the accelerations may be at most this times that of the calm phases: the same noise,
/// give or take the sampling of a few dozen estimates (told, the runs measured 0.79-1.21 x; not told, 1.9-2.5 x).
const CALM_RATIO: f64 = 1.5;

/// Not told, the velocity error in the accelerations is at least this times the told run's (measured: 1.9-2.3 x).
const LAG_RATIO: f64 = 1.4;

fn live_run(known_acceleration: bool) -> LiveServoReport {
    let mut config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
    config.known_acceleration = known_acceleration;
    // 1 kHz: what the loop holds on two cores shared with other jobs (docs/servo.md, "The real-time loop").
    let rate_hz = 1000.0;
    config.control_rate_hz = rate_hz;
    config.timing = Some(CameraTiming {
        rate_hz,
        ..CameraKind::Roi.timing()
    });
    run_live_servo_simulated(&config, &LiveOptions::default()).unwrap()
}

/// The estimates' velocity error against the robot's true velocity (the control ticks' samples, linearly
/// interpolated at each estimate's time; m/s RMS): over the accelerating phases, and over the calm ones (where the
/// path's acceleration is under [`CALM_FRACTION`] of its peak: what is left there is the run's own noise, the
/// velocity's lag under acceleration aside). Also the number of estimates in the accelerating phases.
fn velocity_errors(report: &LiveServoReport) -> (f64, f64, usize) {
    let servo = &report.servo;
    let peak_mps2 = servo
        .samples
        .iter()
        .map(|s| s.reference.acceleration_mps2.norm())
        .fold(0.0, f64::max);
    let (mut accelerating, mut calm) = (Vec::new(), Vec::new());
    for e in &servo.estimates {
        let later = servo.samples.partition_point(|s| s.t_s < e.t_ref_s);
        if later == 0 || later >= servo.samples.len() {
            continue;
        }
        let (a, b) = (&servo.samples[later - 1], &servo.samples[later]);
        let u = ((e.t_ref_s - a.t_s) / (b.t_s - a.t_s).max(1e-12)).clamp(0.0, 1.0);
        let truth: Vector3<f64> = a.achieved_velocity_mps * (1.0 - u) + b.achieved_velocity_mps * u;
        let error_mps = (e.state.velocity_mps - truth).norm();
        let fraction = a.reference.acceleration_mps2.norm() / peak_mps2;
        if fraction >= ACCELERATING_FRACTION {
            accelerating.push(error_mps);
        } else if fraction < CALM_FRACTION {
            calm.push(error_mps);
        }
    }
    (rms(&accelerating), rms(&calm), accelerating.len())
}

fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|x| x * x).sum::<f64>() / values.len().max(1) as f64).sqrt()
}

/// Said and not judged when the machine did not hold the rate (another job on the two cores).
fn held_the_rate(report: &LiveServoReport, label: &str) -> bool {
    let offered = report.loop_report.acquisition.rois + report.loop_report.acquisition.skipped;
    let held =
        report.loop_report.acquisition.skipped as f64 <= MAX_SKIPPED_FRACTION * offered as f64;
    if !held {
        eprintln!(
            "NOT CHECKED: the run {label} did not hold 1 kHz ({} of {offered} ROI slots skipped)",
            report.loop_report.acquisition.skipped
        );
    }
    held
}

/// `ctc` through the simulated camera at 1 kHz, told and not told: told, the estimates' velocity error in the
/// robot's accelerations is that of its calm phases (no lag above the run's own noise), and not told it is
/// [`LAG_RATIO`] times the told run's at least.
#[test]
fn the_live_tracker_told_the_commanded_acceleration_does_not_lag_the_robot() {
    let told = live_run(true);
    let not_told = live_run(false);
    let (accelerating_told, calm_told, n_told) = velocity_errors(&told);
    let (accelerating_not_told, calm_not_told, n_not_told) = velocity_errors(&not_told);
    eprintln!(
        "stop reasons: told {:?}, not told {:?}; missed ticks {} and {}; late slots {} and {}",
        told.servo.stop_reason,
        not_told.servo.stop_reason,
        told.missed_ticks,
        not_told.missed_ticks,
        told.loop_report.acquisition.late,
        not_told.loop_report.acquisition.late
    );
    eprintln!(
        "told: {:.4} mm RMS, velocity error {:.4} m/s RMS in the accelerations ({n_told} estimates), {:.4} in the calm \
         phases; {} accelerations sent, {} told, {} refused, {} superseded; {} of {} ROI slots skipped",
        told.servo.rms_error_mm,
        accelerating_told,
        calm_told,
        told.sent_known_accelerations,
        told.loop_report.known_accelerations,
        told.loop_report.refused_known_accelerations,
        told.superseded_known_accelerations,
        told.loop_report.acquisition.skipped,
        told.loop_report.acquisition.rois + told.loop_report.acquisition.skipped,
    );
    eprintln!(
        "not told: {:.4} mm RMS, velocity error {:.4} m/s RMS in the accelerations ({n_not_told} estimates), {:.4} in \
         the calm phases; {} of {} ROI slots skipped",
        not_told.servo.rms_error_mm,
        accelerating_not_told,
        calm_not_told,
        not_told.loop_report.acquisition.skipped,
        not_told.loop_report.acquisition.rois + not_told.loop_report.acquisition.skipped,
    );
    // The path is wired whatever the machine: every command's acceleration sent reaches the tracker, in order.
    assert!(told.sent_known_accelerations > 0);
    assert_eq!(
        told.loop_report.known_accelerations + told.superseded_known_accelerations,
        told.sent_known_accelerations
    );
    assert_eq!(told.loop_report.refused_known_accelerations, 0);
    assert_eq!(not_told.sent_known_accelerations, 0);
    assert_eq!(not_told.loop_report.known_accelerations, 0);
    if !(held_the_rate(&told, "told") && held_the_rate(&not_told, "not told")) {
        return;
    }
    // A run stopped unstable says nothing of the lag: on two cores shared with other jobs either run, told or not,
    // can be taken over the edge by a burst of late feedback (seen at loads of 5-6, with 2-30 % of the slots
    // skipped). Said, and not judged.
    for (label, report) in [("told", &told), ("not told", &not_told)] {
        if !report.servo.stable {
            eprintln!(
                "NOT CHECKED: the run {label} stopped unstable ({:?})",
                report.servo.stop_reason
            );
            return;
        }
    }
    assert!(
        n_told >= 20 && n_not_told >= 20,
        "{n_told} and {n_not_told} estimates in the accelerations"
    );
    assert!(
        accelerating_told <= CALM_RATIO * calm_told,
        "told: {accelerating_told:.4} m/s RMS in the accelerations, over {CALM_RATIO} x its calm phases' \
         {calm_told:.4}"
    );
    assert!(
        accelerating_not_told >= LAG_RATIO * accelerating_told,
        "not told: {accelerating_not_told:.4} m/s RMS in the accelerations, under {LAG_RATIO} x the told run's \
         {accelerating_told:.4}"
    );
}
