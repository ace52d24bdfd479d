//! `roitrack faults`: the default estimator under measurement faults (outliers, drops, occlusion, a burst of lost
//! ROIs, a time gap, a sudden jump of the target), scored against the ground truth: accuracy, time to recover,
//! re-initialisations and wrong estimates the status did not flag.

use anyhow::Result;
use clap::Args;
use nalgebra::Vector3;
use roitrack_core::estimator::{TrackStatus, TrackerConfig};
use roitrack_sim::{
    Jump, Occlusion, RoiBurst, Scenario, ScenarioKind, SimulationOptions, TimeGap, simulate,
};

use super::demo::score;

/// Run the default estimator on clean and faulty simulated measurements (orthoglide and random scenarios, seed 1,
/// 0.1 px, 4 kHz, bit-reversed order) and print a fault table.
#[derive(Debug, Args)]
pub struct FaultsArgs {
    /// Print one JSON object per row instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Only the orthoglide scenario and three rows (for tests).
    #[arg(long, hide = true)]
    pub quick: bool,
}

/// The position error must stay within this many clean position RMSEs ...
const RECOVERY_FACTOR: f64 = 3.0;
/// ... for this long (s) for the tracker to count as recovered.
const RECOVERY_HOLD_S: f64 = 0.05;
/// An estimate whose position error exceeds this many clean RMSEs is wrong.
const WRONG_FACTOR: f64 = 10.0;

/// One fault case: its name, the options, and the time the fault ends (None for faults spread over the run).
struct Case {
    name: &'static str,
    options: SimulationOptions,
    fault_end_s: Option<f64>,
}

fn cases(kind: ScenarioKind, quick: bool) -> Vec<Case> {
    let base = SimulationOptions {
        seed: 1,
        noise_px: 0.1,
        rate_hz: 4000.0,
        ..SimulationOptions::default()
    };
    // Start times per scenario (the same for both scenarios today, kept apart so that either can move).
    let (occlusion_t0_s, jump_t_s) = match kind {
        ScenarioKind::Orthoglide => (1.0, 2.5),
        _ => (1.0, 2.5),
    };
    let burst = RoiBurst {
        t0_s: 1.5,
        count: 40,
    };
    let gap = TimeGap {
        t0_s: 2.0,
        duration_s: 0.05,
    };
    let all = vec![
        Case {
            name: "clean",
            options: base.clone(),
            fault_end_s: None,
        },
        Case {
            name: "10% outliers",
            options: SimulationOptions {
                outlier_fraction: 0.1,
                ..base.clone()
            },
            fault_end_s: None,
        },
        Case {
            name: "50% dropped",
            options: SimulationOptions {
                drop_fraction: 0.5,
                ..base.clone()
            },
            fault_end_s: None,
        },
        Case {
            name: "occlusion 4 blobs 0.2 s",
            options: SimulationOptions {
                occlusions: vec![Occlusion {
                    ids: vec![0, 5, 10, 15],
                    t0_s: occlusion_t0_s,
                    t1_s: occlusion_t0_s + 0.2,
                }],
                ..base.clone()
            },
            fault_end_s: Some(occlusion_t0_s + 0.2),
        },
        Case {
            name: "burst 40 ROIs lost",
            options: SimulationOptions {
                bursts: vec![burst],
                ..base.clone()
            },
            fault_end_s: Some(burst.t0_s + burst.count as f64 / base.rate_hz),
        },
        Case {
            name: "gap 50 ms",
            options: SimulationOptions {
                gaps: vec![gap],
                ..base.clone()
            },
            fault_end_s: Some(gap.t0_s + gap.duration_s),
        },
        Case {
            name: "jump 20 mm in x",
            options: SimulationOptions {
                jump: Some(Jump {
                    t_s: jump_t_s,
                    offset_m: Vector3::new(0.02, 0.0, 0.0),
                }),
                ..base.clone()
            },
            fault_end_s: Some(jump_t_s),
        },
    ];
    if quick {
        all.into_iter()
            .filter(|c| matches!(c.name, "clean" | "burst 40 ROIs lost" | "jump 20 mm in x"))
            .collect()
    } else {
        all
    }
}

/// One row of the table.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FaultRow {
    pub scenario: &'static str,
    pub fault: &'static str,
    pub estimates: usize,
    pub position_rmse_mm: f64,
    pub velocity_rmse_mm_s: Option<f64>,
    /// When the fault ends (s); None for faults spread over the whole run.
    pub fault_end_s: Option<f64>,
    /// Time from the end of the fault to the first estimate from which the position error stays within 3x the clean
    /// RMSE for 50 ms (ms); None when not applicable or never.
    pub recovery_ms: Option<f64>,
    /// False when the fault has an end and the tracker never recovered.
    pub recovered: bool,
    /// Estimates with status `lost`.
    pub lost: usize,
    /// Re-initialisations: entries into `converging` after the first.
    pub reinitialisations: usize,
    /// Estimates with a position error above 10x the clean RMSE and status `tracking` or `converging`.
    pub unflagged_wrong: usize,
}

/// Per-estimate record: time, position error (m), status.
struct Point {
    t_s: f64,
    error_m: f64,
    status: TrackStatus,
}

