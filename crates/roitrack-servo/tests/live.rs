//! The closed loop in real time on the project's simulated ROI camera (real clock, real threads, the live loop's
//! queues and the estimate handle): stable to the path's end, and its tracking error bounded by the simulated-time
//! run of the same configuration. Latency is printed, not asserted: this machine is shared and noisy.

use roitrack_servo::live::{LiveOptions, run_live_servo_simulated};
use roitrack_servo::{CameraKind, CameraTiming, ControllerKind, ServoConfig, run_servo};

/// The live run's RMS error may be at most this times the simulated-time run's: the target is 1.5x (docs/servo.md);
/// the test leaves room for a loaded machine, whose late ROI slots age the feedback beyond what the gains assume.
const RMS_BOUND_FACTOR: f64 = 2.0;

/// A run that skipped more than this fraction of its ROI slots did not get the machine it needs (stable runs here
/// skipped 8-27 %, under a load of 9-12 on two cores; one that skipped 60 % diverged).
const MAX_SKIPPED_FRACTION: f64 = 0.4;

/// The delay at which a critically damped loop of natural frequency ω goes unstable is `0.6475 / ω` (docs/servo.md,
/// "Gains and how to tune them"): a control thread held up that long in one stretch ran the loop open for longer
/// than any gain rule allows for, whatever it did next.
const DELAY_LIMIT_RAD: f64 = 0.6475;

#[test]
fn the_real_time_loop_tracks_like_the_simulated_time_one() {
    // Both runs tell the tracker the commanded acceleration (the default; in real time through the live loop's
    // queue of known accelerations, `tests/live_known_acceleration.rs`).
    let mut config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
    // 1 kHz: what the loop holds on two cores shared with other jobs (docs/servo.md, "The real-time loop").
    let rate_hz = 1000.0;
    config.control_rate_hz = rate_hz;
    config.timing = Some(CameraTiming {
        rate_hz,
        ..CameraKind::Roi.timing()
    });
    let simulated = run_servo(&config).unwrap();
    assert!(simulated.stable);

    let live = run_live_servo_simulated(&config, &LiveOptions::default()).unwrap();
    let (p50, p99) = live.actuation_latency_quantiles_us();
    eprintln!(
        "simulated time {:.4} mm RMS; real time {:.4} mm RMS ({:.4} max), stable {}; exposure to actuation p50/p99 \
         {p50:.0}/{p99:.0} us; {} ticks, {} missed (at most {} in a row); {} late ROI slots, {} skipped; start {:.2} s; \
         real-time priority {}",
        simulated.rms_error_mm,
        live.servo.rms_error_mm,
        live.servo.max_error_mm,
        live.servo.stable,
        live.ticks,
        live.missed_ticks,
        live.longest_missed_run,
        live.loop_report.acquisition.late,
        live.loop_report.acquisition.skipped,
        live.start_delay_s,
        live.realtime_priority
    );
    // A loop that skipped most of its ROI slots ran on a machine too busy to hold 1 kHz (other jobs on the two
    // cores): its estimates came at a fraction of the rate the gains assume, and what it did says nothing of the
    // loop. Said, and not judged; on a machine that holds the rate the loop is judged below.
    let offered = live.loop_report.acquisition.rois + live.loop_report.acquisition.skipped;
    if live.loop_report.acquisition.skipped as f64 > MAX_SKIPPED_FRACTION * offered as f64 {
        eprintln!(
            "NOT CHECKED: the machine did not hold {rate_hz} Hz ({} of {offered} ROI slots skipped)",
            live.loop_report.acquisition.skipped
        );
        return;
    }
    let held_s = live.longest_missed_run as f64 / rate_hz;
    let limit_s = DELAY_LIMIT_RAD / live.servo.gains.natural_frequency_radps;
    if held_s > limit_s {
        eprintln!(
            "NOT CHECKED: the control thread missed {} ticks in a row ({:.1} ms, beyond the loop's delay limit of \
             {:.1} ms)",
            live.longest_missed_run,
            held_s * 1e3,
            limit_s * 1e3
        );
        return;
    }
    assert!(live.servo.stable, "{:?}", live.servo.stop_reason);
    // To the path's end, one sample a tick.
    let last = live.servo.samples.last().unwrap();
    assert!(last.t_s >= config.path.duration_s(), "{}", last.t_s);
    assert!(!live.exposure_to_actuation_us.is_empty());
    let bound_mm = RMS_BOUND_FACTOR * simulated.rms_error_mm;
    assert!(
        live.servo.rms_error_mm <= bound_mm,
        "{:.4} mm RMS in real time, over {bound_mm:.4} ({RMS_BOUND_FACTOR} x the simulated-time run's)",
        live.servo.rms_error_mm
    );
}
