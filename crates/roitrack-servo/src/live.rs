//! The closed loop in real time: the controller on its own thread at the control rate, on the wall clock, fed by
//! roitrack's live two-thread loop ([`roitrack_pipeline::realtime::run_loop_with_hooks`]) through the estimate handle
//! ([`crate::handle`]), while a camera renders the simulated robot where it is now ([`run_live_servo`]).
//!
//! Three threads (four with Aravis' fake camera, five with its stream thread):
//! - the **control thread** ticks on the wall clock at [`ServoConfig::control_rate_hz`] (or
//!   [`LiveOptions::control_rate_hz`], faster than the ROIs): it reads the newest
//!   estimate ([`crate::handle::EstimateReader::read`]: no lock, no allocation), computes the command (the same
//!   [`Controller`](crate::control::Controller) as [`crate::run_servo`]), and integrates the simulated robot to the
//!   next tick (RK4, the forces acting after the actuation delay), publishing each integration step into a
//!   [`RobotScene`]. A tick woken more than a period late is a deadline miss: the drive holds its last command over
//!   the ticks missed (counted);
//! - the **acquisition thread** (the caller's) runs the live loop's camera side, paced at one ROI per control tick:
//!   each ROI is rendered from the robot's state at its exposure, read from the [`RobotScene`] (lock-free, the
//!   robot's recent steps interpolated);
//! - the **estimation thread** (the loop's) runs the tracker and publishes each estimate it vouches for. With
//!   [`ServoConfig::known_acceleration`] (the default, as in simulated time) the control thread tells it the
//!   acceleration each command asks of the controller's model, from the instant the command acts, through the live
//!   loop's lock-free queue of known accelerations ([`roitrack_pipeline::realtime::known_acceleration_channel`]).
//!
//! Clocks: the robot's clock starts with the [`RobotScene`]; the loop's clock (the ROIs' and estimates' times) starts
//! with the loop. A [`LoopClockCamera`] wrapped around the camera learns the offset between them at each grab (the
//! smallest `robot now - slot time` seen), so that a ROI of loop time `t` shows the robot at robot time `t + offset`
//! and an estimate of loop time `t_ref` is placed on the robot's clock. The path starts when the controller reads the
//! first estimate made on time ([`LiveOptions::start_max_age_s`]): the live loop's full-frame start takes a while, and
//! the paced loop then catches up on the slots it cost; until then the robot's brakes hold it at rest at home.
//!
//! Latency, per estimate: from the mid-exposure of its newest ROI (its `t_ref_s`, on the robot's clock) to the instant
//! the first command made from it acts on the robot (the control thread's wall-clock instant when it issued the
//! command, plus the simulated drive's [`ServoConfig::actuation_delay_s`]); also to the command alone.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering, fence};
use std::time::{Duration, Instant};

use nalgebra::Vector3;
use roitrack_core::Acceleration;
use roitrack_core::time::{Readout, TimeModel};
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_estimators::Estimate;
use roitrack_image::{Frame, GrabError, RoiCamera, RoiImage, RoiTrigger};
use roitrack_pipeline::realtime::{
    KnownAccelerationSender, LoopHooks, known_acceleration_channel, run_loop_with_hooks,
};
use roitrack_pipeline::{LoopConfig, LoopReport};
use roitrack_sim::{RoiRenderer, SensorModel, SimulatedCamera};

use crate::closed_loop::{ServoError, ServoReport, ServoSample, build_controller};
use crate::control::{ControlInput, Observation};
use crate::handle::estimate_channel;
use crate::reference::ReferencePath;
use crate::robot::{Geometry, RobotState, step_rk4};
use crate::{CameraKind, ServoConfig};

