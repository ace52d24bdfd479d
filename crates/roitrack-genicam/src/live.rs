//! The two-thread loop on a live GenICam camera, real or fake.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use roitrack_core::{CameraModel, PoseSample, Target, TwistSample};
use roitrack_estimators::TrackerConfig;
use roitrack_pipeline::{LoopConfig, LoopReport, run_loop_with_sink};
use roitrack_sim::{Scenario, SensorModel};

use crate::{
    CameraStats, FAKE_MAX_FRAME_RATE_HZ, FakeGigeCamera, GenicamCamera, GenicamError,
    GenicamOptions, TriggerChoice,
};

/// Options of a live run.
///
/// ```
/// use roitrack_genicam::LiveOptions;
/// let options = LiveOptions { duration_s: 2.0, ..LiveOptions::default() };
/// assert_eq!(options.rate_hz, 4000.0);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LiveOptions {
    /// The camera to open and how to drive it.
    pub camera: GenicamOptions,
    /// Length of the run (s of the loop's clock).
    pub duration_s: f64,
    /// ROI slots per second: a real camera is paced at this rate (its ROIs are taken at the wall-clock times of
    /// their slots, so the camera must sustain it); the fake camera runs free, each ROI at its slot's scenario time.
    pub rate_hz: f64,
    /// The tracker run on the camera's centroids: estimator, window, control period, noise, gates.
    pub tracker: TrackerConfig,
    /// Keep every measurement handed to the estimator in the report's [`LoopReport::measured`] (a record of what
    /// the tracker saw, the ROS 2 bag's `/roitrack/measurements`). Default: false.
    pub keep_measurements: bool,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            camera: GenicamOptions::default(),
            duration_s: 10.0,
            rate_hz: 4000.0,
            tracker: TrackerConfig::default(),
            keep_measurements: false,
        }
    }
}

/// What a live run did: the loop's report (estimates, latencies, rejections, why it stopped) and the camera's.
///
/// ```no_run
/// use std::sync::{Arc, atomic::AtomicBool};
/// use roitrack_genicam::{LiveOptions, run_fake};
/// use roitrack_sim::{Scenario, ScenarioKind};
/// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
/// let options = LiveOptions { duration_s: 1.0, ..LiveOptions::default() };
/// let report = run_fake(&scenario, &options, 1, Arc::new(AtomicBool::new(false)), |_| {}, &mut |_| {}).unwrap();
/// println!("{}", report.summary());
/// assert!(report.camera.moved_fraction() > 0.95);
/// ```
#[derive(Debug, Clone)]
pub struct LiveReport {
    /// The real-time loop's report: estimates, latencies, rejections, why it stopped.
    pub loop_report: LoopReport,
    /// What the camera did: ROIs grabbed, lost, incomplete, stale, moves, clock offset.
    pub camera: CameraStats,
    /// The camera, as opened ([`GenicamCamera::description`]).
    pub description: String,
    /// Per estimate: host time from the timestamp of the newest buffer it used (the device time on the host's
    /// clock, through the estimated clock offset) to the estimate (µs). See [`timestamp_to_estimate_us`].
    pub timestamp_to_estimate_us: Vec<f64>,
    /// The fake camera: the true `device - host` offset (s), known because both clocks are the host's. The estimate
    /// ([`CameraStats::clock_offset_s`]) is below it by the smallest arrival latency, which the latencies from
    /// buffer timestamp leave out.
    pub true_clock_offset_s: Option<f64>,
}

/// The latency from buffer timestamp to estimate, per estimate (µs): for the estimate of reference time
/// `t_ref_s[i]` (the time of the newest measurement it used), the age of that ROI's buffer when its grab returned
/// (measured by the camera: the host time then, less the buffer's device timestamp on the host's clock) plus the time
/// from that return to the estimate (`grab_to_estimate_us[i]`, measured by the loop); both on the host's monotonic
/// clock. An estimate without such a ROI (none recorded at or before its time) has none.
///
/// ```
/// use roitrack_genicam::{CameraStats, timestamp_to_estimate_us};
/// // Two ROIs at 0.25 and 0.5 ms, their buffers 120 and 80 us old when the grab returned; an estimate from the
/// // second ROI produced 30 us after its grab returned.
/// let camera = CameraStats { timestamp_to_grab_us: vec![(0.25e-3, 120.0), (0.5e-3, 80.0)], ..Default::default() };
/// assert_eq!(timestamp_to_estimate_us(&[0.5e-3], &[30.0], &camera), vec![110.0]);
/// ```
pub fn timestamp_to_estimate_us(
    t_ref_s: &[f64],
    grab_to_estimate_us: &[f64],
    camera: &CameraStats,
) -> Vec<f64> {
    let rois = &camera.timestamp_to_grab_us;
    t_ref_s
        .iter()
        .zip(grab_to_estimate_us)
        .filter_map(|(&t_s, &after_grab_us)| {
            // ROI times follow the run; a blob's time is its ROI's or (rolling shutter) a few rows later.
            let newer = rois.partition_point(|&(roi_s, _)| roi_s <= t_s + 1e-9);
            let &(_, age_us) = rois.get(newer.checked_sub(1)?)?;
            Some(age_us + after_grab_us)
        })
        .collect()
}

