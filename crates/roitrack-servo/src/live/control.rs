//! The control thread: on the wall clock at the control rate, the newest estimate read, the command computed and
//! the simulated robot integrated to the next tick, without allocating or locking.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::Vector3;
use roitrack_core::Acceleration;
use roitrack_pipeline::realtime::KnownAccelerationSender;

use super::run::LiveOptions;
use super::scene::RobotScene;
use crate::ServoConfig;
use crate::closed_loop::{SaturationWindow, ServoSample, build_controller};
use crate::control::{ControlInput, Controller, Observation};
use crate::robot::{Geometry, RobotState, step_rk4};

/// What the control thread hands back.
pub(super) struct ControlSide {
    pub(super) samples: Vec<ServoSample>,
    pub(super) ages_s: Vec<f64>,
    pub(super) to_actuation_us: Vec<f64>,
    pub(super) to_command_us: Vec<f64>,
    pub(super) ticks: usize,
    pub(super) missed: usize,
    pub(super) missed_before_start: usize,
    pub(super) longest_missed_run: usize,
    pub(super) saturated_ticks: usize,
    pub(super) stop_reason: Option<String>,
    pub(super) path_start_robot_s: Option<f64>,
    pub(super) start_delay_s: f64,
    pub(super) realtime_priority: bool,
    pub(super) sent_known_accelerations: usize,
    pub(super) superseded_known_accelerations: usize,
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
pub(super) struct ControlFlags<'a> {
    /// Set when the live loop has ended.
    pub(super) loop_done: &'a AtomicBool,
    /// Set by the control thread when the path starts.
    pub(super) path_started: &'a AtomicBool,
    /// Where the control thread sends the acceleration each command asks of its model
    /// ([`ServoConfig::known_acceleration`]); `None`: the tracker is not told.
    pub(super) known_acceleration: Option<&'a mut KnownAccelerationSender>,
}

/// The control thread: ticks on the robot's clock until the path's end, the loop's end, a divergence or the start's
/// timeout. Everything it keeps is sized before its first tick: no allocation, no lock.
pub(super) fn control_thread(
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
        known_acceleration,
    } = flags;
    let control_rate_hz = options.control_rate_hz.unwrap_or(config.control_rate_hz);
    let mut follower = PathFollower::new(config, scene, control_rate_hz, known_acceleration);
    let tick_s = follower.tick_s;
    let mut last_sequence = 0u64;
    let mut observation: Option<Observation> = None;
    let mut path_start: Option<f64> = None;
    let mut next_tick_s = follower.drive.t_robot_s;
    follower.side.realtime_priority = options
        .realtime_priority
        .is_some_and(request_realtime_priority);
    let stop_reason = loop {
        if loop_done.load(Ordering::Acquire) {
            break Some(loop_ended_reason(path_start.is_some()).into());
        }
        let now_s = scene.robot_time_s();
        if now_s < next_tick_s {
            wait_towards_tick(next_tick_s - now_s);
            continue;
        }
        next_tick_s =
            follower
                .side
                .skip_missed_ticks(now_s, next_tick_s, tick_s, path_start.is_some());
        if path_start.is_none() && wall.elapsed().as_secs_f64() > options.start_timeout_s {
            break Some(format!(
                "no estimate within {:.1} s of the start",
                options.start_timeout_s
            ));
        }
        // The newest estimate, if new: on the robot's clock, then the path's. Its latency is measured when the
        // command it makes is issued, in the tick.
        let mut fresh_exposure_s = None;
        if let Some(snapshot) = read_new_estimate(reader, &mut last_sequence) {
            let t_ref_robot_s = scene.loop_to_robot_s(snapshot.t_ref_s);
            // The path starts with the first estimate the loop makes on time: after its full-frame start the paced
            // loop catches up on the slots it missed, with estimates of the past.
            if path_start.is_none() && now_s - t_ref_robot_s <= options.start_max_age_s {
                follower.side.start_delay_s = wall.elapsed().as_secs_f64();
                follower.side.path_start_robot_s = Some(now_s);
                path_start = Some(now_s);
                path_started.store(true, Ordering::Release);
            }
            if let Some(start) = path_start {
                observation = Some(observation_on_path(
                    &snapshot,
                    t_ref_robot_s - start,
                    config,
                ));
                fresh_exposure_s = Some(t_ref_robot_s);
            }
        }
        let until_s = next_tick_s + tick_s;
        next_tick_s += tick_s;
        let Some(start) = path_start else {
            follower.drive.hold_home(scene, until_s);
            continue;
        };
        match follower.tick(start, observation, fresh_exposure_s, until_s) {
            Ok(TickEnd::PathGoesOn) => {}
            Ok(TickEnd::PathDone) => break None,
            Err(reason) => break Some(reason),
        }
    };
    let mut side = follower.side;
    side.stop_reason = stop_reason;
    side
}

