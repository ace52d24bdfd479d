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

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use roitrack_core::estimator::Estimate;
use roitrack_core::stats;
use roitrack_eval::{EstimateErrors, Metrics};

use crate::{FONT, PlotError, register_font};

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
    /// use roitrack_core::estimator::{TrackerConfig, track_all};
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

// ---------------------------------------------------------------------------------------------------------------
// Data preparation

const MM: f64 = 1e3;
const FIG5_SIZE: (u32, u32) = (1400, 820);
const FIG67_SIZE: (u32, u32) = (1400, 1000);

const AXES: [&str; 3] = ["x", "y", "z"];
const AXIS_COLORS: [RGBColor; 3] = [
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(31, 119, 180),
];
/// Run colours: none of them close to the x/y/z colours or to the black/grey of the truth.
const RUN_COLORS: [RGBColor; 6] = [
    RGBColor(230, 120, 0),
    RGBColor(120, 60, 180),
    RGBColor(0, 160, 170),
    RGBColor(140, 86, 75),
    RGBColor(220, 80, 170),
    RGBColor(150, 150, 20),
];
const GRID_BOLD: RGBColor = RGBColor(222, 222, 222);
const GRID_LIGHT: RGBColor = RGBColor(242, 242, 242);
const FRAME: RGBColor = RGBColor(140, 140, 140);
const NOTE: RGBColor = RGBColor(90, 90, 90);

struct Truth {
    t: Vec<f64>,
    pos: [Vec<f64>; 3],
    vel: [Vec<f64>; 3],
}

/// A run ready to draw: columns in mm and mm/s.
struct Run<'a> {
    label: &'a str,
    color: RGBColor,
    t: Vec<f64>,
    pos: [Vec<f64>; 3],
    vel: [Vec<f64>; 3],
    pos_err: [Vec<f64>; 3],
    /// Empty columns when the run has no velocity errors.
    vel_err: [Vec<f64>; 3],
    residual: Vec<f64>,
    metrics: Option<&'a Metrics>,
    mean_residual_px: Option<f64>,
}

impl Run<'_> {
    /// Line style: the first run (drawn last, on top) is heavier than the others.
    fn style(&self, index: usize) -> ShapeStyle {
        if index == 0 {
            self.color.stroke_width(2)
        } else {
            self.color.mix(0.85).stroke_width(1)
        }
    }
}

struct Data<'a> {
    scenario: &'a str,
    truth: Truth,
    runs: Vec<Run<'a>>,
    t_range: (f64, f64),
}

fn columns(v: &[[f64; 3]], scale: f64) -> [Vec<f64>; 3] {
    std::array::from_fn(|c| v.iter().map(|p| p[c] * scale).collect())
}

fn invalid(what: &str, message: String) -> PlotError {
    PlotError::Invalid {
        what: what.to_string(),
        message,
    }
}

impl<'a> Data<'a> {
    fn new(
        scenario: &'a str,
        truth: &TruthSeries,
        runs: &'a [TrackSeries],
    ) -> Result<Self, PlotError> {
        let n = truth.t_s.len();
        if truth.position_m.len() != n || truth.velocity_mps.len() != n {
            return Err(invalid(
                "truth",
                format!(
                    "{} times, {} positions, {} velocities",
                    n,
                    truth.position_m.len(),
                    truth.velocity_mps.len()
                ),
            ));
        }
        if truth.t_s.iter().any(|t| !t.is_finite()) || truth.t_s.windows(2).any(|w| w[1] < w[0]) {
            return Err(invalid(
                "truth",
                "times must be finite and ascending".to_string(),
            ));
        }
        let finite3 = |p: &[f64; 3]| p.iter().all(|v| v.is_finite());
        if !truth.position_m.iter().any(finite3) {
            return Err(PlotError::Empty {
                title: format!("{scenario}: truth"),
            });
        }
        if runs.is_empty() {
            return Err(PlotError::Empty {
                title: format!("{scenario}: runs"),
            });
        }
        for r in runs {
            let m = r.t_s.len();
            let empty_or_m = |len: usize| len == 0 || len == m;
            if r.position_m.len() != m
                || r.velocity_mps.len() != m
                || !empty_or_m(r.residual_rms_px.len())
                || r.position_error_m.len() != m
                || !empty_or_m(r.velocity_error_mps.len())
            {
                return Err(invalid(
                    &format!("run '{}'", r.label),
                    format!(
                        "{} times, {} positions, {} velocities, {} residuals, {} position errors, {} velocity \
                         errors",
                        m,
                        r.position_m.len(),
                        r.velocity_mps.len(),
                        r.residual_rms_px.len(),
                        r.position_error_m.len(),
                        r.velocity_error_mps.len()
                    ),
                ));
            }
            // Metrics of other estimates than those drawn would label the curves with foreign numbers.
            if let Some(metrics) = r.metrics.as_ref().filter(|metrics| metrics.count != m) {
                return Err(invalid(
                    &format!("run '{}'", r.label),
                    format!("{} times but metrics of {} estimates", m, metrics.count),
                ));
            }
        }
        if !runs.iter().any(|r| {
            r.t_s
                .iter()
                .zip(&r.position_m)
                .any(|(t, p)| t.is_finite() && finite3(p))
        }) {
            return Err(PlotError::Empty {
                title: format!("{scenario}: every run"),
            });
        }

        let truth_data = Truth {
            t: truth.t_s.clone(),
            pos: columns(&truth.position_m, MM),
            vel: columns(&truth.velocity_mps, MM),
        };
        let runs: Vec<Run> = runs
            .iter()
            .enumerate()
            .map(|(i, r)| prepare_run(r, RUN_COLORS[i % RUN_COLORS.len()]))
            .collect();
        let t_range = finite_range(
            std::iter::once(truth_data.t.as_slice()).chain(runs.iter().map(|r| r.t.as_slice())),
        )
        .map(|(lo, hi)| {
            if hi > lo {
                (lo, hi)
            } else {
                (lo - 0.5, hi + 0.5)
            }
        })
        .unwrap_or((0.0, 1.0));
        Ok(Self {
            scenario,
            truth: truth_data,
            runs,
            t_range,
        })
    }
}

fn prepare_run(r: &TrackSeries, color: RGBColor) -> Run<'_> {
    Run {
        label: &r.label,
        color,
        t: r.t_s.clone(),
        pos: columns(&r.position_m, MM),
        vel: columns(&r.velocity_mps, MM),
        pos_err: columns(&r.position_error_m, MM),
        vel_err: columns(&r.velocity_error_mps, MM),
        residual: r.residual_rms_px.clone(),
        metrics: r.metrics.as_ref(),
        mean_residual_px: r.mean_residual_px,
    }
}

fn finite_range<'b>(vs: impl IntoIterator<Item = &'b [f64]>) -> Option<(f64, f64)> {
    let (lo, hi) = vs
        .into_iter()
        .flatten()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (lo <= hi).then_some((lo, hi))
}

fn sorted_finite<'b>(vs: impl IntoIterator<Item = &'b [f64]>, abs: bool) -> Vec<f64> {
    let v: Vec<f64> = vs
        .into_iter()
        .flatten()
        .filter(|v| v.is_finite())
        .map(|&v| if abs { v.abs() } else { v })
        .collect();
    stats::sorted(&v)
}

