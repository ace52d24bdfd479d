//! Simulate your own camera and target, track with several estimators and score them against the ground truth.
//!
//! ```sh
//! cargo run --release -p roitrack --example simulate_and_evaluate
//! ```
//!
//! The camera is a 1280 x 800 sensor behind a distorting 8 mm lens; the target a 3 x 3 grid of 25 mm pitch with one
//! larger key blob; the motion the paper's orthoglide experiment, seen at 4 kHz with 0.15 px of centroid noise.

use roitrack::core::camera::{PinholeIntrinsics, PlumbBob};
use roitrack::eval::{EvalOptions, evaluate_estimates};
use roitrack::nalgebra::Vector3;
use roitrack::sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
use roitrack::{
    CameraModel, EstimatorConfig, Target, TargetPoint, TrackStatus, TrackerConfig, VvsSettings,
    track_all,
};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let camera = CameraModel::new(
        "my_camera",
        1280,
        800,
        PinholeIntrinsics {
            fx_px: 1150.0,
            fy_px: 1150.0,
            skew_px: 0.0,
            cx_px: 640.0,
            cy_px: 400.0,
        },
        PlumbBob::from_coefficients([-0.12, 0.05, 0.0, 0.0, 0.0]),
    )?;
    let points = (0..9)
        .map(|i| TargetPoint {
            id: i,
            point_in_obj_m: Vector3::new(
                0.025 * (f64::from(i % 3) - 1.0),
                0.025 * (f64::from(i / 3) - 1.0),
                0.0,
            ),
            // Point 0 is the key blob: larger, so a full frame can tell the target's orientation.
            diameter_m: Some(if i == 0 { 0.009 } else { 0.006 }),
        })
        .collect();
    let target = Target::new(points)?;
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1)
        .with_camera(camera)
        .with_target(target);
    println!(
        "the blobs stay at least {:.0} px inside the image",
        scenario.min_image_margin_px()
    );
    let noise_px = 0.15;
    let run = simulate(
        &scenario,
        &SimulationOptions {
            noise_px,
            ..SimulationOptions::default()
        },
    )?;
    println!(
        "{} measurements over {:.2} s; ground truth at every one",
        run.measurements.len(),
        scenario.duration_s
    );

    println!(
        "{:<22} {:>8} {:>9} {:>10} {:>8} {:>9}",
        "estimator", "pos mm", "rot deg", "vel mm/s", "lag ms", "tracking"
    );
    for (name, estimator) in [
        ("kalman (default)", EstimatorConfig::default()),
        (
            "paper's VVS, gain 0.5",
            EstimatorConfig::Vvs(VvsSettings {
                gain: 0.5,
                ..VvsSettings::default()
            }),
        ),
        ("batch baseline", EstimatorConfig::Batch),
        ("static baseline", EstimatorConfig::Static),
    ] {
        let config = TrackerConfig {
            estimator,
            noise_px,
            ..TrackerConfig::default()
        };
        let (estimates, report) = track_all(&run.camera, &run.target, config, &run.measurements)?;
        let m = evaluate_estimates(
            &run.truth_poses,
            &run.truth_twists,
            &estimates,
            &EvalOptions::default(),
        )?;
        println!(
            "{name:<22} {:>8.4} {:>9.4} {:>10.2} {:>8.1} {:>8.1}%",
            m.position_rmse_mm,
            m.rotation_rmse_deg,
            m.velocity_rmse_mm_s.unwrap_or(f64::NAN),
            m.velocity_lag_ms.unwrap_or(f64::NAN),
            100.0 * report.estimates.get(TrackStatus::Tracking) as f64
                / report.estimates.total().max(1) as f64
        );
    }
    Ok(())
}
