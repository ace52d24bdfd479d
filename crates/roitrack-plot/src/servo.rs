//! The figures of a closed-loop run (roitrack-servo): the reference and achieved paths, the tracking error over time,
//! the actuator forces, and the largest stable gain against latency. This module draws plain series; the servo crate
//! turns its reports into them.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::{
    Chart, FONT, PALETTE, PlotError, RenderedFile, Series, Style, padded, register_font,
    render_chart, render_png, render_svg,
};

/// The most points drawn per series: a 5 s run at 4 kHz has 20 000 samples, more than a 1000 px wide panel shows,
/// and SVG files grow with every point.
const MAX_POINTS: usize = 2500;

/// One closed-loop run to draw: its samples over time, in the robot frame (metres, newtons).
///
/// ```
/// use roitrack_plot::servo::ServoRunSeries;
/// let run = ServoRunSeries {
///     label: "ctc / roi".into(),
///     t_s: vec![0.0, 0.1],
///     reference_m: vec![[0.0; 3], [0.01, 0.0, 0.0]],
///     achieved_m: vec![[0.0; 3], [0.0099, 0.0, 0.0]],
///     force_n: vec![[0.0; 3], [1.0, 2.0, 3.0]],
/// };
/// let error_mm = run.error_mm();
/// assert_eq!(error_mm[0], 0.0);
/// assert!((error_mm[1] - 0.1).abs() < 1e-12); // 0.01 m - 0.0099 m
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ServoRunSeries {
    /// Legend text (`ctc / roi`).
    pub label: String,
    /// The samples' times (s).
    pub t_s: Vec<f64>,
    /// The path's position at each sample (m).
    pub reference_m: Vec<[f64; 3]>,
    /// The platform's true position at each sample (m).
    pub achieved_m: Vec<[f64; 3]>,
    /// The three actuators' forces acting at each sample (N).
    pub force_n: Vec<[f64; 3]>,
}

impl ServoRunSeries {
    /// The distance between the platform and the path at each sample (mm).
    pub fn error_mm(&self) -> Vec<f64> {
        self.reference_m
            .iter()
            .zip(&self.achieved_m)
            .map(|(r, a)| {
                ((r[0] - a[0]).powi(2) + (r[1] - a[1]).powi(2) + (r[2] - a[2]).powi(2)).sqrt() * 1e3
            })
            .collect()
    }

    fn check(&self) -> Result<(), PlotError> {
        let n = self.t_s.len();
        if self.reference_m.len() != n || self.achieved_m.len() != n || self.force_n.len() != n {
            return Err(PlotError::Invalid {
                what: format!("servo run {}", self.label),
                message: format!(
                    "{n} times but {} reference, {} achieved and {} force samples",
                    self.reference_m.len(),
                    self.achieved_m.len(),
                    self.force_n.len()
                ),
            });
        }
        Ok(())
    }

    /// The indices drawn: the samples split into at most [`MAX_POINTS`] / 2 consecutive bins, and of each bin the
    /// smallest and largest of `value`, in time order. Noise and spikes keep their envelope (a stride would alias
    /// them away or into gaps), and a smooth curve is unchanged.
    fn drawn(&self, value: impl Fn(usize) -> f64) -> Vec<usize> {
        let n = self.t_s.len();
        let bin = n.div_ceil(MAX_POINTS / 2).max(1);
        let mut out = Vec::with_capacity(2 * n.div_ceil(bin));
        for start in (0..n).step_by(bin) {
            let range = start..(start + bin).min(n);
            let by_value = |a: &usize, b: &usize| value(*a).total_cmp(&value(*b));
            let (lo, hi) = (
                range.clone().min_by(by_value).unwrap_or(start),
                range.max_by(by_value).unwrap_or(start),
            );
            out.push(lo.min(hi));
            if hi != lo {
                out.push(lo.max(hi));
            }
        }
        out
    }

    /// (t, value) of the drawn samples of `value`, scaled by `scale`.
    fn envelope(&self, value: impl Fn(usize) -> f64, scale: f64) -> Vec<(f64, f64)> {
        self.drawn(&value)
            .into_iter()
            .map(|i| (self.t_s[i], value(i) * scale))
            .collect()
    }
}

/// The largest stable gain of one control scheme against the latency added to its feedback.
#[derive(Debug, Clone, PartialEq)]
pub struct StableGainCurve {
    /// Legend text (`ctc / roi`).
    pub label: String,
    /// (extra latency in ms, the largest natural frequency in rad/s at which the run stayed stable).
    pub points: Vec<(f64, f64)>,
}