/// A range holding every finite value of `exact` (the truth) and the 0.5–99.5 % quantiles of `robust` (the
/// estimates), padded by 5 % and at least `min_span` wide.
fn robust_range(exact: &[&[f64]], robust: &[&[f64]], min_span: f64) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    if let Some((a, b)) = finite_range(exact.iter().copied()) {
        (lo, hi) = (a, b);
    }
    let sorted = sorted_finite(robust.iter().copied(), false);
    if !sorted.is_empty() {
        lo = lo.min(stats::quantile(&sorted, 0.005));
        hi = hi.max(stats::quantile(&sorted, 0.995));
    }
    if lo > hi {
        return (-min_span / 2.0, min_span / 2.0);
    }
    let pad = 0.05 * (hi - lo);
    widen((lo - pad, hi + pad), min_span)
}

fn widen((lo, hi): (f64, f64), min_span: f64) -> (f64, f64) {
    if hi - lo >= min_span {
        (lo, hi)
    } else {
        let c = 0.5 * (lo + hi);
        (c - min_span / 2.0, c + min_span / 2.0)
    }
}

/// Half-height of a symmetric error axis: 1.2 × the 99th percentile of |error| over all runs.
fn error_limit(errs: &[&[f64]], min: f64) -> f64 {
    let sorted = sorted_finite(errs.iter().copied(), true);
    if sorted.is_empty() {
        return min;
    }
    (1.2 * stats::quantile(&sorted, 0.99)).max(min)
}

/// Number of finite values outside `r`.
fn off_scale(vals: &[&[f64]], r: (f64, f64)) -> usize {
    vals.iter()
        .flat_map(|v| v.iter())
        .filter(|v| v.is_finite() && (**v < r.0 || **v > r.1))
        .count()
}

fn off_scale_note(n: usize) -> Option<String> {
    match n {
        0 => None,
        1 => Some("1 point off-scale".to_string()),
        n => Some(format!("{n} points off-scale")),
    }
}

fn num(v: f64) -> String {
    if !v.is_finite() {
        return "–".to_string();
    }
    let a = v.abs();
    if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Drawing helpers

type Res<T> = Result<T, String>;
type Ctx<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn de<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Chart margins and label areas (px), the same in every panel so that plots line up.
const ML: i32 = 6;
const MR: i32 = 18;
const MT: i32 = 8;
const MB: i32 = 6;
const YLA: i32 = 80;
const XLA: i32 = 44;
const TITLE_PX: u32 = 18;
const NOTE_PX: u32 = 13;
const LEGEND_PX: u32 = 14;

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

/// The largest font size (≤ `size`) at which `text` fits in `max_w` pixels.
fn fitting_size<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    size: u32,
    max_w: u32,
) -> Res<u32> {
    let mut s = size;
    while s > 10 {
        let (w, _) = area
            .estimate_text_size(text, &TextStyle::from((FONT, s).into_font()))
            .map_err(de)?;
        if w <= max_w {
            break;
        }
        s -= 1;
    }
    Ok(s)
}

/// Draws a centred line of text at `y` (top) and returns its height.
fn centred_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    size: u32,
    color: RGBColor,
    y: i32,
) -> Res<i32> {
    let (w, _) = area.dim_in_pixel();
    let s = fitting_size(area, text, size, w.saturating_sub(12))?;
    let style = TextStyle::from((FONT, s).into_font())
        .color(&color)
        .pos(Pos::new(HPos::Center, VPos::Top));
    area.draw_text(text, &style, (w as i32 / 2, y))
        .map_err(de)?;
    Ok(s as i32 + 6)
}

/// Figure title; returns the area below it.
fn figure_title<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> Res<DrawingArea<DB, Shift>> {
    let h = centred_text(root, title, 22, BLACK, 8)?;
    Ok(root.split_vertically(h + 12).1)
}

/// Panel title and an optional grey note line under it (its room is kept when `keep_note_room`, so that panels
/// side by side keep the same plot height); returns the area below.
fn panel_header<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    note: Option<&str>,
    keep_note_room: bool,
) -> Res<DrawingArea<DB, Shift>> {
    let mut h = 4 + centred_text(area, title, TITLE_PX, BLACK, 4)?;
    if let Some(n) = note {
        centred_text(area, n, NOTE_PX, NOTE, h)?;
    }
    if note.is_some() || keep_note_room {
        h += NOTE_PX as i32 + 6;
    }
    Ok(area.split_vertically(h).1)
}

struct Key {
    label: String,
    style: ShapeStyle,
}

/// A legend laid out in rows above a plot (so that it hides nothing); returns the area below it.
fn legend_strip<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    keys: &[Key],
) -> Res<DrawingArea<DB, Shift>> {
    const SAMPLE: i32 = 28;
    const GAP: i32 = 6;
    const SEP: i32 = 26;
    let (w, _) = area.dim_in_pixel();
    let max_w = w as i32 - 2 * YLA.min(40);
    let style = TextStyle::from((FONT, LEGEND_PX).into_font());
    let mut lines: Vec<(i32, Vec<(usize, i32)>)> = vec![(0, Vec::new())];
    for (i, k) in keys.iter().enumerate() {
        let (tw, _) = area.estimate_text_size(&k.label, &style).map_err(de)?;
        let item = SAMPLE + GAP + tw as i32;
        let line = lines.last_mut().expect("one line at least");
        if !line.1.is_empty() && line.0 + SEP + item > max_w {
            lines.push((item, vec![(i, item)]));
        } else {
            line.0 += if line.1.is_empty() { item } else { SEP + item };
            line.1.push((i, item));
        }
    }
    let line_h = LEGEND_PX as i32 + 8;
    let text_style = style.pos(Pos::new(HPos::Left, VPos::Center));
    for (li, (line_w, items)) in lines.iter().enumerate() {
        let mut x = (w as i32 - line_w) / 2;
        let y = 2 + li as i32 * line_h + line_h / 2;
        for &(i, item) in items {
            let k = &keys[i];
            area.draw(&PathElement::new(vec![(x, y), (x + SAMPLE, y)], k.style))
                .map_err(de)?;
            area.draw(&Text::new(
                k.label.clone(),
                (x + SAMPLE + GAP, y),
                text_style.clone(),
            ))
            .map_err(de)?;
            x += item + SEP;
        }
    }
    Ok(area.split_vertically(4 + lines.len() as i32 * line_h).1)
}

/// Pixel size of the plotting area that `chart` builds in `area`.
fn plot_size<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, x_ticks: bool) -> (f64, f64) {
    let (w, h) = area.dim_in_pixel();
    let xla = if x_ticks { XLA } else { 0 };
    (
        (w as i32 - ML - MR - YLA).max(1) as f64,
        (h as i32 - MT - MB - xla).max(1) as f64,
    )
}

