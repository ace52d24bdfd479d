//! A real-time run's options ([`LiveOptions`]) and its entry points: the live loop on this thread and the
//! estimation thread, the control thread beside them ([`run_live_servo`] and its variants).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use roitrack_estimators::Estimate;
use roitrack_image::RoiCamera;
use roitrack_pipeline::LoopConfig;
use roitrack_pipeline::realtime::{LoopHooks, known_acceleration_channel, run_loop_with_hooks};
use roitrack_sim::{RoiRenderer, SensorModel, SimulatedCamera};

use super::camera::{LoopClockCamera, roi_camera_model, servo_target};
use super::control::{ControlFlags, PushWithinCapacity, control_thread};
use super::report::{LiveServoReport, report};
use super::scene::RobotScene;
use crate::closed_loop::ServoError;
use crate::handle::estimate_channel;
use crate::{CameraKind, ServoConfig};

/// Known accelerations the control thread may have sent ahead of the estimation thread: 1024 commands (a quarter
/// of a second at 4 kHz), far more than the estimation thread lags by unless it is descheduled; a full queue keeps the
/// newest (counted in [`LiveServoReport::superseded_known_accelerations`]).
const KNOWN_ACCELERATION_SLOTS: usize = 1024;

/// Options of a real-time run beyond the closed loop's own.
///
/// ```
/// use roitrack_servo::live::LiveOptions;
/// assert_eq!(LiveOptions::default().start_timeout_s, 5.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveOptions {
    /// Every ROI this square size (px): a camera whose window is fixed (Aravis', 32); `None`: the scheduler's sizes.
    pub window_px: Option<u32>,
    /// The wall time a full frame (the start, a re-initialisation) is given (s): the paced loop skips this many
    /// seconds of ROI slots after one ([`LoopConfig::full_frame_slots`]) instead of catching up on them with ROIs
    /// of the past. Default 0.25 s: Aravis' fake camera renders and sends its 1024 x 1024 frame in about that on
    /// two shared cores.
    pub full_frame_s: f64,
    /// The longest wait for the first estimate (s, wall clock) before the run is given up.
    pub start_timeout_s: f64,
    /// The path starts with the first estimate at most this old (s, from its newest ROI's mid-exposure to the
    /// control tick that reads it): once the paced loop has caught up on the slots its full-frame start cost.
    pub start_max_age_s: f64,
    /// Run the control thread under `SCHED_FIFO` at this priority (1-99) where the process may (root, or
    /// `CAP_SYS_NICE`; otherwise it runs as an ordinary thread, which [`LiveServoReport::realtime_priority`] says).
    /// It sleeps between ticks, so it takes a core only for its ticks. Default: 50.
    pub realtime_priority: Option<i32>,
    /// The control thread's rate (Hz) when it should tick faster than the ROIs ([`ServoConfig::control_rate_hz`],
    /// one ROI slot a tick, as in simulated time): a command then follows each estimate sooner. The gains do not
    /// change (they follow the estimates' age). Default: none (the configuration's).
    pub control_rate_hz: Option<f64>,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            window_px: None,
            full_frame_s: 0.25,
            start_timeout_s: 5.0,
            start_max_age_s: 0.01,
            realtime_priority: Some(50),
            control_rate_hz: None,
        }
    }
}

/// Runs the closed loop in real time ([`run_live_servo`]) through the project's simulated ROI camera: the servo's
/// camera and target ([`roi_camera_model`], [`servo_target`]), a default sensor and `config.seed`, rendering the
/// robot where a fresh [`RobotScene`] of `config`'s path has it at each grab.
///
/// ```no_run
/// use roitrack_servo::live::{LiveOptions, run_live_servo_simulated};
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
///
/// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
/// let report = run_live_servo_simulated(&config, &LiveOptions::default()).unwrap();
/// println!("{:.3} mm RMS", report.servo.rms_error_mm);
/// ```
pub fn run_live_servo_simulated(
    config: &ServoConfig,
    options: &LiveOptions,
) -> Result<LiveServoReport, ServoError> {
    run_live_servo_simulated_with_sink(config, options, &mut |_| {})
}

