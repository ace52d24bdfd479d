//! The figures of one tracking run, from its files (`roitrack plot`): what the estimator said over time, and, with a
//! truth, how wrong it was against what it claimed.
//!
//! * `motion`: position (mm), orientation as a rotation vector (deg), linear velocity (mm/s) and angular velocity
//!   (deg/s) of the target, camera frame, x y z against time; the truth dashed where given.
//! * `errors` (with a truth): the same four, as estimate minus truth, each axis with its ±3 sigma band from the
//!   estimator's covariance where it has one (sigmas from the covariance file, or position and velocity sigmas from
//!   the diagnostics file). The rotation error is the rotation vector `Log(R_est R_trueᵀ)`, camera frame, whose
//!   covariance is the covariance's rotation block.
//! * `status` (with diagnostics): the estimator's status over time, and its residual (px, log axis).
//!
//! Each is written as PNG and SVG by the same drawing code, with the embedded font. The errors are roitrack-eval's
//! ([`EstimateErrors`]); nothing is computed here but axis ranges.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use roitrack_core::{PoseSample, TwistSample, so3};
use roitrack_estimators::TrackStatus;
use roitrack_eval::EstimateErrors;

use crate::{FONT, PlotError, register_font};

/// Everything `roitrack plot` draws, read from a run's files.
#[derive(Debug, Clone, Default)]
pub struct RunFigureInputs {
    /// Title shown on every figure (e.g. the poses file's name).
    pub title: String,
    /// The estimates' poses.
    pub poses: Vec<PoseSample>,
    /// The estimates' twists, if written (at the poses' times).
    pub twists: Option<Vec<TwistSample>>,
    /// The true poses, sampled densely.
    pub truth_poses: Option<Vec<PoseSample>>,
    /// The true twists, sampled densely.
    pub truth_twists: Option<Vec<TwistSample>>,
    /// The errors of the estimates against the truth (roitrack-eval).
    pub errors: Option<EstimateErrors>,
    /// Per estimate (same times as `poses`): the 1-sigma of the 12 error-state components (position m, rotation rad,
    /// velocity m/s, angular velocity rad/s; `NaN` where unknown).
    pub sigmas: Option<Vec<[f64; 12]>>,
    /// Per estimate: status and residual (px), from the diagnostics file.
    pub status: Option<Vec<(f64, TrackStatus, f64)>>,
}

const AXIS_COLORS: [RGBColor; 3] = [
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(31, 119, 180),
];
const SIZE: (u32, u32) = (1400, 1100);

/// One panel: three coloured curves against time, their dashed truth, and optional ±bands.
struct Panel {
    title: String,
    unit: &'static str,
    t: Vec<f64>,
    values: [Vec<f64>; 3],
    truth_t: Vec<f64>,
    truth: Option<[Vec<f64>; 3]>,
    /// Half-width of the band around zero, per axis and time (the error panels' 3 sigma).
    band: Option<[Vec<f64>; 3]>,
}

fn columns<T>(items: &[T], f: impl Fn(&T) -> [f64; 3]) -> [Vec<f64>; 3] {
    let rows: Vec<[f64; 3]> = items.iter().map(f).collect();
    std::array::from_fn(|c| rows.iter().map(|r| r[c]).collect())
}

fn rotation_vector_deg(p: &PoseSample) -> [f64; 3] {
    (so3::log_quaternion(&p.cam_from_obj.rotation) * 180.0 / std::f64::consts::PI).into()
}