/// Decimals for tick labels of a range split in about `n` steps.
fn tick_decimals((lo, hi): (f64, f64), n: usize) -> usize {
    let step = (hi - lo).abs() / n.max(1) as f64;
    if step > 0.0 && step.is_finite() {
        (-step.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        0
    }
}

fn fmt_tick(v: f64, dec: usize) -> String {
    let s = format!("{v:.dec$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

struct Axes<'s> {
    xr: (f64, f64),
    yr: (f64, f64),
    x_desc: &'s str,
    y_desc: &'s str,
    /// Whether tick labels and the description of the x axis are drawn (only under the bottom row of a stack).
    x_ticks: bool,
    /// The plotted vertical values are the negated data (an axis pointing down): label ticks with `-v`.
    y_down: bool,
    n_x: usize,
    n_y: usize,
}

fn chart<'a, DB: DrawingBackend>(area: &'a DrawingArea<DB, Shift>, a: &Axes) -> Res<Ctx<'a, DB>>
where
    DB::ErrorType: 'static,
{
    let mut ctx = ChartBuilder::on(area)
        .margin_left(ML)
        .margin_right(MR)
        .margin_top(MT)
        .margin_bottom(MB)
        .y_label_area_size(YLA)
        .x_label_area_size(if a.x_ticks { XLA } else { 0 })
        .build_cartesian_2d(a.xr.0..a.xr.1, a.yr.0..a.yr.1)
        .map_err(de)?;
    let xd = tick_decimals(a.xr, a.n_x);
    let yd = tick_decimals(a.yr, a.n_y);
    let y_down = a.y_down;
    let xf = move |v: &f64| fmt_tick(*v, xd);
    let yf = move |v: &f64| fmt_tick(if y_down { -*v } else { *v }, yd);
    {
        let mut mesh = ctx.configure_mesh();
        mesh.label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .bold_line_style(GRID_BOLD)
            .light_line_style(GRID_LIGHT)
            .axis_style(FRAME)
            .x_labels(a.n_x)
            .y_labels(a.n_y)
            .y_desc(a.y_desc)
            .y_label_formatter(&yf)
            .x_label_formatter(&xf);
        if a.x_ticks {
            mesh.x_desc(a.x_desc);
        }
        mesh.draw().map_err(de)?;
    }
    ctx.draw_series(std::iter::once(Rectangle::new(
        [(a.xr.0, a.yr.0), (a.xr.1, a.yr.1)],
        FRAME.stroke_width(1),
    )))
    .map_err(de)?;
    Ok(ctx)
}

/// Liang–Barsky: the parameters `(t0, t1)` of the part of segment p→q inside the box, if any.
fn clip_segment(
    p: (f64, f64),
    q: (f64, f64),
    xr: (f64, f64),
    yr: (f64, f64),
) -> Option<(f64, f64)> {
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (pk, qk) in [
        (-dx, p.0 - xr.0),
        (dx, xr.1 - p.0),
        (-dy, p.1 - yr.0),
        (dy, yr.1 - p.1),
    ] {
        if pk == 0.0 {
            if qk < 0.0 {
                return None;
            }
        } else {
            let r = qk / pk;
            if pk < 0.0 {
                if r > t1 {
                    return None;
                }
                t0 = t0.max(r);
            } else {
                if r < t0 {
                    return None;
                }
                t1 = t1.min(r);
            }
        }
    }
    Some((t0, t1))
}

/// The polyline through (xs, ys), broken at non-finite values and clipped to the box.
fn clipped_paths(xs: &[f64], ys: &[f64], xr: (f64, f64), yr: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let mut paths: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    let mut prev: Option<(f64, f64)> = None;
    for (&x, &y) in xs.iter().zip(ys) {
        if !(x.is_finite() && y.is_finite()) {
            prev = None;
            open = false;
            continue;
        }
        let q = (x, y);
        if let Some(p) = prev {
            if let Some((t0, t1)) = clip_segment(p, q, xr, yr) {
                let at = |t: f64| (p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1));
                match paths.last_mut() {
                    Some(path) if open && t0 == 0.0 => path.push(at(t1)),
                    _ => paths.push(vec![at(t0), at(t1)]),
                }
                open = t1 == 1.0;
            } else {
                open = false;
            }
        }
        prev = Some(q);
    }
    paths
}

/// Keeps the minimum and maximum of each chunk of `chunk` points (in their order), so that a dense noisy line keeps
/// its envelope with fewer points.
fn decimate(path: Vec<(f64, f64)>, chunk: usize) -> Vec<(f64, f64)> {
    if chunk <= 2 || path.len() <= 2 * chunk {
        return path;
    }
    let mut out = Vec::with_capacity(2 * path.len() / chunk + 2);
    for c in path.chunks(chunk) {
        let (mut imin, mut imax) = (0, 0);
        for (i, p) in c.iter().enumerate() {
            if p.1 < c[imin].1 {
                imin = i;
            }
            if p.1 > c[imax].1 {
                imax = i;
            }
        }
        let (a, b) = (imin.min(imax), imin.max(imax));
        out.push(c[a]);
        if b != a {
            out.push(c[b]);
        }
    }
    if let (Some(first), Some(out_first)) = (path.first(), out.first_mut()) {
        *out_first = *first;
    }
    if let (Some(last), Some(out_last)) = (path.last(), out.last_mut()) {
        *out_last = *last;
    }
    out
}

/// Draws a line clipped to the chart; time series (`dense`) are decimated to about 3 points per pixel column.
fn line<DB: DrawingBackend>(
    ctx: &mut Ctx<DB>,
    a: &Axes,
    xs: &[f64],
    ys: &[f64],
    style: ShapeStyle,
    dense: bool,
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let paths = clipped_paths(xs, ys, a.xr, a.yr);
    let chunk = if dense {
        let total: usize = paths.iter().map(Vec::len).sum();
        let (w, _) = ctx.plotting_area().dim_in_pixel();
        total / (3 * w.max(1) as usize).max(1)
    } else {
        0
    };
    ctx.draw_series(
        paths
            .into_iter()
            .map(|p| PathElement::new(decimate(p, chunk), style)),
    )
    .map_err(de)?;
    // A finite point between two gaps belongs to no segment: show it as a dot.
    let n = xs.len().min(ys.len());
    let finite = |i: usize| i < n && xs[i].is_finite() && ys[i].is_finite();
    let isolated = (0..n).filter(|&i| {
        finite(i)
            && !(i > 0 && finite(i - 1))
            && !finite(i + 1)
            && (a.xr.0..=a.xr.1).contains(&xs[i])
            && (a.yr.0..=a.yr.1).contains(&ys[i])
    });
    let dot = ShapeStyle {
        filled: true,
        ..style
    };
    ctx.draw_series(isolated.map(|i| Circle::new((xs[i], ys[i]), 3, dot)))
        .map_err(de)?;
    Ok(())
}

/// Splits `area` into `n` stacked rows of equal plot height; the bottom row also holds the x axis labels.
fn rows<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    n: usize,
) -> Vec<DrawingArea<DB, Shift>> {
    let (_, h) = area.dim_in_pixel();
    let n_i = n as i32;
    let plot_h = (h as i32 - XLA - n_i * (MT + MB)) / n_i;
    let breaks: Vec<i32> = (1..n_i).map(|k| k * (plot_h + MT + MB)).collect();
    area.split_by_breakpoints([] as [i32; 0], breaks)
}

/// One row of a stack of x/y/z plots against time.
struct TimeRow<'d> {
    y_desc: String,
    yr: (f64, f64),
    /// (times, values, style), drawn in this order.
    lines: Vec<(&'d [f64], &'d [f64], ShapeStyle)>,
    zero_line: bool,
}

fn time_rows<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    t_range: (f64, f64),
    stack: &[TimeRow],
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let areas = rows(area, stack.len());
    for (k, (row, a)) in stack.iter().zip(&areas).enumerate() {
        let axes = Axes {
            xr: t_range,
            yr: row.yr,
            x_desc: "time (s)",
            y_desc: &row.y_desc,
            x_ticks: k + 1 == stack.len(),
            y_down: false,
            n_x: 10,
            n_y: 6,
        };
        let mut ctx = chart(a, &axes)?;
        if row.zero_line && row.yr.0 < 0.0 && row.yr.1 > 0.0 {
            line(
                &mut ctx,
                &axes,
                &[t_range.0, t_range.1],
                &[0.0, 0.0],
                BLACK.mix(0.6).stroke_width(1),
                false,
            )?;
        }
        for (xs, ys, style) in &row.lines {
            line(&mut ctx, &axes, xs, ys, *style, true)?;
        }
    }
    Ok(())
}