/// The newest estimate, if the loop published one since `last_sequence` (then updated to it).
fn read_new_estimate(
    reader: &crate::handle::EstimateReader,
    last_sequence: &mut u64,
) -> Option<crate::handle::EstimateSnapshot> {
    let snapshot = reader.read()?;
    if snapshot.sequence == *last_sequence {
        return None;
    }
    *last_sequence = snapshot.sequence;
    Some(snapshot)
}

/// What the controller observes of an estimate: the platform's position relative to home (the target's position at
/// the path's home, in the camera frame: the robot frame has the camera's axes) and its velocity, at `t_path_s` on
/// the path's clock.
fn observation_on_path(
    snapshot: &crate::handle::EstimateSnapshot,
    t_path_s: f64,
    config: &ServoConfig,
) -> Observation {
    let (_, home_cam) = config.path.home_in_camera();
    Observation {
        t_s: t_path_s,
        position_m: snapshot.state.cam_t_obj_m - home_cam,
        velocity_mps: snapshot.state.velocity_mps,
        acceleration_mps2: None,
    }
}

/// How a tick of the running path ended, when nothing stopped the thread.
enum TickEnd {
    PathGoesOn,
    PathDone,
}

/// The running path's side of the control thread: each tick's command, the simulated drive it acts on, the
/// watch for instability and what is counted for the report.
struct PathFollower<'a> {
    config: &'a ServoConfig,
    scene: &'a RobotScene,
    tick_s: f64,
    /// The integration step (s): a tick in `config.substeps`.
    step_s: f64,
    controller: Box<dyn Controller + Send>,
    /// Where each command's believed acceleration goes; `None`: the tracker is not told.
    known_acceleration: Option<&'a mut KnownAccelerationSender>,
    drive: SimulatedDrive,
    saturation: SaturationWindow,
    side: ControlSide,
}

impl<'a> PathFollower<'a> {
    /// Sized for the whole path at `control_rate_hz`, the robot at rest at home (published to `scene`).
    fn new(
        config: &'a ServoConfig,
        scene: &'a RobotScene,
        control_rate_hz: f64,
        known_acceleration: Option<&'a mut KnownAccelerationSender>,
    ) -> Self {
        let (_, controller) = build_controller(config);
        let tick_s = 1.0 / control_rate_hz;
        let step_s = tick_s / config.substeps as f64;
        let path_ticks = (config.path.duration_s() / tick_s).round() as usize;
        let expected_estimates = path_ticks / config.tracker.every.max(1) + 256;
        let window_ticks = ((config.saturation_window_s * control_rate_hz).round() as usize).max(1);
        PathFollower {
            config,
            scene,
            tick_s,
            step_s,
            controller,
            known_acceleration,
            side: ControlSide::with_room(path_ticks, expected_estimates),
            saturation: SaturationWindow::new(window_ticks),
            drive: SimulatedDrive::at_home(config, scene),
        }
    }