/// Renders the figures of closed-loop runs, in memory: `servo_path` (the path in the image plane and the depth over
/// time, reference and achieved), `servo_error` (distance from the path over time) and `servo_forces` (the three
/// actuator forces of each run), each as PNG and SVG.
///
/// ```
/// use roitrack_plot::servo::{ServoRunSeries, render_servo_figures};
/// let t_s: Vec<f64> = (0..200).map(|k| k as f64 * 1e-2).collect();
/// let reference_m: Vec<[f64; 3]> = t_s.iter().map(|t| [0.05 * t.cos(), 0.05 * t.sin(), 0.0]).collect();
/// let achieved_m = reference_m.iter().map(|p| [p[0] + 1e-4, p[1], p[2]]).collect();
/// let force_n = t_s.iter().map(|t| [t.sin(), t.cos(), 1.0]).collect();
/// let run = ServoRunSeries { label: "ctc / roi".into(), t_s, reference_m, achieved_m, force_n };
/// let files = render_servo_figures(&[run]).unwrap();
/// assert_eq!(files.len(), 6);
/// assert!(files.iter().any(|f| f.name == "servo_forces.svg"));
/// ```
pub fn render_servo_figures(runs: &[ServoRunSeries]) -> Result<Vec<RenderedFile>, PlotError> {
    register_font();
    for run in runs {
        run.check()?;
    }
    let Some(first) = runs.first() else {
        return Err(PlotError::Empty {
            title: "servo figures".into(),
        });
    };
    // The path: the image plane (x right, y down: drawn as in the image) and the depth over time.
    let plane = |run: &ServoRunSeries, of: &dyn Fn(&ServoRunSeries, usize) -> [f64; 3]| {
        // The plane is drawn point by point along the path: every sample, at most MAX_POINTS of them.
        let stride = run.t_s.len().div_ceil(MAX_POINTS).max(1);
        (0..run.t_s.len())
            .step_by(stride)
            .map(|i| {
                let p = of(run, i);
                (p[0] * 1e3, -p[1] * 1e3)
            })
            .collect::<Vec<_>>()
    };
    let mut plane_series = vec![Series::new(
        "reference",
        plane(first, &|r, i| r.reference_m[i]),
        Style::Line,
    )];
    let mut depth_series = vec![Series::new(
        "reference",
        first.envelope(|i| first.reference_m[i][2], 1e3),
        Style::Line,
    )];
    for run in runs {
        plane_series.push(Series::new(
            run.label.clone(),
            plane(run, &|r, i| r.achieved_m[i]),
            Style::Line,
        ));
        depth_series.push(Series::new(
            run.label.clone(),
            run.envelope(|i| run.achieved_m[i][2], 1e3),
            Style::Line,
        ));
    }
    let path = [
        Chart {
            title: "Path in the image plane".into(),
            x_label: "x (mm, robot frame)".into(),
            y_label: "-y (mm, up)".into(),
            series: plane_series,
            log_y: false,
        },
        Chart {
            title: "Depth (optical axis)".into(),
            x_label: "t (s)".into(),
            y_label: "z (mm)".into(),
            series: depth_series,
            log_y: false,
        },
    ];
    let error = Chart {
        title: "Distance from the path".into(),
        x_label: "t (s)".into(),
        y_label: "error (mm)".into(),
        series: runs
            .iter()
            .map(|run| {
                let e = run.error_mm();
                Series::new(run.label.clone(), run.envelope(|i| e[i], 1.0), Style::Line)
            })
            .collect(),
        log_y: false,
    };
    let forces: Vec<Chart> = runs
        .iter()
        .map(|run| Chart {
            title: format!("Actuator forces, {}", run.label),
            x_label: "t (s)".into(),
            y_label: "force (N)".into(),
            series: (0..3)
                .map(|k| {
                    Series::new(
                        format!("actuator {}", k + 1),
                        run.envelope(|i| run.force_n[i][k], 1.0),
                        Style::Line,
                    )
                })
                .collect(),
            log_y: false,
        })
        .collect();
    let mut files = render_panels("servo_path", (1600, 700), (1, 2), &path)?.to_vec();
    files.extend(render_panels("servo_error", (1000, 700), (1, 1), &[error])?);
    let rows = forces.len().div_ceil(2);
    let cols = forces.len().min(2);
    files.extend(render_panels(
        "servo_forces",
        (800 * cols as u32, 450 * rows as u32),
        (rows, cols),
        &forces,
    )?);
    Ok(files)
}

/// Renders `servo_stable_gain.png` and `.svg`: for each scheme, the largest natural frequency (or λ) at which the
/// loop stayed stable against the latency added to its feedback (log scale).
///
/// ```
/// use roitrack_plot::servo::{StableGainCurve, render_stable_gain};
/// let curve = StableGainCurve { label: "ctc / roi".into(), points: vec![(0.0, 600.0), (1.0, 300.0)] };
/// let [png, svg] = render_stable_gain(&[curve]).unwrap();
/// assert_eq!((png.name.as_str(), svg.name.as_str()), ("servo_stable_gain.png", "servo_stable_gain.svg"));
/// ```
pub fn render_stable_gain(curves: &[StableGainCurve]) -> Result<[RenderedFile; 2], PlotError> {
    let chart = Chart {
        title: "Largest stable gain against latency".into(),
        x_label: "extra latency (ms)".into(),
        y_label: "largest stable natural frequency (rad/s)".into(),
        series: curves
            .iter()
            .map(|c| {
                Series::new(
                    c.label.clone(),
                    c.points.iter().copied().filter(|(_, w)| *w > 0.0).collect(),
                    Style::LinePoints,
                )
            })
            .collect(),
        log_y: true,
    };
    render_chart("servo_stable_gain", &chart)
}