/// Writes the run's figures (`motion`, and with their inputs `errors` and `status`; each `.png` and `.svg`) into
/// `dir` (created if needed) and returns their paths.
///
/// ```
/// use roitrack_estimators::{TrackerConfig, track_all};
/// use roitrack_eval::{EvalOptions, estimate_errors_of, samples_of};
/// use roitrack_plot::run::{RunFigureInputs, write_run_figures};
/// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
///
/// let run = simulate(&Scenario::new(ScenarioKind::Spin, 1), &SimulationOptions::default()).unwrap();
/// let (estimates, _) = track_all(&run.camera, &run.target, TrackerConfig::default(), &run.measurements).unwrap();
/// let errors = estimate_errors_of(&run.truth_poses, &run.truth_twists, &estimates, &EvalOptions::default()).unwrap();
/// let (poses, twists) = samples_of(&estimates);
/// let inputs = RunFigureInputs {
///     title: "spin".into(),
///     poses,
///     twists: Some(twists),
///     truth_poses: Some(run.truth_poses.clone()),
///     truth_twists: Some(run.truth_twists.clone()),
///     errors: Some(errors),
///     sigmas: Some(estimates.iter().map(|e| e.standard_deviations()).collect()),
///     status: Some(estimates.iter().map(|e| (e.t_ref_s, e.status, e.residual_rms_px)).collect()),
/// };
/// let dir = tempfile::tempdir().unwrap();
/// let paths = write_run_figures(dir.path(), &inputs).unwrap();
/// assert_eq!(paths.len(), 6);
/// ```
pub fn write_run_figures(dir: &Path, inputs: &RunFigureInputs) -> Result<Vec<PathBuf>, PlotError> {
    let files = render_run_figures(inputs)?;
    crate::write_rendered(dir, &files)
}

/// [`write_run_figures`] in memory: the files (`motion.png`, `motion.svg`, ...), for a caller that writes them its
/// own way; the same checks and errors.
pub fn render_run_figures(inputs: &RunFigureInputs) -> Result<Vec<crate::RenderedFile>, PlotError> {
    register_font();
    let n = inputs.poses.len();
    if n == 0 {
        return Err(PlotError::Empty {
            title: format!("{}: no estimate", inputs.title),
        });
    }
    let invalid = |what: &str, len: usize| PlotError::Invalid {
        what: what.to_string(),
        message: format!("{len} rows for {n} poses"),
    };
    if let Some(twists) = &inputs.twists
        && twists.len() != n
    {
        return Err(invalid("twists", twists.len()));
    }
    if let Some(sigmas) = &inputs.sigmas
        && sigmas.len() != n
    {
        return Err(invalid("sigmas", sigmas.len()));
    }
    if let Some(status) = &inputs.status
        && status.len() != n
    {
        return Err(invalid("diagnostics", status.len()));
    }
    let mut figures: Vec<(&str, Figure)> = vec![("motion", motion_panels(inputs))];
    if let Some(errors) = &inputs.errors {
        figures.push(("errors", error_panels(inputs, errors)));
    }
    if let Some(status) = &inputs.status {
        figures.push(("status", Figure::Status(status.clone())));
    }
    let mut files = Vec::new();
    for (stem, figure) in &figures {
        let title = format!("{}: {stem}", inputs.title);
        files.push(crate::render_png(&format!("{stem}.png"), SIZE, |area| {
            draw(area, &title, figure)
        })?);
        files.push(crate::render_svg(&format!("{stem}.svg"), SIZE, |area| {
            draw(area, &title, figure)
        })?);
    }
    Ok(files)
}

enum Figure {
    Panels(Vec<Panel>),
    Status(Vec<(f64, TrackStatus, f64)>),
}

fn motion_panels(inputs: &RunFigureInputs) -> Figure {
    let t: Vec<f64> = inputs.poses.iter().map(|p| p.t_s).collect();
    let truth_t: Vec<f64> = inputs
        .truth_poses
        .as_ref()
        .map_or_else(Vec::new, |p| p.iter().map(|p| p.t_s).collect());
    let truth_twist_t: Vec<f64> = inputs
        .truth_twists
        .as_ref()
        .map_or_else(Vec::new, |p| p.iter().map(|p| p.t_s).collect());
    let mm = |p: &PoseSample| (p.cam_from_obj.translation.vector * 1e3).into();
    let mut panels = vec![
        Panel {
            title: "position of the target's origin".into(),
            unit: "mm",
            t: t.clone(),
            values: columns(&inputs.poses, mm),
            truth_t: truth_t.clone(),
            truth: inputs.truth_poses.as_ref().map(|p| columns(p, mm)),
            band: None,
        },
        Panel {
            title: "orientation (rotation vector, camera frame)".into(),
            unit: "deg",
            t: t.clone(),
            values: columns(&inputs.poses, rotation_vector_deg),
            truth_t,
            truth: inputs
                .truth_poses
                .as_ref()
                .map(|p| columns(p, rotation_vector_deg)),
            band: None,
        },
    ];
    if let Some(twists) = &inputs.twists {
        let v = |w: &TwistSample| (w.velocity_mps * 1e3).into();
        let w = |w: &TwistSample| (w.angular_velocity_radps.map(f64::to_degrees)).into();
        panels.push(Panel {
            title: "linear velocity of the target's origin".into(),
            unit: "mm/s",
            t: t.clone(),
            values: columns(twists, v),
            truth_t: truth_twist_t.clone(),
            truth: inputs.truth_twists.as_ref().map(|p| columns(p, v)),
            band: None,
        });
        panels.push(Panel {
            title: "angular velocity".into(),
            unit: "deg/s",
            t,
            values: columns(twists, w),
            truth_t: truth_twist_t,
            truth: inputs.truth_twists.as_ref().map(|p| columns(p, w)),
            band: None,
        });
    }
    Figure::Panels(panels)
}

