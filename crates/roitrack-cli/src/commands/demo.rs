//! `roitrack demo`: the main job on a built-in scenario, end to end: simulate, track with the default estimator and
//! the baselines, score each against the ground truth, print a table and write every file.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use roitrack_core::estimator::{Estimate, TrackerConfig};
use roitrack_core::{PoseSample, TwistSample};
use roitrack_eval::{EvalOptions, Metrics, evaluate};
use roitrack_sim::{Scenario, SimulatedRun, SimulationOptions, simulate};

use super::simulate::{ScenarioArg, write_run};
use super::track::{EstimateWriter, EstimatorArg, TrackSummary, track_stream};

/// Run a built-in scenario end to end and print the accuracy of the default estimator and the baselines.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Which scenario.
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    /// Output folder: the simulated inputs and ground truth, and each estimator's poses and twists.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Seed of the simulation.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print one JSON object per estimator instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// The estimators the demo compares: label, estimator, VVS gain.
const LINEUP: [(&str, EstimatorArg, f64); 5] = [
    ("kalman (default)", EstimatorArg::Kalman, 1.0),
    ("paper, gain 1.0", EstimatorArg::Paper, 1.0),
    ("paper, gain 0.5", EstimatorArg::Paper, 0.5),
    ("batch baseline", EstimatorArg::Batch, 1.0),
    ("static baseline", EstimatorArg::Static, 1.0),
];

pub fn run(args: &DemoArgs) -> Result<()> {
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let options = SimulationOptions {
        seed: args.seed,
        ..SimulationOptions::default()
    };
    let data = simulate(&scenario, &options)?;
    write_run(&data, &args.out)?;
    eprintln!(
        "roitrack demo: {} scenario, {} ROIs at {} Hz over {:.3} s, noise {} px, written to {}",
        scenario.kind.name(),
        data.measurements.len(),
        options.rate_hz,
        scenario.duration_s,
        options.noise_px,
        args.out.display()
    );
    let mut rows = Vec::new();
    for (label, estimator, gain) in LINEUP {
        let mut config = TrackerConfig {
            gain,
            ..TrackerConfig::default()
        };
        estimator.apply(&mut config);
        let stem = label.split([' ', ',']).next().unwrap_or(label);
        let stem = if gain == 1.0 {
            stem.to_string()
        } else {
            format!("{stem}_gain{gain}")
        };
        let poses_path = args.out.join(format!("{stem}_poses.tum"));
        let twists_path = args.out.join(format!("{stem}_twists.csv"));
        let diagnostics_path = args.out.join(format!("{stem}_diagnostics.csv"));
        let mut writer =
            EstimateWriter::create(&poses_path, &twists_path, Some(&diagnostics_path))?;
        let (metrics, summary) = score(&data, config, |e| writer.write(e))?;
        writer.finish()?;
        rows.push((label, metrics, summary));
    }
    if args.json {
        for (label, metrics, summary) in &rows {
            println!(
                "{{\"estimator\":\"{label}\",\"us_per_measurement\":{},\"us_per_estimate\":{},\"metrics\":{}}}",
                summary.us_per_measurement(),
                summary.us_per_estimate(),
                metrics.to_json()
            );
        }
    } else {
        print!("{}", table(&rows));
    }
    Ok(())
}

/// Tracks a simulated run with `config`, handing each estimate to `sink`, and scores it against the ground truth.
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

fn table(rows: &[(&str, Metrics, TrackSummary)]) -> String {
    let mut out = format!(
        "{:<18} {:>9} {:>15} {:>8} {:>9} {:>9} {:>9} {:>12} {:>6} {:>9}\n",
        "estimator",
        "pos mm",
        "pos x/y mm",
        "rot deg",
        "vel mm/s",
        "vz mm/s",
        "w deg/s",
        "lag smp(ms)",
        "degen",
        "us/step"
    );
    for (label, m, s) in rows {
        let vel = m.velocity_rmse_xyz_mm_s.unwrap_or([f64::NAN; 3]);
        out += &format!(
            "{:<18} {:>9.4} {:>7.4}/{:<7.4} {:>8.4} {:>9.2} {:>9.2} {:>9.2} {:>5} ({:>4.1}) {:>6} {:>9.2}\n",
            label,
            m.position_rmse_mm,
            m.position_rmse_xyz_mm[0],
            m.position_rmse_xyz_mm[1],
            m.rotation_rmse_deg,
            m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
            vel[2],
            m.angular_velocity_rmse_deg_s.unwrap_or(f64::NAN),
            m.velocity_lag_samples.unwrap_or(0),
            m.velocity_lag_ms.unwrap_or(f64::NAN),
            s.degenerate,
            s.us_per_estimate()
        );
    }
    out
}