/// Grid cells of a 2 × 2 figure, with some room between them.
fn cells<DB: DrawingBackend>(body: &DrawingArea<DB, Shift>) -> Vec<DrawingArea<DB, Shift>> {
    body.split_evenly((2, 2))
        .into_iter()
        .map(|c| c.margin(2, 10, 6, 6))
        .collect()
}

fn truth_key(style: ShapeStyle) -> Key {
    Key {
        label: "truth".to_string(),
        style,
    }
}

/// Runs from the last to the first, so that the first (default) estimator is drawn on top.
fn runs_back_to_front<'r, 'a>(d: &'r Data<'a>) -> impl Iterator<Item = (usize, &'r Run<'a>)> {
    d.runs.iter().enumerate().rev()
}

// ---------------------------------------------------------------------------------------------------------------
// Figure 5: trajectory projections

/// Ranges `(xr, yr)` grown so that one unit spans as many pixels on both axes.
fn equal_aspect(xr: (f64, f64), yr: (f64, f64), (pw, ph): (f64, f64)) -> ((f64, f64), (f64, f64)) {
    let s = ((xr.1 - xr.0) / pw).max((yr.1 - yr.0) / ph);
    let grow = |r: (f64, f64), px: f64| {
        let c = 0.5 * (r.0 + r.1);
        (c - 0.5 * s * px, c + 0.5 * s * px)
    };
    (grow(xr, pw), grow(yr, ph))
}

/// Says how much the vertical axis is stretched relative to the horizontal one, when they are not to scale.
fn scale_note(
    h: (f64, f64),
    v: (f64, f64),
    (pw, ph): (f64, f64),
    h_name: &str,
    v_name: &str,
) -> Option<String> {
    let h_mm_px = (h.1 - h.0) / pw;
    let v_mm_px = (v.1 - v.0) / ph;
    let m = h_mm_px / v_mm_px;
    if m > 1.5 {
        Some(format!(
            "{v_name} axis stretched ×{} relative to {h_name}",
            num(m)
        ))
    } else if m < 1.0 / 1.5 {
        Some(format!(
            "{h_name} axis stretched ×{} relative to {v_name}",
            num(1.0 / m)
        ))
    } else {
        None
    }
}

fn join_notes(notes: &[Option<String>]) -> Option<String> {
    let v: Vec<&str> = notes.iter().flatten().map(String::as_str).collect();
    (!v.is_empty()).then(|| v.join(" · "))
}

fn fig5<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let body = figure_title(
        root,
        &format!(
            "Fig. 5 — Trajectory of the target origin in the camera frame, projected on three planes — scenario '{}'",
            d.scenario
        ),
    )?;
    let truth_style = BLACK.mix(0.3).stroke_width(6);
    let mut keys = vec![truth_key(truth_style)];
    keys.extend(d.runs.iter().enumerate().map(|(i, r)| Key {
        label: r.metrics.map_or_else(
            || r.label.to_string(),
            |m| {
                format!(
                    "{} (3-D position RMS error {} mm)",
                    r.label,
                    num(m.position_rmse_mm)
                )
            },
        ),
        style: r.style(i),
    }));
    let body = legend_strip(&body, &keys)?;
    let panels: Vec<_> = body
        .split_evenly((1, 3))
        .into_iter()
        .map(|c| c.margin(2, 10, 6, 6))
        .collect();

    let range = |c: usize| {
        let runs: Vec<&[f64]> = d.runs.iter().map(|r| r.pos[c].as_slice()).collect();
        robust_range(&[&d.truth.pos[c]], &runs, 1.0)
    };
    let (xr, yr, zr) = (range(0), range(1), range(2));
    // The plot size does not depend on the header text, since every header keeps room for a note.
    let probe = panel_header_size(&panels[0]);
    let plot = plot_size(&probe, true);
    let (xr, yr) = equal_aspect(xr, yr, plot);
    let y_down = (-yr.1, -yr.0);

    struct Panel<'s> {
        title: &'s str,
        h: usize,
        v: usize,
        hr: (f64, f64),
        vr: (f64, f64),
        h_desc: &'s str,
        v_desc: &'s str,
    }
    let specs = [
        Panel {
            title: "(a) x–y: image plane, as seen by the camera",
            h: 0,
            v: 1,
            hr: xr,
            vr: y_down,
            h_desc: "x (mm)",
            v_desc: "y (mm, pointing down)",
        },
        Panel {
            title: "(b) x–z: top view",
            h: 0,
            v: 2,
            hr: xr,
            vr: zr,
            h_desc: "x (mm)",
            v_desc: "z, depth (mm)",
        },
        Panel {
            title: "(c) y–z: side view",
            h: 2,
            v: 1,
            hr: zr,
            vr: y_down,
            h_desc: "z, depth (mm)",
            v_desc: "y (mm, pointing down)",
        },
    ];
    for (p, area) in specs.iter().zip(&panels) {
        let sign = |c: usize| if c == 1 { -1.0 } else { 1.0 };
        let v_of =
            |vals: &[f64], c: usize| -> Vec<f64> { vals.iter().map(|v| sign(c) * v).collect() };
        let truth_h = v_of(&d.truth.pos[p.h], p.h);
        let truth_v = v_of(&d.truth.pos[p.v], p.v);
        let run_hv: Vec<(Vec<f64>, Vec<f64>)> = d
            .runs
            .iter()
            .map(|r| (v_of(&r.pos[p.h], p.h), v_of(&r.pos[p.v], p.v)))
            .collect();
        let off: usize = run_hv
            .iter()
            .map(|(h, v)| {
                h.iter()
                    .zip(v)
                    .filter(|(h, v)| {
                        h.is_finite()
                            && v.is_finite()
                            && (**h < p.hr.0 || **h > p.hr.1 || **v < p.vr.0 || **v > p.vr.1)
                    })
                    .count()
            })
            .sum();
        let h_name = p
            .h_desc
            .split(' ')
            .next()
            .unwrap_or("")
            .trim_end_matches(',');
        let v_name = p
            .v_desc
            .split(' ')
            .next()
            .unwrap_or("")
            .trim_end_matches(',');
        let note = join_notes(&[
            scale_note(p.hr, p.vr, plot, h_name, v_name),
            off_scale_note(off),
        ]);
        let inner = panel_header(area, p.title, note.as_deref(), true)?;
        let axes = Axes {
            xr: p.hr,
            yr: p.vr,
            x_desc: p.h_desc,
            y_desc: p.v_desc,
            x_ticks: true,
            y_down: p.v == 1,
            n_x: 6,
            n_y: 10,
        };
        let mut ctx = chart(&inner, &axes)?;
        line(&mut ctx, &axes, &truth_h, &truth_v, truth_style, false)?;
        for (i, r) in runs_back_to_front(d) {
            let (h, v) = &run_hv[i];
            line(&mut ctx, &axes, h, v, r.style(i), false)?;
        }
        start_and_direction(&mut ctx, &axes, &truth_h, &truth_v)?;
    }
    Ok(())
}