impl LiveReport {
    /// The end-of-run summary: ROIs grabbed, lost, incomplete, the fraction read from the window asked for, ROIs/s,
    /// latencies, the clock offset, and why the run stopped early if it did.
    pub fn summary(&self) -> String {
        let r = &self.loop_report;
        let c = &self.camera;
        let grab = roitrack_core::stats::sorted(&c.grab_us);
        let (stamp_p50, stamp_p99) = self.timestamp_to_estimate_quantiles_us();
        let age: Vec<f64> = c.timestamp_to_grab_us.iter().map(|&(_, us)| us).collect();
        let age = roitrack_core::stats::sorted(&age);
        let text = format!(
            "{}\nROIs grabbed {}, lost (no image in time) {}, incomplete {}, stale (old window) {}, moved as asked \
             {:.2} %, refused moves {}, full frames {}; Aravis dropped {} buffers (none free) and gave up on {}\n\
             {:.0} ROIs/s over {:.2} s; grab (move, trigger, buffer) p50/p99 {:.0}/{:.0} us; latency from buffer \
             timestamp to estimate p50/p99 {:.0}/{:.0} us (buffer timestamp to the grab's return {:.0}/{:.0} us, \
             the grab's return to the estimate {:.0}/{:.0} us)\n{} estimates, \
             {} measurements, {} rejected blobs, {} initialisations ({} failed), {} dropped measurements, {} ROIs \
             served more than a slot late (paced)",
            self.description,
            c.rois,
            c.lost,
            c.incomplete,
            c.stale,
            100.0 * c.moved_fraction(),
            c.refused_moves,
            c.full_frames,
            c.driver_underruns,
            c.driver_failures,
            r.rois_per_s(),
            r.wall_s,
            roitrack_core::stats::quantile(&grab, 0.5),
            roitrack_core::stats::quantile(&grab, 0.99),
            stamp_p50,
            stamp_p99,
            roitrack_core::stats::quantile(&age, 0.5),
            roitrack_core::stats::quantile(&age, 0.99),
            r.latency_quantile_us(0.5),
            r.latency_quantile_us(0.99),
            r.estimates.len(),
            r.acquisition.measurements,
            r.acquisition.rejections.total(),
            r.acquisition.initialisations,
            r.acquisition.failed_initialisations,
            r.acquisition.dropped,
            r.acquisition.late,
        );
        let mut text = text;
        if c.retimed > 0 {
            text.push_str(&format!(
                "\n{} ROIs exposed at another time than their slot's (free run), each placed at its own",
                c.retimed
            ));
        }
        if let Some(offset) = c.clock_offset_s {
            let (mean, std) = c.arrival_jitter_s.unwrap_or((f64::NAN, f64::NAN));
            text.push_str(&format!(
                "\nclock offset device - host {offset:.6} s (moved {:.3} ms during the run); arrival latency above \
                 the smallest: mean {:.0} us, std {:.0} us",
                1e3 * c.clock_change_s.unwrap_or(0.0),
                mean * 1e6,
                std * 1e6
            ));
        }
        if let (Some(truth), Some(estimate)) = (self.true_clock_offset_s, c.clock_offset_s) {
            text.push_str(&format!(
                "\nthe fake camera's true offset (the same clock on both sides) {truth:.6} s: the estimate is {:.0} us \
                 below it, the smallest arrival latency, which the latencies from buffer timestamp leave out",
                (truth - estimate) * 1e6
            ));
        }
        if let Some(e) = &r.acquisition.stopped_by {
            text.push_str(&format!("\nthe run stopped early: {e}"));
        }
        text
    }

