//! # roitrack-plot
//!
//! Line and scatter charts written as PNG and SVG with the same look everywhere: the font is embedded, nothing is
//! read from the system, and the SVG files carry their text as outlines of that font (no font needed to view them).
//!
//! [`figures`] draws the multi-panel figures of a tracking run (trajectory, position and velocity against the
//! truth), after figures 5 to 7 of the paper.
#![deny(missing_docs)]

pub mod figures;
pub mod run;
pub mod servo;
mod svg_text;

pub use figures::{TrackSeries, TruthSeries, render_figures, write_figures};

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use thiserror::Error;

const FONT: &str = "roitrack-sans";
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

/// A figure file rendered in memory: its file name (`fig5_trajectory.png`) and its content, for a caller that writes
/// files its own way (the command line writes them with the run's other outputs, all or none).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RenderedFile {
    /// The file name, without a folder.
    pub name: String,
    /// The file's content (PNG or SVG).
    pub bytes: Vec<u8>,
}

/// Draws with `draw` on an RGB canvas of `size` and encodes it as PNG, named `name` in errors.
fn render_png(
    name: &str,
    size: (u32, u32),
    draw: impl FnOnce(DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<RenderedFile, PlotError> {
    use image::ImageEncoder;
    let failed = |message: String| PlotError::Draw {
        path: PathBuf::from(name),
        message,
    };
    let mut pixels = vec![0u8; size.0 as usize * size.1 as usize * 3];
    draw(BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area()).map_err(failed)?;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(&pixels, size.0, size.1, image::ColorType::Rgb8)
        .map_err(|e| failed(e.to_string()))?;
    Ok(RenderedFile {
        name: name.to_string(),
        bytes,
    })
}

/// Draws with `draw` as SVG of `size`, its text as the embedded font's outlines (see the `svg_text` module).
fn render_svg(
    name: &str,
    size: (u32, u32),
    draw: impl FnOnce(DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<RenderedFile, PlotError> {
    let failed = |message: String| PlotError::Draw {
        path: PathBuf::from(name),
        message,
    };
    let mut svg = String::new();
    draw(SVGBackend::with_string(&mut svg, size).into_drawing_area()).map_err(failed)?;
    let outlined = svg_text::outline_text(&svg, FONT_BYTES).map_err(failed)?;
    Ok(RenderedFile {
        name: name.to_string(),
        bytes: outlined.into_bytes(),
    })
}

/// Writes rendered files into `dir` (created if needed) and returns their paths.
fn write_rendered(dir: &Path, files: &[RenderedFile]) -> Result<Vec<PathBuf>, PlotError> {
    let failed = |path: &Path, e: std::io::Error| PlotError::Draw {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(dir).map_err(|e| failed(dir, e))?;
    files
        .iter()
        .map(|file| {
            let path = dir.join(&file.name);
            std::fs::write(&path, &file.bytes).map_err(|e| failed(&path, e))?;
            Ok(path)
        })
        .collect()
}

fn register_font() {
    REGISTER.call_once(|| {
        // The embedded font is a valid TrueType file: registration cannot fail at run time.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES);
    });
}

/// Why a chart or figure was not written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// Drawing or writing the file at `path` failed.
    #[error("cannot draw {path}: {message}")]
    Draw {
        /// The file.
        path: PathBuf,
        /// What the drawing back-end said.
        message: String,
    },
    /// There is no finite value to draw in the chart or figure `title`.
    #[error("nothing to plot in {title}: every series is empty or not finite")]
    Empty {
        /// The chart's or figure's title.
        title: String,
    },
    /// The input `what` is inconsistent (e.g. vectors of different lengths), as `message` says.
    #[error("invalid {what}: {message}")]
    Invalid {
        /// Which input.
        what: String,
        /// What is wrong with it.
        message: String,
    },
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Points joined by a line.
    Line,
    /// Points as dots.
    Points,
    /// Points as dots joined by a line.
    LinePoints,
}

/// One named series of (x, y) points, optionally labelled point by point.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// The (x, y) points, in drawing order; non-finite ones are skipped.
    pub points: Vec<(f64, f64)>,
    /// Text written next to each point (same length as `points`, or empty).
    pub point_labels: Vec<String>,
    /// How the points are drawn.
    pub style: Style,
}

impl Series {
    /// A series without point labels.
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Self {
        Self {
            name: name.into(),
            points,
            point_labels: Vec::new(),
            style,
        }
    }

    /// The series with `labels` written next to its points (one per point).
    pub fn with_labels(mut self, labels: Vec<String>) -> Self {
        self.point_labels = labels;
        self
    }
}

/// A chart: title, axis labels and series.
#[derive(Debug, Clone)]
pub struct Chart {
    /// Caption above the plot.
    pub title: String,
    /// Description of the x axis.
    pub x_label: String,
    /// Description of the y axis.
    pub y_label: String,
    /// The series, drawn in order with the colours of a fixed palette.
    pub series: Vec<Series>,
    /// A logarithmic y axis, for positive values.
    pub log_y: bool,
}

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(80, 80, 80),
];

fn finite_points(series: &[Series]) -> impl Iterator<Item = &(f64, f64)> {
    series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
}

fn padded(lo: f64, hi: f64) -> (f64, f64) {
    let span = (hi - lo).abs().max(1e-12 * hi.abs().max(1.0));
    (lo - 0.05 * span, hi + 0.05 * span)
}

fn draw<DB: DrawingBackend>(area: DrawingArea<DB, Shift>, chart: &Chart) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(|e| e.to_string())?;
    let (x_lo, x_hi, y_lo, y_hi) = finite_points(&chart.series).fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), &(x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    let (x0, x1) = padded(x_lo, x_hi);
    let mut builder = ChartBuilder::on(&area);
    builder
        .caption(&chart.title, (FONT, 22))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70);
    macro_rules! body {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            ctx.configure_mesh()
                .x_desc(&chart.x_label)
                .y_desc(&chart.y_label)
                .label_style((FONT, 14))
                .axis_desc_style((FONT, 16))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(|e| e.to_string())?;
            for (i, s) in chart.series.iter().enumerate() {
                let color = PALETTE[i % PALETTE.len()];
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|(x, y)| x.is_finite() && y.is_finite())
                    .collect();
                let legend_color = color;
                if matches!(s.style, Style::Line | Style::LinePoints) {
                    ctx.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                        .map_err(|e| e.to_string())?
                        .label(&s.name)
                        .legend(move |(x, y)| {
                            PathElement::new(
                                vec![(x, y), (x + 18, y)],
                                legend_color.stroke_width(2),
                            )
                        });
                }
                if matches!(s.style, Style::Points | Style::LinePoints) {
                    let drawn = ctx
                        .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                        .map_err(|e| e.to_string())?;
                    if s.style == Style::Points {
                        drawn.label(&s.name).legend(move |(x, y)| {
                            Circle::new((x + 9, y), 4, legend_color.filled())
                        });
                    }
                }
                for (p, label) in s.points.iter().zip(&s.point_labels) {
                    if p.0.is_finite() && p.1.is_finite() {
                        ctx.draw_series(std::iter::once(Text::new(
                            label.clone(),
                            *p,
                            (FONT, 12).into_font().color(&color),
                        )))
                        .map_err(|e| e.to_string())?;
                    }
                }
            }
            ctx.configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .label_font((FONT, 14))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(|e| e.to_string())?;
        }};
    }
    if chart.log_y {
        let (y0, y1) = (y_lo.max(1e-12) / 1.3, y_hi * 1.3);
        body!(
            builder
                .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
                .map_err(|e| e.to_string())?
        );
    } else {
        let (y0, y1) = padded(y_lo, y_hi);
        body!(
            builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| e.to_string())?
        );
    }
    area.present().map_err(|e| e.to_string())
}

