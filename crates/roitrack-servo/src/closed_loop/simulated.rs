//! The loop in simulated time, tick by tick: the controller's command, the robot integrated, the camera exposed.

use std::collections::VecDeque;

use nalgebra::Vector3;
use roitrack_estimators::Estimate;

use crate::control::{ControlInput, Controller, Observation};
use crate::robot::{Geometry, RobotState, step_rk4};

use super::camera::CameraSide;
use super::{ControllerKind, SaturationWindow, ServoConfig, ServoError, ServoSample};

/// The robot's motion so far, at every integration step, to render the camera's exposures from.
struct History {
    dt_s: f64,
    states: Vec<RobotState>,
}

impl History {
    /// The state at `t_s`, interpolated (cubic Hermite: position and velocity are both known at each step).
    fn at(&self, t_s: f64) -> RobotState {
        let last = self.states.len() - 1;
        let x = (t_s / self.dt_s).clamp(0.0, last as f64);
        let k = (x.floor() as usize).min(last.saturating_sub(1));
        if last == 0 {
            return self.states[0];
        }
        let (a, b) = (&self.states[k], &self.states[k + 1]);
        let u = x - k as f64;
        let h = self.dt_s;
        let (u2, u3) = (u * u, u * u * u);
        let position = a.position_m * (2.0 * u3 - 3.0 * u2 + 1.0)
            + a.velocity_mps * (h * (u3 - 2.0 * u2 + u))
            + b.position_m * (-2.0 * u3 + 3.0 * u2)
            + b.velocity_mps * (h * (u3 - u2));
        let velocity = (a.position_m * (6.0 * u2 - 6.0 * u) + b.position_m * (-6.0 * u2 + 6.0 * u))
            / h
            + a.velocity_mps * (3.0 * u2 - 4.0 * u + 1.0)
            + b.velocity_mps * (3.0 * u2 - 2.0 * u);
        RobotState {
            position_m: position,
            velocity_mps: velocity,
        }
    }
}

/// One closed loop in simulated time: the controller, the robot it drives, the camera and tracker watching it, and
/// what is kept for the report. Ticks run one after the other from [`SimulatedLoop::tick`].
pub(super) struct SimulatedLoop<'a> {
    config: &'a ServoConfig,
    controller: Box<dyn Controller + Send>,
    /// The controller sees the true state (the floor): no actuation delay, no camera.
    truth_fed: bool,
    actuation_delay_s: f64,
    /// When an estimate reaches the controller after the instant it refers to: the camera's latency and the extra.
    availability_s: f64,
    tick_s: f64,
    step_s: f64,
    pub(super) ticks: usize,
    camera: CameraSide,
    state: RobotState,
    /// Every integration step's state, for the camera and the delayed truth.
    history: History,
    /// The forces acting.
    force: Vector3<f64>,
    /// The commands waiting for their actuation instant.
    commands: VecDeque<(f64, Vector3<f64>)>,
    /// The estimates not yet available to the controller, with the instant they are.
    pending: VecDeque<(f64, Observation)>,
    /// The newest estimate available to the controller.
    observation: Option<Observation>,
    pub(super) estimates: Vec<Estimate>,
    new_estimates: Vec<Estimate>,
    pub(super) samples: Vec<ServoSample>,
    pub(super) ages: Vec<f64>,
    pub(super) saturated_ticks: usize,
    saturation: SaturationWindow,
}

