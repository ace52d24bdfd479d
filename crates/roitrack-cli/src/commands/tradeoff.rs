//! `roitrack tradeoff`: velocity noise against velocity lag, for the paper's loop over its gain and for the Kalman
//! filter over its process noise, on one scenario. Writes a CSV and a plot (PNG and SVG).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use roitrack_core::JacobianKind;
use roitrack_core::estimator::{EstimatorConfig, KalmanTuning, TrackerConfig, VvsSettings};
use roitrack_plot::{Chart, Series, Style, write_chart};
use roitrack_sim::{Scenario, SimulationOptions, simulate};

use super::demo::score;
use super::simulate::ScenarioArg;

/// Velocity RMSE against velocity lag: the paper's loop at gains 0.2-1.0 and the Kalman filter over its tuning range.
#[derive(Debug, Args)]
pub struct TradeoffArgs {
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder for tradeoff.csv, tradeoff.png and tradeoff.svg.
    #[arg(long, default_value = "out/tradeoff")]
    pub out: PathBuf,
}

/// Paper gains and Kalman linear-acceleration spectral densities ((m/s²)²/Hz) swept.
const GAINS: [f64; 9] = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0];
const ACCEL_PSDS: [f64; 9] = [0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0];

pub fn run(args: &TradeoffArgs) -> Result<()> {
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let data = simulate(
        &scenario,
        &SimulationOptions {
            seed: args.seed,
            ..Default::default()
        },
    )?;
    std::fs::create_dir_all(&args.out)?;
    let mut csv = roitrack_formats::AtomicFile::create(args.out.join("tradeoff.csv"))?;
    writeln!(
        csv,
        "estimator,parameter,value,velocity_rmse_mm_s,velocity_lag_samples,velocity_lag_subsample,velocity_lag_ms,position_rmse_mm"
    )?;
    println!(
        "{:<8} {:>14} {:>12} {:>10} {:>12} {:>9}",
        "scheme", "parameter", "vel mm/s", "lag smp", "lag (sub)", "pos mm"
    );
    let mut paper = Vec::new();
    let mut kalman = Vec::new();
    let runs = GAINS
        .iter()
        .map(|&g| ("paper", "gain", g))
        .chain(ACCEL_PSDS.iter().map(|&q| ("kalman", "accel_psd", q)));
    for (scheme, parameter, value) in runs {
        let estimator = if scheme == "paper" {
            EstimatorConfig::Vvs(VvsSettings {
                jacobian: JacobianKind::Paper,
                gain: value,
                iterations: 1,
            })
        } else {
            EstimatorConfig::Kalman(KalmanTuning {
                linear_accel_psd: value,
                ..KalmanTuning::default()
            })
        };
        let config = TrackerConfig {
            estimator,
            ..TrackerConfig::default()
        };
        let (m, _) = score(&data, config, |_| Ok(()))?;
        let vel = m.velocity_rmse_mm_s.unwrap_or(f64::NAN);
        let lag = m.velocity_lag_samples.unwrap_or(0);
        let sub = m.velocity_lag_subsample.unwrap_or(f64::NAN);
        writeln!(
            csv,
            "{scheme},{parameter},{value},{vel},{lag},{sub},{},{}",
            m.velocity_lag_ms.unwrap_or(f64::NAN),
            m.position_rmse_mm
        )?;
        println!(
            "{scheme:<8} {:>14} {vel:>12.2} {lag:>10} {sub:>12.2} {:>9.4}",
            format!("{parameter}={value}"),
            m.position_rmse_mm
        );
        let point = (
            (sub, vel),
            if scheme == "paper" {
                format!("  λ={value}")
            } else {
                format!("  q={value}")
            },
        );
        if scheme == "paper" {
            paper.push(point)
        } else {
            kalman.push(point)
        }
    }
    csv.finish()?;
    let series = |name: &str, pts: Vec<((f64, f64), String)>| {
        let (points, labels): (Vec<_>, Vec<_>) = pts.into_iter().unzip();
        Series::new(name, points, Style::LinePoints).with_labels(labels)
    };
    let chart = Chart {
        title: format!(
            "{}: velocity error vs lag (seed {}, 0.1 px, 4 kHz ROIs, 400 Hz estimates)",
            scenario.kind.name(),
            args.seed
        ),
        x_label: "velocity lag (estimator samples of 2.5 ms, cross-correlation peak)".into(),
        y_label: "linear velocity RMSE (mm/s)".into(),
        series: vec![
            series("paper's VVS loop, gain λ (1 iteration)", paper),
            series("Kalman filter (default), accel. PSD q (m²/s³)", kalman),
        ],
        log_y: true,
    };
    let (png, svg) = write_chart(&args.out.join("tradeoff"), &chart)?;
    eprintln!(
        "roitrack: wrote {}, {} and tradeoff.csv",
        png.display(),
        svg.display()
    );
    Ok(())
}
