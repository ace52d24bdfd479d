//! The default estimator under faults, scored against the ground truth: accuracy, time to recover,
//! re-initialisations, flagged estimates and wrong estimates the status did not flag. Measurement faults (outliers,
//! drops, occlusion, blobs leaving the image, a burst of lost ROIs, a time gap, a sudden jump of the target) go
//! through the measurement simulator; reflections (a second spot in the ROI) go through the simulated camera, the
//! centroid and the two-thread loop, compared with the clean run from images.
//!
//! ```no_run
//! use roitrack_experiments::faults::{scenario_rows, table};
//! use roitrack_sim::ScenarioKind;
//!
//! let rows = scenario_rows(ScenarioKind::Orthoglide, false).unwrap();
//! print!("{}", table(&rows));
//! ```

use nalgebra::Vector3;
use roitrack_estimators::{Estimate, TrackStatus, TrackerConfig};
use roitrack_pipeline::{LoopConfig, run_loop_with_progress};
use roitrack_sim::{
    Excursion, Jump, Occlusion, ReflectionFault, RoiBurst, Scenario, ScenarioKind, SimulatedCamera,
    SimulationOptions, TimeGap, simulate,
};

use crate::ExperimentError;
use roitrack_demo::scoring::{score, track_and_score};
use roitrack_demo::{image_noise_px, image_side};

/// The position error must stay within this many clean position RMSEs ...
const RECOVERY_FACTOR: f64 = 3.0;
/// ... for this long (s) for the tracker to count as recovered.
const RECOVERY_HOLD_S: f64 = 0.05;
/// An estimate whose position error exceeds this many clean RMSEs is wrong.
const WRONG_FACTOR: f64 = 10.0;

/// Where a case's measurements come from.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Source {
    /// The measurement simulator (ideal centroids plus noise and the options' faults).
    Measurements,
    /// Rendered ROIs through the simulated camera (with these reflections), the centroid and the two-thread loop.
    Images(Option<ReflectionFault>),
}

/// One fault case: its name, the options, where the measurements come from, and the time the fault ends (None for
/// faults spread over the run). The first case of each source is its clean reference.
struct Case {
    name: &'static str,
    options: SimulationOptions,
    source: Source,
    fault_end_s: Option<f64>,
}

/// An excursion to the right during `[t0_s, t1_s]`, sized on the scenario's pose at mid-interval so that the image's
/// right edge falls between the target's last two columns of blobs at its peak: 4 of the 16 blobs leave the image.
fn excursion_taking_a_column_off(scenario: &Scenario, t0_s: f64, t1_s: f64) -> Excursion {
    let camera = &scenario.camera;
    let state = scenario.state_at(0.5 * (t0_s + t1_s));
    // Pixel columns of the blobs at the peak pose without the excursion.
    let mut u: Vec<f64> = scenario
        .target
        .points()
        .iter()
        .filter_map(|p| {
            camera
                .intrinsics
                .pixel_from_cam(&state.point_in_cam_at(&p.point_in_obj_m, 0.0))
        })
        .map(|px| px.x)
        .collect();
    u.sort_by(f64::total_cmp);
    // Between the 4th and 5th blob from the right.
    let n = u.len();
    let cut_px = 0.5 * (u[n - 4] + u[n - 5]);
    let shift_px = f64::from(camera.width_px) - cut_px;
    Excursion {
        t0_s,
        t1_s,
        offset_m: Vector3::new(
            shift_px * state.cam_t_obj_m.z / camera.intrinsics.fx_px,
            0.0,
            0.0,
        ),
    }
}