/// Marks where the truth starts and, with an arrow head a little later, which way it goes.
fn start_and_direction<DB: DrawingBackend>(
    ctx: &mut Ctx<DB>,
    a: &Axes,
    xs: &[f64],
    ys: &[f64],
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let inside = |i: usize| {
        let (x, y) = (xs[i], ys[i]);
        x.is_finite() && y.is_finite() && x >= a.xr.0 && x <= a.xr.1 && y >= a.yr.0 && y <= a.yr.1
    };
    let n = xs.len().min(ys.len());
    let Some(i0) = (0..n).find(|&i| inside(i)) else {
        return Ok(());
    };
    let p0 = (xs[i0], ys[i0]);
    let label = TextStyle::from((FONT, 13).into_font()).pos(Pos::new(HPos::Left, VPos::Bottom));
    ctx.draw_series(std::iter::once(
        EmptyElement::at(p0)
            + Circle::new((0, 0), 5, BLACK.filled())
            + Text::new("start", (7, -5), label),
    ))
    .map_err(de)?;
    // The arrow points along the first stretch of the truth long enough to show a direction on screen.
    let from = ctx.backend_coord(&p0);
    let Some(i1) = (i0 + 1..n).find(|&i| {
        let q = ctx.backend_coord(&(xs[i], ys[i]));
        inside(i) && (q.0 - from.0).pow(2) + (q.1 - from.1).pow(2) >= 40 * 40
    }) else {
        return Ok(());
    };
    let Some(i2) = (i1 + 1..n).find(|&i| {
        let (q, r) = (
            ctx.backend_coord(&(xs[i1], ys[i1])),
            ctx.backend_coord(&(xs[i], ys[i])),
        );
        inside(i) && (q.0 - r.0).pow(2) + (q.1 - r.1).pow(2) >= 6 * 6
    }) else {
        return Ok(());
    };
    let (q, r) = (
        ctx.backend_coord(&(xs[i1], ys[i1])),
        ctx.backend_coord(&(xs[i2], ys[i2])),
    );
    let (dx, dy) = ((r.0 - q.0) as f64, (r.1 - q.1) as f64);
    let len = dx.hypot(dy);
    let (ux, uy) = (dx / len, dy / len);
    let pt = |along: f64, across: f64| {
        (
            (along * ux - across * uy).round() as i32,
            (along * uy + across * ux).round() as i32,
        )
    };
    ctx.draw_series(std::iter::once(
        EmptyElement::at((xs[i1], ys[i1]))
            + Polygon::new(
                vec![pt(9.0, 0.0), pt(-7.0, 7.0), pt(-7.0, -7.0)],
                BLACK.filled(),
            ),
    ))
    .map_err(de)?;
    Ok(())
}

/// The area left for the chart under a panel header that keeps room for a note (without drawing anything).
fn panel_header_size<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>) -> DrawingArea<DB, Shift> {
    let h = 4 + TITLE_PX as i32 + 6 + NOTE_PX as i32 + 6;
    area.split_vertically(h).1
}

// ---------------------------------------------------------------------------------------------------------------
// Figures 6 and 7: position and velocity against time

#[derive(Clone, Copy, PartialEq)]
enum Quantity {
    Position,
    Velocity,
}

impl Quantity {
    fn unit(self) -> &'static str {
        match self {
            Self::Position => "mm",
            Self::Velocity => "mm/s",
        }
    }
    fn name(self) -> &'static str {
        match self {
            Self::Position => "position",
            Self::Velocity => "velocity",
        }
    }
    fn truth<'d>(self, d: &'d Data) -> &'d [Vec<f64>; 3] {
        match self {
            Self::Position => &d.truth.pos,
            Self::Velocity => &d.truth.vel,
        }
    }
    fn est<'r>(self, r: &'r Run) -> &'r [Vec<f64>; 3] {
        match self {
            Self::Position => &r.pos,
            Self::Velocity => &r.vel,
        }
    }
    fn err<'r>(self, r: &'r Run) -> &'r [Vec<f64>; 3] {
        match self {
            Self::Position => &r.pos_err,
            Self::Velocity => &r.vel_err,
        }
    }
    /// The run's RMS error along x, y, z and of the 3-D error (mm or mm/s), from its metrics; `None` without them.
    fn rms(self, r: &Run) -> Option<([f64; 3], f64)> {
        let m = r.metrics?;
        match self {
            Self::Position => Some((m.position_rmse_xyz_mm, m.position_rmse_mm)),
            Self::Velocity => Some((m.velocity_rmse_xyz_mm_s?, m.velocity_rmse_mm_s?)),
        }
    }
}

/// Panels (a), (b) and (c) of figures 6 and 7, in the first three cells.
fn truth_estimate_error<DB: DrawingBackend>(
    cells: &[DrawingArea<DB, Shift>],
    d: &Data,
    q: Quantity,
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let unit = q.unit();
    let truth = q.truth(d);
    let first = &d.runs[0];
    // (a) and (b) share their ranges, so that truth and estimate can be compared row by row.
    let ranges: [(f64, f64); 3] =
        std::array::from_fn(|c| robust_range(&[&truth[c]], &[&q.est(first)[c]], 1.0));
    let off_b: usize = (0..3)
        .map(|c| off_scale(&[&q.est(first)[c]], ranges[c]))
        .sum();

    // (a) truth
    let inner = panel_header(
        &cells[0],
        &format!("(a) True {} (camera frame)", q.name()),
        None,
        true,
    )?;
    let stack: Vec<TimeRow> = (0..3)
        .map(|c| TimeRow {
            y_desc: format!("{} ({unit})", AXES[c]),
            yr: ranges[c],
            lines: vec![(
                d.truth.t.as_slice(),
                truth[c].as_slice(),
                AXIS_COLORS[c].stroke_width(2),
            )],
            zero_line: false,
        })
        .collect();
    time_rows(&inner, d.t_range, &stack)?;

    // (b) first run's estimate over the truth in grey
    let note_b = join_notes(&[Some("grey: truth".to_string()), off_scale_note(off_b)]);
    let inner = panel_header(
        &cells[1],
        &format!("(b) Estimated {}: {}", q.name(), first.label),
        note_b.as_deref(),
        true,
    )?;
    let stack: Vec<TimeRow> = (0..3)
        .map(|c| TimeRow {
            y_desc: format!("{} ({unit})", AXES[c]),
            yr: ranges[c],
            lines: vec![
                (
                    d.truth.t.as_slice(),
                    truth[c].as_slice(),
                    BLACK.mix(0.22).stroke_width(5),
                ),
                (
                    first.t.as_slice(),
                    q.est(first)[c].as_slice(),
                    AXIS_COLORS[c].stroke_width(1),
                ),
            ],
            zero_line: false,
        })
        .collect();
    time_rows(&inner, d.t_range, &stack)?;

    // (c) errors of every run, on a robust symmetric range
    let limits: [f64; 3] = std::array::from_fn(|c| {
        let errs: Vec<&[f64]> = d.runs.iter().map(|r| q.err(r)[c].as_slice()).collect();
        error_limit(&errs, 1e-3)
    });
    let off_c: usize = (0..3)
        .map(|c| {
            let errs: Vec<&[f64]> = d.runs.iter().map(|r| q.err(r)[c].as_slice()).collect();
            off_scale(&errs, (-limits[c], limits[c]))
        })
        .sum();
    let note_c = off_scale_note(off_c).map(|off| {
        format!("range of each row: ±1.2 × 99th percentile of |error| over all runs; {off}")
    });
    let inner = panel_header(
        &cells[2],
        &format!("(c) {} error: estimate − truth", capitalised(q.name())),
        note_c.as_deref(),
        true,
    )?;
    let keys: Vec<Key> = d
        .runs
        .iter()
        .enumerate()
        .map(|(i, r)| Key {
            label: q.rms(r).map_or_else(
                || r.label.to_string(),
                |(xyz, norm)| {
                    format!(
                        "{} (RMS x {} · y {} · z {} · 3-D {} {unit})",
                        r.label,
                        num(xyz[0]),
                        num(xyz[1]),
                        num(xyz[2]),
                        num(norm)
                    )
                },
            ),
            style: r.style(i),
        })
        .collect();
    let inner = legend_strip(&inner, &keys)?;
    let stack: Vec<TimeRow> = (0..3)
        .map(|c| TimeRow {
            y_desc: format!("{} error ({unit})", AXES[c]),
            yr: (-limits[c], limits[c]),
            lines: runs_back_to_front(d)
                .map(|(i, r)| (r.t.as_slice(), q.err(r)[c].as_slice(), r.style(i)))
                .collect(),
            zero_line: true,
        })
        .collect();
    time_rows(&inner, d.t_range, &stack)
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().chain(c).collect())
        .unwrap_or_default()
}