/// [`run_live_servo_simulated`], also handing each estimate to `on_estimate` as [`run_live_servo_with_sink`] does.
pub fn run_live_servo_simulated_with_sink(
    config: &ServoConfig,
    options: &LiveOptions,
    on_estimate: &mut (dyn FnMut(&Estimate) + Send),
) -> Result<LiveServoReport, ServoError> {
    let scene = RobotScene::new(&config.path);
    let renderer = RoiRenderer::new(
        roi_camera_model(config),
        servo_target(),
        SensorModel::default(),
    )?;
    let truth = {
        let scene = scene.clone();
        move |t: f64| scene.camera_state_at_loop_s(t)
    };
    let mut camera = LoopClockCamera::new(
        SimulatedCamera::new(renderer, truth, config.seed),
        scene.clone(),
    );
    run_live_servo_with_sink(&mut camera, &scene, config, options, on_estimate)
}

/// Runs the closed loop in real time (see the [module docs](super)): the controller of `config` on its own thread,
/// ticking on the wall clock; the live loop on `camera` (which must render `scene`'s robot at each grab's time:
/// [`RobotScene::camera_state_at_loop_s`]) on this thread and the loop's estimation thread, one ROI per control tick.
/// The run ends at the path's end, when the loop ends (the camera fails), on divergence (reported unstable, as
/// [`crate::run_servo`]), or if no estimate comes within [`LiveOptions::start_timeout_s`].
///
/// A rate the machine cannot hold is run, not refused: deadline misses ([`LiveServoReport::missed_ticks`]) and late
/// ROI slots ([`AcquisitionCounts::late`] of [`LoopReport::acquisition`]) are counted.
///
/// [`AcquisitionCounts::late`]: roitrack_pipeline::AcquisitionCounts::late
/// [`LoopReport::acquisition`]: roitrack_pipeline::LoopReport::acquisition
///
/// ```no_run
/// use roitrack_sim::{RoiRenderer, SensorModel, SimulatedCamera};
/// use roitrack_servo::live::{
///     LiveOptions, LoopClockCamera, RobotScene, roi_camera_model, run_live_servo, servo_target,
/// };
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
///
/// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
/// let scene = RobotScene::new(&config.path);
/// let renderer = RoiRenderer::new(roi_camera_model(&config), servo_target(), SensorModel::default()).unwrap();
/// let truth = { let scene = scene.clone(); move |t: f64| scene.camera_state_at_loop_s(t) };
/// let mut camera = LoopClockCamera::new(SimulatedCamera::new(renderer, truth, 1), scene.clone());
/// let report = run_live_servo(&mut camera, &scene, &config, &LiveOptions::default()).unwrap();
/// let (p50, p99) = report.actuation_latency_quantiles_us();
/// println!("{:.3} mm RMS, latency {p50:.0}/{p99:.0} us", report.servo.rms_error_mm);
/// ```
pub fn run_live_servo<C: RoiCamera>(
    camera: &mut LoopClockCamera<C>,
    scene: &RobotScene,
    config: &ServoConfig,
    options: &LiveOptions,
) -> Result<LiveServoReport, ServoError> {
    run_live_servo_with_sink(camera, scene, config, options, &mut |_| {})
}