/// Renders `chart` as `STEM.png` and `STEM.svg` (1000 x 700 px), in memory.
pub fn render_chart(stem: &str, chart: &Chart) -> Result<[RenderedFile; 2], PlotError> {
    register_font();
    if finite_points(&chart.series).next().is_none() {
        return Err(PlotError::Empty {
            title: chart.title.clone(),
        });
    }
    let size = (1000, 700);
    Ok([
        render_png(&format!("{stem}.png"), size, |area| draw(area, chart))?,
        render_svg(&format!("{stem}.svg"), size, |area| draw(area, chart))?,
    ])
}

/// Writes `stem.png` and `stem.svg` (1000 x 700 px).
pub fn write_chart(stem: &Path, chart: &Chart) -> Result<(PathBuf, PathBuf), PlotError> {
    let name = stem
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let dir = match stem.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let files = render_chart(&name, chart)?;
    let paths = write_rendered(dir, &files)?;
    Ok((paths[0].clone(), paths[1].clone()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_png_and_svg() {
        let dir = tempfile::tempdir().unwrap();
        let chart = Chart {
            title: "test".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![
                Series::new(
                    "a",
                    vec![(0.0, 1.0), (1.0, 2.0), (2.0, 1.5)],
                    Style::LinePoints,
                )
                .with_labels(vec!["p".into(), "q".into(), "r".into()]),
                Series::new("b", vec![(0.5, 3.0)], Style::Points),
            ],
            log_y: true,
        };
        let (png, svg) = write_chart(&dir.path().join("chart"), &chart).unwrap();
        assert!(std::fs::metadata(&png).unwrap().len() > 5000);
        let svg_text = std::fs::read_to_string(&svg).unwrap();
        assert!(svg_text.contains("<svg") && svg_text.contains("test"));
    }

    #[test]
    fn refuses_empty_charts() {
        let dir = tempfile::tempdir().unwrap();
        let chart = Chart {
            title: "empty".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series::new("nan", vec![(f64::NAN, 1.0)], Style::Line)],
            log_y: false,
        };
        assert!(matches!(
            write_chart(&dir.path().join("c"), &chart),
            Err(PlotError::Empty { .. })
        ));
    }
}