fn fig6<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let body = figure_title(
        root,
        &format!(
            "Fig. 6 — Position of the target origin: truth, estimate, error and image residual — scenario '{}'",
            d.scenario
        ),
    )?;
    let cells = cells(&body);
    truth_estimate_error(&cells, d, Quantity::Position)?;

    // (d) image residual
    let with_residual: Vec<(usize, &Run)> = d
        .runs
        .iter()
        .enumerate()
        .filter(|(_, r)| r.residual.iter().any(|v| v.is_finite()))
        .collect();
    let all: Vec<&[f64]> = with_residual
        .iter()
        .map(|(_, r)| r.residual.as_slice())
        .collect();
    let hi = error_limit(&all, 1e-3);
    let off = off_scale(&all, (0.0, hi));
    let note = if with_residual.is_empty() {
        Some("no run reports an image residual".to_string())
    } else {
        off_scale_note(off)
            .map(|off| format!("range: 0 to 1.2 × 99th percentile over all runs; {off}"))
    };
    let inner = panel_header(
        &cells[3],
        "(d) Image residual: RMS reprojection error per point",
        note.as_deref(),
        true,
    )?;
    let keys: Vec<Key> = with_residual
        .iter()
        .map(|(i, r)| Key {
            label: format!(
                "{} (mean {} px)",
                r.label,
                r.mean_residual_px.map_or("–".to_string(), num)
            ),
            style: r.style(*i),
        })
        .collect();
    let inner = legend_strip(&inner, &keys)?;
    let axes = Axes {
        xr: d.t_range,
        yr: (0.0, hi),
        x_desc: "time (s)",
        y_desc: "residual RMS (px)",
        x_ticks: true,
        y_down: false,
        n_x: 10,
        n_y: 8,
    };
    let mut ctx = chart(&inner, &axes)?;
    for (i, r) in with_residual.iter().rev() {
        line(&mut ctx, &axes, &r.t, &r.residual, r.style(*i), true)?;
    }
    Ok(())
}

fn fig7<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let body = figure_title(
        root,
        &format!(
            "Fig. 7 — Velocity of the target origin: truth, estimate and error — scenario '{}'",
            d.scenario
        ),
    )?;
    let cells = cells(&body);
    truth_estimate_error(&cells, d, Quantity::Velocity)?;
    statistics(&cells[3], d)
}

/// Panel (d) of figure 7: a table of the error statistics of every run.
fn statistics<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let inner = panel_header(
        area,
        "(d) Error statistics of each run (RMS of estimate − truth)",
        None,
        true,
    )?;
    let (w, h) = inner.dim_in_pixel();
    inner
        .draw(&Rectangle::new(
            [(YLA / 2, 4), (w as i32 - MR, h as i32 - 4)],
            FRAME.stroke_width(1),
        ))
        .map_err(de)?;
    let font = |size: u32, color: &'static RGBColor| {
        TextStyle::from((FONT, size).into_font())
            .color(color)
            .pos(Pos::new(HPos::Left, VPos::Top))
    };
    let x0 = YLA / 2 + 14;
    let cols = [x0 + 8, x0 + 120, x0 + 228, x0 + 336, x0 + 444, x0 + 570];
    let line_h = 24;
    let mut y = 14;
    let bottom = h as i32 - 12 - FOOTNOTES.len() as i32 * line_h;
    for (i, r) in d.runs.iter().enumerate() {
        if y + 4 * line_h > bottom {
            let left = d.runs.len() - i;
            inner
                .draw(&Text::new(
                    format!("… {left} more run{}", if left > 1 { "s" } else { "" }),
                    (x0, y),
                    font(14, &NOTE),
                ))
                .map_err(de)?;
            break;
        }
        inner
            .draw(&PathElement::new(
                vec![(x0, y + 10), (x0 + 24, y + 10)],
                r.style(i),
            ))
            .map_err(de)?;
        let title = r.metrics.map_or_else(
            || r.label.to_string(),
            |m| {
                format!(
                    "{}  ({} estimate{})",
                    r.label,
                    m.count,
                    if m.count == 1 { "" } else { "s" }
                )
            },
        );
        inner
            .draw(&Text::new(title, (x0 + 32, y), font(16, &BLACK)))
            .map_err(de)?;
        y += line_h + 2;
        for q in [Quantity::Position, Quantity::Velocity] {
            let cells = match q.rms(r) {
                Some((xyz, norm)) => vec![
                    q.name().to_string(),
                    format!("x {}", num(xyz[0])),
                    format!("y {}", num(xyz[1])),
                    format!("z {}", num(xyz[2])),
                    format!("3-D {}", num(norm)),
                    q.unit().to_string(),
                ],
                None => vec![q.name().to_string(), "n/a".to_string()],
            };
            for (text, &x) in cells.iter().zip(&cols) {
                inner
                    .draw(&Text::new(text.clone(), (x, y), font(15, &BLACK)))
                    .map_err(de)?;
            }
            y += line_h;
        }
        let residual = r
            .mean_residual_px
            .map_or("no image residual".to_string(), |m| {
                format!("mean image residual {} px", num(m))
            });
        inner
            .draw(&Text::new(
                format!("{} · {residual}", lag_text(r.metrics)),
                (cols[0], y),
                font(14, &NOTE),
            ))
            .map_err(de)?;
        y += line_h + 10;
    }
    for (k, text) in FOOTNOTES.iter().enumerate() {
        inner
            .draw(&Text::new(
                text.to_string(),
                (x0, bottom + 4 + k as i32 * line_h),
                font(13, &NOTE),
            ))
            .map_err(de)?;
    }
    Ok(())
}

/// The footnote of figure 7 (d): how roitrack-eval defines what the table shows. Three lines leave room for three
/// runs in the table.
const FOOTNOTES: [&str; 3] = [
    "Velocity lag: the shift, in estimator samples, maximising the cross-correlation of estimated and true",
    "velocity; positive: the estimate lags. ms: samples × median period; sub-sample: parabola through the peak.",
    "3-D: RMS of the error vector's length. RMS values use every estimate, off-scale points included.",
];