/// [`run_live_servo`], also handing each finite estimate of the live loop to `on_estimate` as it is made: those
/// [`ServoReport::estimates`] and the run's files hold, in their order, on the estimation thread, after the
/// controller's estimate handle has it (so that the controller never waits for it). Their times are on the loop's
/// clock (the camera's; [`LiveServoReport::loop_to_path_s`] takes them to the path's clock of the files, which is
/// known only once the path has started). The sink must not block, or it holds the tracker back: a ROS 2 publisher
/// hands each estimate over to a thread of its own (`roitrack_ros::ros2::Ros2Publisher::publish_estimate`).
///
///
/// [`ServoReport::estimates`]: crate::ServoReport::estimates
/// ```no_run
/// use roitrack_servo::live::{LiveOptions, run_live_servo_simulated_with_sink};
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
///
/// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
/// let mut times_s = Vec::new();
/// let report =
///     run_live_servo_simulated_with_sink(&config, &LiveOptions::default(), &mut |e| times_s.push(e.t_ref_s))
///         .unwrap();
/// assert_eq!(times_s.len(), report.servo.estimates.iter().filter(|e| e.state.is_finite()).count());
/// let on_the_path_s = times_s[0] + report.loop_to_path_s;
/// # let _ = on_the_path_s;
/// ```
pub fn run_live_servo_with_sink<C: RoiCamera>(
    camera: &mut LoopClockCamera<C>,
    scene: &RobotScene,
    config: &ServoConfig,
    options: &LiveOptions,
    on_estimate: &mut (dyn FnMut(&Estimate) + Send),
) -> Result<LiveServoReport, ServoError> {
    let loop_config = checked_loop_config(config, options)?;
    let camera_model = roi_camera_model(config);
    let target = servo_target();
    let (mut publisher, reader) = estimate_channel();
    let (mut known_tx, mut known_rx) = known_acceleration_channel(KNOWN_ACCELERATION_SLOTS);
    let published = AtomicU64::new(0);
    let mut to_estimate_us =
        Vec::with_capacity(loop_config.roi_slots / config.tracker.every.max(1) + 64);
    let loop_done = AtomicBool::new(false);
    // Set by the control thread when the path starts: the estimation thread's latencies are kept from then on.
    let path_started = AtomicBool::new(false);
    let stop = camera.stop_flag();
    let wall = Instant::now();

    let (loop_result, control) = std::thread::scope(|threads| {
        let control = threads.spawn(|| {
            let flags = ControlFlags {
                loop_done: &loop_done,
                path_started: &path_started,
                known_acceleration: config.known_acceleration.then_some(&mut known_tx),
            };
            let side = control_thread(config, options, scene, &reader, flags, wall);
            // The path is done (or the run stopped): the loop's next grab ends it.
            stop.store(true, Ordering::Release);
            side
        });
        let mut sink = |e: &Estimate| {
            if e.status.is_vouched_for() && e.state.is_finite() {
                publisher.publish(e);
                published.fetch_add(1, Ordering::Relaxed);
                if path_started.load(Ordering::Acquire) {
                    let age_us = (scene.robot_time_s() - scene.loop_to_robot_s(e.t_ref_s)) * 1e6;
                    to_estimate_us.push_within_capacity_or_skip(age_us);
                }
            }
            // After the controller's handle: what the files will hold (the finite ones), as it comes.
            if e.state.is_finite() {
                on_estimate(e);
            }
        };
        let hooks = LoopHooks {
            progress: None,
            on_estimate: &mut sink,
            known_acceleration: config.known_acceleration.then_some(&mut known_rx),
        };
        let result = run_loop_with_hooks(
            camera,
            &camera_model,
            &target,
            config.tracker,
            &loop_config,
            hooks,
        );
        loop_done.store(true, Ordering::Release);
        (result, control.join())
    });
    let loop_report = loop_result.map_err(|e| ServoError::Tracker(e.to_string()))?;
    let control = control.map_err(|_| ServoError::Tracker("the control thread panicked".into()))?;
    let mut report = report(config, scene, loop_report, control, published.into_inner());
    report.exposure_to_estimate_us = to_estimate_us;
    Ok(report)
}

/// The live loop's configuration for `config` and `options`, both checked first: one ROI slot per control tick,
/// paced, late slots skipped.
fn checked_loop_config(
    config: &ServoConfig,
    options: &LiveOptions,
) -> Result<LoopConfig, ServoError> {
    config.check()?;
    if config.camera != CameraKind::Roi {
        return Err(ServoError::Invalid {
            field: "camera (the real-time loop runs the ROI camera)",
            value: f64::NAN,
        });
    }
    for (field, value) in [
        (
            "control_rate_hz",
            options.control_rate_hz.unwrap_or(config.control_rate_hz),
        ),
        ("start_timeout_s", options.start_timeout_s),
        ("start_max_age_s", options.start_max_age_s),
        ("full_frame_s", options.full_frame_s),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(ServoError::Invalid { field, value });
        }
    }
    // One ROI slot per control tick of the configuration (as `run_servo`); the control thread may tick faster.
    let rate_hz = config.control_rate_hz;
    let mut loop_config = LoopConfig {
        rate_hz,
        paced: true,
        // A slot the camera side reaches late is skipped: a ROI of the past is worth less to the controller.
        skip_late_slots: true,
        // The path, the start's allowance and a second: the control thread ends the run before.
        roi_slots: ((config.path.duration_s() + options.start_timeout_s + 1.0) * rate_hz).ceil()
            as usize,
        full_frame_slots: ((options.full_frame_s * rate_hz).ceil() as usize).max(1),
        ..LoopConfig::default()
    };
    if let Some(side) = options.window_px {
        loop_config.scheduler.min_size_px = side;
        loop_config.scheduler.max_size_px = side;
    }
    loop_config.validate().map_err(|_| ServoError::Invalid {
        field: "window_px (1 to 64)",
        value: f64::from(options.window_px.unwrap_or(0)),
    })?;
    Ok(loop_config)
}
