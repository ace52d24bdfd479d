//! Drawing helpers shared by every figure: the layout of titles, panel headers and legends, charts with clipped
//! and decimated lines, and the rows of panels against time.

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::FONT;

use super::data::{Data, FRAME, GRID_BOLD, GRID_LIGHT, NOTE, Run};

pub(super) type Res<T> = Result<T, String>;

pub(super) type Ctx<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

pub(super) fn de<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Chart margins and label areas (px), the same in every panel so that plots line up.
const ML: i32 = 6;

pub(super) const MR: i32 = 18;

const MT: i32 = 8;

const MB: i32 = 6;

pub(super) const YLA: i32 = 80;

const XLA: i32 = 44;

pub(super) const TITLE_PX: u32 = 18;

pub(super) const NOTE_PX: u32 = 13;

const LEGEND_PX: u32 = 14;

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
pub(super) fn figure_title<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> Res<DrawingArea<DB, Shift>> {
    let h = centred_text(root, title, 22, BLACK, 8)?;
    Ok(root.split_vertically(h + 12).1)
}

/// Panel title and an optional grey note line under it (its room is kept when `keep_note_room`, so that panels
/// side by side keep the same plot height); returns the area below.
pub(super) fn panel_header<DB: DrawingBackend>(
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

pub(super) struct Key {
    pub(super) label: String,
    pub(super) style: ShapeStyle,
}

/// A legend laid out in rows above a plot (so that it hides nothing); returns the area below it.
pub(super) fn legend_strip<DB: DrawingBackend>(
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
pub(super) fn plot_size<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x_ticks: bool,
) -> (f64, f64) {
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

pub(super) struct Axes<'s> {
    pub(super) xr: (f64, f64),
    pub(super) yr: (f64, f64),
    pub(super) x_desc: &'s str,
    pub(super) y_desc: &'s str,
    /// Whether tick labels and the description of the x axis are drawn (only under the bottom row of a stack).
    pub(super) x_ticks: bool,
    /// The plotted vertical values are the negated data (an axis pointing down): label ticks with `-v`.
    pub(super) y_down: bool,
    pub(super) n_x: usize,
    pub(super) n_y: usize,
}

pub(super) fn chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    a: &Axes,
) -> Res<Ctx<'a, DB>>
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
pub(super) fn clipped_paths(
    xs: &[f64],
    ys: &[f64],
    xr: (f64, f64),
    yr: (f64, f64),
) -> Vec<Vec<(f64, f64)>> {
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
pub(super) fn decimate(path: Vec<(f64, f64)>, chunk: usize) -> Vec<(f64, f64)> {
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
pub(super) fn line<DB: DrawingBackend>(
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
pub(super) struct TimeRow<'d> {
    pub(super) y_desc: String,
    pub(super) yr: (f64, f64),
    /// (times, values, style), drawn in this order.
    pub(super) lines: Vec<(&'d [f64], &'d [f64], ShapeStyle)>,
    pub(super) zero_line: bool,
}

pub(super) fn time_rows<DB: DrawingBackend>(
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
pub(super) fn cells<DB: DrawingBackend>(
    body: &DrawingArea<DB, Shift>,
) -> Vec<DrawingArea<DB, Shift>> {
    body.split_evenly((2, 2))
        .into_iter()
        .map(|c| c.margin(2, 10, 6, 6))
        .collect()
}

pub(super) fn truth_key(style: ShapeStyle) -> Key {
    Key {
        label: "truth".to_string(),
        style,
    }
}

/// Runs from the last to the first, so that the first (default) estimator is drawn on top.
pub(super) fn runs_back_to_front<'r, 'a>(
    d: &'r Data<'a>,
) -> impl Iterator<Item = (usize, &'r Run<'a>)> {
    d.runs.iter().enumerate().rev()
}