/// Robot steps kept for the camera to render from: 1024 integration steps (64 ms at 4 kHz and 4 steps a tick).
const TRACE_SLOTS: usize = 1024;
/// Known accelerations the control thread may have sent ahead of the estimation thread: 1024 commands (a quarter
/// of a second at 4 kHz), far more than the estimation thread lags by unless it is descheduled; a full queue keeps the
/// newest (counted in [`LiveServoReport::superseded_known_accelerations`]).
const KNOWN_ACCELERATION_SLOTS: usize = 1024;
/// Words per step: time, position (3), velocity (3).
const TRACE_WORDS: usize = 7;

struct TraceSlot {
    /// `2 k + 2` once step `k` is written here, odd while it is being written.
    sequence: AtomicU64,
    words: [AtomicU64; TRACE_WORDS],
}

struct SceneShared {
    epoch: Instant,
    slots: Vec<TraceSlot>,
    /// Steps written.
    head: AtomicU64,
    /// Robot time minus loop time (s), the smallest seen; +inf before the first grab.
    offset_s: AtomicU64,
    path: ReferencePath,
}

/// The simulated robot as the camera sees it in a real-time run: its clock (started at [`RobotScene::new`]), its
/// recent integration steps (written by the control thread, read by any camera thread without locks: a sequence
/// number per step), and the offset from the live loop's clock to its own.
///
/// ```
/// use roitrack_servo::live::RobotScene;
/// use roitrack_servo::reference::ReferencePath;
///
/// let path = ReferencePath::orthoglide(1.0);
/// let scene = RobotScene::new(&path);
/// // Before any step, the robot is at rest at home, where the path starts.
/// let seen = scene.camera_state_at_loop_s(0.0);
/// assert_eq!(seen.cam_t_obj_m, path.home_in_camera().1);
/// assert!(scene.robot_time_s() >= 0.0);
/// ```
#[derive(Clone)]
pub struct RobotScene {
    shared: Arc<SceneShared>,
}

impl RobotScene {
    /// A robot at rest at `path`'s home, its clock starting now.
    pub fn new(path: &ReferencePath) -> Self {
        Self {
            shared: Arc::new(SceneShared {
                epoch: Instant::now(),
                slots: (0..TRACE_SLOTS)
                    .map(|_| TraceSlot {
                        sequence: AtomicU64::new(0),
                        words: std::array::from_fn(|_| AtomicU64::new(0)),
                    })
                    .collect(),
                head: AtomicU64::new(0),
                offset_s: AtomicU64::new(f64::INFINITY.to_bits()),
                path: path.clone(),
            }),
        }
    }

    /// The robot's clock now (s since [`Self::new`]).
    pub fn robot_time_s(&self) -> f64 {
        self.shared.epoch.elapsed().as_secs_f64()
    }

    /// Robot time minus loop time (s), once a grab has been seen ([`Self::observe_loop_time`]).
    pub fn loop_offset_s(&self) -> Option<f64> {
        let offset = f64::from_bits(self.shared.offset_s.load(Ordering::Acquire));
        offset.is_finite().then_some(offset)
    }

    /// A grab of the loop's time `t_loop_s` begins now: the offset between the clocks is at most `now - t_loop_s`
    /// (the loop grabs a slot at its time or later), and is kept as the smallest such value.
    pub fn observe_loop_time(&self, t_loop_s: f64) {
        let candidate = self.robot_time_s() - t_loop_s;
        let mut current = self.shared.offset_s.load(Ordering::Acquire);
        while candidate < f64::from_bits(current) {
            match self.shared.offset_s.compare_exchange_weak(
                current,
                candidate.to_bits(),
                Ordering::AcqRel,
                Ordering::Acquire,
            ) {
                Ok(_) => break,
                Err(now) => current = now,
            }
        }
    }

    /// The loop's time `t_loop_s` on the robot's clock (the robot's clock now before the first grab).
    pub fn loop_to_robot_s(&self, t_loop_s: f64) -> f64 {
        match self.loop_offset_s() {
            Some(offset) => t_loop_s + offset,
            None => self.robot_time_s(),
        }
    }