/// The time (s) of the first estimate at or after `from_s` from which every error stays within `threshold_m` for
/// `hold_s` (and the run lasts that long), or None.
fn recovery_time(points: &[Point], from_s: f64, threshold_m: f64, hold_s: f64) -> Option<f64> {
    let mut candidate: Option<f64> = None;
    for p in points.iter().filter(|p| p.t_s >= from_s) {
        if p.error_m > threshold_m {
            candidate = None;
            continue;
        }
        let start = *candidate.get_or_insert(p.t_s);
        if p.t_s - start >= hold_s {
            return Some(start);
        }
    }
    None
}

fn run_case(scenario: &Scenario, case: &Case) -> Result<(FaultRow, Vec<Point>)> {
    let data = simulate(scenario, &case.options)?;
    let mut points = Vec::new();
    let config = TrackerConfig {
        noise_px: case.options.noise_px,
        ..TrackerConfig::default()
    };
    let (metrics, summary) = score(&data, config, |e| {
        let truth = case.options.truth_at(scenario, e.t_ref_s);
        points.push(Point {
            t_s: e.t_ref_s,
            error_m: (e.state.cam_t_obj_m - truth.cam_t_obj_m).norm(),
            status: e.status,
        });
        Ok(())
    })?;
    let reinitialisations = points
        .windows(2)
        .filter(|w| {
            w[1].status == TrackStatus::Converging && w[0].status != TrackStatus::Converging
        })
        .count();
    let row = FaultRow {
        scenario: scenario.kind.name(),
        fault: case.name,
        estimates: summary.estimates,
        position_rmse_mm: metrics.position_rmse_mm,
        velocity_rmse_mm_s: metrics.velocity_rmse_mm_s,
        fault_end_s: case.fault_end_s,
        recovery_ms: None,
        recovered: true,
        lost: summary.lost,
        reinitialisations,
        unflagged_wrong: 0,
    };
    Ok((row, points))
}

/// Every row of the table for one scenario; the first case must be the clean run (it sets the thresholds).
pub fn scenario_rows(kind: ScenarioKind, quick: bool) -> Result<Vec<FaultRow>> {
    let scenario = Scenario::new(kind, 1);
    let cases = cases(kind, quick);
    // The cases are independent: run them on threads.
    let results: Vec<Result<(FaultRow, Vec<Point>)>> = std::thread::scope(|s| {
        let handles: Vec<_> = cases
            .iter()
            .map(|case| s.spawn(|| run_case(&scenario, case)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a fault case panicked"))
            .collect()
    });
    let results = results.into_iter().collect::<Result<Vec<_>>>()?;
    let clean_rmse_m = results[0].0.position_rmse_mm * 1e-3;
    Ok(results
        .into_iter()
        .map(|(mut row, points)| {
            row.unflagged_wrong = points
                .iter()
                .filter(|p| {
                    p.error_m > WRONG_FACTOR * clean_rmse_m
                        && matches!(p.status, TrackStatus::Tracking | TrackStatus::Converging)
                })
                .count();
            if let Some(end_s) = row.fault_end_s {
                match recovery_time(
                    &points,
                    end_s,
                    RECOVERY_FACTOR * clean_rmse_m,
                    RECOVERY_HOLD_S,
                ) {
                    Some(t) => row.recovery_ms = Some(1e3 * (t - end_s)),
                    None => row.recovered = false,
                }
            }
            row
        })
        .collect())
}

pub fn run(args: &FaultsArgs) -> Result<()> {
    let kinds: &[ScenarioKind] = if args.quick {
        &[ScenarioKind::Orthoglide]
    } else {
        &[ScenarioKind::Orthoglide, ScenarioKind::Random]
    };
    if !args.json {
        println!(
            "{:<11} {:<24} {:>9} {:>10} {:>12} {:>5} {:>7} {:>10}",
            "scenario", "fault", "pos mm", "vel mm/s", "recover ms", "lost", "reinit", "unflagged"
        );
    }
    for &kind in kinds {
        for row in scenario_rows(kind, args.quick)? {
            if args.json {
                println!("{}", serde_json::to_string(&row)?);
                continue;
            }
            let recovery = match (row.fault_end_s, row.recovery_ms) {
                (None, _) => "-".to_string(),
                (Some(_), Some(ms)) => format!("{ms:.1}"),
                (Some(_), None) => "never".to_string(),
            };
            println!(
                "{:<11} {:<24} {:>9.4} {:>10.2} {:>12} {:>5} {:>7} {:>10}",
                row.scenario,
                row.fault,
                row.position_rmse_mm,
                row.velocity_rmse_mm_s.unwrap_or(f64::NAN),
                recovery,
                row.lost,
                row.reinitialisations,
                row.unflagged_wrong
            );
        }
    }
    if !args.json {
        println!(
            "recover: from the end of the fault until the position error stays within {RECOVERY_FACTOR}x the clean \
             RMSE for {} ms; unflagged: estimates off by more than {WRONG_FACTOR}x the clean RMSE with status \
             tracking or converging (target 0)",
            1e3 * RECOVERY_HOLD_S
        );
    }
    Ok(())
}