fn cases(scenario: &Scenario, quick: bool) -> Vec<Case> {
    let kind = scenario.kind;
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
    let excursion = excursion_taking_a_column_off(scenario, 3.0, 3.4);
    let all = vec![
        Case {
            name: "clean",
            options: base.clone(),
            source: Source::Measurements,
            fault_end_s: None,
        },
        Case {
            name: "10% outliers",
            source: Source::Measurements,
            options: SimulationOptions {
                outlier_fraction: 0.1,
                ..base.clone()
            },
            fault_end_s: None,
        },
        Case {
            name: "50% dropped",
            source: Source::Measurements,
            options: SimulationOptions {
                drop_fraction: 0.5,
                ..base.clone()
            },
            fault_end_s: None,
        },
        Case {
            name: "occlusion 4 blobs 0.2 s",
            source: Source::Measurements,
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
            source: Source::Measurements,
            options: SimulationOptions {
                bursts: vec![burst],
                ..base.clone()
            },
            fault_end_s: Some(burst.t0_s + burst.count as f64 / base.rate_hz),
        },
        Case {
            name: "gap 50 ms",
            source: Source::Measurements,
            options: SimulationOptions {
                gaps: vec![gap],
                ..base.clone()
            },
            fault_end_s: Some(gap.t0_s + gap.duration_s),
        },
        Case {
            name: "jump 20 mm in x",
            source: Source::Measurements,
            options: SimulationOptions {
                jump: Some(Jump {
                    t_s: jump_t_s,
                    offset_m: Vector3::new(0.02, 0.0, 0.0),
                }),
                ..base.clone()
            },
            fault_end_s: Some(jump_t_s),
        },
        Case {
            name: "4 blobs leave image 0.4 s",
            source: Source::Measurements,
            options: SimulationOptions {
                excursion: Some(excursion),
                skip_off_image: true,
                ..base.clone()
            },
            fault_end_s: Some(excursion.t1_s),
        },
        Case {
            name: "images: clean",
            source: Source::Images(None),
            options: base.clone(),
            fault_end_s: None,
        },
        Case {
            name: "images: 10% reflections",
            source: Source::Images(Some(ReflectionFault::default())),
            options: base.clone(),
            fault_end_s: None,
        },
    ];
    if quick {
        all.into_iter()
            .filter(|c| {
                matches!(
                    c.name,
                    "clean"
                        | "burst 40 ROIs lost"
                        | "jump 20 mm in x"
                        | "4 blobs leave image 0.4 s"
                )
            })
            .collect()
    } else {
        all
    }
}

/// One row of the table.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FaultRow {
    /// The scenario's name.
    pub scenario: &'static str,
    /// The fault's name.
    pub fault: &'static str,
    /// Estimates the default estimator gave.
    pub estimates: usize,
    /// RMS position error over the estimates (mm).
    pub position_rmse_mm: f64,
    /// RMS velocity error over the estimates (mm/s); `None` without twists.
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
    /// Estimates flagged: status `disputed`, `degenerate` or `lost`.
    pub flagged: usize,
    /// Re-initialisations: entries into `converging` after the first.
    pub reinitialisations: usize,
    /// Estimates with a position error above 10x the clean RMSE (of the same source) and status `tracking` or
    /// `converging`.
    pub unflagged_wrong: usize,
    /// The largest position error of an estimate with status `tracking` or `converging` (mm).
    pub worst_unflagged_mm: f64,
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

/// The tracker's view of a case: its estimates, scored, and their per-estimate errors.
fn run_case(scenario: &Scenario, case: &Case) -> Result<(FaultRow, Vec<Point>), ExperimentError> {
    let data = simulate(scenario, &case.options)?;
    let mut config = TrackerConfig {
        noise_px: case.options.noise_px,
        ..TrackerConfig::default()
    };
    let scored = match case.source {
        Source::Measurements => track_and_score(&data, config)?,
        Source::Images(reflections) => {
            let (renderer, accuracy) = image_side(scenario, 500, case.options.seed)?;
            config.noise_px = image_noise_px(&accuracy);
            let truth = {
                let s = scenario.clone();
                let options = case.options.clone();
                move |t: f64| options.truth_at(&s, t)
            };
            let mut camera = SimulatedCamera::new(renderer, truth, case.options.seed);
            if let Some(fault) = reflections {
                camera = camera.with_reflections(fault);
            }
            let loop_config = LoopConfig {
                rate_hz: case.options.rate_hz,
                roi_slots: data.truth_poses.len(),
                ..LoopConfig::default()
            };
            let report = run_loop_with_progress(
                &mut camera,
                &scenario.camera,
                &scenario.target,
                config,
                &loop_config,
                None,
            )?;
            score(&data, report.estimates, report.wall_s)?
        }
    };
    let (metrics, estimates) = (&scored.metrics, &scored.estimates);
    let lost = scored.count(TrackStatus::Lost);
    let points: Vec<Point> = estimates
        .iter()
        .zip(&scored.errors.position_m)
        .map(|(e, error): (&Estimate, _)| Point {
            t_s: e.t_ref_s,
            error_m: error.norm(),
            status: e.status,
        })
        .collect();
    let reinitialisations = points
        .windows(2)
        .filter(|w| {
            w[1].status == TrackStatus::Converging && w[0].status != TrackStatus::Converging
        })
        .count();
    let row = FaultRow {
        scenario: scenario.kind.name(),
        fault: case.name,
        estimates: estimates.len(),
        position_rmse_mm: metrics.position_rmse_mm,
        velocity_rmse_mm_s: metrics.velocity_rmse_mm_s,
        fault_end_s: case.fault_end_s,
        recovery_ms: None,
        recovered: true,
        lost,
        flagged: points.iter().filter(|p| !p.status.is_vouched_for()).count(),
        reinitialisations,
        unflagged_wrong: 0,
        worst_unflagged_mm: points
            .iter()
            .filter(|p| p.status.is_vouched_for())
            .map(|p| 1e3 * p.error_m)
            .fold(0.0, f64::max),
    };
    Ok((row, points))
}