    /// Writes integration step `k` (the `k`-th since the start; one writer, the control thread).
    fn push(&self, t_s: f64, state: &RobotState) {
        let shared = &*self.shared;
        let k = shared.head.load(Ordering::Relaxed);
        let slot = &shared.slots[(k as usize) % TRACE_SLOTS];
        slot.sequence.store(2 * k + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let words = [
            t_s,
            state.position_m.x,
            state.position_m.y,
            state.position_m.z,
            state.velocity_mps.x,
            state.velocity_mps.y,
            state.velocity_mps.z,
        ];
        for (word, value) in slot.words.iter().zip(words) {
            word.store(value.to_bits(), Ordering::Relaxed);
        }
        slot.sequence.store(2 * k + 2, Ordering::Release);
        shared.head.store(k + 1, Ordering::Release);
    }

    /// Step `k` as written, if it is still in its slot and was not overwritten while read.
    fn step(&self, k: u64) -> Option<(f64, RobotState)> {
        let slot = &self.shared.slots[(k as usize) % TRACE_SLOTS];
        let before = slot.sequence.load(Ordering::Acquire);
        if before != 2 * k + 2 {
            return None;
        }
        let mut w = [0.0; TRACE_WORDS];
        for (value, word) in w.iter_mut().zip(&slot.words) {
            *value = f64::from_bits(word.load(Ordering::Relaxed));
        }
        fence(Ordering::Acquire);
        (slot.sequence.load(Ordering::Relaxed) == before).then(|| {
            (
                w[0],
                RobotState {
                    position_m: Vector3::new(w[1], w[2], w[3]),
                    velocity_mps: Vector3::new(w[4], w[5], w[6]),
                },
            )
        })
    }

    /// The robot's state at robot time `t_s`: between two written steps, cubic Hermite (positions and velocities);
    /// after the newest, the newest moved on at its velocity; before the oldest kept, the oldest. At rest at home
    /// before the first step. Lock-free: a bisection over the steps kept, each read under its sequence number.
    ///
    /// ```
    /// use roitrack_servo::live::RobotScene;
    /// use roitrack_servo::reference::ReferencePath;
    /// let scene = RobotScene::new(&ReferencePath::orthoglide(1.0));
    /// assert_eq!(scene.state_at(0.5).position_m, nalgebra::Vector3::zeros());
    /// ```
    pub fn state_at(&self, t_s: f64) -> RobotState {
        let head = self.shared.head.load(Ordering::Acquire);
        if head == 0 {
            return RobotState::default();
        }
        let newest = head - 1;
        let Some((t_new, s_new)) = self.step(newest) else {
            return RobotState::default();
        };
        if t_new <= t_s {
            return RobotState {
                position_m: s_new.position_m + s_new.velocity_mps * (t_s - t_new),
                velocity_mps: s_new.velocity_mps,
            };
        }
        // Bisection on the steps kept (their times increase): `lo` at or before `t_s` (or the oldest readable),
        // `hi` after it. A step overwritten while searching counts as too old.
        let (mut lo, mut hi) = (head.saturating_sub(TRACE_SLOTS as u64 - 1), newest);
        let mut later = (t_new, s_new);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            match self.step(mid) {
                Some((t_mid, s_mid)) if t_mid > t_s => {
                    hi = mid;
                    later = (t_mid, s_mid);
                }
                _ => lo = mid,
            }
        }
        match self.step(lo) {
            Some((t_lo, s_lo)) if t_lo <= t_s => hermite(t_lo, &s_lo, later.0, &later.1, t_s),
            // Older than every step kept: the oldest there is.
            Some((_, s_lo)) => s_lo,
            None => later.1,
        }
    }

    /// The target's state in the camera frame at the loop's time `t_loop_s`: what a camera exposed then sees.
    pub fn camera_state_at_loop_s(&self, t_loop_s: f64) -> MotionState {
        let s = self.state_at(self.loop_to_robot_s(t_loop_s));
        self.shared
            .path
            .camera_state(&s.position_m, &s.velocity_mps)
    }
}

