//! The largest stable gain against latency: for a scheme (controller and camera) and each latency added to its
//! feedback, the largest natural frequency (λ for the kinematic servo) at which the closed loop stays stable on its
//! path, bracketed from the gain rule's and bisected on a log scale ([`largest_stable_gain`], [`stable_gain_sweep`]).
//!
//! Stable means what [`crate::ServoReport::stable`] means: the run goes to the end of its path without passing
//! [`ServoConfig::divergence_error_m`], leaving the workspace or a force that is not finite. The bisection assumes a
//! single change from stable to unstable along the gain, which delay margins give (more gain, more phase lost to the
//! same delay); the tests check the result against runs on either side.

use crate::closed_loop::{CameraKind, ControllerKind, ServoConfig, ServoError, run_servo};
use crate::control::Gains;

/// The gains that a sweep may try, and its resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GainSearch {
    /// The lowest gain tried (rad/s).
    pub lowest_radps: f64,
    /// The highest gain tried (rad/s).
    pub highest_radps: f64,
    /// Bisection steps after the bracket (a factor 2): the result is within a factor `2^(1 / 2^steps)` of the edge.
    pub steps: u32,
}

impl Default for GainSearch {
    /// 2 to 4000 rad/s (0.3 Hz to 640 Hz: from far below a 30 Hz camera's loop to above the 4 kHz control rate's
    /// reach), 5 steps: within 2.2 %.
    fn default() -> Self {
        Self {
            lowest_radps: 2.0,
            highest_radps: 4000.0,
            steps: 5,
        }
    }
}

/// The largest stable gain of one scheme at one extra latency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StableGain {
    /// The latency added to the loop's own (s).
    pub extra_latency_s: f64,
    /// The largest natural frequency found stable (rad/s; λ in 1/s for the kinematic servo); 0 when even
    /// [`GainSearch::lowest_radps`] is not, [`GainSearch::highest_radps`] when that is.
    pub largest_stable_radps: f64,
    /// What the gain rule chooses for the same total latency ([`Gains::for_latency`] of the feedback's age):
    /// the margin is `largest_stable_radps / rule_radps`.
    pub rule_radps: f64,
    /// Runs made.
    pub runs: usize,
}

impl StableGain {
    /// How many times the rule's gain the loop can take before it goes unstable.
    pub fn margin(&self) -> f64 {
        self.largest_stable_radps / self.rule_radps
    }
}

/// Whether `base` with its gains set to the natural frequency `radps` (the depth factor of `base` along the
/// optical axis, 1 for the true-state floor) runs stable to its end.
pub fn is_stable_at(base: &ServoConfig, radps: f64) -> Result<bool, ServoError> {
    let mut config = base.clone();
    let depth_factor = if config.controller == ControllerKind::TrueState {
        1.0
    } else {
        config.depth_factor
    };
    config.gains = Some(Gains::critically_damped(radps).with_depth_factor(depth_factor));
    config.gain_scale = 1.0;
    Ok(run_servo(&config)?.stable)
}

