//! `roitrack demo`: the main job, end to end from pixels. A simulated ROI camera renders each ROI the scheduler asks
//! for; the acquisition thread centroids it and the estimation thread tracks, joined by lock-free queues. The same
//! scenario is also tracked from ideal measurements (the measurement-level simulator) to show what the image side
//! costs. Prints a table of accuracy (SPEC section 9), writes the figures (after the paper's figures 5-7) and every
//! estimate in SPEC section 8's formats.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Args;
use roitrack_core::estimator::{Estimate, TrackStatus, TrackerConfig};
use roitrack_core::{PoseSample, TwistSample};
use roitrack_eval::{EvalOptions, Metrics, evaluate};
use roitrack_image::{CentroidOptions, RoiRenderer, SensorModel, centroid_accuracy};
use roitrack_pipeline::cameras::SimulatedCamera;
use roitrack_pipeline::realtime::{LoopConfig, LoopReport, run_loop_with_progress};
use roitrack_pipeline::scheduler::ScheduleOrder;
use roitrack_plot::figures::{TrackSeries, TruthSeries, write_figures};
use roitrack_sim::{Scenario, SimulatedRun, SimulationOptions, simulate};

use super::simulate::{ScenarioArg, write_run};
use super::track::{EstimateWriter, EstimatorArg, TrackSummary, track_stream};

/// Run a built-in scenario end to end from rendered ROIs through the two-thread loop; print the accuracy of the
/// default estimator, the paper's scheme and the static baseline; write plots and estimates.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Which scenario.
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    /// Output folder: inputs, ground truth, estimates, figures.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Seed of the simulation (motion, pixel noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Pace the camera at the ROI rate (4 kHz, real time) instead of running free.
    #[arg(long)]
    pub paced: bool,
    /// Order in which the scheduler reads the points: bit-reversed, row-major, or active (most informative next).
    #[arg(long, value_enum, default_value = "bitrev")]
    pub order: ScheduleOrderArg,
    /// Print one JSON object per row instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ScheduleOrderArg {
    Bitrev,
    Rowmajor,
    Active,
}

impl From<ScheduleOrderArg> for ScheduleOrder {
    fn from(o: ScheduleOrderArg) -> Self {
        match o {
            ScheduleOrderArg::Bitrev => ScheduleOrder::BitReversed,
            ScheduleOrderArg::Rowmajor => ScheduleOrder::RowMajor,
            ScheduleOrderArg::Active => ScheduleOrder::Active,
        }
    }
}

/// The estimators the demo compares: label, file stem, estimator, VVS gain.
const LINEUP: [(&str, &str, EstimatorArg, f64); 3] = [
    ("kalman (default)", "kalman", EstimatorArg::Kalman, 1.0),
    ("paper, gain 0.5", "paper", EstimatorArg::Paper, 0.5),
    ("static baseline", "static", EstimatorArg::Static, 1.0),
];

/// One row of the table.
struct Row {
    label: String,
    source: &'static str,
    metrics: Metrics,
    us_per_estimate: f64,
    degenerate: usize,
    notes: String,
}