    /// One tick of the path started at `start` (robot clock): the command from the newest observation, queued to
    /// act the drive's delay after it is ready, and the robot integrated to `until_s`. Err: why the thread stops
    /// (a force or state not finite, the robot out of reach, instability, divergence).
    fn tick(
        &mut self,
        start: f64,
        observation: Option<Observation>,
        fresh_exposure_s: Option<f64>,
        until_s: f64,
    ) -> Result<TickEnd, String> {
        let config = self.config;
        let issued = self.issue_command(start, observation)?;
        let acts_s = issued.ready_s + config.actuation_delay_s;
        if let Some(exposure_s) = fresh_exposure_s {
            self.side.record_latency(issued.ready_s, acts_s, exposure_s);
        }
        if !issued.force_n.iter().all(|f| f.is_finite()) {
            return Err(format!(
                "the controller gave a force that is not finite at t = {:.4} s",
                issued.issued_s - start
            ));
        }
        let command = self.drive.clip(issued.force_n);
        let queued = self.drive.queue(acts_s, command);
        // A command the drive never gets (its queue full) is not told to the tracker either.
        if queued && let Some(sender) = self.known_acceleration.as_deref_mut() {
            tell_known_acceleration(
                sender,
                self.controller.as_ref(),
                &command,
                acts_s,
                self.scene,
                &mut self.side,
            );
        }
        // The robot to the next tick.
        let saturated = self
            .drive
            .advance(config, self.scene, until_s, self.step_s)?;
        self.side.ticks += 1;
        self.side.saturated_ticks += usize::from(saturated);
        if let Some(saturated_percent) = self.saturation.push(saturated) {
            return Err(format!(
                "unstable: an actuator at its force limit {:.0} % of the {:.0} ms before t = {:.4} s",
                saturated_percent,
                config.saturation_window_s * 1e3,
                self.drive.t_robot_s - start
            ));
        }
        let t_path_s = self.drive.t_robot_s - start;
        let sample = ServoSample {
            t_s: t_path_s,
            reference: config.path.at(t_path_s),
            achieved_m: self.drive.state.position_m,
            achieved_velocity_mps: self.drive.state.velocity_mps,
            force_n: self.drive.force_n,
        };
        self.side.samples.push_within_capacity_or_skip(sample);
        if sample.error_m() > config.divergence_error_m {
            return Err(format!(
                "diverged: {:.1} mm from the path at t = {t_path_s:.4} s (limit {:.1} mm)",
                sample.error_m() * 1e3,
                config.divergence_error_m * 1e3
            ));
        }
        Ok(if t_path_s >= config.path.duration_s() {
            TickEnd::PathDone
        } else {
            TickEnd::PathGoesOn
        })
    }

    /// Asks the controller for the tick's command, for the instant it will act (the drive's delay after it is
    /// issued), and records the observation's age at that instant. Err when the robot's geometry is out of reach.
    fn issue_command(
        &mut self,
        start: f64,
        observation: Option<Observation>,
    ) -> Result<IssuedCommand, String> {
        let config = self.config;
        let state = &self.drive.state;
        let geometry = Geometry::at(&config.robot, &state.position_m).map_err(|e| e.to_string())?;
        let issued_s = self.scene.robot_time_s();
        let t_act_s = issued_s + config.actuation_delay_s;
        if let Some(o) = &observation {
            self.side
                .ages_s
                .push_within_capacity_or_skip(t_act_s - start - o.t_s);
        }
        let input = ControlInput {
            t_act_s: t_act_s - start,
            dt_s: self.tick_s,
            reference: config.path.at(t_act_s - start),
            observation,
            drive_joint_velocity_mps: geometry.joint_velocity(&state.velocity_mps),
        };
        let force_n = self.controller.command(&input);
        Ok(IssuedCommand {
            issued_s,
            ready_s: self.scene.robot_time_s(),
            force_n,
        })
    }
}

impl ControlSide {
    /// Nothing counted yet, with room for every tick's sample and every estimate's latency the path is expected to
    /// need: the control thread pushes only within this room.
    fn with_room(path_ticks: usize, expected_estimates: usize) -> Self {
        ControlSide {
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
        }
    }

    /// Counts the ticks whose instant passed a whole period before `now_s` as missed (the drive held its force over
    /// them) and gives the instant of the tick due now.
    fn skip_missed_ticks(
        &mut self,
        now_s: f64,
        next_tick_s: f64,
        tick_s: f64,
        path_running: bool,
    ) -> f64 {
        let behind = ((now_s - next_tick_s) / tick_s).floor() as usize;
        if behind == 0 {
            return next_tick_s;
        }
        if path_running {
            self.missed += behind;
            self.longest_missed_run = self.longest_missed_run.max(behind);
        } else {
            self.missed_before_start += behind;
        }
        next_tick_s + behind as f64 * tick_s
    }

    /// A fresh estimate's latency (µs) from its exposure to the command it made being ready, and to that command
    /// acting.
    fn record_latency(&mut self, ready_s: f64, acts_s: f64, exposure_s: f64) {
        self.to_command_us
            .push_within_capacity_or_skip((ready_s - exposure_s) * 1e6);
        self.to_actuation_us
            .push_within_capacity_or_skip((acts_s - exposure_s) * 1e6);
    }
}

/// Why the control thread stopped when the live loop ended first.
fn loop_ended_reason(path_running: bool) -> &'static str {
    if path_running {
        "the live loop ended before the path's end"
    } else {
        "the live loop ended before its first estimate"
    }
}

/// Waits towards a tick `left_s` ahead: asleep until just before it, then spinning. The caller checks the clock
/// again after.
fn wait_towards_tick(left_s: f64) {
    if left_s > SPIN_BEFORE_TICK_S {
        std::thread::sleep(Duration::from_secs_f64(left_s - SPIN_BEFORE_TICK_S));
    } else {
        std::hint::spin_loop();
    }
}