    /// Median and 99th percentile (nearest rank) of [`Self::timestamp_to_estimate_us`] (µs); NaN without estimates.
    pub fn timestamp_to_estimate_quantiles_us(&self) -> (f64, f64) {
        let sorted = roitrack_core::stats::sorted(&self.timestamp_to_estimate_us);
        (
            roitrack_core::stats::quantile(&sorted, 0.5),
            roitrack_core::stats::quantile(&sorted, 0.99),
        )
    }
}

/// ```no_run
/// use roitrack_genicam::{GenicamCamera, GenicamOptions, LiveOptions, run_live};
/// let (camera_model, target) = (roitrack_core::CameraModel::canonical(), roitrack_core::Target::grid4x4());
/// let options = LiveOptions {
///     camera: GenicamOptions { address: "192.168.1.20".into(), ..GenicamOptions::default() },
///     rate_hz: 1000.0,
///     ..LiveOptions::default()
/// };
/// let mut camera = GenicamCamera::open(&options.camera, (1024, 1024)).unwrap();
/// let report = run_live(&mut camera, &camera_model, &target, &options, true, &mut |_| {}).unwrap();
/// println!("{}", report.summary());
/// ```
///
/// Runs the loop on `camera` for `options.duration_s`: the full-frame start (and re-initialisations), then one ROI a
/// slot where the tracker predicts each blob. `paced`: slots at their wall-clock times (a real camera); otherwise as
/// fast as the camera delivers. A camera that stops (disconnected, Ctrl-C) ends the run with the estimates so far
/// ([`roitrack_pipeline::AcquisitionCounts::stopped_by`] of [`LoopReport::acquisition`]). `on_estimate` gets each
/// estimate on the loop's estimation thread as it is made (a live view); it must not block.
pub fn run_live(
    camera: &mut GenicamCamera,
    camera_model: &CameraModel,
    target: &Target,
    options: &LiveOptions,
    paced: bool,
    on_estimate: &mut (dyn FnMut(&roitrack_estimators::Estimate) + Send),
) -> Result<LiveReport, GenicamError> {
    let (w, h) = camera.window();
    let config = loop_config(options, w.min(h), paced);
    let loop_report = run_loop_with_sink(
        camera,
        camera_model,
        target,
        options.tracker,
        &config,
        None,
        on_estimate,
    )?;
    let stats = camera.stats();
    let t_ref_s: Vec<f64> = loop_report.estimates.iter().map(|e| e.t_ref_s).collect();
    let timestamp_to_estimate_us =
        timestamp_to_estimate_us(&t_ref_s, &loop_report.latencies_us, &stats);
    Ok(LiveReport {
        loop_report,
        camera: stats,
        description: camera.description().to_string(),
        timestamp_to_estimate_us,
        true_clock_offset_s: None,
    })
}

/// The loop's options of a live run whose camera reads a window of `side_px`: the scheduler places ROIs of at most
/// that size, each read through the window centred on it and measured within the ROI alone (a neighbouring blob in
/// the rest of the window does not get it refused).
pub(crate) fn loop_config(options: &LiveOptions, side_px: u32, paced: bool) -> LoopConfig {
    let mut config = LoopConfig {
        rate_hz: options.rate_hz,
        paced,
        roi_slots: (options.duration_s * options.rate_hz).round().max(0.0) as usize,
        keep_measurements: options.keep_measurements,
        crop_to_request: true,
        ..LoopConfig::default()
    };
    config.scheduler.min_size_px = config.scheduler.min_size_px.min(side_px);
    config.scheduler.max_size_px = side_px;
    config
}

/// How to open `fake` with the options `camera` asks for: its address, its serial number checked, and in free run
/// its fastest frame rate unless asked (it starts at 25 Hz).
pub(crate) fn fake_camera_options(
    fake: &FakeGigeCamera,
    camera: &GenicamOptions,
) -> GenicamOptions {
    GenicamOptions {
        address: fake.address().to_string(),
        expected_serial: Some(fake.serial().to_string()),
        frame_rate_hz: match camera.trigger {
            TriggerChoice::FreeRun => camera.frame_rate_hz.or(Some(FAKE_MAX_FRAME_RATE_HZ)),
            TriggerChoice::Software => camera.frame_rate_hz,
        },
        ..camera.clone()
    }
}