/// Every row of the table for one scenario; the first case of each source is its clean run (it sets the thresholds).
/// `quick`: four measurement rows only.
///
/// ```
/// use roitrack_experiments::faults::scenario_rows;
/// use roitrack_sim::ScenarioKind;
///
/// let rows = scenario_rows(ScenarioKind::Orthoglide, true).unwrap();
/// assert_eq!(rows[0].fault, "clean");
/// // No fault leaves a wrong estimate presented as valid.
/// assert!(rows.iter().all(|r| r.unflagged_wrong == 0 && r.recovered), "{rows:?}");
/// ```
pub fn scenario_rows(kind: ScenarioKind, quick: bool) -> Result<Vec<FaultRow>, ExperimentError> {
    let scenario = Scenario::new(kind, 1);
    let cases = cases(&scenario, quick);
    // The cases are independent: run them on threads.
    let results: Vec<Result<(FaultRow, Vec<Point>), ExperimentError>> = std::thread::scope(|s| {
        let handles: Vec<_> = cases
            .iter()
            .map(|case| s.spawn(|| run_case(&scenario, case)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a fault case panicked"))
            .collect()
    });
    let results = results.into_iter().collect::<Result<Vec<_>, _>>()?;
    // Per case, the clean RMSE of its source (the first case of that source).
    let clean_rmse_m: Vec<f64> = cases
        .iter()
        .map(|case| {
            let same = |c: &Case| {
                std::mem::discriminant(&c.source) == std::mem::discriminant(&case.source)
            };
            let first = cases
                .iter()
                .position(same)
                .expect("a case is its own source");
            results[first].0.position_rmse_mm * 1e-3
        })
        .collect();
    Ok(results
        .into_iter()
        .zip(clean_rmse_m)
        .map(|((mut row, points), clean_rmse_m)| {
            row.unflagged_wrong = points
                .iter()
                .filter(|p| p.error_m > WRONG_FACTOR * clean_rmse_m && p.status.is_vouched_for())
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

/// The scenarios of the full table (the quick one has orthoglide only).
pub fn scenarios(quick: bool) -> &'static [ScenarioKind] {
    if quick {
        &[ScenarioKind::Orthoglide]
    } else {
        &[ScenarioKind::Orthoglide, ScenarioKind::Random]
    }
}

/// The table's header line.
pub fn header() -> String {
    format!(
        "{:<11} {:<26} {:>9} {:>10} {:>12} {:>5} {:>7} {:>8} {:>10} {:>15}",
        "scenario",
        "fault",
        "pos mm",
        "vel mm/s",
        "recover ms",
        "lost",
        "reinit",
        "flagged",
        "unflagged",
        "worst unflg mm"
    )
}

/// One row of the table.
pub fn line(row: &FaultRow) -> String {
    let recovery = match (row.fault_end_s, row.recovery_ms) {
        (None, _) => "-".to_string(),
        (Some(_), Some(ms)) => format!("{ms:.1}"),
        (Some(_), None) => "never".to_string(),
    };
    format!(
        "{:<11} {:<26} {:>9.4} {:>10.2} {:>12} {:>5} {:>7} {:>8} {:>10} {:>15.3}",
        row.scenario,
        row.fault,
        row.position_rmse_mm,
        row.velocity_rmse_mm_s.unwrap_or(f64::NAN),
        recovery,
        row.lost,
        row.reinitialisations,
        row.flagged,
        row.unflagged_wrong,
        row.worst_unflagged_mm
    )
}

/// The explanation printed under the table.
pub fn footnote() -> String {
    format!(
        "recover: from the end of the fault until the position error stays within {RECOVERY_FACTOR}x the clean \
         RMSE for {} ms; flagged: estimates with status disputed, degenerate or lost; unflagged: estimates off \
         by more than {WRONG_FACTOR}x the clean RMSE (of the same source) with status tracking or converging \
         (target 0); worst unflg: the largest error of such an estimate",
        1e3 * RECOVERY_HOLD_S
    )
}

/// Header, rows and footnote.
pub fn table(rows: &[FaultRow]) -> String {
    let mut out = header() + "\n";
    for row in rows {
        out += &(line(row) + "\n");
    }
    out + &footnote() + "\n"
}

impl FaultRow {
    /// The row as one JSON object (its fields by name).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a fault row holds only numbers and strings")
    }
}