pub fn run(args: &DemoArgs) -> Result<()> {
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let options = SimulationOptions {
        seed: args.seed,
        ..SimulationOptions::default()
    };
    let sensor = SensorModel::default();
    let renderer = RoiRenderer::new(scenario.camera.clone(), scenario.target.clone(), sensor)
        .context("invalid sensor model")?;
    // The centroid noise of the image side, measured on rendered ROIs: the ideal-centroid runs get the same noise, so
    // the two rows of an estimator compare the image side with a perfect one of equal precision, and the trackers are
    // told that noise.
    let accuracy = centroid_accuracy(&renderer, &CentroidOptions::default(), 32, 2000, args.seed);
    let noise_px = image_noise_px(&accuracy);
    let options = SimulationOptions {
        noise_px,
        ..options
    };
    let data = simulate(&scenario, &options)?;
    write_run(&data, &args.out)?;
    let slots = data.truth_poses.len();
    eprintln!(
        "roitrack demo: {} scenario, {:.3} s, {} ROI slots at {} Hz, {} estimators from rendered ROIs (two threads) \
         and from ideal centroids; centroid error of the image side over {} ROIs: bias {:+.4}/{:+.4} px, std \
         {:.4}/{:.4} px (u/v); output in {}",
        scenario.kind.name(),
        scenario.duration_s,
        slots,
        options.rate_hz,
        LINEUP.len(),
        accuracy.count,
        accuracy.bias_u_px,
        accuracy.bias_v_px,
        accuracy.std_u_px,
        accuracy.std_v_px,
        args.out.display()
    );
    let bar = indicatif::ProgressBar::new((slots * LINEUP.len()) as u64).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {percent:>3}% ROIs {msg} ({elapsed})")
            .expect("valid progress template"),
    );
    let mut rows = Vec::new();
    let mut series = Vec::new();
    for (k, (label, stem, estimator, gain)) in LINEUP.into_iter().enumerate() {
        let config = TrackerConfig {
            estimator: estimator.with_gain(gain),
            noise_px,
            ..TrackerConfig::default()
        };
        bar.set_message(label);
        // From pixels, through the real-time loop.
        let camera = SimulatedCamera::new(
            renderer.clone(),
            {
                let s = scenario.clone();
                move |t: f64| s.state_at(t)
            },
            args.seed,
        );
        let mut loop_config = LoopConfig {
            rate_hz: options.rate_hz,
            paced: args.paced,
            roi_slots: slots,
            ..LoopConfig::default()
        };
        loop_config.scheduler.order = args.order.into();
        loop_config.scheduler.noise_px = noise_px;
        let done = AtomicUsize::new(0);
        let finished = AtomicBool::new(false);
        let report = std::thread::scope(|scope| {
            scope.spawn(|| {
                while !finished.load(Ordering::Relaxed) {
                    bar.set_position((k * slots + done.load(Ordering::Relaxed)) as u64);
                    std::thread::sleep(Duration::from_millis(100));
                }
            });
            let report = run_loop_with_progress(
                camera,
                &scenario.camera,
                &scenario.target,
                config,
                &loop_config,
                Some(&done),
            );
            finished.store(true, Ordering::Relaxed);
            report
        })?;
        bar.set_position(((k + 1) * slots) as u64);
        let metrics = write_and_score(&data, &report.estimates, &args.out, stem)?;
        series.push(track_series(label, &report.estimates));
        rows.push(Row {
            label: label.to_string(),
            source: "images",
            metrics,
            us_per_estimate: 1e6 * report.wall_s / report.estimates.len().max(1) as f64,
            degenerate: count(&report.estimates, TrackStatus::Degenerate),
            notes: loop_notes(&report),
        });
        // From ideal centroids, for comparison.
        let (metrics, summary) = score(&data, config, |_| Ok(()))?;
        rows.push(Row {
            label: label.to_string(),
            source: "centroids",
            metrics,
            us_per_estimate: summary.us_per_estimate(),
            degenerate: summary.degenerate,
            notes: String::new(),
        });
    }
    bar.finish_and_clear();
    let truth = TruthSeries {
        t_s: data.truth_poses.iter().map(|p| p.t_s).collect(),
        position_m: data
            .truth_poses
            .iter()
            .map(|p| p.cam_from_obj.translation.vector.into())
            .collect(),
        velocity_mps: data
            .truth_twists
            .iter()
            .map(|w| w.velocity_mps.into())
            .collect(),
    };
    let figures = write_figures(&args.out, scenario.kind.name(), &truth, &series)?;
    if args.json {
        for r in &rows {
            println!(
                "{{\"estimator\":\"{}\",\"source\":\"{}\",\"us_per_estimate\":{},\"metrics\":{}}}",
                r.label,
                r.source,
                r.us_per_estimate,
                r.metrics.to_json()
            );
        }
    } else {
        print!("{}", table(&rows));
        println!(
            "images: rendered ROIs through the two-thread loop (us/step includes rendering); centroids: ideal \
             centroids with the image side's measured noise, {:.4} px.",
            options.noise_px
        );
    }
    eprintln!(
        "roitrack demo: wrote {} figures and the estimates of each estimator to {}",
        figures.len(),
        args.out.display()
    );
    Ok(())
}

/// The centroid noise (px per axis) the trackers are told for rendered ROIs: the measured spread, at least 0.005 px.
pub fn image_noise_px(accuracy: &roitrack_image::CentroidAccuracy) -> f64 {
    (0.5 * (accuracy.std_u_px.powi(2) + accuracy.std_v_px.powi(2)))
        .sqrt()
        .max(0.005)
}

fn count(estimates: &[Estimate], status: TrackStatus) -> usize {
    estimates.iter().filter(|e| e.status == status).count()
}

