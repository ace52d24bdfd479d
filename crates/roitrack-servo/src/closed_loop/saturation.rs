//! The saturation window: how long the actuators have stayed at their force limit.

use std::collections::VecDeque;

/// The share of recent control ticks with an actuator at its force limit, over a window of ticks: a loop that keeps
/// its actuators saturated most of the time has gone unstable (in simulated time and in real time alike).
pub(crate) struct SaturationWindow {
    recent: VecDeque<bool>,
    saturated: usize,
    window_ticks: usize,
}

impl SaturationWindow {
    pub(crate) fn new(window_ticks: usize) -> Self {
        SaturationWindow {
            recent: VecDeque::with_capacity(window_ticks + 1),
            saturated: 0,
            window_ticks,
        }
    }

    /// Adds a tick; once the window is full and more than half its ticks saturated, their share (%).
    pub(crate) fn push(&mut self, saturated: bool) -> Option<f64> {
        self.recent.push_back(saturated);
        self.saturated += usize::from(saturated);
        if self.recent.len() > self.window_ticks {
            self.saturated -= usize::from(self.recent.pop_front().unwrap_or(false));
        }
        (self.recent.len() == self.window_ticks && 2 * self.saturated > self.window_ticks)
            .then(|| 100.0 * self.saturated as f64 / self.window_ticks as f64)
    }
}