/// The velocity lag of a run, e.g. "velocity lag: 2 samples (5.0 ms; sub-sample 1.74)", or "velocity lag: n/a"
/// without velocity metrics.
fn lag_text(metrics: Option<&Metrics>) -> String {
    let lag = metrics.and_then(|m| {
        Some((
            m.velocity_lag_samples?,
            m.velocity_lag_ms?,
            m.velocity_lag_subsample?,
        ))
    });
    let Some((samples, ms, subsample)) = lag else {
        return "velocity lag: n/a".to_string();
    };
    // One decimal is exact for the usual periods (2.5 ms and its multiples); shorter lags need two.
    let ms = if ms.abs() >= 1.0 || ms == 0.0 {
        format!("{ms:.1}")
    } else {
        format!("{ms:.2}")
    };
    format!(
        "velocity lag: {samples} sample{} ({ms} ms; sub-sample {subsample:.2})",
        if samples.abs() == 1 { "" } else { "s" }
    )
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
    use roitrack_core::{PoseSample, TwistSample};
    use roitrack_eval::{EvalOptions, estimate_errors};

    use super::*;

    /// A small deterministic normal generator (xorshift + Box–Muller), to avoid a dependency.
    struct Noise(u64);
    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// Interval between the estimates of the synthetic runs (s): 400 Hz.
    const PERIOD_S: f64 = 1.0 / 400.0;

    /// Two laps of a 60 mm circle in the image plane at 0.6 m depth, in 2 s, sampled at 4 kHz.
    fn circle_truth() -> TruthSeries {
        let w = std::f64::consts::TAU;
        let r = 0.06;
        let t_s: Vec<f64> = (0..8000).map(|i| i as f64 / 4000.0).collect();
        TruthSeries {
            position_m: t_s
                .iter()
                .map(|t| [r * (w * t).cos(), r * (w * t).sin(), 0.6])
                .collect(),
            velocity_mps: t_s
                .iter()
                .map(|t| [-r * w * (w * t).sin(), r * w * (w * t).cos(), 0.0])
                .collect(),
            t_s,
        }
    }

    /// The truth's position and velocity at `t`, interpolated linearly and held at the ends: a lagging estimate
    /// between the truth's samples.
    fn truth_at(truth: &TruthSeries, t: f64) -> ([f64; 3], [f64; 3]) {
        let ts = &truth.t_s;
        let j = ts.partition_point(|&s| s <= t).clamp(1, ts.len() - 1);
        let i = j - 1;
        let a = ((t - ts[i]) / (ts[j] - ts[i])).clamp(0.0, 1.0);
        let lerp = |p: &[f64; 3], q: &[f64; 3]| std::array::from_fn(|c| p[c] + a * (q[c] - p[c]));
        (
            lerp(&truth.position_m[i], &truth.position_m[j]),
            lerp(&truth.velocity_mps[i], &truth.velocity_mps[j]),
        )
    }

    fn poses(t_s: &[f64], position_m: &[[f64; 3]]) -> Vec<PoseSample> {
        t_s.iter()
            .zip(position_m)
            .map(|(&t_s, p)| PoseSample {
                t_s,
                cam_from_obj: Isometry3::from_parts(
                    Translation3::new(p[0], p[1], p[2]),
                    UnitQuaternion::identity(),
                ),
            })
            .collect()
    }

    fn twists(t_s: &[f64], velocity_mps: &[[f64; 3]]) -> Vec<TwistSample> {
        t_s.iter()
            .zip(velocity_mps)
            .map(|(&t_s, v)| TwistSample {
                t_s,
                velocity_mps: Vector3::from(*v),
                angular_velocity_radps: Vector3::zeros(),
            })
            .collect()
    }

    /// `run` with its errors and metrics from roitrack-eval against `truth`, as a caller gives them; without
    /// `twists`, the estimate's twists are withheld, so that the run has no velocity error or lag.
    fn scored(truth: &TruthSeries, mut run: TrackSeries, with_twists: bool) -> TrackSeries {
        let opts = EvalOptions::default();
        let truth_twists = twists(&truth.t_s, &truth.velocity_mps);
        let est_twists = twists(&run.t_s, &run.velocity_mps);
        let errors = estimate_errors(
            &poses(&truth.t_s, &truth.position_m),
            Some(&truth_twists),
            &poses(&run.t_s, &run.position_m),
            with_twists.then_some(est_twists.as_slice()),
            &opts,
        )
        .unwrap();
        (run.position_error_m, run.velocity_error_mps) = error_columns(&errors);
        run.metrics = Some(errors.metrics(&opts));
        run.mean_residual_px = finite_mean(&run.residual_rms_px);
        run
    }

    /// A run at 400 Hz: the truth `lag_s` late, plus noise (position sigma in m, depth 3× larger; velocity sigma),
    /// scored against `truth`.
    fn run(
        truth: &TruthSeries,
        label: &str,
        lag_s: f64,
        pos_sigma: f64,
        vel_sigma: f64,
        residual: f64,
        seed: u64,
    ) -> TrackSeries {
        let mut noise = Noise(seed);
        let t_s: Vec<f64> = (0..800).map(|i| i as f64 * PERIOD_S).collect();
        let mut out = TrackSeries {
            label: label.to_string(),
            ..TrackSeries::default()
        };
        for &t in &t_s {
            let (p, v) = truth_at(truth, t - lag_s);
            out.position_m.push([
                p[0] + pos_sigma * noise.normal(),
                p[1] + pos_sigma * noise.normal(),
                p[2] + 3.0 * pos_sigma * noise.normal(),
            ]);
            out.velocity_mps
                .push(std::array::from_fn(|c| v[c] + vel_sigma * noise.normal()));
            out.residual_rms_px
                .push(residual * (1.0 + 0.2 * noise.normal()).abs());
        }
        out.t_s = t_s;
        scored(truth, out, true)
    }

    fn example_runs(truth: &TruthSeries) -> Vec<TrackSeries> {
        let mut default = run(truth, "kalman (default)", PERIOD_S, 0.0002, 0.01, 0.12, 7);
        // A gap in the estimates must not break the figures (the metrics were computed before it).
        default.position_m[300] = [f64::NAN; 3];
        default.position_error_m[300] = [f64::NAN; 3];
        default.velocity_mps[301][1] = f64::INFINITY;
        default.velocity_error_mps[301][1] = f64::INFINITY;
        default.residual_rms_px[302] = f64::NAN;
        let baseline = run(
            truth,
            "baseline (noisy, 10 ms lag)",
            4.0 * PERIOD_S,
            0.002,
            1.0,
            0.6,
            11,
        );
        vec![default, baseline]
    }

    #[test]
    fn mean_residual_skips_non_finite_values() {
        assert_eq!(finite_mean(&[1.0, f64::NAN, 3.0, f64::INFINITY]), Some(2.0));
        assert_eq!(finite_mean(&[f64::NAN]), None);
        assert_eq!(finite_mean(&[]), None);
    }

    #[test]
    fn figure_7_shows_the_velocity_lag_of_eval() {
        let truth = circle_truth();
        let lagging = run(&truth, "lagging", 2.0 * PERIOD_S, 0.0, 0.0, 0.1, 3);
        let metrics = lagging.metrics.clone().unwrap();
        assert_eq!(metrics.velocity_lag_samples, Some(2), "{metrics:?}");
        let subsample = metrics.velocity_lag_subsample.unwrap();
        let mut no_twists = run(&truth, "no twists", 0.0, 0.0002, 0.01, 0.1, 5);
        no_twists.velocity_error_mps.clear();
        let no_twists = scored(&truth, no_twists, false);
        assert!(no_twists.velocity_error_mps.is_empty());
        assert_eq!(
            no_twists.metrics.as_ref().unwrap().velocity_lag_samples,
            None
        );

        let dir = tempfile::tempdir().unwrap();
        write_figures(dir.path(), "circle", &truth, &[lagging, no_twists]).unwrap();
        let fig7 = std::fs::read_to_string(dir.path().join("fig7_velocity.svg")).unwrap();
        let shown = format!("velocity lag: 2 samples (5.0 ms; sub-sample {subsample:.2})");
        assert!(fig7.contains(&shown), "fig7 lacks '{shown}'");
        assert!(fig7.contains("velocity lag: n/a"));
        assert!(fig7.contains(&format!("lagging  ({} estimates)", metrics.count)));
    }

    #[test]
    fn polylines_are_split_at_gaps_and_clipped() {
        let xs = [0.0, 1.0, 2.0, 3.0, f64::NAN, 5.0, 6.0];
        let ys = [0.0, 0.0, 10.0, 0.0, 0.0, 0.0, 0.0];
        let paths = clipped_paths(&xs, &ys, (-1.0, 10.0), (-1.0, 1.0));
        // 0→1→(1.1, 1) | (2.9, 1)→3 | 5→6
        assert_eq!(paths.len(), 3);
        assert_eq!(paths[0].len(), 3);
        assert!((paths[0][2].0 - 1.1).abs() < 1e-12 && paths[0][2].1 == 1.0);
        assert!((paths[1][0].0 - 2.9).abs() < 1e-12);
        assert_eq!(paths[2], vec![(5.0, 0.0), (6.0, 0.0)]);
    }

    #[test]
    fn decimation_keeps_the_envelope() {
        let path: Vec<(f64, f64)> = (0..1000)
            .map(|i| (i as f64, if i == 437 { 50.0 } else { (i % 7) as f64 }))
            .collect();
        let out = decimate(path, 20);
        assert!(out.len() <= 102);
        assert!(out.iter().any(|p| p.1 == 50.0));
        assert_eq!(out[0], (0.0, 0.0));
        assert_eq!(out.last().unwrap().0, 999.0);
    }

    #[test]
    fn writes_the_three_figures() {
        let truth = circle_truth();
        let runs = example_runs(&truth);
        let dir = tempfile::tempdir().unwrap();
        let paths = write_figures(dir.path(), "circle", &truth, &runs).unwrap();
        assert_eq!(paths.len(), 6);
        let titles = [
            ("fig5_trajectory", "Fig. 5", "(c) y–z: side view"),
            ("fig6_position", "Fig. 6", "(d) Image residual"),
            ("fig7_velocity", "Fig. 7", "(d) Error statistics"),
        ];
        for (stem, title, panel) in titles {
            let png = dir.path().join(format!("{stem}.png"));
            let svg = dir.path().join(format!("{stem}.svg"));
            assert!(paths.contains(&png) && paths.contains(&svg));
            let len = std::fs::metadata(&png).unwrap().len();
            assert!(len > 20_000, "{stem}.png is {len} bytes");
            let text = std::fs::read_to_string(&svg).unwrap();
            assert!(text.contains("<svg"), "{stem}.svg");
            assert!(
                text.contains(title) && text.contains(panel),
                "{stem}.svg lacks its titles"
            );
            assert!(
                text.contains("kalman (default)"),
                "{stem}.svg lacks the run legend"
            );
        }
        // The numbers shown are eval's.
        let m = runs[0].metrics.as_ref().unwrap();
        let fig5 = std::fs::read_to_string(dir.path().join("fig5_trajectory.svg")).unwrap();
        assert!(fig5.contains(&format!(
            "kalman (default) (3-D position RMS error {} mm)",
            num(m.position_rmse_mm)
        )));
        let fig6 = std::fs::read_to_string(dir.path().join("fig6_position.svg")).unwrap();
        assert!(fig6.contains(&format!("3-D {} mm)", num(m.position_rmse_mm))));
        // The noisy baseline's velocity swamps the error axes unless they are clipped.
        let fig7 = std::fs::read_to_string(dir.path().join("fig7_velocity.svg")).unwrap();
        assert!(fig7.contains("points off-scale"));
        assert!(fig7.contains(&format!("3-D {} mm/s)", num(m.velocity_rmse_mm_s.unwrap()))));
        // Keep a copy to look at when asked to.
        if let Some(keep) = std::env::var_os("ROITRACK_PLOT_KEEP") {
            write_figures(Path::new(&keep), "circle", &truth, &runs).unwrap();
        }
    }

    #[test]
    fn draws_tiny_and_static_input() {
        let dir = tempfile::tempdir().unwrap();
        let truth = TruthSeries {
            t_s: vec![0.0, 1.0],
            position_m: vec![[0.0, 0.0, 0.5]; 2],
            velocity_mps: vec![[0.0; 3]; 2],
        };
        let one = TrackSeries {
            label: "one estimate, no residual".into(),
            t_s: vec![0.5],
            position_m: vec![[0.001, 0.0, 0.5]],
            velocity_mps: vec![[0.0; 3]],
            ..TrackSeries::default()
        };
        let one = scored(&truth, one, true);
        assert_eq!(one.metrics.as_ref().unwrap().count, 1);
        assert_eq!(one.mean_residual_px, None);
        let unscored = TrackSeries {
            label: "no metrics".into(),
            metrics: None,
            ..one.clone()
        };
        let runs = [one, unscored];
        let paths = write_figures(dir.path(), "static", &truth, &runs).unwrap();
        assert!(paths.iter().all(|p| p.exists()));
        if let Some(keep) = std::env::var_os("ROITRACK_PLOT_KEEP") {
            write_figures(&Path::new(&keep).join("static"), "static", &truth, &runs).unwrap();
        }
    }

    #[test]
    fn refuses_empty_and_inconsistent_input() {
        let dir = tempfile::tempdir().unwrap();
        let truth = circle_truth();
        assert!(matches!(
            write_figures(dir.path(), "s", &truth, &[]),
            Err(PlotError::Empty { .. })
        ));
        assert!(matches!(
            write_figures(
                dir.path(),
                "s",
                &TruthSeries::default(),
                &example_runs(&truth)
            ),
            Err(PlotError::Empty { .. })
        ));
        let nan_run = TrackSeries {
            label: "nan".into(),
            t_s: vec![0.0, 0.1],
            position_m: vec![[f64::NAN; 3]; 2],
            velocity_mps: vec![[0.0; 3]; 2],
            position_error_m: vec![[f64::NAN; 3]; 2],
            ..TrackSeries::default()
        };
        assert!(matches!(
            write_figures(dir.path(), "s", &truth, &[nan_run]),
            Err(PlotError::Empty { .. })
        ));
        let good = example_runs(&truth).remove(0);
        let broken: [fn(&mut TrackSeries); 5] = [
            |r| {
                r.velocity_mps.pop();
            },
            |r| {
                r.position_error_m.pop();
            },
            |r| r.position_error_m.clear(),
            |r| {
                r.velocity_error_mps.pop();
            },
            |r| r.metrics.as_mut().unwrap().count += 1,
        ];
        for (k, breaking) in broken.iter().enumerate() {
            let mut run = good.clone();
            breaking(&mut run);
            assert!(
                matches!(
                    write_figures(dir.path(), "s", &truth, &[run]),
                    Err(PlotError::Invalid { .. })
                ),
                "case {k}"
            );
        }
        // Velocity errors may be absent (no twists), and so may the metrics.
        let mut without = good.clone();
        without.velocity_error_mps.clear();
        without.metrics = None;
        assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
        write_figures(&dir.path().join("ok"), "s", &truth, &[without]).unwrap();
    }
}
