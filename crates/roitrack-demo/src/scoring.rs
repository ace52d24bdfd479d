//! Tracking a simulated run and scoring it against its ground truth.

use std::time::Instant;

use roitrack_estimators::{Estimate, StatusCounts, TrackStatus, TrackerConfig, track_all};
use roitrack_eval::{EstimateErrors, EvalOptions, Metrics, estimate_errors_of};
use roitrack_sim::SimulatedRun;

use crate::DemoError;

/// A run tracked and scored.
#[derive(Debug, Clone)]
pub struct Scored {
    /// The estimates, in time order.
    pub estimates: Vec<Estimate>,
    /// The estimates' statuses, counted.
    pub statuses: StatusCounts,
    /// Every estimate's error against the truth, and their metrics.
    pub errors: EstimateErrors,
    /// The metrics of those errors.
    pub metrics: Metrics,
    /// Wall time of the tracking (s).
    pub seconds: f64,
}

impl Scored {
    /// Wall time per control step, including the handling of the `k` measurements that lead to it (µs).
    pub fn us_per_estimate(&self) -> f64 {
        1e6 * self.seconds / self.estimates.len().max(1) as f64
    }

    /// Estimates with this status.
    pub fn count(&self, status: TrackStatus) -> usize {
        self.statuses.get(status)
    }
}

/// Tracks a simulated run's measurements with `config` and scores the estimates against its truth.
///
/// ```
/// use roitrack_estimators::TrackerConfig;
/// use roitrack_demo::scoring::track_and_score;
/// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
///
/// let run = simulate(&Scenario::new(ScenarioKind::Orthoglide, 1), &SimulationOptions::default()).unwrap();
/// let scored = track_and_score(&run, TrackerConfig::default()).unwrap();
/// assert!(scored.metrics.position_rmse_mm < 0.5);
/// assert_eq!(scored.metrics.velocity_lag_samples, Some(0));
/// ```
pub fn track_and_score(run: &SimulatedRun, config: TrackerConfig) -> Result<Scored, DemoError> {
    let start = Instant::now();
    let (estimates, _) = track_all(&run.camera, &run.target, config, &run.measurements)?;
    let seconds = start.elapsed().as_secs_f64();
    score(run, estimates, seconds)
}

/// Scores estimates (from any source) against a simulated run's truth.
pub fn score(
    run: &SimulatedRun,
    estimates: Vec<Estimate>,
    seconds: f64,
) -> Result<Scored, DemoError> {
    let errors = estimate_errors_of(
        &run.truth_poses,
        &run.truth_twists,
        &estimates,
        &EvalOptions::default(),
    )?;
    let metrics = errors.metrics(&EvalOptions::default());
    Ok(Scored {
        statuses: StatusCounts::of(&estimates),
        estimates,
        errors,
        metrics,
        seconds,
    })
}
