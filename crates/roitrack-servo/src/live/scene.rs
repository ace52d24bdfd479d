//! The simulated robot as the camera sees it ([`RobotScene`]): its clock, its recent integration steps published
//! lock-free by the control thread and interpolated for any camera thread, and the offset to the loop's clock.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering, fence};
use std::time::Instant;

use nalgebra::Vector3;
use roitrack_core::MotionState;

use crate::reference::ReferencePath;
use crate::robot::RobotState;

/// Robot steps kept for the camera to render from: 1024 integration steps (64 ms at 4 kHz and 4 steps a tick).
const TRACE_SLOTS: usize = 1024;
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
    pub(super) fn push(&self, t_s: f64, state: &RobotState) {
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