/// Renders `charts` on a grid of `(rows, cols)` panels as `STEM.png` and `STEM.svg` of `size`.
fn render_panels(
    stem: &str,
    size: (u32, u32),
    grid: (usize, usize),
    charts: &[Chart],
) -> Result<[RenderedFile; 2], PlotError> {
    register_font();
    if charts.iter().all(|c| {
        !c.series
            .iter()
            .flat_map(|s| &s.points)
            .any(|(x, y)| x.is_finite() && y.is_finite())
    }) {
        return Err(PlotError::Empty {
            title: stem.to_string(),
        });
    }
    fn draw_all<DB: DrawingBackend>(
        area: DrawingArea<DB, Shift>,
        grid: (usize, usize),
        charts: &[Chart],
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        area.fill(&WHITE).map_err(|e| e.to_string())?;
        for (panel, chart) in area.split_evenly(grid).into_iter().zip(charts) {
            draw_panel(&panel, chart)?;
        }
        area.present().map_err(|e| e.to_string())
    }
    Ok([
        render_png(&format!("{stem}.png"), size, |area| {
            draw_all(area, grid, charts)
        })?,
        render_svg(&format!("{stem}.svg"), size, |area| {
            draw_all(area, grid, charts)
        })?,
    ])
}

/// Draws one linear-axis chart of lines into `area` without presenting it (the figure is presented once, whole).
fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    chart: &Chart,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let finite = || {
        chart
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    if finite().next().is_none() {
        return Ok(());
    }
    let (x_lo, x_hi, y_lo, y_hi) = finite().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), &(x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    let ((x0, x1), (y0, y1)) = (padded(x_lo, x_hi), padded(y_lo, y_hi));
    let mut ctx = ChartBuilder::on(area)
        .caption(&chart.title, (FONT, 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    ctx.configure_mesh()
        .x_desc(&chart.x_label)
        .y_desc(&chart.y_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| e.to_string())?;
    for (i, s) in chart.series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let points: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        // One pixel wide: the series are dense (thousands of points a panel), and wide strokes of steep segments
        // smear.
        ctx.draw_series(LineSeries::new(points, color.stroke_width(1)))
            .map_err(|e| e.to_string())?
            .label(&s.name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    ctx.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .label_font((FONT, 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(label: &str, n: usize) -> ServoRunSeries {
        let t_s: Vec<f64> = (0..n).map(|k| k as f64 * 2.5e-4).collect();
        let reference_m: Vec<[f64; 3]> = t_s
            .iter()
            .map(|t| [0.05 * (3.0 * t).cos(), 0.05 * (3.0 * t).sin(), 0.0])
            .collect();
        ServoRunSeries {
            label: label.into(),
            achieved_m: reference_m.iter().map(|p| [p[0], p[1], 1e-4]).collect(),
            force_n: t_s.iter().map(|t| [t.sin(), 2.0, -1.0]).collect(),
            t_s,
            reference_m,
        }
    }

    #[test]
    fn draws_every_figure_of_several_runs_with_few_points() {
        let runs = [run("a", 20_001), run("b", 20_001), run("c", 100)];
        let files = render_servo_figures(&runs).unwrap();
        let names: Vec<&str> = files.iter().map(|f| f.name.as_str()).collect();
        for stem in ["servo_path", "servo_error", "servo_forces"] {
            for ext in ["png", "svg"] {
                assert!(
                    names.contains(&format!("{stem}.{ext}").as_str()),
                    "{names:?}"
                );
            }
        }
        for file in files.iter().filter(|f| f.name.ends_with(".svg")) {
            let text = std::str::from_utf8(&file.bytes).unwrap();
            // One closing tag: the figure was presented once, after every panel.
            assert_eq!(text.matches("</svg>").count(), 1, "{}", file.name);
        }
        // The envelope keeps every bin's extremes, in time order.
        let value = |i: usize| runs[0].force_n[i][0];
        let drawn = runs[0].drawn(value);
        assert!(drawn.len() <= MAX_POINTS + 2, "{}", drawn.len());
        assert!(drawn.windows(2).all(|w| w[0] < w[1]));
        let all_max = (0..20_001).map(value).fold(f64::MIN, f64::max);
        let drawn_max = drawn.iter().map(|&i| value(i)).fold(f64::MIN, f64::max);
        assert_eq!(all_max, drawn_max);
    }

    #[test]
    fn refuses_inconsistent_and_empty_input() {
        let mut bad = run("bad", 10);
        bad.force_n.pop();
        assert!(matches!(
            render_servo_figures(&[bad]),
            Err(PlotError::Invalid { .. })
        ));
        assert!(matches!(
            render_servo_figures(&[]),
            Err(PlotError::Empty { .. })
        ));
        assert!(matches!(
            render_stable_gain(&[StableGainCurve {
                label: "none".into(),
                points: vec![(0.0, f64::NAN)]
            }]),
            Err(PlotError::Empty { .. })
        ));
    }
}