/// Cubic Hermite interpolation between `(t_a, a)` and `(t_b, b)` at `t_s`.
fn hermite(t_a: f64, a: &RobotState, t_b: f64, b: &RobotState, t_s: f64) -> RobotState {
    let h = t_b - t_a;
    if h <= 0.0 {
        return *b;
    }
    let u = ((t_s - t_a) / h).clamp(0.0, 1.0);
    let (u2, u3) = (u * u, u * u * u);
    RobotState {
        position_m: a.position_m * (2.0 * u3 - 3.0 * u2 + 1.0)
            + a.velocity_mps * (h * (u3 - 2.0 * u2 + u))
            + b.position_m * (-2.0 * u3 + 3.0 * u2)
            + b.velocity_mps * (h * (u3 - u2)),
        velocity_mps: (a.position_m * (6.0 * u2 - 6.0 * u) + b.position_m * (-6.0 * u2 + 6.0 * u))
            / h
            + a.velocity_mps * (3.0 * u2 - 4.0 * u + 1.0)
            + b.velocity_mps * (3.0 * u2 - 2.0 * u),
    }
}

/// A camera of the live loop, its grabs telling a [`RobotScene`] the loop's time (so that the scene learns the
/// offset between the clocks before the ROI is rendered), and ending the run with [`GrabError::Stopped`] once
/// [`Self::stop_flag`] is set (the control thread's end of the path).
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::RoiCamera;
/// use roitrack_sim::{RoiRenderer, SensorModel, SimulatedCamera};
/// use roitrack_servo::live::{LoopClockCamera, RobotScene};
/// use roitrack_servo::reference::ReferencePath;
///
/// let scene = RobotScene::new(&ReferencePath::orthoglide(1.0));
/// let renderer = RoiRenderer::new(CameraModel::canonical(), Target::grid4x4(), SensorModel::default()).unwrap();
/// let truth = { let scene = scene.clone(); move |t: f64| scene.camera_state_at_loop_s(t) };
/// let mut camera = LoopClockCamera::new(SimulatedCamera::new(renderer, truth, 1), scene.clone());
/// camera.grab_full_frame(0.0, &mut Default::default()).unwrap();
/// assert!(scene.loop_offset_s().unwrap() >= 0.0);
/// camera.stop_flag().store(true, std::sync::atomic::Ordering::Release);
/// assert!(camera.grab_full_frame(0.0, &mut Default::default()).is_err());
/// ```
pub struct LoopClockCamera<C> {
    inner: C,
    scene: RobotScene,
    stop: Arc<AtomicBool>,
}

impl<C: RoiCamera> LoopClockCamera<C> {
    /// `inner`, telling `scene` the time of each grab.
    pub fn new(inner: C, scene: RobotScene) -> Self {
        Self {
            inner,
            scene,
            stop: Arc::new(AtomicBool::new(false)),
        }
    }

    /// Set: the next grab ends the run.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// The camera inside.
    pub fn inner(&self) -> &C {
        &self.inner
    }

    fn check(&self, t_s: f64) -> Result<(), GrabError> {
        if self.stop.load(Ordering::Acquire) {
            return Err(GrabError::Stopped {
                reason: "the control thread ended the run".into(),
            });
        }
        self.scene.observe_loop_time(t_s);
        Ok(())
    }
}

impl<C: RoiCamera> RoiCamera for LoopClockCamera<C> {
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
        self.check(trigger.t_s)?;
        self.inner.grab_roi(trigger, image)
    }

    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
        self.check(t_s)?;
        self.inner.grab_full_frame(t_s, frame)
    }
}

