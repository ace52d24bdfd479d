//! What a case yields: each filter's figures pooled over the seeds ([`RunSummary`]), the hand-tuned filters run,
//! and whether the default filter meets each target ([`CaseResult`]).

use roitrack_estimators::StatusCounts;
use roitrack_eval::{Consistency, EvalOptions, PooledErrors, consistency_of};
use roitrack_sim::SimulatedRun;
use serde::Serialize;

use super::case::Case;
use super::goal::{BOUND_FACTOR, Goal, MAX_LAG_SAMPLES, RMSE_RATIO_LIMIT};
use super::grid::HandTuning;
use crate::ExperimentError;
use roitrack_demo::scoring::Scored;

/// One filter's figures on a case, pooled over its seeds.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Estimates, of every status.
    pub estimates: usize,
    /// Seeds on which the filter gave no estimate at all (it never initialised): every figure then comes from the
    /// other seeds (NaN when none is left), and every target fails.
    pub runs_without_estimates: usize,
    /// RMSE of the position error over every estimate (mm), pooled over the seeds.
    pub position_rmse_mm: f64,
    /// RMSE of the velocity error over every estimate (mm/s).
    pub velocity_rmse_mm_s: f64,
    /// The largest position error of an estimate marked tracking or converging (mm); NaN without one.
    pub max_vouched_error_mm: f64,
    /// The velocity lag (estimator samples), the largest in magnitude over the seeds.
    pub velocity_lag_samples: Option<i64>,
    /// Estimates whose status was converging.
    pub converging: usize,
    /// Estimates whose status was tracking.
    pub tracking: usize,
    /// Estimates whose status was degenerate (the update not applied, the state only predicted).
    pub degenerate: usize,
    /// Estimates whose status was disputed (the newest measurement at odds with the earlier ones).
    pub disputed: usize,
    /// Estimates whose status was lost.
    pub lost: usize,
    /// NEES of position and velocity of the vouched estimates with a covariance.
    pub consistency: Consistency,
    /// The mean of [`Estimate::noise_px`](roitrack_estimators::Estimate::noise_px) over the vouched estimates:
    /// the noise the filter worked with (px).
    pub mean_noise_px: f64,
}

impl RunSummary {
    /// The figures of a filter's runs, one per seed (`None`: the run gave no estimate at all).
    pub(super) fn of(
        runs: &[SimulatedRun],
        scored: &[Option<Scored>],
    ) -> Result<Self, ExperimentError> {
        let mut metrics = Vec::with_capacity(scored.len());
        let mut max_vouched_error_mm: f64 = 0.0;
        let mut lag: Option<i64> = None;
        let mut statuses = StatusCounts::default();
        let mut consistencies = Vec::with_capacity(scored.len());
        let (mut noise_sum, mut vouched) = (0.0, 0usize);
        let mut runs_without_estimates = 0;
        for (run, s) in runs.iter().zip(scored) {
            let Some(s) = s else {
                runs_without_estimates += 1;
                continue;
            };
            let m = &s.metrics;
            metrics.push(m);
            if let Some(l) = m.velocity_lag_samples
                && lag.is_none_or(|worst| l.abs() > worst.abs())
            {
                lag = Some(l);
            }
            statuses.converging += s.statuses.converging;
            statuses.tracking += s.statuses.tracking;
            statuses.degenerate += s.statuses.degenerate;
            statuses.disputed += s.statuses.disputed;
            statuses.lost += s.statuses.lost;
            for (e, error) in s.estimates.iter().zip(&s.errors.position_m) {
                if e.status.is_vouched_for() {
                    max_vouched_error_mm = max_vouched_error_mm.max(error.norm() * 1e3);
                    noise_sum += e.noise_px;
                    vouched += 1;
                }
            }
            consistencies.push(consistency_of(
                &run.truth_poses,
                &run.truth_twists,
                &s.estimates,
                &EvalOptions::default(),
            )?);
        }
        let pooled = PooledErrors::of(metrics);
        Ok(Self {
            estimates: pooled.count,
            runs_without_estimates,
            position_rmse_mm: pooled.position_rmse_mm,
            velocity_rmse_mm_s: pooled.velocity_rmse_mm_s,
            max_vouched_error_mm: if vouched == 0 {
                f64::NAN
            } else {
                max_vouched_error_mm
            },
            velocity_lag_samples: lag,
            converging: statuses.converging,
            tracking: statuses.tracking,
            degenerate: statuses.degenerate,
            disputed: statuses.disputed,
            lost: statuses.lost,
            consistency: Consistency::pooled(&consistencies),
            mean_noise_px: noise_sum / vouched as f64,
        })
    }
}

