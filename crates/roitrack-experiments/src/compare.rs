//! Every estimator and baseline on one scenario at the measurement level (ideal centroids with Gaussian noise),
//! scored against the ground truth: the accuracy tables of `docs/results.md`.

use roitrack_core::JacobianKind;
use roitrack_estimators::{EstimatorConfig, KalmanTuning, TrackStatus, TrackerConfig, VvsSettings};
use roitrack_eval::Metrics;
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};

use crate::ExperimentError;
use roitrack_demo::scoring::track_and_score;

/// The estimators compared: label, estimator.
pub fn lineup() -> [(&'static str, EstimatorConfig); 5] {
    let paper = |gain| {
        EstimatorConfig::Vvs(VvsSettings {
            jacobian: JacobianKind::Paper,
            gain,
            iterations: 1,
        })
    };
    [
        (
            "kalman (default)",
            EstimatorConfig::Kalman(KalmanTuning::default()),
        ),
        ("paper, gain 1.0", paper(1.0)),
        ("paper, gain 0.5", paper(0.5)),
        ("batch baseline", EstimatorConfig::Batch),
        ("static baseline", EstimatorConfig::Static),
    ]
}

/// One estimator's accuracy.
#[derive(Debug, Clone)]
pub struct CompareRow {
    /// The estimator's name in the table ([`lineup`]).
    pub label: &'static str,
    /// Its accuracy against the truth.
    pub metrics: Metrics,
    /// Estimates flagged degenerate.
    pub degenerate: usize,
    /// Wall time per control step (µs).
    pub us_per_estimate: f64,
}

/// Simulates `kind` (seed, centroid noise) and tracks it with every estimator of [`lineup`], each told the noise.
pub fn compare(
    kind: ScenarioKind,
    seed: u64,
    noise_px: f64,
) -> Result<Vec<CompareRow>, ExperimentError> {
    compare_on(&Scenario::new(kind, seed), seed, noise_px)
}

/// [`compare`] on a scenario of one's own (another camera, target, distance or speed).
pub fn compare_on(
    scenario: &Scenario,
    seed: u64,
    noise_px: f64,
) -> Result<Vec<CompareRow>, ExperimentError> {
    let options = SimulationOptions {
        seed,
        noise_px,
        ..SimulationOptions::default()
    };
    let run = simulate(scenario, &options)?;
    lineup()
        .into_iter()
        .map(|(label, estimator)| {
            let config = TrackerConfig {
                estimator,
                noise_px,
                ..TrackerConfig::default()
            };
            let scored = track_and_score(&run, config)?;
            Ok(CompareRow {
                label,
                degenerate: scored.count(TrackStatus::Degenerate),
                us_per_estimate: scored.us_per_estimate(),
                metrics: scored.metrics,
            })
        })
        .collect()
}

/// The rows as a table with a header line.
pub fn table(rows: &[CompareRow]) -> String {
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
    for r in rows {
        let m = &r.metrics;
        let vel = m.velocity_rmse_xyz_mm_s.unwrap_or([f64::NAN; 3]);
        out += &format!(
            "{:<18} {:>9.4} {:>7.4}/{:<7.4} {:>8.4} {:>9.2} {:>9.2} {:>9.2} {:>5} ({:>4.1}) {:>6} {:>9.2}\n",
            r.label,
            m.position_rmse_mm,
            m.position_rmse_xyz_mm[0],
            m.position_rmse_xyz_mm[1],
            m.rotation_rmse_deg,
            m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
            vel[2],
            m.angular_velocity_rmse_deg_s.unwrap_or(f64::NAN),
            m.velocity_lag_samples.unwrap_or(0),
            m.velocity_lag_ms.unwrap_or(f64::NAN),
            r.degenerate,
            r.us_per_estimate
        );
    }
    out
}

/// One row as a JSON object: label, time per step and metrics.
pub fn json(row: &CompareRow) -> String {
    format!(
        "{{\"estimator\":\"{}\",\"us_per_estimate\":{},\"metrics\":{}}}",
        row.label,
        row.us_per_estimate,
        row.metrics.to_json()
    )
}
