//! Multi-panel figures of a tracking run, after figures 5, 6 and 7 of the paper:
//!
//! * `fig5_trajectory`: the trajectory of the target origin projected on the camera x–y (image) plane and on the
//!   x–z and y–z planes, truth and every run;
//! * `fig6_position`: (a) true position, (b) position estimated by the first run, (c) position error of every run,
//!   (d) image residual RMS of every run, against time;
//! * `fig7_velocity`: (a) true velocity, (b) velocity estimated by the first run, (c) velocity error of every run,
//!   (d) error statistics of every run (RMS errors, velocity lag, mean residual).
//!
//! The figures compute no statistic of their own: the errors, RMS values and velocity lag of a run are those of
//! roitrack-eval ([`EstimateErrors`], [`Metrics`]), handed over with the run ([`TrackSeries::from_estimates`]), so
//! that a figure and a metrics table never disagree. Only the axis ranges are chosen here.
//!
//! Each figure is written as PNG and SVG by the same drawing code. Lengths are shown in mm, velocities in mm/s.

mod data;
mod draw;
mod statistics;
#[cfg(test)]
mod tests;
mod time_series;
mod trajectory;

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use roitrack_core::stats;
use roitrack_estimators::Estimate;
use roitrack_eval::{EstimateErrors, Metrics};

use crate::{PlotError, register_font};

use data::{Data, FIG5_SIZE, FIG67_SIZE};
use draw::{Res, de};
use time_series::{fig6, fig7};
use trajectory::fig5;

/// One estimator's output at its estimate times, with its errors and metrics as roitrack-eval computes them.
///
/// Positions and velocities are those of the target origin, in the camera frame. Every vector holds one entry per
/// time of `t_s`, except those documented as possibly empty.
#[derive(Debug, Clone, Default)]
pub struct TrackSeries {
    /// Legend text, e.g. `"kalman (default)"`.
    pub label: String,
    /// Estimate times (s), on the same clock as the truth.
    pub t_s: Vec<f64>,
    /// Estimated camera-frame x, y, z of the target origin (m).
    pub position_m: Vec<[f64; 3]>,
    /// Estimated camera-frame velocity of the target origin (m/s).
    pub velocity_mps: Vec<[f64; 3]>,
    /// Image residual RMS (px) as the estimator reports it ([`Estimate::residual_rms_px`]); empty when the
    /// estimator has none.
    pub residual_rms_px: Vec<f64>,
    /// Position error, estimate minus truth at the same time, camera frame (m): [`EstimateErrors::position_m`].
    pub position_error_m: Vec<[f64; 3]>,
    /// Linear velocity error, estimate minus truth at the same time, camera frame (m/s):
    /// [`EstimateErrors::velocity_mps`]; empty when the truth or the estimate has no twists.
    pub velocity_error_mps: Vec<[f64; 3]>,
    /// The run's metrics, whose RMS errors (mm, mm/s), velocity lag and estimate count the figures show; `None`
    /// shows no number for this run.
    pub metrics: Option<Metrics>,
    /// Mean of the finite values of `residual_rms_px` (px); `None` when there are none.
    pub mean_residual_px: Option<f64>,
}

impl TrackSeries {
    /// The series of a tracker's `estimates`, with the `errors` and `metrics` of roitrack-eval for these same
    /// estimates (as [`roitrack_eval::estimate_errors_of`] and [`EstimateErrors::metrics`] give them).
    ///
    /// ```
    /// use roitrack_estimators::{TrackerConfig, track_all};
    /// use roitrack_eval::{EvalOptions, estimate_errors_of};
    /// use roitrack_plot::{TrackSeries, TruthSeries, write_figures};
    /// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
    ///
    /// let run = simulate(&Scenario::new(ScenarioKind::Static, 1), &SimulationOptions::default()).unwrap();
    /// let (estimates, _) = track_all(&run.camera, &run.target, TrackerConfig::default(), &run.measurements).unwrap();
    /// let opts = EvalOptions::default();
    /// let errors = estimate_errors_of(&run.truth_poses, &run.truth_twists, &estimates, &opts).unwrap();
    /// let series = TrackSeries::from_estimates("kalman", &estimates, &errors, errors.metrics(&opts));
    /// assert_eq!(series.position_error_m.len(), estimates.len());
    /// assert_eq!(series.metrics.as_ref().map(|m| m.count), Some(estimates.len()));
    /// assert!(series.mean_residual_px.is_some());
    ///
    /// let truth = TruthSeries {
    ///     t_s: run.truth_poses.iter().map(|p| p.t_s).collect(),
    ///     position_m: run.truth_poses.iter().map(|p| p.cam_from_obj.translation.vector.into()).collect(),
    ///     velocity_mps: run.truth_twists.iter().map(|w| w.velocity_mps.into()).collect(),
    /// };
    /// let dir = tempfile::tempdir().unwrap();
    /// let paths = write_figures(dir.path(), "static", &truth, &[series]).unwrap();
    /// assert_eq!(paths.len(), 6);
    /// ```
    pub fn from_estimates(
        label: impl Into<String>,
        estimates: &[Estimate],
        errors: &EstimateErrors,
        metrics: Metrics,
    ) -> Self {
        let residual_rms_px: Vec<f64> = estimates.iter().map(|e| e.residual_rms_px).collect();
        let (position_error_m, velocity_error_mps) = error_columns(errors);
        Self {
            label: label.into(),
            t_s: estimates.iter().map(|e| e.t_ref_s).collect(),
            position_m: estimates
                .iter()
                .map(|e| e.state.cam_t_obj_m.into())
                .collect(),
            velocity_mps: estimates
                .iter()
                .map(|e| e.state.velocity_mps.into())
                .collect(),
            mean_residual_px: finite_mean(&residual_rms_px),
            residual_rms_px,
            position_error_m,
            velocity_error_mps,
            metrics: Some(metrics),
        }
    }
}