fn error_panels(inputs: &RunFigureInputs, errors: &EstimateErrors) -> Figure {
    // The errors are those of the estimates inside the truth (and, with an offset, on its clock): their sigmas are
    // found by time.
    let sigma_at = |block: usize, scale: f64| -> Option<[Vec<f64>; 3]> {
        let sigmas = inputs.sigmas.as_ref()?;
        let times: Vec<f64> = inputs.poses.iter().map(|p| p.t_s).collect();
        let mut out: [Vec<f64>; 3] = Default::default();
        for &t in &errors.t_s {
            let t_est = t - errors.time_offset_s;
            let k = times
                .partition_point(|&s| s < t_est - 1e-9)
                .min(times.len() - 1);
            for (c, column) in out.iter_mut().enumerate() {
                column.push(3.0 * sigmas[k][block + c] * scale);
            }
        }
        out.iter()
            .any(|c| c.iter().any(|v| v.is_finite()))
            .then_some(out)
    };
    let deg = 180.0 / std::f64::consts::PI;
    let vectors = |v: &[nalgebra::Vector3<f64>], scale: f64| columns(v, |e| (e * scale).into());
    let mut panels = vec![
        Panel {
            title: "position error (estimate - truth), ±3 sigma".into(),
            unit: "mm",
            t: errors.t_s.clone(),
            values: vectors(&errors.position_m, 1e3),
            truth_t: Vec::new(),
            truth: None,
            band: sigma_at(0, 1e3),
        },
        Panel {
            title: "rotation error Log(R_est R_true^T), ±3 sigma".into(),
            unit: "deg",
            t: errors.t_s.clone(),
            values: vectors(&errors.rotation_vector_rad, deg),
            truth_t: Vec::new(),
            truth: None,
            band: sigma_at(3, deg),
        },
    ];
    if let Some(v) = &errors.velocity_mps {
        panels.push(Panel {
            title: "linear velocity error, ±3 sigma".into(),
            unit: "mm/s",
            t: errors.t_s.clone(),
            values: vectors(v, 1e3),
            truth_t: Vec::new(),
            truth: None,
            band: sigma_at(6, 1e3),
        });
    }
    if let Some(w) = &errors.angular_velocity_radps {
        panels.push(Panel {
            title: "angular velocity error, ±3 sigma".into(),
            unit: "deg/s",
            t: errors.t_s.clone(),
            values: vectors(w, deg),
            truth_t: Vec::new(),
            truth: None,
            band: sigma_at(9, deg),
        });
    }
    Figure::Panels(panels)
}

type Res = Result<(), String>;

fn de<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, title: &str, figure: &Figure) -> Res
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(de)?;
    let root = root.titled(title, (FONT, 26)).map_err(de)?;
    match figure {
        Figure::Panels(panels) => {
            let areas = root.split_evenly((panels.len(), 1));
            for (panel, area) in panels.iter().zip(&areas) {
                draw_panel(area, panel)?;
            }
        }
        Figure::Status(rows) => {
            let areas = root.split_evenly((2, 1));
            draw_status(&areas[0], rows)?;
            draw_residual(&areas[1], rows)?;
        }
    }
    root.present().map_err(de)
}

