//! Figures 6 and 7: position and velocity against time, the truth, the first run's estimate and every run's error.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::data::{
    AXES, AXIS_COLORS, Data, Run, error_limit, num, off_scale, off_scale_note, robust_range,
};
use super::draw::{
    Axes, Key, Res, TimeRow, cells, chart, figure_title, legend_strip, line, panel_header,
    runs_back_to_front, time_rows,
};
use super::statistics::statistics;
use super::trajectory::join_notes;

#[derive(Clone, Copy, PartialEq)]
pub(super) enum Quantity {
    Position,
    Velocity,
}

impl Quantity {
    pub(super) fn unit(self) -> &'static str {
        match self {
            Self::Position => "mm",
            Self::Velocity => "mm/s",
        }
    }
    pub(super) fn name(self) -> &'static str {
        match self {
            Self::Position => "position",
            Self::Velocity => "velocity",
        }
    }
    pub(super) fn truth<'d>(self, d: &'d Data) -> &'d [Vec<f64>; 3] {
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
    pub(super) fn rms(self, r: &Run) -> Option<([f64; 3], f64)> {
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
    let truth = q.truth(d);
    let first = &d.runs[0];
    // (a) and (b) share their ranges, so that truth and estimate can be compared row by row.
    let ranges: [(f64, f64); 3] =
        std::array::from_fn(|c| robust_range(&[&truth[c]], &[&q.est(first)[c]], 1.0));
    truth_panel(&cells[0], d, q, &ranges)?;
    estimate_panel(&cells[1], d, q, &ranges)?;
    error_panel(&cells[2], d, q)
}

/// Panel (a): the true quantity along x, y and z against time, on `ranges`.
fn truth_panel<DB: DrawingBackend>(
    cell: &DrawingArea<DB, Shift>,
    d: &Data,
    q: Quantity,
    ranges: &[(f64, f64); 3],
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let unit = q.unit();
    let truth = q.truth(d);
    // (a) truth
    let inner = panel_header(
        cell,
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
    Ok(())
}

/// Panel (b): the first run's estimate over the truth in grey, on the truth's `ranges`.
fn estimate_panel<DB: DrawingBackend>(
    cell: &DrawingArea<DB, Shift>,
    d: &Data,
    q: Quantity,
    ranges: &[(f64, f64); 3],
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let unit = q.unit();
    let truth = q.truth(d);
    let first = &d.runs[0];
    let off_b: usize = (0..3)
        .map(|c| off_scale(&[&q.est(first)[c]], ranges[c]))
        .sum();

    // (b) first run's estimate over the truth in grey
    let note_b = join_notes(&[Some("grey: truth".to_string()), off_scale_note(off_b)]);
    let inner = panel_header(
        cell,
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
    Ok(())
}

/// Panel (c): every run's error against time on a robust symmetric range, its RMS errors in the legend.
fn error_panel<DB: DrawingBackend>(cell: &DrawingArea<DB, Shift>, d: &Data, q: Quantity) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let unit = q.unit();
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
        cell,
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

pub(super) fn fig6<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
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

pub(super) fn fig7<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
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