/// The camera model of the servo's ROI camera for `config` (the canonical camera, ROIs read one after the other,
/// the timing's exposure), as [`crate::run_servo`] renders: give it to the camera that renders the live run.
///
/// ```
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
/// let config = ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0);
/// assert_eq!(roitrack_servo::live::roi_camera_model(&config).time.exposure_s, 100e-6);
/// ```
pub fn roi_camera_model(config: &ServoConfig) -> CameraModel {
    let mut camera = CameraModel::canonical();
    camera.time = TimeModel {
        readout: Readout::SequentialRois,
        exposure_s: config.camera_timing().exposure_s,
    };
    camera
}

/// The servo's target (the 4 x 4 grid), as [`crate::run_servo`] renders.
///
/// ```
/// assert_eq!(roitrack_servo::live::servo_target().points().len(), 16);
/// ```
pub fn servo_target() -> Target {
    Target::grid4x4()
}

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
    pub loop_to_path_s: f64,
    /// Estimates published to the control thread (vouched for and finite).
    pub published: usize,
    /// Whether the control thread ran under the real-time priority asked for ([`LiveOptions::realtime_priority`]).
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

/// What the control thread hands back.
struct ControlSide {
    samples: Vec<ServoSample>,
    ages_s: Vec<f64>,
    to_actuation_us: Vec<f64>,
    to_command_us: Vec<f64>,
    ticks: usize,
    missed: usize,
    missed_before_start: usize,
    longest_missed_run: usize,
    saturated_ticks: usize,
    stop_reason: Option<String>,
    path_start_robot_s: Option<f64>,
    start_delay_s: f64,
    realtime_priority: bool,
    sent_known_accelerations: usize,
    superseded_known_accelerations: usize,
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

/// Runs the closed loop in real time (see the [module docs](self)): the controller of `config` on its own thread,
/// ticking on the wall clock; the live loop on `camera` (which must render `scene`'s robot at each grab's time:
/// [`RobotScene::camera_state_at_loop_s`]) on this thread and the loop's estimation thread, one ROI per control tick.
/// The run ends at the path's end, when the loop ends (the camera fails), on divergence (reported unstable, as
/// [`crate::run_servo`]), or if no estimate comes within [`LiveOptions::start_timeout_s`].
///
/// A rate the machine cannot hold is run, not refused: deadline misses ([`LiveServoReport::missed_ticks`]) and late
/// ROI slots ([`LoopReport::late`]) are counted.
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
    let camera_model = roi_camera_model(config);
    let target = servo_target();
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

fn report(
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

/// The control thread sleeps until this long before each tick (s), then spins: a sleep wakes tens of microseconds
/// late, and the other threads need the two cores between ticks.
const SPIN_BEFORE_TICK_S: f64 = 10e-6;

/// Asks the scheduler to run the calling thread under `SCHED_FIFO` at `priority` (1-99): it then preempts the
/// machine's ordinary threads when its sleep ends. Refused without the privilege (`CAP_SYS_NICE`); false then, or
/// off Linux.
fn request_realtime_priority(priority: i32) -> bool {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param {
            sched_priority: priority,
        };
        // SAFETY: `pthread_self` is the calling thread, alive during the call; `param` outlives it.
        unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) == 0 }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = priority;
        false
    }
}

/// What the control thread and the loop tell each other.
struct ControlFlags<'a> {
    /// Set when the live loop has ended.
    loop_done: &'a AtomicBool,
    /// Set by the control thread when the path starts.
    path_started: &'a AtomicBool,
    /// Where the control thread sends the acceleration each command asks of its model
    /// ([`ServoConfig::known_acceleration`]); `None`: the tracker is not told.
    known_acceleration: Option<&'a mut KnownAccelerationSender>,
}