/// See [`LiveReport`] for an example.
///
/// Starts Aravis' fake camera on 127.0.0.1 rendering `scenario` (default sensor, noise seeded with `seed`), opens it
/// through the protocol like a real camera (its serial number checked) and runs the loop free on it for
/// `options.duration_s` of scenario time (at most the scenario's). `stop` ends the run early (Ctrl-C); `on_start`
/// gets the fake camera once the run is about to start (a test stops it from there to play a camera that
/// disappears); `on_estimate` each estimate as it is made (see [`run_live`]).
pub fn run_fake(
    scenario: &Scenario,
    options: &LiveOptions,
    seed: u64,
    stop: Arc<AtomicBool>,
    on_start: impl FnOnce(Arc<FakeGigeCamera>),
    on_estimate: &mut (dyn FnMut(&roitrack_estimators::Estimate) + Send),
) -> Result<LiveReport, GenicamError> {
    let fake = Arc::new(FakeGigeCamera::start(
        scenario,
        SensorModel::default(),
        seed,
    )?);
    let camera_options = fake_camera_options(&fake, &options.camera);
    let full_size = (scenario.camera.width_px, scenario.camera.height_px);
    let mut camera = GenicamCamera::open(&camera_options, full_size)?
        .with_scene_clock(fake.clock())
        .with_stop_flag(stop);
    let options = LiveOptions {
        duration_s: options.duration_s.min(scenario.duration_s),
        ..options.clone()
    };
    on_start(fake.clone());
    let report = run_live(
        &mut camera,
        &scenario.camera,
        &scenario.target,
        &options,
        false,
        on_estimate,
    )
    .map(|mut report| {
        report.true_clock_offset_s = camera
            .host_epoch()
            .map(|(instant, loop_s)| fake.device_time_at_s(instant) - loop_s);
        report
    });
    drop(camera);
    fake.stop();
    report
}

/// ```
/// use roitrack_sim::{Scenario, ScenarioKind};
/// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
/// let (poses, twists) = roitrack_genicam::truth_samples(&scenario, 0.5, 4000.0);
/// assert_eq!((poses.len(), twists.len()), (2001, 2001));
/// assert_eq!(poses[4].t_s, 0.001);
/// ```
///
/// The scenario's true poses and twists at the fake camera's ROI slot times (`k / rate_hz`, the scenario's time, the
/// fake camera's clock) up to `duration_s`: the ground truth of a fake run, on the estimates' time base.
pub fn truth_samples(
    scenario: &Scenario,
    duration_s: f64,
    rate_hz: f64,
) -> (Vec<PoseSample>, Vec<TwistSample>) {
    let end_s = duration_s.min(scenario.duration_s).max(0.0);
    let count = (end_s * rate_hz).floor() as usize + 1;
    (0..count)
        .map(|k| {
            let t_s = k as f64 / rate_hz;
            let state = scenario.state_at(t_s);
            (
                PoseSample::from_state(t_s, &state),
                TwistSample::from_state(t_s, &state),
            )
        })
        .unzip()
}

/// ```no_run
/// use std::sync::{Arc, atomic::AtomicBool};
/// use roitrack_genicam::{GenicamOptions, LiveOptions, run_device};
/// let (camera_model, target) = (roitrack_core::CameraModel::canonical(), roitrack_core::Target::grid4x4());
/// let options = LiveOptions {
///     camera: GenicamOptions { address: "192.168.1.20".into(), ..GenicamOptions::default() },
///     rate_hz: 1000.0,
///     ..LiveOptions::default()
/// };
/// let report = run_device(&camera_model, &target, &options, Arc::new(AtomicBool::new(false)), &mut |_| {}).unwrap();
/// println!("{}", report.summary());
/// ```
///
/// Opens the camera at `options.camera.address` (no scan) and runs the loop on it, paced at `options.rate_hz` on the
/// host's clock, for `options.duration_s`; `stop` ends it early (Ctrl-C). The camera must sustain the rate: a ROI
/// taken late is still placed for its slot's time.
pub fn run_device(
    camera_model: &CameraModel,
    target: &Target,
    options: &LiveOptions,
    stop: Arc<AtomicBool>,
    on_estimate: &mut (dyn FnMut(&roitrack_estimators::Estimate) + Send),
) -> Result<LiveReport, GenicamError> {
    let full_size = (camera_model.width_px, camera_model.height_px);
    let mut camera = GenicamCamera::open(&options.camera, full_size)?.with_stop_flag(stop);
    run_live(
        &mut camera,
        camera_model,
        target,
        options,
        true,
        on_estimate,
    )
}
