//! A user's control thread fed by the estimate handle: the tracker's estimates of a closed-loop run are published
//! from one thread at their times, a control thread reads the newest at 4 kHz and predicts it to its actuation
//! instant (250 µs ahead) with its covariance, without locks or allocation.
//!
//! `cargo run --release -p roitrack-servo --example estimate_handle`

use roitrack_servo::handle::estimate_channel;
use roitrack_servo::{CameraKind, ControllerKind, ServoConfig, run_servo};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let report = run_servo(&ServoConfig::new(ControllerKind::Ctc, CameraKind::Roi, 1.0))?;
    let (mut publisher, reader) = estimate_channel();
    let estimates = report.estimates;
    let ticks = 2000;
    std::thread::scope(|scope| {
        scope.spawn(move || {
            for e in estimates.iter().take(ticks / 10) {
                publisher.publish(e);
                std::thread::sleep(std::time::Duration::from_micros(2500));
            }
        });
        scope.spawn(move || {
            let mut worst_sigma_mm: f64 = 0.0;
            let mut read = 0;
            for n in 0..ticks {
                let t_act_s = n as f64 * 2.5e-4 + 2.5e-4;
                if let Some((t_ref_s, state, covariance)) = reader.predicted_to(t_act_s) {
                    read += 1;
                    if let Some(p) = covariance {
                        worst_sigma_mm = worst_sigma_mm.max(p[(0, 0)].max(p[(1, 1)]).sqrt() * 1e3);
                    }
                    if n % 400 == 0 {
                        println!(
                            "tick {n}: estimate of t = {t_ref_s:.5} s, position at t = {t_act_s:.5} s: {:.2?} mm",
                            (state.cam_t_obj_m * 1e3).as_slice()
                        );
                    }
                }
                std::thread::sleep(std::time::Duration::from_micros(250));
            }
            println!("{read} reads; largest 1-sigma across the image: {worst_sigma_mm:.4} mm");
        });
    });
    Ok(())
}
