//! The data of the figures: the truth and the runs in mm, their columns checked, and the axis ranges chosen from
//! them (robust ranges, off-scale notes); the figures' sizes and colours.

use plotters::prelude::*;
use roitrack_core::stats;
use roitrack_eval::Metrics;

use crate::PlotError;

use super::{TrackSeries, TruthSeries};

const MM: f64 = 1e3;

pub(super) const FIG5_SIZE: (u32, u32) = (1400, 820);

pub(super) const FIG67_SIZE: (u32, u32) = (1400, 1000);

pub(super) const AXES: [&str; 3] = ["x", "y", "z"];

pub(super) const AXIS_COLORS: [RGBColor; 3] = [
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

pub(super) const GRID_BOLD: RGBColor = RGBColor(222, 222, 222);

pub(super) const GRID_LIGHT: RGBColor = RGBColor(242, 242, 242);

pub(super) const FRAME: RGBColor = RGBColor(140, 140, 140);

pub(super) const NOTE: RGBColor = RGBColor(90, 90, 90);

pub(super) struct Truth {
    pub(super) t: Vec<f64>,
    pub(super) pos: [Vec<f64>; 3],
    pub(super) vel: [Vec<f64>; 3],
}

/// A run ready to draw: columns in mm and mm/s.
pub(super) struct Run<'a> {
    pub(super) label: &'a str,
    pub(super) color: RGBColor,
    pub(super) t: Vec<f64>,
    pub(super) pos: [Vec<f64>; 3],
    pub(super) vel: [Vec<f64>; 3],
    pub(super) pos_err: [Vec<f64>; 3],
    /// Empty columns when the run has no velocity errors.
    pub(super) vel_err: [Vec<f64>; 3],
    pub(super) residual: Vec<f64>,
    pub(super) metrics: Option<&'a Metrics>,
    pub(super) mean_residual_px: Option<f64>,
}

impl Run<'_> {
    /// Line style: the first run (drawn last, on top) is heavier than the others.
    pub(super) fn style(&self, index: usize) -> ShapeStyle {
        if index == 0 {
            self.color.stroke_width(2)
        } else {
            self.color.mix(0.85).stroke_width(1)
        }
    }
}

pub(super) struct Data<'a> {
    pub(super) scenario: &'a str,
    pub(super) truth: Truth,
    pub(super) runs: Vec<Run<'a>>,
    pub(super) t_range: (f64, f64),
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
    pub(super) fn new(
        scenario: &'a str,
        truth: &TruthSeries,
        runs: &'a [TrackSeries],
    ) -> Result<Self, PlotError> {
        check_truth(scenario, truth)?;
        if runs.is_empty() {
            return Err(PlotError::Empty {
                title: format!("{scenario}: runs"),
            });
        }
        for r in runs {
            check_run(r)?;
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

/// Whether the three coordinates are finite.
fn finite3(p: &[f64; 3]) -> bool {
    p.iter().all(|v| v.is_finite())
}

/// Refuses a truth whose columns differ in length, whose times are not finite and ascending, or with no finite
/// position.
fn check_truth(scenario: &str, truth: &TruthSeries) -> Result<(), PlotError> {
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
    if !truth.position_m.iter().any(finite3) {
        return Err(PlotError::Empty {
            title: format!("{scenario}: truth"),
        });
    }
    Ok(())
}

/// Refuses a run whose columns differ in length, or whose metrics are of another number of estimates.
fn check_run(r: &TrackSeries) -> Result<(), PlotError> {
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
    Ok(())
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
pub(super) fn robust_range(exact: &[&[f64]], robust: &[&[f64]], min_span: f64) -> (f64, f64) {
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
pub(super) fn error_limit(errs: &[&[f64]], min: f64) -> f64 {
    let sorted = sorted_finite(errs.iter().copied(), true);
    if sorted.is_empty() {
        return min;
    }
    (1.2 * stats::quantile(&sorted, 0.99)).max(min)
}

/// Number of finite values outside `r`.
pub(super) fn off_scale(vals: &[&[f64]], r: (f64, f64)) -> usize {
    vals.iter()
        .flat_map(|v| v.iter())
        .filter(|v| v.is_finite() && (**v < r.0 || **v > r.1))
        .count()
}

pub(super) fn off_scale_note(n: usize) -> Option<String> {
    match n {
        0 => None,
        1 => Some("1 point off-scale".to_string()),
        n => Some(format!("{n} points off-scale")),
    }
}

pub(super) fn num(v: f64) -> String {
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
