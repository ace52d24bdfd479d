//! The sweep's results as text: the checks and failures, the description, the markdown tables and the JSON.

use std::fmt::Write as _;

use roitrack_estimators::KalmanTuning;
use roitrack_sim::ScenarioKind;

use super::case::Purpose;
use super::goal::{Check, Goal};
use super::results::CaseResult;
use super::scene::Scene;
use super::sweep::Sweep;

/// `yes` or a bold `no`.
fn mark(holds: bool) -> &'static str {
    if holds { "yes" } else { "**no**" }
}

/// A number in a short form: at most 3 significant digits without trailing zeros, or a power of ten far from 1.
fn short(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if (-3..4).contains(&magnitude) {
        let decimals = (2 - magnitude).max(0) as usize;
        let text = format!("{x:.decimals$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        }
    } else {
        format!("{x:.0e}")
    }
}

impl Sweep {
    /// Every target of every case, checked on the default filter.
    pub fn checks(&self) -> Vec<Check> {
        self.cases
            .iter()
            .flat_map(|r| {
                r.case.goals().into_iter().map(move |goal| Check {
                    case: r.case.name,
                    goal,
                    figure: r.figure(goal),
                    holds: r.holds(goal),
                })
            })
            .collect()
    }

    /// The checks that do not hold, as `case: target` lines.
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{SweepOptions, sweep};
    /// let mut options = SweepOptions::quick();
    /// options.cases.truncate(1);
    /// (options.max_duration_s, options.grid.max_rounds) = (Some(0.3), 0);
    /// let result = sweep(&options, None).unwrap();
    /// assert!(result.failures().iter().all(|line| line.starts_with("4 kHz, 0.1 px: ")));
    /// ```
    pub fn failures(&self) -> Vec<String> {
        self.checks()
            .into_iter()
            .filter(|c| !c.holds)
            .map(|c| {
                format!(
                    "{}: {} ({}; {})",
                    c.case,
                    c.goal.name(),
                    c.goal.description(),
                    c.figure
                )
            })
            .collect()
    }

    /// What was run, in a paragraph.
    pub fn description(&self) -> String {
        let o = &self.options;
        let g = &o.grid;
        let list = |axis: &[f64]| {
            axis.iter()
                .map(|&x| short(x))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let seeds: Vec<u64> = {
            let mut s: Vec<u64> = o.cases.iter().flat_map(|c| c.seeds.clone()).collect();
            s.sort_unstable();
            s.dedup();
            s
        };
        format!(
            "{}Each case simulated at the measurement level (ideal centroids with Gaussian noise, bit-reversed ROI \
             order; seed{} {}{}) and tracked by the default Kalman filter (`TrackerConfig::default()`: 0.1 px \
             assumed, q_a = {} (m/s²)²/Hz, q_α = {} (rad/s²)²/Hz, adapt_noise and adapt_motion on) and by \
             hand-tuned filters (adaptation off, the settings taken as the truth). Hand-tuned grid: noise {} x the \
             true noise, q_a {} and q_α {}; searched by a coarse stage (the true noise, {} of each axis, and the \
             told-the-truth point: the true noise, the default densities) then pattern search on the full grid \
             from the best point (each round the unvisited neighbours one step along each axis, up to {} round{}, \
             until none improves): about {} of the {} points run per case; (edge): the best lies on the grid's \
             boundary along some axis, and a better setting may lie beyond. Nominal error = the best \
             hand-tuned position RMSE. RMSEs over every estimate; NEES over the estimates marked tracking or \
             converging (mean NEES / 3 of position and of velocity, and the share inside the 99 % chi-square bound \
             11.34); lag = the shift of the velocity cross-correlation peak in estimator samples (400 Hz at 4 kHz); \
             noise = the mean noise the default filter worked with (`Estimate::noise_px`) against the truth.",
            if o.quick {
                "Quick mode (a smoke run, not the table of record): a few cases, each cut to at most \
                 0.6 s, on a small grid. "
            } else {
                ""
            },
            if seeds.len() == 1 { "" } else { "s" },
            seeds
                .iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join(", "),
            o.max_duration_s
                .map_or(String::new(), |m| format!(", at most {m} s")),
            short(KalmanTuning::default().linear_accel_psd),
            short(KalmanTuning::default().angular_accel_psd),
            list(&g.noise_factors),
            list(&g.linear_accel_psd),
            list(&g.angular_accel_psd),
            match g.coarse_stride {
                1 => "every density".to_string(),
                2 => "every other density and the last".to_string(),
                n => format!("every {n}th density and the last"),
            },
            g.max_rounds,
            if g.max_rounds == 1 { "" } else { "s" },
            self.mean_visited(),
            g.points(),
        )
    }

    /// The mean number of grid points run per accuracy case, rounded.
    fn mean_visited(&self) -> usize {
        let searched: Vec<usize> = self
            .cases
            .iter()
            .filter(|c| c.best.is_some())
            .map(|c| c.visited.len())
            .collect();
        (searched.iter().sum::<usize>() as f64 / searched.len().max(1) as f64).round() as usize
    }

    /// The cases as a markdown list: scene, camera, target, rate, noise.
    pub fn cases_list(&self) -> String {
        let mut out = String::new();
        for r in &self.cases {
            let c = &r.case;
            let _ = writeln!(
                out,
                "- **{}** ({}): {}, {} camera, {} target, {} kHz, {} px, {} measurements{}",
                c.name,
                match c.purpose {
                    Purpose::Accuracy => "accuracy",
                    Purpose::Calibration => "calibration",
                },
                c.scene.name(),
                c.camera.name(),
                c.target.name(),
                c.rate_hz / 1000.0,
                c.noise_px,
                r.measurements,
                if c.in_calibration_set && c.purpose == Purpose::Accuracy {
                    "; also in the calibration set"
                } else {
                    ""
                }
            );
        }
        out
    }

    /// The accuracy cases as a markdown table.
    pub fn accuracy_table(&self) -> String {
        let mut out = String::from(
            "| case | default mm | best hand-tuned mm | noise px, q_a, q_α | ratio | worst vouched mm | > 10x nominal | \
             disputed / lost / degenerate | NEES/3 pos, vel | inside 99 % pos, vel | lag default, hand-tuned | \
             noise est. / true px | fails |\n\
             |---|---:|---:|---|---:|---:|---:|---:|---|---|---|---|---|\n",
        );
        for r in self.cases.iter().filter(|r| r.best.is_some()) {
            let d = &r.default;
            let Some(best) = &r.best else { continue };
            let t = &best.tuning;
            let lag = |l: Option<i64>| l.map_or("-".to_string(), |l| l.to_string());
            let fails: Vec<&str> = r
                .case
                .goals()
                .into_iter()
                .filter(|&g| !r.holds(g))
                .map(|g| g.name())
                .collect();
            let _ = writeln!(
                out,
                "| {} | {:.4} | {:.4} | {}, {}, {}{} | {:.2} | {:.3} | {} | {} / {} / {} | {:.2}, {:.2} | {:.1} %, {:.1} % \
                 | {}, {} | {:.3} / {} | {} |",
                r.case.name,
                d.position_rmse_mm,
                best.summary.position_rmse_mm,
                short(t.noise_px),
                short(t.linear_accel_psd),
                short(t.angular_accel_psd),
                if best.on_edge { " (edge)" } else { "" },
                r.rmse_ratio(),
                d.max_vouched_error_mm,
                r.beyond_bound.unwrap_or(0),
                d.disputed,
                d.lost,
                d.degenerate,
                d.consistency.position_nees_per_dof,
                d.consistency.velocity_nees_per_dof,
                100.0 * d.consistency.position_inside_99,
                100.0 * d.consistency.velocity_inside_99,
                lag(d.velocity_lag_samples),
                lag(best.summary.velocity_lag_samples),
                d.mean_noise_px,
                r.case.noise_px,
                if d.runs_without_estimates > 0 {
                    format!("all (no estimate on {} seed(s))", d.runs_without_estimates)
                } else if fails.is_empty() {
                    "none".to_string()
                } else {
                    fails.join(", ")
                }
            );
        }
        out
    }

    /// The calibration set as a markdown table: the default filter's and the told-the-truth filter's NEES.
    pub fn calibration_table(&self) -> String {
        let mut out = String::from(
            "| scene | noise px | default NEES/3 pos, vel | inside 99 % pos, vel | disputed / lost | calibrated | \
             told-the-truth NEES/3 pos, vel | inside 99 % pos, vel |\n\
             |---|---:|---|---|---:|---|---|---|\n",
        );
        let mut rows: Vec<&CaseResult> = self
            .cases
            .iter()
            .filter(|r| r.case.in_calibration_set)
            .collect();
        let scene_order = |r: &CaseResult| match r.case.scene {
            Scene::Spec(kind) => ScenarioKind::ALL
                .iter()
                .position(|k| *k == kind)
                .unwrap_or(usize::MAX),
            _ => usize::MAX,
        };
        rows.sort_by(|a, b| {
            scene_order(a)
                .cmp(&scene_order(b))
                .then(a.case.noise_px.total_cmp(&b.case.noise_px))
        });
        for r in rows {
            let (d, t) = (&r.default.consistency, &r.told_truth.summary.consistency);
            let _ = writeln!(
                out,
                "| {} | {} | {:.2}, {:.2} | {:.1} %, {:.1} % | {} / {} | {} | {:.2}, {:.2} | {:.1} %, {:.1} % |",
                r.case.scene.name(),
                r.case.noise_px,
                d.position_nees_per_dof,
                d.velocity_nees_per_dof,
                100.0 * d.position_inside_99,
                100.0 * d.velocity_inside_99,
                r.default.disputed,
                r.default.lost,
                mark(d.is_calibrated()),
                t.position_nees_per_dof,
                t.velocity_nees_per_dof,
                100.0 * t.position_inside_99,
                100.0 * t.velocity_inside_99,
            );
        }
        out
    }

    /// Each target: on how many cases it is checked and holds, and where it fails, as a markdown table.
    pub fn goals_table(&self) -> String {
        let checks = self.checks();
        let mut out = String::from(
            "| target | what | checked | holds | fails on |\n|---|---|---:|---:|---|\n",
        );
        for goal in Goal::ALL {
            let of: Vec<&Check> = checks.iter().filter(|c| c.goal == goal).collect();
            let failing: Vec<&str> = of.iter().filter(|c| !c.holds).map(|c| c.case).collect();
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} |",
                goal.name(),
                goal.description(),
                of.len(),
                of.len() - failing.len(),
                if failing.is_empty() {
                    "-".to_string()
                } else {
                    failing.join("; ")
                }
            );
        }
        out
    }

    /// The description, the cases, the accuracy table, the calibration table and the targets, in markdown.
    pub fn markdown(&self) -> String {
        let checks = self.checks();
        let failing = checks.iter().filter(|c| !c.holds).count();
        format!(
            "{}\n\nCases:\n\n{}\nAccuracy cases (default filter against the best hand-tuned one):\n\n{}\n\
             Calibration set (every built-in scenario at 4 kHz):\n\n{}\nTargets:\n\n{}\n{}\n",
            self.description(),
            self.cases_list(),
            self.accuracy_table(),
            self.calibration_table(),
            self.goals_table(),
            if failing == 0 {
                format!("All {} checks hold.", checks.len())
            } else {
                format!("{failing} of {} checks do not hold.", checks.len())
            }
        )
    }

    /// Everything as one JSON object: `description`, `options`, `cases` (with every grid point visited), `checks`,
    /// `failures`, `holds` and `seconds`.
    ///
    /// ```
    /// use roitrack_experiments::adaptive::{SweepOptions, sweep};
    /// let mut options = SweepOptions::quick();
    /// options.cases.truncate(1);
    /// (options.max_duration_s, options.grid.max_rounds) = (Some(0.3), 0);
    /// let json: serde_json::Value = serde_json::from_str(&sweep(&options, None).unwrap().json()).unwrap();
    /// assert_eq!(json["cases"][0]["case"]["name"], "4 kHz, 0.1 px");
    /// assert!(json["cases"][0]["default"]["position_rmse_mm"].as_f64().unwrap() > 0.0);
    /// ```
    pub fn json(&self) -> String {
        let failures = self.failures();
        serde_json::json!({
            "description": self.description(),
            "options": self.options,
            "cases": self.cases,
            "checks": self.checks(),
            "holds": failures.is_empty(),
            "failures": failures,
            "seconds": self.seconds,
        })
        .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_numbers() {
        assert_eq!(short(0.001), "0.001");
        assert_eq!(short(1e-4), "1e-4");
        assert_eq!(short(10.0), "10");
        assert_eq!(short(1000.0), "1000");
        assert_eq!(short(1e4), "1e4");
        assert_eq!(short(0.14), "0.14");
        assert_eq!(short(0.0333333), "0.0333");
    }
}