/// The control thread: ticks on the robot's clock until the path's end, the loop's end, a divergence or the start's
/// timeout. Everything it keeps is sized before its first tick: no allocation, no lock.
fn control_thread(
    config: &ServoConfig,
    options: &LiveOptions,
    scene: &RobotScene,
    reader: &crate::handle::EstimateReader,
    flags: ControlFlags<'_>,
    wall: Instant,
) -> ControlSide {
    let ControlFlags {
        loop_done,
        path_started,
        mut known_acceleration,
    } = flags;
    let robot = config.robot;
    let path = &config.path;
    let (_, mut controller) = build_controller(config);
    let model = robot
        .with_mass_factor(config.model_mass_factor)
        .with_friction_factor(config.model_friction_factor);
    let control_rate_hz = options.control_rate_hz.unwrap_or(config.control_rate_hz);
    let tick_s = 1.0 / control_rate_hz;
    let step_s = tick_s / config.substeps as f64;
    let path_ticks = (path.duration_s() / tick_s).round() as usize;
    let expected_estimates = path_ticks / config.tracker.every.max(1) + 256;
    let mut side = ControlSide {
        samples: Vec::with_capacity(path_ticks + 2),
        ages_s: Vec::with_capacity(path_ticks + 2),
        to_actuation_us: Vec::with_capacity(expected_estimates),
        to_command_us: Vec::with_capacity(expected_estimates),
        ticks: 0,
        missed: 0,
        missed_before_start: 0,
        longest_missed_run: 0,
        saturated_ticks: 0,
        stop_reason: None,
        path_start_robot_s: None,
        start_delay_s: f64::NAN,
        realtime_priority: false,
        sent_known_accelerations: 0,
        superseded_known_accelerations: 0,
    };
    let (_, home_cam) = path.home_in_camera();
    let limit = robot.force_limit_n;
    let clip = |f: Vector3<f64>| f.map(|x| x.clamp(-limit, limit));
    let hold = Geometry::at(&model, &Vector3::zeros())
        .map(|g| g.gravity_forces(&model))
        .unwrap_or_else(|_| Vector3::zeros());
    let mut force = hold;
    // Commands waiting for their actuation instant (robot clock); a few at most.
    let mut commands: VecDeque<(f64, Vector3<f64>)> = VecDeque::with_capacity(256);
    let window_ticks = ((config.saturation_window_s * control_rate_hz).round() as usize).max(1);
    let mut recent_saturation: VecDeque<bool> = VecDeque::with_capacity(window_ticks + 1);
    let mut recent_saturated = 0usize;
    let mut state = RobotState::default();
    let mut t_robot_s = scene.robot_time_s();
    scene.push(t_robot_s, &state);
    let mut last_sequence = 0u64;
    let mut observation: Option<Observation> = None;
    let mut path_start: Option<f64> = None;
    let mut next_tick_s = t_robot_s;
    side.realtime_priority = options
        .realtime_priority
        .is_some_and(request_realtime_priority);
    loop {
        if loop_done.load(Ordering::Acquire) {
            if path_start.is_none() {
                side.stop_reason = Some("the live loop ended before its first estimate".into());
            } else {
                side.stop_reason = Some("the live loop ended before the path's end".into());
            }
            break;
        }
        // Wait for the tick's instant: asleep until just before it, then spinning.
        let now_s = scene.robot_time_s();
        if now_s < next_tick_s {
            let left_s = next_tick_s - now_s;
            if left_s > SPIN_BEFORE_TICK_S {
                std::thread::sleep(Duration::from_secs_f64(left_s - SPIN_BEFORE_TICK_S));
            } else {
                std::hint::spin_loop();
            }
            continue;
        }
        // Ticks whose instant passed a whole period ago were missed: the drive held its force over them.
        let behind = ((now_s - next_tick_s) / tick_s).floor() as usize;
        if behind > 0 {
            if path_start.is_some() {
                side.missed += behind;
                side.longest_missed_run = side.longest_missed_run.max(behind);
            } else {
                side.missed_before_start += behind;
            }
            next_tick_s += behind as f64 * tick_s;
        }
        if path_start.is_none() && wall.elapsed().as_secs_f64() > options.start_timeout_s {
            side.stop_reason = Some(format!(
                "no estimate within {:.1} s of the start",
                options.start_timeout_s
            ));
            break;
        }
        // The newest estimate, if new: on the robot's clock, then the path's. Its latency is measured when the
        // command it makes is issued, below.
        let mut fresh_exposure_s = None;
        if let Some(snapshot) = reader.read()
            && snapshot.sequence != last_sequence
        {
            last_sequence = snapshot.sequence;
            let t_ref_robot_s = scene.loop_to_robot_s(snapshot.t_ref_s);
            // The path starts with the first estimate the loop makes on time: after its full-frame start the paced
            // loop catches up on the slots it missed, with estimates of the past.
            if path_start.is_none() && now_s - t_ref_robot_s <= options.start_max_age_s {
                side.start_delay_s = wall.elapsed().as_secs_f64();
                side.path_start_robot_s = Some(now_s);
                path_start = Some(now_s);
                path_started.store(true, Ordering::Release);
            }
            let Some(start) = path_start else {
                hold_home(scene, &mut t_robot_s, next_tick_s + tick_s);
                next_tick_s += tick_s;
                continue;
            };
            observation = Some(Observation {
                t_s: t_ref_robot_s - start,
                position_m: snapshot.state.cam_t_obj_m - home_cam,
                velocity_mps: snapshot.state.velocity_mps,
                acceleration_mps2: None,
            });
            fresh_exposure_s = Some(t_ref_robot_s);
        }
        let Some(start) = path_start else {
            hold_home(scene, &mut t_robot_s, next_tick_s + tick_s);
            next_tick_s += tick_s;
            continue;
        };
        // The command, acting the drive's delay after it is issued.
        let geometry = match Geometry::at(&robot, &state.position_m) {
            Ok(g) => g,
            Err(e) => {
                side.stop_reason = Some(e.to_string());
                break;
            }
        };
        let issued_s = scene.robot_time_s();
        let t_act_s = issued_s + config.actuation_delay_s;
        if let Some(o) = &observation {
            side.ages_s
                .push_within_capacity_or_skip(t_act_s - start - o.t_s);
        }
        let input = ControlInput {
            t_act_s: t_act_s - start,
            dt_s: tick_s,
            reference: path.at(t_act_s - start),
            observation,
            drive_joint_velocity_mps: geometry.joint_velocity(&state.velocity_mps),
        };
        let command = controller.command(&input);
        let after_s = scene.robot_time_s();
        if let Some(exposure_s) = fresh_exposure_s {
            side.to_command_us
                .push_within_capacity_or_skip((after_s - exposure_s) * 1e6);
            side.to_actuation_us.push_within_capacity_or_skip(
                (after_s + config.actuation_delay_s - exposure_s) * 1e6,
            );
        }
        if !command.iter().all(|f| f.is_finite()) {
            side.stop_reason = Some(format!(
                "the controller gave a force that is not finite at t = {:.4} s",
                issued_s - start
            ));
            break;
        }
        let command = clip(command);
        let queued = commands.len() < commands.capacity();
        if queued {
            commands.push_back((after_s + config.actuation_delay_s, command));
        }
        // What the command asks of the controller's model, from the instant it acts, told to the tracker on the
        // loop's clock (as `run_servo` does in simulated time: the robot frame has the camera's axes). A command the
        // drive never gets (its queue full) is not told either.
        if queued
            && let Some(sender) = known_acceleration.as_deref_mut()
            && let Some(believed_mps2) = controller.believed_acceleration(&command)
            && let Some(offset_s) = scene.loop_offset_s()
        {
            let acceleration = Acceleration {
                linear_mps2: believed_mps2,
                angular_radps2: Vector3::zeros(),
            };
            sender.send(after_s + config.actuation_delay_s - offset_s, acceleration);
            side.sent_known_accelerations += 1;
            side.superseded_known_accelerations = sender.superseded();
        }
        // The robot to the next tick.
        let saturated_before = force.amax() >= limit;
        if let Err(reason) = integrate(
            config,
            scene,
            &mut state,
            &mut t_robot_s,
            next_tick_s + tick_s,
            step_s,
            &mut commands,
            &mut force,
        ) {
            side.stop_reason = Some(reason);
            break;
        }
        next_tick_s += tick_s;
        side.ticks += 1;
        let saturated = saturated_before || force.amax() >= limit;
        side.saturated_ticks += usize::from(saturated);
        recent_saturation.push_back(saturated);
        recent_saturated += usize::from(saturated);
        if recent_saturation.len() > window_ticks {
            recent_saturated -= usize::from(recent_saturation.pop_front().unwrap_or(false));
        }
        if recent_saturation.len() == window_ticks && 2 * recent_saturated > window_ticks {
            side.stop_reason = Some(format!(
                "unstable: an actuator at its force limit {:.0} % of the {:.0} ms before t = {:.4} s",
                100.0 * recent_saturated as f64 / window_ticks as f64,
                config.saturation_window_s * 1e3,
                t_robot_s - start
            ));
            break;
        }
        let t_path_s = t_robot_s - start;
        let sample = ServoSample {
            t_s: t_path_s,
            reference: path.at(t_path_s),
            achieved_m: state.position_m,
            achieved_velocity_mps: state.velocity_mps,
            force_n: force,
        };
        if side.samples.len() < side.samples.capacity() {
            side.samples.push(sample);
        }
        if sample.error_m() > config.divergence_error_m {
            side.stop_reason = Some(format!(
                "diverged: {:.1} mm from the path at t = {t_path_s:.4} s (limit {:.1} mm)",
                sample.error_m() * 1e3,
                config.divergence_error_m * 1e3
            ));
            break;
        }
        if t_path_s >= path.duration_s() {
            break;
        }
    }
    side
}