impl<'a> SimulatedLoop<'a> {
    /// The robot at rest at home, holding against gravity the force the controller's model asks there.
    pub(super) fn new(
        config: &'a ServoConfig,
        controller: Box<dyn Controller + Send>,
    ) -> Result<Self, ServoError> {
        let path = &config.path;
        let model = config
            .robot
            .with_mass_factor(config.model_mass_factor)
            .with_friction_factor(config.model_friction_factor);
        let truth_fed = config.controller == ControllerKind::TrueState;
        let actuation_delay_s = if truth_fed {
            0.0
        } else {
            config.actuation_delay_s
        };
        let timing = config.camera_timing();
        let availability_s = timing.latency_s() + config.extra_latency_s;
        let tick_s = 1.0 / config.control_rate_hz;
        let step_s = tick_s / config.substeps as f64;
        let ticks = (path.duration_s() / tick_s).round() as usize;
        let camera = CameraSide::new(config)?;
        let state = RobotState::default();
        let mut history = History {
            dt_s: step_s,
            states: Vec::with_capacity(ticks * config.substeps + 1),
        };
        history.states.push(state);
        let hold = Geometry::at(&model, &Vector3::zeros())
            .expect("home is in the workspace")
            .gravity_forces(&model);
        let mut samples = Vec::with_capacity(ticks + 1);
        samples.push(ServoSample {
            t_s: 0.0,
            reference: path.at(0.0),
            achieved_m: state.position_m,
            achieved_velocity_mps: state.velocity_mps,
            force_n: hold,
        });
        // The ticks of the last `saturation_window_s` at which an actuator was at its limit.
        let window_ticks =
            ((config.saturation_window_s * config.control_rate_hz).round() as usize).max(1);
        Ok(SimulatedLoop {
            config,
            controller,
            truth_fed,
            actuation_delay_s,
            availability_s,
            tick_s,
            step_s,
            ticks,
            camera,
            state,
            history,
            force: hold,
            commands: VecDeque::new(),
            pending: VecDeque::new(),
            observation: None,
            estimates: Vec::new(),
            new_estimates: Vec::new(),
            samples,
            ages: Vec::with_capacity(ticks),
            saturated_ticks: 0,
            saturation: SaturationWindow::new(window_ticks),
        })
    }

    /// Tick `n`: the estimates ready by now, the command, the robot to the next tick, the camera. Some: why the
    /// loop stops there (a force or state not finite, instability, divergence).
    pub(super) fn tick(&mut self, n: usize) -> Result<Option<String>, ServoError> {
        let config = self.config;
        let path = &config.path;
        let tick_s = self.tick_s;
        let t_s = n as f64 * tick_s;
        // 1. The estimates ready by now.
        while self
            .pending
            .front()
            .is_some_and(|(ready_s, _)| *ready_s <= t_s + 1e-12)
        {
            self.observation = self.pending.pop_front().map(|(_, o)| o);
        }
        // 2. The command.
        let t_act_s = t_s + self.actuation_delay_s;
        let command = self.command(t_s, t_act_s);
        if !command.iter().all(|f| f.is_finite()) {
            return Ok(Some(format!(
                "the controller gave a force that is not finite at t = {t_s:.4} s"
            )));
        }
        let limit = config.robot.force_limit_n;
        let command = command.map(|x| x.clamp(-limit, limit));
        self.commands.push_back((t_act_s, command));
        if config.known_acceleration
            && let Some(believed) = self.controller.believed_acceleration(&command)
        {
            // The robot frame has the camera's axes (docs/servo.md, "The robot"): the platform's acceleration is
            // the target's in the camera frame as it is; the platform only translates.
            self.camera.tell_acceleration(t_act_s, &believed)?;
        }
        // 3. The robot to the next tick.
        let saturated = match self.advance_robot(t_s) {
            Ok(saturated) => saturated,
            Err(reason) => return Ok(Some(reason)),
        };
        self.saturated_ticks += usize::from(saturated);
        if let Some(saturated_percent) = self.saturation.push(saturated) {
            return Ok(Some(format!(
                "unstable: an actuator at its force limit {:.0} % of the {:.0} ms before t = {:.4} s (a limit cycle \
                 the force limit bounds)",
                saturated_percent,
                config.saturation_window_s * 1e3,
                t_s + tick_s
            )));
        }
        let t_next = (n + 1) as f64 * tick_s;
        let sample = ServoSample {
            t_s: t_next,
            reference: path.at(t_next),
            achieved_m: self.state.position_m,
            achieved_velocity_mps: self.state.velocity_mps,
            force_n: self.force,
        };
        self.samples.push(sample);
        if sample.error_m() > config.divergence_error_m {
            return Ok(Some(format!(
                "diverged: {:.1} mm from the path at t = {t_next:.4} s (limit {:.1} mm)",
                sample.error_m() * 1e3,
                config.divergence_error_m * 1e3
            )));
        }
        // 4. The camera: the ROI exposed around this tick (its exposure has ended), or the frames due.
        self.expose(t_s, t_next)?;
        Ok(None)
    }

