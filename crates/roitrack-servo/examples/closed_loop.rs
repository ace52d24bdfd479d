//! The closed loop from a program: each controller on the orthoglide path at 1 m/s through the ROI camera, and the
//! true-state floor, with their tracking errors.
//!
//! `cargo run --release -p roitrack-servo --example closed_loop [speed-scale]`

use roitrack_servo::{CameraKind, ControllerKind, ServoConfig, run_servo};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let speed_scale: f64 = std::env::args().nth(1).map_or(Ok(1.0), |s| s.parse())?;
    let cameras: Vec<CameraKind> = std::env::args().nth(2).map_or(vec![CameraKind::Roi], |s| {
        s.split(',').filter_map(CameraKind::from_name).collect()
    });
    println!("controller  camera      rms_mm   max_mm  stable  omega  age_ms  sat");
    for camera in cameras {
        for controller in ControllerKind::ALL {
            if controller == ControllerKind::TrueState && camera != CameraKind::Roi {
                continue;
            }
            let report = run_servo(&ServoConfig::new(controller, camera, speed_scale))?;
            println!(
                "{:<11} {:<10} {:>7.4} {:>8.4}  {:<6}  {:>5.0}  {:>6.3}  {:.3}",
                report.controller.name(),
                report.camera.name(),
                report.rms_error_mm,
                report.max_error_mm,
                report.stable,
                report.gains.natural_frequency_radps,
                report.median_feedback_age_s * 1e3,
                report.saturated_fraction
            );
            if let Some(reason) = &report.stop_reason {
                println!("    stopped: {reason}");
            }
        }
    }
    Ok(())
}
