//! `roitrack soak`: a long run at full speed, to show that nothing drifts or grows: the orthoglide motion repeated for
//! the requested stream length (its start and end are the same rest pose, so the repetition is seamless), generated
//! on the fly (nothing stored), tracked by the default estimator; per simulated minute: position and velocity RMSE,
//! processing time per measurement, and the process's resident memory.

use std::time::Instant;

use anyhow::{Result, bail};
use clap::Args;
use nalgebra::Vector2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use roitrack_core::Measurement;
use roitrack_core::estimator::{Estimator, TrackStatus, Tracker, TrackerConfig};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_sim::{Scenario, ScenarioKind};

/// Track a long simulated stream at full speed and report, per simulated minute, accuracy, time and memory.
#[derive(Debug, Args)]
pub struct SoakArgs {
    /// Length of the simulated stream (minutes at 4 kHz).
    #[arg(long, default_value_t = 10.0)]
    pub minutes: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Figures of one simulated minute (or the last, partial one).
#[derive(Debug, Clone, Copy)]
struct Slice {
    position_rmse_mm: f64,
    velocity_rmse_mm_s: f64,
    us_per_measurement: f64,
    resident_mib: f64,
    lost: usize,
}

/// Resident set size of this process (MiB), from /proc (Linux); NaN elsewhere.
fn resident_mib() -> f64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| {
            s.split_whitespace()
                .nth(1)
                .and_then(|p| p.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |pages| pages * 4096.0 / (1024.0 * 1024.0))
}

pub fn run(args: &SoakArgs) -> Result<()> {
    if !(args.minutes > 0.0 && args.minutes <= 120.0) {
        bail!("--minutes must be in (0, 120], got {}", args.minutes);
    }
    const RATE_HZ: f64 = 4000.0;
    const NOISE_PX: f64 = 0.1;
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let period_s = scenario.duration_s;
    let order = bit_reversed_indices(scenario.target.len());
    let mut tracker = Tracker::new(
        scenario.camera.clone(),
        scenario.target.clone(),
        TrackerConfig::default(),
    )?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let noise = Normal::new(0.0, NOISE_PX)?;
    let total = (args.minutes * 60.0 * RATE_HZ) as usize;
    let per_slice = (60.0 * RATE_HZ) as usize;
    let mut slices = Vec::new();
    let (mut sum_p2, mut sum_v2, mut count, mut lost) = (0.0, 0.0, 0usize, 0usize);
    let mut slice_measurements = 0usize;
    let mut busy_s = 0.0;
    for k in 0..total {
        let t_s = k as f64 / RATE_HZ;
        let truth_at = |t: f64| scenario.state_at(t % period_s);
        let state = truth_at(t_s);
        let point = scenario.target.points()[order[k % order.len()]];
        let px = scenario
            .camera
            .raw_pixel_from_cam(&state.point_in_cam_at(&point.point_in_obj_m, 0.0))
            .unwrap_or(Vector2::new(f64::NAN, f64::NAN));
        let m = Measurement {
            t_s,
            id: point.id,
            u_px: px.x + noise.sample(&mut rng),
            v_px: px.y + noise.sample(&mut rng),
        };
        let start = Instant::now();
        let estimate = tracker.push(&m)?;
        busy_s += start.elapsed().as_secs_f64();
        slice_measurements += 1;
        if let Some(e) = estimate {
            let truth = truth_at(e.t_ref_s);
            sum_p2 += (e.state.cam_t_obj_m - truth.cam_t_obj_m).norm_squared();
            sum_v2 += (e.state.velocity_mps - truth.velocity_mps).norm_squared();
            count += 1;
            lost += usize::from(e.status == TrackStatus::Lost);
        }
        if (k + 1) % per_slice == 0 || k + 1 == total {
            slices.push(Slice {
                position_rmse_mm: 1e3 * (sum_p2 / count.max(1) as f64).sqrt(),
                velocity_rmse_mm_s: 1e3 * (sum_v2 / count.max(1) as f64).sqrt(),
                us_per_measurement: 1e6 * busy_s / slice_measurements.max(1) as f64,
                resident_mib: resident_mib(),
                lost,
            });
            (sum_p2, sum_v2, count, lost, busy_s, slice_measurements) = (0.0, 0.0, 0, 0, 0.0, 0);
        }
    }
    let first = slices[0];
    let last = *slices.last().expect("at least one slice");
    let memory_growth_mib = last.resident_mib - first.resident_mib;
    let error_ratio = last.position_rmse_mm / first.position_rmse_mm;
    let time_ratio = last.us_per_measurement / first.us_per_measurement;
    if args.json {
        let list = |f: &dyn Fn(&Slice) -> f64| {
            slices
                .iter()
                .map(|s| format!("{:.4}", f(s)))
                .collect::<Vec<_>>()
                .join(",")
        };
        println!(
            "{{\"minutes\":{},\"measurements\":{},\"position_rmse_mm\":[{}],\"velocity_rmse_mm_s\":[{}],\
             \"us_per_measurement\":[{}],\"resident_mib\":[{}],\"lost\":{},\"memory_growth_mib\":{:.3},\
             \"last_to_first_error_ratio\":{:.4},\"last_to_first_time_ratio\":{:.4}}}",
            args.minutes,
            total,
            list(&|s| s.position_rmse_mm),
            list(&|s| s.velocity_rmse_mm_s),
            list(&|s| s.us_per_measurement),
            list(&|s| s.resident_mib),
            slices.iter().map(|s| s.lost).sum::<usize>(),
            memory_growth_mib,
            error_ratio,
            time_ratio
        );
    } else {
        println!(
            "soak: {} min of orthoglide at 4 kHz ({} measurements), default estimator",
            args.minutes, total
        );
        println!(
            "{:>6} {:>10} {:>12} {:>12} {:>12} {:>5}",
            "minute", "pos mm", "vel mm/s", "us/meas", "RSS MiB", "lost"
        );
        for (i, s) in slices.iter().enumerate() {
            println!(
                "{:>6} {:>10.4} {:>12.2} {:>12.3} {:>12.2} {:>5}",
                i + 1,
                s.position_rmse_mm,
                s.velocity_rmse_mm_s,
                s.us_per_measurement,
                s.resident_mib,
                s.lost
            );
        }
        println!(
            "memory growth {memory_growth_mib:.3} MiB; last/first minute: error x{error_ratio:.3}, time x{time_ratio:.3}"
        );
    }
    Ok(())
}