/// Before the path starts the robot's brakes hold it at rest at home: its state as it is, published up to `until_s`.
fn hold_home(scene: &RobotScene, t_robot_s: &mut f64, until_s: f64) {
    *t_robot_s = until_s;
    scene.push(until_s, &RobotState::default());
}

/// Pushes onto a vector only within the room it was given: the control thread never allocates.
trait PushWithinCapacity<T> {
    fn push_within_capacity_or_skip(&mut self, value: T);
}

impl<T> PushWithinCapacity<T> for Vec<T> {
    fn push_within_capacity_or_skip(&mut self, value: T) {
        if self.len() < self.capacity() {
            self.push(value);
        }
    }
}

/// Integrates the robot from `t_robot_s` to `until_s` (robot clock) in steps of at most `step_s`, applying each
/// queued command from its actuation instant, and publishes every step to `scene`.
#[allow(clippy::too_many_arguments)]
fn integrate(
    config: &ServoConfig,
    scene: &RobotScene,
    state: &mut RobotState,
    t_robot_s: &mut f64,
    until_s: f64,
    step_s: f64,
    commands: &mut VecDeque<(f64, Vector3<f64>)>,
    force: &mut Vector3<f64>,
) -> Result<(), String> {
    while *t_robot_s < until_s - 1e-12 {
        while let Some(&(at_s, f)) = commands.front()
            && at_s <= *t_robot_s + 1e-12
        {
            *force = f;
            commands.pop_front();
        }
        let dt_s = step_s.min(until_s - *t_robot_s);
        let next = step_rk4(&config.robot, state, force, dt_s).map_err(|e| e.to_string())?;
        if !next
            .position_m
            .iter()
            .chain(&next.velocity_mps)
            .all(|x| x.is_finite())
        {
            return Err(format!(
                "the robot's state is not finite at robot time {:.4} s",
                *t_robot_s
            ));
        }
        *state = next;
        *t_robot_s += dt_s;
        scene.push(*t_robot_s, state);
    }
    Ok(())
}