    /// The controller's command at tick `t_s` for the instant it acts, `t_act_s`, from what it is fed; records the
    /// feedback's age at that instant.
    fn command(&mut self, t_s: f64, t_act_s: f64) -> Vector3<f64> {
        let config = self.config;
        let geometry =
            Geometry::at(&config.robot, &self.state.position_m).expect("checked at each step");
        let fed = if self.truth_fed {
            // The true state, `extra_latency_s` old.
            let t_seen_s = (t_s - config.extra_latency_s).max(0.0);
            let seen = if config.extra_latency_s > 0.0 {
                self.history.at(t_seen_s)
            } else {
                self.state
            };
            Some(Observation {
                t_s: t_seen_s,
                position_m: seen.position_m,
                velocity_mps: seen.velocity_mps,
                acceleration_mps2: None,
            })
        } else {
            self.observation
        };
        if let Some(o) = &fed {
            self.ages.push(t_act_s - o.t_s);
        }
        let input = ControlInput {
            t_act_s,
            dt_s: self.tick_s,
            reference: config.path.at(t_act_s),
            observation: fed,
            drive_joint_velocity_mps: geometry.joint_velocity(&self.state.velocity_mps),
        };
        self.controller.command(&input)
    }

    /// Integrates the robot over the tick from `t_s` in `substeps` steps, each command taking over from its
    /// actuation instant; whether an actuator was at its force limit at any step. Err: why the loop stops.
    fn advance_robot(&mut self, t_s: f64) -> Result<bool, String> {
        let robot = &self.config.robot;
        let step_s = self.step_s;
        let mut saturated = false;
        for j in 0..self.config.substeps {
            let t_step = t_s + j as f64 * step_s;
            while self
                .commands
                .front()
                .is_some_and(|(at_s, _)| *at_s <= t_step + 1e-12)
            {
                self.force = self.commands.pop_front().map(|(_, f)| f).expect("checked");
            }
            saturated |= self.force.amax() >= robot.force_limit_n;
            match step_rk4(robot, &self.state, &self.force, step_s) {
                Ok(next)
                    if next
                        .position_m
                        .iter()
                        .chain(&next.velocity_mps)
                        .all(|x| x.is_finite()) =>
                {
                    self.state = next
                }
                Ok(_) => {
                    return Err(format!(
                        "the robot's state is not finite at t = {t_step:.4} s"
                    ));
                }
                Err(e) => return Err(format!("at t = {t_step:.4} s {e}")),
            }
            self.history.states.push(self.state);
        }
        Ok(saturated)
    }

    /// The camera over the tick from `t_s` to `t_next`: its new estimates kept, and those the tracker vouches for
    /// queued for the controller from the instant they are available, in the robot frame (relative to home).
    fn expose(&mut self, t_s: f64, t_next: f64) -> Result<(), ServoError> {
        let path = &self.config.path;
        let history = &self.history;
        let state_at = |t: f64| {
            let s = history.at(t);
            path.camera_state(&s.position_m, &s.velocity_mps)
        };
        self.new_estimates.clear();
        self.camera
            .expose(t_s, t_next, &state_at, &mut self.new_estimates)?;
        let (_, home_cam) = path.home_in_camera();
        for estimate in &self.new_estimates {
            if estimate.status.is_vouched_for() && estimate.state.is_finite() {
                self.pending.push_back((
                    estimate.t_ref_s + self.availability_s,
                    Observation {
                        t_s: estimate.t_ref_s,
                        position_m: estimate.state.cam_t_obj_m - home_cam,
                        velocity_mps: estimate.state.velocity_mps,
                        acceleration_mps2: estimate.acceleration.map(|a| a.linear_mps2),
                    },
                ));
            }
        }
        self.estimates.extend_from_slice(&self.new_estimates);
        Ok(())
    }
}