/// A tick's command as the controller gave it (not yet checked or clipped), with when it was asked for and when it
/// was ready (robot clock, s).
struct IssuedCommand {
    issued_s: f64,
    ready_s: f64,
    force_n: Vector3<f64>,
}

/// Tells the tracker what `command` asks of the controller's model, from the instant it acts (`acts_s`, robot
/// clock), on the loop's clock (as `run_servo` does in simulated time: the robot frame has the camera's axes).
/// Nothing when the controller has no model or the clocks are not yet tied.
fn tell_known_acceleration(
    sender: &mut KnownAccelerationSender,
    controller: &(dyn Controller + Send),
    command: &Vector3<f64>,
    acts_s: f64,
    scene: &RobotScene,
    side: &mut ControlSide,
) {
    let Some(believed_mps2) = controller.believed_acceleration(command) else {
        return;
    };
    let Some(offset_s) = scene.loop_offset_s() else {
        return;
    };
    let acceleration = Acceleration {
        linear_mps2: believed_mps2,
        angular_radps2: Vector3::zeros(),
    };
    sender.send(acts_s - offset_s, acceleration);
    side.sent_known_accelerations += 1;
    side.superseded_known_accelerations = sender.superseded();
}

/// The simulated robot as the control thread drives it: its state on the robot's clock, the force its actuators
/// hold and the commands waiting for their actuation instant.
struct SimulatedDrive {
    state: RobotState,
    t_robot_s: f64,
    force_n: Vector3<f64>,
    /// Commands waiting for their actuation instant (robot clock); a few at most.
    commands: VecDeque<(f64, Vector3<f64>)>,
    force_limit_n: f64,
}

impl SimulatedDrive {
    /// At rest at home now, holding the force the controller's model needs against gravity there; published to
    /// `scene`.
    fn at_home(config: &ServoConfig, scene: &RobotScene) -> Self {
        let model = config
            .robot
            .with_mass_factor(config.model_mass_factor)
            .with_friction_factor(config.model_friction_factor);
        let hold_n = Geometry::at(&model, &Vector3::zeros())
            .map(|g| g.gravity_forces(&model))
            .unwrap_or_else(|_| Vector3::zeros());
        let drive = SimulatedDrive {
            state: RobotState::default(),
            t_robot_s: scene.robot_time_s(),
            force_n: hold_n,
            commands: VecDeque::with_capacity(256),
            force_limit_n: config.robot.force_limit_n,
        };
        scene.push(drive.t_robot_s, &drive.state);
        drive
    }

    /// Before the path starts the robot's brakes hold it at rest at home, up to `until_s`.
    fn hold_home(&mut self, scene: &RobotScene, until_s: f64) {
        hold_home(scene, &mut self.t_robot_s, until_s);
    }

    /// A force within the actuators' limit, axis by axis.
    fn clip(&self, force_n: Vector3<f64>) -> Vector3<f64> {
        let limit = self.force_limit_n;
        force_n.map(|x| x.clamp(-limit, limit))
    }

    /// Queues a command to act at `acts_s` (robot clock); false, and dropped, when the queue is full.
    fn queue(&mut self, acts_s: f64, command: Vector3<f64>) -> bool {
        let queued = self.commands.len() < self.commands.capacity();
        if queued {
            self.commands.push_back((acts_s, command));
        }
        queued
    }

    /// Integrates the robot to `until_s`, publishing every step; whether an actuator was at its force limit at the
    /// tick's start or end.
    fn advance(
        &mut self,
        config: &ServoConfig,
        scene: &RobotScene,
        until_s: f64,
        step_s: f64,
    ) -> Result<bool, String> {
        let saturated_before = self.force_n.amax() >= self.force_limit_n;
        integrate(
            config,
            scene,
            &mut self.state,
            &mut self.t_robot_s,
            until_s,
            step_s,
            &mut self.commands,
            &mut self.force_n,
        )?;
        Ok(saturated_before || self.force_n.amax() >= self.force_limit_n)
    }
}

/// Before the path starts the robot's brakes hold it at rest at home: its state as it is, published up to `until_s`.
fn hold_home(scene: &RobotScene, t_robot_s: &mut f64, until_s: f64) {
    *t_robot_s = until_s;
    scene.push(until_s, &RobotState::default());
}

/// Pushes onto a vector only within the room it was given: the control thread never allocates.
pub(super) trait PushWithinCapacity<T> {
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
