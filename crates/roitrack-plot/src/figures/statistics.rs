//! The statistics panel of figure 7: every run's RMS errors, velocity lag and mean residual, as roitrack-eval
//! computed them.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use roitrack_eval::Metrics;

use crate::FONT;

use super::data::{Data, FRAME, NOTE, Run, num};
use super::draw::{MR, Res, YLA, de, panel_header};
use super::time_series::Quantity;

/// Panel (d) of figure 7: a table of the error statistics of every run.
pub(super) fn statistics<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
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
                    text_style(14, &NOTE),
                ))
                .map_err(de)?;
            break;
        }
        y = run_block(&inner, i, r, x0, &cols, y, line_h)?;
    }
    for (k, text) in FOOTNOTES.iter().enumerate() {
        inner
            .draw(&Text::new(
                text.to_string(),
                (x0, bottom + 4 + k as i32 * line_h),
                text_style(13, &NOTE),
            ))
            .map_err(de)?;
    }
    Ok(())
}

/// Text of the embedded font at `size` px in `color`, anchored at its top left.
fn text_style(size: u32, color: &'static RGBColor) -> TextStyle<'static> {
    TextStyle::from((FONT, size).into_font())
        .color(color)
        .pos(Pos::new(HPos::Left, VPos::Top))
}

/// Run `i`'s block of the statistics panel, from height `y`: its key and title, a row per quantity (RMS errors
/// along x, y, z and 3-D), then its velocity lag and mean residual. Returns the height below the block.
fn run_block<DB: DrawingBackend>(
    inner: &DrawingArea<DB, Shift>,
    i: usize,
    r: &Run,
    x0: i32,
    cols: &[i32; 6],
    mut y: i32,
    line_h: i32,
) -> Res<i32>
where
    DB::ErrorType: 'static,
{
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
        .draw(&Text::new(title, (x0 + 32, y), text_style(16, &BLACK)))
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
        for (text, &x) in cells.iter().zip(cols) {
            inner
                .draw(&Text::new(text.clone(), (x, y), text_style(15, &BLACK)))
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
            text_style(14, &NOTE),
        ))
        .map_err(de)?;
    y += line_h + 10;
    Ok(y)
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