/// The largest natural frequency at which `base` stays stable (see the [module docs](self)), and the runs made.
///
/// The stable gains are a band: too low and the model error alone takes the platform past
/// [`ServoConfig::divergence_error_m`] (at 2 rad/s a 20 % mass error is metres of error), too high and the delay
/// makes the loop oscillate. The search starts at the gain rule's ([`ServoConfig::rule_gain_radps`]), doubles (or
/// halves, if that is not stable) until it brackets the upper edge, and bisects on a log scale; the result is the
/// upper edge of the band that holds the rule's gain, or the nearest stable gain below the rule's.
///
/// ```no_run
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig};
/// use roitrack_servo::sweep::{GainSearch, largest_stable_gain};
/// let config = ServoConfig::new(ControllerKind::TrueState, CameraKind::Truth, 1.0);
/// let (radps, _runs) = largest_stable_gain(&config, &GainSearch::default()).unwrap();
/// assert!(radps > 251.0);
/// ```
pub fn largest_stable_gain(
    base: &ServoConfig,
    search: &GainSearch,
) -> Result<(f64, usize), ServoError> {
    if !(search.lowest_radps > 0.0 && search.highest_radps > search.lowest_radps) {
        return Err(ServoError::Invalid {
            field: "gain search range (0 < lowest < highest)",
            value: search.lowest_radps,
        });
    }
    let mut runs = 0;
    let mut stable_at = |radps: f64| {
        runs += 1;
        is_stable_at(base, radps)
    };
    let start = base
        .rule_gain_radps()
        .clamp(search.lowest_radps, search.highest_radps);
    let (mut stable, mut unstable) = if stable_at(start)? {
        // Up until unstable.
        let mut stable = start;
        loop {
            if stable >= search.highest_radps {
                return Ok((search.highest_radps, runs));
            }
            let next = (stable * 2.0).min(search.highest_radps);
            if stable_at(next)? {
                stable = next;
            } else {
                break (stable, next);
            }
        }
    } else {
        // Down until stable.
        let mut unstable = start;
        loop {
            if unstable <= search.lowest_radps {
                return Ok((0.0, runs));
            }
            let next = (unstable / 2.0).max(search.lowest_radps);
            if stable_at(next)? {
                break (next, unstable);
            }
            unstable = next;
        }
    };
    for _ in 0..search.steps {
        let middle = (stable * unstable).sqrt();
        if stable_at(middle)? {
            stable = middle;
        } else {
            unstable = middle;
        }
    }
    Ok((stable, runs))
}

/// [`largest_stable_gain`] of `base` at each of `extra_latencies_s`, with the rule's gain for each total latency.
pub fn stable_gain_sweep(
    base: &ServoConfig,
    extra_latencies_s: &[f64],
    search: &GainSearch,
) -> Result<Vec<StableGain>, ServoError> {
    extra_latencies_s
        .iter()
        .map(|&extra_latency_s| {
            let mut config = base.clone();
            config.extra_latency_s = extra_latency_s;
            let (largest_stable_radps, runs) = largest_stable_gain(&config, search)?;
            Ok(StableGain {
                extra_latency_s,
                largest_stable_radps,
                rule_radps: config.rule_gain_radps(),
                runs,
            })
        })
        .collect()
}

/// The extra latencies of the command line's sweep (s): none, a quarter of a millisecond to 4 ms.
pub const EXTRA_LATENCIES_S: [f64; 6] = [0.0, 0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3];

/// The file of a sweep's rows.
pub const CSV_FILE: &str = "stable_gain.csv";
/// The header of [`CSV_FILE`].
pub const CSV_HEADER: &str =
    "controller,camera,extra_latency_s,largest_stable_radps,rule_radps,margin,runs";
/// The header of the printed table.
pub const TABLE_HEADER: &str =
    "controller  camera      extra_ms  largest_stable  rule_radps  margin";

/// One row of a sweep: a scheme and one of its points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// The controller.
    pub controller: ControllerKind,
    /// Its camera.
    pub camera: CameraKind,
    /// The largest stable gain found at one extra latency.
    pub point: StableGain,
}

impl Row {
    /// The row as a line of [`CSV_FILE`] (columns of [`CSV_HEADER`]).
    pub fn csv_row(&self) -> String {
        let p = &self.point;
        format!(
            "{},{},{},{:.3},{:.3},{:.4},{}",
            self.controller.name(),
            self.camera.name(),
            p.extra_latency_s,
            p.largest_stable_radps,
            p.rule_radps,
            p.margin(),
            p.runs
        )
    }

    /// The row as a line of the printed table (columns of [`TABLE_HEADER`]).
    pub fn table_row(&self) -> String {
        let p = &self.point;
        format!(
            "{:<11} {:<10} {:>9.2} {:>15.0} {:>11.0} {:>7.2}",
            self.controller.name(),
            self.camera.name(),
            p.extra_latency_s * 1e3,
            p.largest_stable_radps,
            p.rule_radps,
            p.margin()
        )
    }
}

/// The sweep of one scheme as the figure's curve (extra latency in ms).
pub fn curve(
    controller: ControllerKind,
    camera: CameraKind,
    points: &[StableGain],
) -> roitrack_plot::servo::StableGainCurve {
    roitrack_plot::servo::StableGainCurve {
        label: format!("{} / {}", controller.name(), camera.name()),
        points: points
            .iter()
            .map(|p| (p.extra_latency_s * 1e3, p.largest_stable_radps))
            .collect(),
    }
}
