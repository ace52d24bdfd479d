//! The soak run of `roitrack soak`: a long stream at full speed, to show that nothing drifts or grows. The orthoglide
//! motion is repeated for the requested length (its start and end are the same rest pose, so the repetition is
//! seamless), generated on the fly (nothing stored) and tracked by the default estimator; per simulated minute:
//! position and velocity RMSE, processing time per measurement, and the process's resident memory.

use std::time::Instant;

use nalgebra::Vector2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use roitrack_core::Measurement;
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_estimators::{
    ConfigError, Estimator, TrackError, TrackStatus, Tracker, TrackerConfig,
};
use roitrack_sim::{Scenario, ScenarioKind};
use thiserror::Error;

/// ROI rate of the soak stream (Hz).
pub const RATE_HZ: f64 = 4000.0;
/// Standard deviation of the soak stream's centroid noise, per image axis (px).
pub const NOISE_PX: f64 = 0.1;
/// Longest soak run (minutes).
pub const MAX_MINUTES: f64 = 120.0;

/// Figures of one simulated minute (or the last, partial one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slice {
    /// RMS error of the estimated position against the truth (mm).
    pub position_rmse_mm: f64,
    /// RMS error of the estimated velocity against the truth (mm/s).
    pub velocity_rmse_mm_s: f64,
    /// Processing time per measurement, the estimator's calls only (µs of wall time).
    pub us_per_measurement: f64,
    /// The process's resident memory at the end of the slice (MiB; NaN where /proc is not available).
    pub resident_mib: f64,
    /// Estimates whose status was lost.
    pub lost: usize,
}

/// A soak run, minute by minute.
#[derive(Debug, Clone, PartialEq)]
pub struct SoakReport {
    /// Length of the run (simulated minutes).
    pub minutes: f64,
    /// Measurements tracked.
    pub measurements: usize,
    /// The figures of each simulated minute, in order.
    pub slices: Vec<Slice>,
}

/// Why a soak run could not run.
#[derive(Debug, Error)]
pub enum SoakError {
    /// The length asked for (minutes) is not in (0, [`MAX_MINUTES`]].
    #[error("the length must be in (0, {MAX_MINUTES}] minutes, got {0}")]
    Length(f64),
    /// The tracker refused its configuration.
    #[error("invalid tracker options: {0}")]
    Config(#[from] ConfigError),
    /// The tracker refused a measurement.
    #[error("a measurement was refused: {0}")]
    Refused(#[from] TrackError),
}

/// Resident set size of this process (MiB), from /proc (Linux); NaN elsewhere.
pub fn resident_mib() -> f64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| {
            s.split_whitespace()
                .nth(1)
                .and_then(|p| p.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |pages| pages * 4096.0 / (1024.0 * 1024.0))
}

/// Tracks `minutes` of the repeated orthoglide motion at 4 kHz (seed 1, 0.1 px) with the default estimator.
///
/// ```
/// // Six seconds: more than one repetition of the motion, in one (partial) slice.
/// let report = roitrack_bench::soak::run(0.1).unwrap();
/// assert_eq!((report.measurements, report.slices.len()), (24_000, 1));
/// assert!(report.slices[0].position_rmse_mm < 0.5 && report.slices[0].lost == 0);
/// assert!(report.to_table().contains("memory growth"));
/// ```
pub fn run(minutes: f64) -> Result<SoakReport, SoakError> {
    if !(minutes > 0.0 && minutes <= MAX_MINUTES) {
        return Err(SoakError::Length(minutes));
    }
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let period_s = scenario.duration_s;
    let order = bit_reversed_indices(scenario.target.len());
    let mut tracker = Tracker::new(
        scenario.camera.clone(),
        scenario.target.clone(),
        TrackerConfig::default(),
    )?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let noise = Normal::new(0.0, NOISE_PX).expect("a valid noise");
    let total = (minutes * 60.0 * RATE_HZ) as usize;
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
    Ok(SoakReport {
        minutes,
        measurements: total,
        slices,
    })
}

impl SoakReport {
    fn first_last(&self) -> (Slice, Slice) {
        (
            self.slices[0],
            *self.slices.last().expect("at least one slice"),
        )
    }

    /// Resident memory of the last minute minus that of the first (MiB).
    pub fn memory_growth_mib(&self) -> f64 {
        let (first, last) = self.first_last();
        last.resident_mib - first.resident_mib
    }

    /// Position error and time per measurement of the last minute over the first.
    pub fn last_to_first_ratios(&self) -> (f64, f64) {
        let (first, last) = self.first_last();
        (
            last.position_rmse_mm / first.position_rmse_mm,
            last.us_per_measurement / first.us_per_measurement,
        )
    }

    /// One JSON object.
    pub fn to_json(&self) -> String {
        let list = |f: &dyn Fn(&Slice) -> f64| {
            self.slices
                .iter()
                .map(|s| format!("{:.4}", f(s)))
                .collect::<Vec<_>>()
                .join(",")
        };
        let (error_ratio, time_ratio) = self.last_to_first_ratios();
        format!(
            "{{\"minutes\":{},\"measurements\":{},\"position_rmse_mm\":[{}],\"velocity_rmse_mm_s\":[{}],\
             \"us_per_measurement\":[{}],\"resident_mib\":[{}],\"lost\":{},\"memory_growth_mib\":{:.3},\
             \"last_to_first_error_ratio\":{:.4},\"last_to_first_time_ratio\":{:.4}}}",
            self.minutes,
            self.measurements,
            list(&|s| s.position_rmse_mm),
            list(&|s| s.velocity_rmse_mm_s),
            list(&|s| s.us_per_measurement),
            list(&|s| s.resident_mib),
            self.slices.iter().map(|s| s.lost).sum::<usize>(),
            self.memory_growth_mib(),
            error_ratio,
            time_ratio
        )
    }

    /// A table, one row per minute, and the summary line.
    pub fn to_table(&self) -> String {
        let mut out = format!(
            "soak: {} min of orthoglide at 4 kHz ({} measurements), default estimator\n{:>6} {:>10} {:>12} {:>12} {:>12} {:>5}\n",
            self.minutes,
            self.measurements,
            "minute",
            "pos mm",
            "vel mm/s",
            "us/meas",
            "RSS MiB",
            "lost"
        );
        for (i, s) in self.slices.iter().enumerate() {
            out += &format!(
                "{:>6} {:>10.4} {:>12.2} {:>12.3} {:>12.2} {:>5}\n",
                i + 1,
                s.position_rmse_mm,
                s.velocity_rmse_mm_s,
                s.us_per_measurement,
                s.resident_mib,
                s.lost
            );
        }
        let (error_ratio, time_ratio) = self.last_to_first_ratios();
        out + &format!(
            "memory growth {:.3} MiB; last/first minute: error x{error_ratio:.3}, time x{time_ratio:.3}\n",
            self.memory_growth_mib()
        )
    }
}
