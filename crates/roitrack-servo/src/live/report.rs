//! What a real-time run did ([`LiveServoReport`]): the closed loop's report on the path's clock, the live loop's,
//! and the control thread's timing and latencies.

use roitrack_estimators::Estimate;
use roitrack_pipeline::LoopReport;

use super::control::ControlSide;
use super::scene::RobotScene;
use crate::ServoConfig;
use crate::closed_loop::{ServoReport, ServoSample, build_controller};

/// What a real-time run did: the closed loop's report (its samples, estimates and times on the path's clock, which
/// starts when the controller reads the first on-time estimate), the live loop's, and the control thread's timing.
///
/// ```no_run
/// # use roitrack_servo::live::LiveServoReport;
/// # fn show(report: &LiveServoReport) {
/// let (p50_us, p99_us) = report.actuation_latency_quantiles_us();
/// println!(
///     "{:.3} mm RMS, stable {}, exposure to actuation {p50_us:.0}/{p99_us:.0} us, {} of {} deadlines missed",
///     report.servo.rms_error_mm, report.servo.stable, report.missed_ticks, report.ticks
/// );
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct LiveServoReport {
    /// The closed loop, as [`crate::run_servo`] reports it (its files are written the same way).
    pub servo: ServoReport,
    /// The live loop's report (ROIs, rejections, late slots, the estimation thread's latencies).
    pub loop_report: LoopReport,
    /// Per estimate the controller used: from its newest ROI's mid-exposure to the instant the first command made
    /// from it acts (µs, the control thread's wall clock plus the simulated drive's delay).
    pub exposure_to_actuation_us: Vec<f64>,
    /// The same to the instant the command was issued (µs): without the drive's delay.
    pub exposure_to_command_us: Vec<f64>,
    /// Per estimate published once the path has started: from its newest ROI's mid-exposure to its publication on
    /// the estimation thread (µs), the live loop's part of the latency (the rest is the wait for the next control
    /// tick and the drive's delay).
    pub exposure_to_estimate_us: Vec<f64>,
    /// Control ticks run.
    pub ticks: usize,
    /// Control ticks of the path whose deadline passed before the control thread woke (the drive held its last
    /// command over them).
    pub missed_ticks: usize,
    /// The same before the path started (the robot held at home by its brakes).
    pub missed_before_start: usize,
    /// The most control ticks of the path missed in a row (the longest the drive held one command beyond its tick):
    /// a loop whose delay margin is a few milliseconds is open for that long.
    pub longest_missed_run: usize,
    /// Wall time from the start to the first estimate read by the controller (s): the live loop's full-frame start.
    pub start_delay_s: f64,
    /// Added to an estimate's time on the live loop's clock (the camera's: the times the estimation thread made
    /// them with, which [`run_live_servo_with_sink`]'s sink sees) gives its time on the path's clock, that of
    /// [`ServoReport::estimates`] and the run's files (s); 0 if the path never started.
    ///
    /// [`run_live_servo_with_sink`]: super::run_live_servo_with_sink
    pub loop_to_path_s: f64,
    /// Estimates published to the control thread (vouched for and finite).
    pub published: usize,
    /// Whether the control thread ran under the real-time priority asked for ([`LiveOptions::realtime_priority`]).
    ///
    /// [`LiveOptions::realtime_priority`]: super::LiveOptions::realtime_priority
    pub realtime_priority: bool,
    /// Known accelerations the control thread sent to the live loop's tracker ([`ServoConfig::known_acceleration`]);
    /// how many the tracker took and refused is in [`LoopReport::known_accelerations`] and
    /// [`LoopReport::refused_known_accelerations`].
    pub sent_known_accelerations: usize,
    /// Known accelerations lost because the queue to the estimation thread was full and a newer one replaced them.
    pub superseded_known_accelerations: usize,
}

impl LiveServoReport {
    /// Median and 99th percentile (nearest rank) of [`Self::exposure_to_actuation_us`]; NaN without any.
    pub fn actuation_latency_quantiles_us(&self) -> (f64, f64) {
        quantiles(&self.exposure_to_actuation_us)
    }

    /// Median and 99th percentile of [`Self::exposure_to_estimate_us`]; NaN without any.
    pub fn estimate_latency_quantiles_us(&self) -> (f64, f64) {
        quantiles(&self.exposure_to_estimate_us)
    }

    /// Median and 99th percentile of [`Self::exposure_to_command_us`]; NaN without any.
    pub fn command_latency_quantiles_us(&self) -> (f64, f64) {
        quantiles(&self.exposure_to_command_us)
    }
}

fn quantiles(values: &[f64]) -> (f64, f64) {
    let sorted = roitrack_core::stats::sorted(values);
    (
        roitrack_core::stats::quantile(&sorted, 0.5),
        roitrack_core::stats::quantile(&sorted, 0.99),
    )
}

pub(super) fn report(
    config: &ServoConfig,
    scene: &RobotScene,
    loop_report: LoopReport,
    control: ControlSide,
    published: u64,
) -> LiveServoReport {
    let errors: Vec<f64> = control.samples.iter().map(ServoSample::error_m).collect();
    let rms_error_mm = if errors.is_empty() {
        f64::NAN
    } else {
        (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt() * 1e3
    };
    let max_error_mm = errors.iter().copied().fold(0.0, f64::max) * 1e3;
    // The estimates on the path's clock, as the samples.
    let shift_s = match (scene.loop_offset_s(), control.path_start_robot_s) {
        (Some(offset), Some(start)) => offset - start,
        _ => 0.0,
    };
    let estimates = loop_report
        .estimates
        .iter()
        .map(|e| Estimate {
            t_ref_s: e.t_ref_s + shift_s,
            ..*e
        })
        .collect();
    let (gains, _) = build_controller(config);
    let servo = ServoReport {
        controller: config.controller,
        camera: config.camera,
        path: config.path.clone(),
        rms_error_mm,
        max_error_mm,
        stable: control.stop_reason.is_none(),
        stop_reason: control.stop_reason,
        gains,
        median_feedback_age_s: if control.ages_s.is_empty() {
            f64::NAN
        } else {
            roitrack_core::stats::median(&control.ages_s)
        },
        saturated_fraction: control.saturated_ticks as f64 / control.ticks.max(1) as f64,
        samples: control.samples,
        estimates,
    };
    LiveServoReport {
        servo,
        loop_report,
        exposure_to_actuation_us: control.to_actuation_us,
        exposure_to_command_us: control.to_command_us,
        exposure_to_estimate_us: Vec::new(),
        ticks: control.ticks,
        missed_ticks: control.missed,
        missed_before_start: control.missed_before_start,
        longest_missed_run: control.longest_missed_run,
        start_delay_s: control.start_delay_s,
        loop_to_path_s: shift_s,
        published: published as usize,
        realtime_priority: control.realtime_priority,
        sent_known_accelerations: control.sent_known_accelerations,
        superseded_known_accelerations: control.superseded_known_accelerations,
    }
}