fn loop_notes(r: &LoopReport) -> String {
    let mut latencies = r.latencies_us.clone();
    latencies.sort_by(f64::total_cmp);
    let pct = |q: f64| {
        latencies
            .get(((latencies.len() as f64 - 1.0) * q) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    format!(
        "{} ROIs, {} rejected, {} dropped, {} init, latency p50/p99 {:.0}/{:.0} us",
        r.rois,
        r.rejections.total(),
        r.dropped,
        r.initialisations,
        pct(0.5),
        pct(0.99)
    )
}

fn track_series(label: &str, estimates: &[Estimate]) -> TrackSeries {
    TrackSeries {
        label: label.to_string(),
        t_s: estimates.iter().map(|e| e.t_ref_s).collect(),
        position_m: estimates
            .iter()
            .map(|e| e.state.cam_t_obj_m.into())
            .collect(),
        velocity_mps: estimates
            .iter()
            .map(|e| e.state.velocity_mps.into())
            .collect(),
        residual_rms_px: estimates.iter().map(|e| e.residual_rms_px).collect(),
    }
}

/// Writes `STEM_poses.tum`, `STEM_twists.csv`, `STEM_diagnostics.csv` and scores the estimates.
fn write_and_score(
    data: &SimulatedRun,
    estimates: &[Estimate],
    dir: &Path,
    stem: &str,
) -> Result<Metrics> {
    let mut writer = EstimateWriter::create(
        &dir.join(format!("{stem}_poses.tum")),
        &dir.join(format!("{stem}_twists.csv")),
        Some(&dir.join(format!("{stem}_diagnostics.csv"))),
    )?;
    for e in estimates {
        writer.write(e)?;
    }
    writer.finish()?;
    score_estimates(data, estimates)
}

/// Scores estimates against a simulated run's ground truth.
pub fn score_estimates(data: &SimulatedRun, estimates: &[Estimate]) -> Result<Metrics> {
    let poses: Vec<PoseSample> = estimates
        .iter()
        .map(|e| PoseSample::from_state(e.t_ref_s, &e.state))
        .collect();
    let twists: Vec<TwistSample> = estimates
        .iter()
        .map(|e| TwistSample::from_state(e.t_ref_s, &e.state))
        .collect();
    Ok(evaluate(
        &data.truth_poses,
        Some(&data.truth_twists),
        &poses,
        Some(&twists),
        &EvalOptions::default(),
    )?)
}

/// Tracks a simulated run's ideal measurements with `config`, handing each estimate to `sink`, and scores it.
pub fn score(
    data: &SimulatedRun,
    config: TrackerConfig,
    mut sink: impl FnMut(&Estimate) -> Result<()>,
) -> Result<(Metrics, TrackSummary)> {
    let mut poses = Vec::new();
    let mut twists = Vec::new();
    let summary = track_stream(
        &data.camera,
        &data.target,
        config,
        data.measurements.iter().map(|m| Ok(*m)),
        |e| {
            poses.push(PoseSample::from_state(e.t_ref_s, &e.state));
            twists.push(TwistSample::from_state(e.t_ref_s, &e.state));
            sink(e)
        },
    )?;
    let metrics = evaluate(
        &data.truth_poses,
        Some(&data.truth_twists),
        &poses,
        Some(&twists),
        &EvalOptions::default(),
    )?;
    Ok((metrics, summary))
}

fn table(rows: &[Row]) -> String {
    let mut out = format!(
        "{:<18} {:<9} {:>8} {:>15} {:>8} {:>9} {:>9} {:>12} {:>5} {:>8}  {}\n",
        "estimator",
        "from",
        "pos mm",
        "pos x/y mm",
        "rot deg",
        "vel mm/s",
        "w deg/s",
        "lag smp(ms)",
        "degen",
        "us/step",
        "loop"
    );
    for r in rows {
        let m = &r.metrics;
        out += &format!(
            "{:<18} {:<9} {:>8.4} {:>7.4}/{:<7.4} {:>8.4} {:>9.2} {:>9.2} {:>5} ({:>4.1}) {:>5} {:>8.2}  {}\n",
            r.label,
            r.source,
            m.position_rmse_mm,
            m.position_rmse_xyz_mm[0],
            m.position_rmse_xyz_mm[1],
            m.rotation_rmse_deg,
            m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
            m.angular_velocity_rmse_deg_s.unwrap_or(f64::NAN),
            m.velocity_lag_samples.unwrap_or(0),
            m.velocity_lag_ms.unwrap_or(f64::NAN),
            r.degenerate,
            r.us_per_estimate,
            r.notes
        );
    }
    out
}