/// A range over the finite values (and bands), padded by 5 %, never empty.
fn range_of<'a>(values: impl IntoIterator<Item = &'a f64>) -> (f64, f64) {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return (-1.0, 1.0);
    }
    let span = (hi - lo).max(1e-9 * hi.abs().max(1.0)).max(1e-9);
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// Points of `(t, v)` with both finite, in order.
fn finite_points(t: &[f64], v: &[f64]) -> Vec<(f64, f64)> {
    t.iter()
        .zip(v)
        .filter(|(t, v)| t.is_finite() && v.is_finite())
        .map(|(&t, &v)| (t, v))
        .collect()
}

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, panel: &Panel) -> Res
where
    DB::ErrorType: 'static,
{
    // The truth is drawn over the estimates' span only.
    let x_range = range_of(panel.t.iter());
    let y_range = panel_y_range(panel, x_range);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 17))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(78)
        .build_cartesian_2d(x_range.0..x_range.1, y_range.0..y_range.1)
        .map_err(de)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(panel.unit)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(de)?;
    draw_bands(&mut chart, panel)?;
    draw_truth(&mut chart, panel, x_range)?;
    for (c, column) in panel.values.iter().enumerate() {
        let color = AXIS_COLORS[c];
        chart
            .draw_series(LineSeries::new(
                finite_points(&panel.t, column),
                color.stroke_width(1),
            ))
            .map_err(de)?
            .label(["x", "y", "z"][c])
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .label_font((FONT, 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(de)
}

/// The chart of one panel: time (s) across, the panel's values up.
type PanelChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The vertical range of a panel: its values, its truth within the estimates' span `x_range`, and its bands on both
/// sides of zero.
fn panel_y_range(panel: &Panel, x_range: (f64, f64)) -> (f64, f64) {
    let in_span = |t: &f64| *t >= x_range.0 && *t <= x_range.1;
    let mut y_values: Vec<f64> = panel.values.iter().flatten().copied().collect();
    if let Some(truth) = &panel.truth {
        for column in truth {
            y_values.extend(
                panel
                    .truth_t
                    .iter()
                    .zip(column)
                    .filter(|(t, _)| in_span(t))
                    .map(|(_, v)| *v),
            );
        }
    }
    if let Some(band) = &panel.band {
        for column in band {
            y_values.extend(column.iter().flat_map(|b| [*b, -*b]));
        }
    }
    range_of(y_values.iter())
}

/// The ±bands of a panel around zero, filled in its axes' colours.
fn draw_bands<DB: DrawingBackend>(chart: &mut PanelChart<DB>, panel: &Panel) -> Res
where
    DB::ErrorType: 'static,
{
    if let Some(band) = &panel.band {
        for (c, column) in band.iter().enumerate() {
            let upper = finite_points(&panel.t, column);
            if upper.is_empty() {
                continue;
            }
            let mut outline = upper.clone();
            outline.extend(upper.iter().rev().map(|&(t, b)| (t, -b)));
            chart
                .draw_series(std::iter::once(Polygon::new(
                    outline,
                    AXIS_COLORS[c].mix(0.12).filled(),
                )))
                .map_err(de)?;
        }
    }
    Ok(())
}

/// The panel's truth, dashed, within the estimates' span `x_range`, with one legend entry.
fn draw_truth<DB: DrawingBackend>(
    chart: &mut PanelChart<DB>,
    panel: &Panel,
    x_range: (f64, f64),
) -> Res
where
    DB::ErrorType: 'static,
{
    let in_span = |t: &f64| *t >= x_range.0 && *t <= x_range.1;
    if let Some(truth) = &panel.truth {
        for (c, column) in truth.iter().enumerate() {
            let points: Vec<(f64, f64)> = finite_points(&panel.truth_t, column)
                .into_iter()
                .filter(|(t, _)| in_span(t))
                .collect();
            chart
                .draw_series(DashedLineSeries::new(
                    points,
                    6,
                    4,
                    RGBColor(60, 60, 60).stroke_width(1),
                ))
                .map_err(de)?;
            // One legend entry for the truth.
            if c == 0 {
                chart
                    .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                    .map_err(de)?
                    .label("truth")
                    .legend(|(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], RGBColor(60, 60, 60))
                    });
            }
        }
    }
    Ok(())
}

