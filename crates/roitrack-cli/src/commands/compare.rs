//! `roitrack compare`: every estimator and baseline on one scenario at the measurement level (ideal centroids with
//! Gaussian noise), scored against the ground truth: the accuracy tables of docs/results.md.

use anyhow::Result;
use clap::Args;
use roitrack_core::estimator::TrackerConfig;
use roitrack_sim::{Scenario, SimulationOptions, simulate};

use super::demo::score;
use super::simulate::ScenarioArg;
use super::track::EstimatorArg;

/// Track one simulated scenario with every estimator and baseline and print their accuracy (SPEC section 9).
#[derive(Debug, Args)]
pub struct CompareArgs {
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Centroid noise (px, per axis).
    #[arg(long, default_value_t = 0.1)]
    pub noise_px: f64,
    /// Print one JSON object per estimator instead of a table.
    #[arg(long)]
    pub json: bool,
}

const LINEUP: [(&str, EstimatorArg, f64); 5] = [
    ("kalman (default)", EstimatorArg::Kalman, 1.0),
    ("paper, gain 1.0", EstimatorArg::Paper, 1.0),
    ("paper, gain 0.5", EstimatorArg::Paper, 0.5),
    ("batch baseline", EstimatorArg::Batch, 1.0),
    ("static baseline", EstimatorArg::Static, 1.0),
];

pub fn run(args: &CompareArgs) -> Result<()> {
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let options = SimulationOptions {
        seed: args.seed,
        noise_px: args.noise_px,
        ..SimulationOptions::default()
    };
    let data = simulate(&scenario, &options)?;
    if !args.json {
        println!(
            "{:<18} {:>9} {:>15} {:>8} {:>9} {:>9} {:>9} {:>12} {:>6} {:>9}",
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
    }
    for (label, estimator, gain) in LINEUP {
        let config = TrackerConfig {
            estimator: estimator.with_gain(gain),
            noise_px: args.noise_px,
            ..TrackerConfig::default()
        };
        let (m, s) = score(&data, config, |_| Ok(()))?;
        if args.json {
            println!(
                "{{\"estimator\":\"{label}\",\"us_per_estimate\":{},\"metrics\":{}}}",
                s.us_per_estimate(),
                m.to_json()
            );
            continue;
        }
        let vel = m.velocity_rmse_xyz_mm_s.unwrap_or([f64::NAN; 3]);
        println!(
            "{:<18} {:>9.4} {:>7.4}/{:<7.4} {:>8.4} {:>9.2} {:>9.2} {:>9.2} {:>5} ({:>4.1}) {:>6} {:>9.2}",
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
    Ok(())
}
