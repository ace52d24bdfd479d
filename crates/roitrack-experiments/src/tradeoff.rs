//! Velocity noise against velocity lag, for the paper's loop over its gain and for the Kalman filter over its process
//! noise, on one scenario: what a smoother velocity costs in delay.

use roitrack_core::JacobianKind;
use roitrack_estimators::{EstimatorConfig, KalmanTuning, TrackerConfig, VvsSettings};
use roitrack_eval::Metrics;
use roitrack_plot::{Chart, Series, Style};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};

use crate::ExperimentError;
use roitrack_demo::scoring::track_and_score;

/// The gains λ of the paper's loop swept.
pub const GAINS: [f64; 9] = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0];
/// The Kalman filter's linear-acceleration spectral densities swept ((m/s²)²/Hz).
pub const ACCEL_PSDS: [f64; 9] = [0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0];

/// Which scheme a point of the trade-off belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheme {
    /// The paper's loop, swept over its gain λ.
    Paper,
    /// The Kalman filter, swept over its linear acceleration density q.
    Kalman,
}

impl Scheme {
    /// The scheme's name in tables and files.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Kalman => "kalman",
        }
    }

    /// The name of the swept parameter.
    pub fn parameter(&self) -> &'static str {
        match self {
            Self::Paper => "gain",
            Self::Kalman => "accel_psd",
        }
    }
}

/// One point of the trade-off.
#[derive(Debug, Clone)]
pub struct TradeoffPoint {
    /// The scheme swept.
    pub scheme: Scheme,
    /// The parameter's value (gain, or (m/s²)²/Hz).
    pub value: f64,
    /// The accuracy at that value, lag included.
    pub metrics: Metrics,
}

/// Tracks the scenario (0.1 px, 4 kHz) with every gain of the paper's loop (1 iteration, its own Jacobian) and every
/// process noise of the Kalman filter.
///
/// ```
/// use roitrack_experiments::tradeoff::{Scheme, sweep};
/// use roitrack_sim::ScenarioKind;
///
/// let points = sweep(ScenarioKind::Orthoglide, 1).unwrap();
/// let lag = |scheme, value| {
///     let p = points.iter().find(|p| p.scheme == scheme && p.value == value).unwrap();
///     p.metrics.velocity_lag_subsample.unwrap()
/// };
/// // A lower gain smooths the paper's velocity, and delays it.
/// assert!(lag(Scheme::Paper, 0.2) > lag(Scheme::Paper, 1.0));
/// ```
pub fn sweep(kind: ScenarioKind, seed: u64) -> Result<Vec<TradeoffPoint>, ExperimentError> {
    sweep_on(&Scenario::new(kind, seed), seed)
}

/// [`sweep`] on a scenario of one's own (another camera, target, distance or speed).
pub fn sweep_on(scenario: &Scenario, seed: u64) -> Result<Vec<TradeoffPoint>, ExperimentError> {
    let run = simulate(
        scenario,
        &SimulationOptions {
            seed,
            ..Default::default()
        },
    )?;
    let points = GAINS
        .iter()
        .map(|&g| (Scheme::Paper, g))
        .chain(ACCEL_PSDS.iter().map(|&q| (Scheme::Kalman, q)));
    points
        .map(|(scheme, value)| {
            let estimator = match scheme {
                Scheme::Paper => EstimatorConfig::Vvs(VvsSettings {
                    jacobian: JacobianKind::Paper,
                    gain: value,
                    iterations: 1,
                }),
                // The process noise held at the value swept (not learnt), and the noise told.
                Scheme::Kalman => EstimatorConfig::Kalman(KalmanTuning {
                    linear_accel_psd: value,
                    adapt_noise: false,
                    adapt_motion: false,
                    ..KalmanTuning::default()
                }),
            };
            let config = TrackerConfig {
                estimator,
                ..TrackerConfig::default()
            };
            let metrics = track_and_score(&run, config)?.metrics;
            Ok(TradeoffPoint {
                scheme,
                value,
                metrics,
            })
        })
        .collect()
}

/// The CSV's header line.
pub const CSV_HEADER: &str = "estimator,parameter,value,velocity_rmse_mm_s,velocity_lag_samples,velocity_lag_subsample,velocity_lag_ms,position_rmse_mm";

/// One point as a CSV row.
pub fn csv_row(p: &TradeoffPoint) -> String {
    let m = &p.metrics;
    format!(
        "{},{},{},{},{},{},{},{}",
        p.scheme.name(),
        p.scheme.parameter(),
        p.value,
        m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
        m.velocity_lag_samples.unwrap_or(0),
        m.velocity_lag_subsample.unwrap_or(f64::NAN),
        m.velocity_lag_ms.unwrap_or(f64::NAN),
        m.position_rmse_mm
    )
}

/// The table's header line.
pub fn table_header() -> String {
    format!(
        "{:<8} {:>14} {:>12} {:>10} {:>12} {:>9}",
        "scheme", "parameter", "vel mm/s", "lag smp", "lag (sub)", "pos mm"
    )
}

/// One point as a table row.
pub fn table_row(p: &TradeoffPoint) -> String {
    let m = &p.metrics;
    format!(
        "{:<8} {:>14} {:>12.2} {:>10} {:>12.2} {:>9.4}",
        p.scheme.name(),
        format!("{}={}", p.scheme.parameter(), p.value),
        m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
        m.velocity_lag_samples.unwrap_or(0),
        m.velocity_lag_subsample.unwrap_or(f64::NAN),
        m.position_rmse_mm
    )
}

/// The trade-off as a chart: velocity RMSE (log scale) against the sub-sample velocity lag, one curve per scheme.
pub fn chart(points: &[TradeoffPoint], kind: ScenarioKind, seed: u64) -> Chart {
    let series = |scheme: Scheme, name: &str, symbol: &str| {
        let (points, labels): (Vec<_>, Vec<_>) = points
            .iter()
            .filter(|p| p.scheme == scheme)
            .map(|p| {
                (
                    (
                        p.metrics.velocity_lag_subsample.unwrap_or(f64::NAN),
                        p.metrics.velocity_rmse_mm_s.unwrap_or(f64::NAN),
                    ),
                    format!("  {symbol}={}", p.value),
                )
            })
            .unzip();
        Series::new(name, points, Style::LinePoints).with_labels(labels)
    };
    Chart {
        title: format!(
            "{}: velocity error vs lag (seed {seed}, 0.1 px, 4 kHz ROIs, 400 Hz estimates)",
            kind.name()
        ),
        x_label: "velocity lag (estimator samples of 2.5 ms, cross-correlation peak)".into(),
        y_label: "linear velocity RMSE (mm/s)".into(),
        series: vec![
            series(Scheme::Paper, "paper's VVS loop, gain λ (1 iteration)", "λ"),
            series(
                Scheme::Kalman,
                "Kalman filter (hand-tuned: q held), accel. PSD q (m²/s³)",
                "q",
            ),
        ],
        log_y: true,
    }
}