/// The position and velocity errors of `errors` as plain arrays (m, m/s); no velocity errors without twists.
fn error_columns(errors: &EstimateErrors) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let position = errors.position_m.iter().map(|&e| e.into()).collect();
    let velocity = errors
        .velocity_mps
        .as_ref()
        .map_or_else(Vec::new, |v| v.iter().map(|&e| e.into()).collect());
    (position, velocity)
}

/// The mean of the finite values; `None` when there are none (an estimator may report no residual).
fn finite_mean(values: &[f64]) -> Option<f64> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    (!finite.is_empty()).then(|| stats::mean(&finite))
}

/// The true motion of the target origin, sampled densely, drawn as the reference of every panel.
#[derive(Debug, Clone, Default)]
pub struct TruthSeries {
    /// Sample times (s), finite and ascending, on the same clock as the runs.
    pub t_s: Vec<f64>,
    /// True camera-frame x, y, z of the target origin (m), one per time.
    pub position_m: Vec<[f64; 3]>,
    /// True camera-frame velocity of the target origin (m/s), one per time.
    pub velocity_mps: Vec<[f64; 3]>,
}

/// Writes `fig5_trajectory`, `fig6_position` and `fig7_velocity` (each `.png` and `.svg`) into `dir` (created if
/// needed) and returns the six paths. `runs[0]` is the estimator shown in panels (b) of figures 6 and 7.
///
/// Non-finite values are skipped when drawing. The errors and numbers shown are those each run carries
/// ([`TrackSeries::position_error_m`], [`TrackSeries::metrics`], ...): nothing is compared with `truth` here.
///
/// Fails with [`PlotError::Invalid`] when the truth's or a run's vectors disagree in length (or a run's metrics
/// count other estimates than its times), with [`PlotError::Empty`] when there is no run or nothing finite to draw,
/// and with [`PlotError::Draw`] when a file cannot be written. [`TrackSeries::from_estimates`] shows a complete use.
///
/// ```
/// use roitrack_plot::{PlotError, TruthSeries, write_figures};
/// let truth = TruthSeries { t_s: vec![0.0, 1.0], position_m: vec![[0.0; 3]; 2], velocity_mps: vec![[0.0; 3]; 2] };
/// let dir = tempfile::tempdir().unwrap();
/// // No run: nothing to compare with the truth.
/// assert!(matches!(write_figures(dir.path(), "empty", &truth, &[]), Err(PlotError::Empty { .. })));
/// ```
pub fn write_figures(
    dir: &Path,
    scenario: &str,
    truth: &TruthSeries,
    runs: &[TrackSeries],
) -> Result<Vec<PathBuf>, PlotError> {
    let files = render_figures(scenario, truth, runs)?;
    crate::write_rendered(dir, &files)
}

/// [`write_figures`] in memory: the six files (`fig5_trajectory.png`, `fig5_trajectory.svg`, ...), for a caller
/// that writes them its own way; the same checks and errors.
pub fn render_figures(
    scenario: &str,
    truth: &TruthSeries,
    runs: &[TrackSeries],
) -> Result<Vec<crate::RenderedFile>, PlotError> {
    register_font();
    let data = Data::new(scenario, truth, runs)?;
    let mut out = Vec::with_capacity(6);
    for (fig, stem, size) in [
        (Fig::Trajectory, "fig5_trajectory", FIG5_SIZE),
        (Fig::Position, "fig6_position", FIG67_SIZE),
        (Fig::Velocity, "fig7_velocity", FIG67_SIZE),
    ] {
        out.push(crate::render_png(&format!("{stem}.png"), size, |area| {
            draw_figure(area, fig, &data)
        })?);
        out.push(crate::render_svg(&format!("{stem}.svg"), size, |area| {
            draw_figure(area, fig, &data)
        })?);
    }
    Ok(out)
}

#[derive(Clone, Copy)]
enum Fig {
    Trajectory,
    Position,
    Velocity,
}

fn draw_figure<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, fig: Fig, d: &Data) -> Res<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(de)?;
    match fig {
        Fig::Trajectory => fig5(&root, d)?,
        Fig::Position => fig6(&root, d)?,
        Fig::Velocity => fig7(&root, d)?,
    }
    root.present().map_err(de)
}