fn draw_status<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    rows: &[(f64, TrackStatus, f64)],
) -> Res
where
    DB::ErrorType: 'static,
{
    let times: Vec<f64> = rows.iter().map(|r| r.0).collect();
    let x_range = range_of(times.iter());
    let level = |s: TrackStatus| TrackStatus::ALL.iter().position(|&a| a == s).unwrap_or(0) as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(
            "estimator status (only converging and tracking are vouched for)",
            (FONT, 17),
        )
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(110)
        .build_cartesian_2d(
            x_range.0..x_range.1,
            -0.5f64..(TrackStatus::ALL.len() as f64 - 0.5),
        )
        .map_err(de)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_labels(TrackStatus::ALL.len())
        .y_label_formatter(&|y: &f64| {
            let k = y.round();
            if (y - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < TrackStatus::ALL.len() {
                TrackStatus::ALL[k as usize].name().to_string()
            } else {
                String::new()
            }
        })
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(de)?;
    chart
        .draw_series(rows.iter().map(|&(t, s, _)| {
            let color = if s.is_vouched_for() {
                RGBColor(44, 160, 44)
            } else {
                RGBColor(214, 39, 40)
            };
            Circle::new((t, level(s)), 2, color.filled())
        }))
        .map_err(de)?;
    Ok(())
}

fn draw_residual<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    rows: &[(f64, TrackStatus, f64)],
) -> Res
where
    DB::ErrorType: 'static,
{
    let times: Vec<f64> = rows.iter().map(|r| r.0).collect();
    let x_range = range_of(times.iter());
    let positive: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.2.is_finite() && r.2 > 0.0)
        .map(|r| (r.0, r.2))
        .collect();
    let (lo, hi) = positive
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.1), hi.max(p.1))
        });
    // Whole decades around the data, so that the log axis's ticks are labelled powers of ten.
    let (lo, hi) = if lo <= hi {
        (
            10f64.powf(lo.log10().floor()),
            10f64.powf(hi.log10().ceil().max(lo.log10().floor() + 1.0)),
        )
    } else {
        (0.01, 10.0)
    };
    let mut chart = ChartBuilder::on(area)
        .caption("residual (RMS, px; log scale)", (FONT, 17))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(110)
        .build_cartesian_2d(x_range.0..x_range.1, (lo..hi).log_scale())
        .map_err(de)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("px")
        .y_label_formatter(&|y: &f64| format_log_tick(*y))
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(de)?;
    chart
        .draw_series(
            positive
                .iter()
                .map(|&p| Circle::new(p, 1, RGBColor(31, 119, 180).filled())),
        )
        .map_err(de)?;
    Ok(())
}

/// A log axis's tick: plain decimals from 0.001 to 10,000 (`0.05`, `2`, `300`), powers of ten beyond.
pub fn format_log_tick(value: f64) -> String {
    if !(value.is_finite() && value > 0.0) {
        return String::new();
    }
    let exponent = value.log10().floor();
    if (-3.0..=4.0).contains(&exponent) {
        let decimals = (-exponent).max(0.0) as usize;
        let text = format!("{value:.decimals$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        }
    } else {
        let mantissa = value / 10f64.powf(exponent);
        if (mantissa - 1.0).abs() < 1e-9 {
            format!("1e{exponent}")
        } else {
            format!("{mantissa:.1}e{exponent}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::format_log_tick;

    #[test]
    fn log_ticks_read_as_numbers() {
        assert_eq!(format_log_tick(0.01), "0.01");
        assert_eq!(format_log_tick(0.05), "0.05");
        assert_eq!(format_log_tick(1.0), "1");
        assert_eq!(format_log_tick(300.0), "300");
        assert_eq!(format_log_tick(1e6), "1e6");
        assert_eq!(format_log_tick(2e-5), "2.0e-5");
        assert_eq!(format_log_tick(0.0), "");
    }
}