/// A hand-tuned filter and its figures.
#[derive(Debug, Clone, Serialize)]
pub struct HandTuned {
    /// The filter's settings.
    pub tuning: HandTuning,
    /// Whether the settings lie on the grid's boundary along some axis (for the best: a better one may lie beyond).
    pub on_edge: bool,
    /// Its figures over the case's seeds.
    pub summary: RunSummary,
}

/// One grid point visited by the search, and its pooled position RMSE (mm).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Visited {
    /// The grid point's settings.
    pub tuning: HandTuning,
    /// Position RMSE over the runs that gave estimates.
    pub position_rmse_mm: f64,
    /// Runs (seeds) in which the filter never started: such a setting is no candidate for the best.
    pub runs_without_estimates: usize,
}

/// A case's figures.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    /// The case.
    pub case: Case,
    /// Measurements simulated, over every seed.
    pub measurements: usize,
    /// The default filter (`TrackerConfig::default()`).
    pub default: RunSummary,
    /// The told-the-truth hand-tuned filter: the true noise, the default densities, adaptation off.
    pub told_truth: HandTuned,
    /// The best hand-tuned filter of the grid search (accuracy cases).
    pub best: Option<HandTuned>,
    /// Every grid point the search ran, in the order run.
    pub visited: Vec<Visited>,
    /// The nominal error (mm): the best hand-tuned position RMSE (accuracy cases).
    pub nominal_mm: Option<f64>,
    /// The default filter's vouched estimates more than [`BOUND_FACTOR`] times the nominal error off.
    pub beyond_bound: Option<usize>,
    /// Wall time of the case (s).
    pub seconds: f64,
}

impl CaseResult {
    /// The default filter's position RMSE over the best hand-tuned one (NaN without a search).
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{SweepOptions, sweep};
    /// let mut options = SweepOptions::quick();
    /// options.cases.truncate(1);
    /// (options.max_duration_s, options.grid.max_rounds) = (Some(0.3), 0);
    /// let case = &sweep(&options, None).unwrap().cases[0];
    /// assert!(case.rmse_ratio() > 0.5);
    /// ```
    pub fn rmse_ratio(&self) -> f64 {
        self.best.as_ref().map_or(f64::NAN, |b| {
            self.default.position_rmse_mm / b.summary.position_rmse_mm
        })
    }

    /// Whether the default filter meets `goal` on this case (see [`Goal`]). No target holds when the default filter
    /// gave no estimate on some seed.
    pub fn holds(&self, goal: Goal) -> bool {
        let d = &self.default;
        if d.runs_without_estimates > 0 {
            return false;
        }
        match goal {
            Goal::Rmse => self.rmse_ratio() <= RMSE_RATIO_LIMIT,
            Goal::Clean => d.disputed == 0 && d.lost == 0,
            Goal::Calibrated => d.consistency.is_calibrated(),
            Goal::Lag => d
                .velocity_lag_samples
                .is_some_and(|l| l.abs() <= MAX_LAG_SAMPLES),
            Goal::Bounded => self.beyond_bound == Some(0),
        }
    }

    /// The figure `goal` is judged on, as text.
    pub(super) fn figure(&self, goal: Goal) -> String {
        let d = &self.default;
        if d.runs_without_estimates > 0 {
            return format!("no estimate on {} seed(s)", d.runs_without_estimates);
        }
        match goal {
            Goal::Rmse => format!("{:.3}", self.rmse_ratio()),
            Goal::Clean => format!("{} disputed, {} lost", d.disputed, d.lost),
            Goal::Calibrated => format!(
                "NEES/3 {:.2} / {:.2}, inside {:.1} % / {:.1} %",
                d.consistency.position_nees_per_dof,
                d.consistency.velocity_nees_per_dof,
                100.0 * d.consistency.position_inside_99,
                100.0 * d.consistency.velocity_inside_99
            ),
            Goal::Lag => d
                .velocity_lag_samples
                .map_or("none".to_string(), |l| l.to_string()),
            Goal::Bounded => format!(
                "{} beyond {:.3} mm",
                self.beyond_bound.unwrap_or(0),
                BOUND_FACTOR * self.nominal_mm.unwrap_or(f64::NAN)
            ),
        }
    }
}
