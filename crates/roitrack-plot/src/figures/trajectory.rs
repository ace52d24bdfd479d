//! Figure 5: the trajectory of the target origin projected on the camera's x–y, x–z and y–z planes, at equal scales.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::FONT;

use super::data::{Data, num, off_scale_note, robust_range};
use super::draw::{
    Axes, Ctx, Key, NOTE_PX, Res, TITLE_PX, chart, de, figure_title, legend_strip, line,
    panel_header, plot_size, runs_back_to_front, truth_key,
};

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

pub(super) fn join_notes(notes: &[Option<String>]) -> Option<String> {
    let v: Vec<&str> = notes.iter().flatten().map(String::as_str).collect();
    (!v.is_empty()).then(|| v.join(" · "))
}

pub(super) fn fig5<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, d: &Data) -> Res<()>
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
    let body = legend_strip(&body, &trajectory_keys(d, truth_style))?;
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

    for (p, area) in projections(xr, zr, y_down).iter().zip(&panels) {
        projection_panel(area, d, p, plot, truth_style)?;
    }
    Ok(())
}

/// The legend of figure 5: the truth, and each run with its 3-D position RMS error.
fn trajectory_keys(d: &Data, truth_style: ShapeStyle) -> Vec<Key> {
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
    keys
}

/// One panel of figure 5: the plane of axes `h` (across) and `v` (up), their ranges and descriptions.
struct Projection<'s> {
    title: &'s str,
    h: usize,
    v: usize,
    hr: (f64, f64),
    vr: (f64, f64),
    h_desc: &'s str,
    v_desc: &'s str,
}

/// The three panels of figure 5 from the ranges of x, z and y (pointing down, `y_down`).
fn projections(xr: (f64, f64), zr: (f64, f64), y_down: (f64, f64)) -> [Projection<'static>; 3] {
    [
        Projection {
            title: "(a) x–y: image plane, as seen by the camera",
            h: 0,
            v: 1,
            hr: xr,
            vr: y_down,
            h_desc: "x (mm)",
            v_desc: "y (mm, pointing down)",
        },
        Projection {
            title: "(b) x–z: top view",
            h: 0,
            v: 2,
            hr: xr,
            vr: zr,
            h_desc: "x (mm)",
            v_desc: "z, depth (mm)",
        },
        Projection {
            title: "(c) y–z: side view",
            h: 2,
            v: 1,
            hr: zr,
            vr: y_down,
            h_desc: "z, depth (mm)",
            v_desc: "y (mm, pointing down)",
        },
    ]
}

/// Draws panel `p` of figure 5 in `area`: the truth and every run projected on its plane, with a note on its scale
/// and on the points off it.
fn projection_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    d: &Data,
    p: &Projection,
    plot: (f64, f64),
    truth_style: ShapeStyle,
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let sign = |c: usize| if c == 1 { -1.0 } else { 1.0 };
    let v_of = |vals: &[f64], c: usize| -> Vec<f64> { vals.iter().map(|v| sign(c) * v).collect() };
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
