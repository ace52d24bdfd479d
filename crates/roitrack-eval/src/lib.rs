//! # roitrack-eval
//!
//! Accuracy of an estimated trajectory against ground truth (SPEC section 9), as pure computation on in-memory
//! samples: the caller reads the files.
//!
//! [`evaluate`] pairs each estimate with the truth at its time (the truth sample itself when one lies within
//! [`EvalOptions::max_time_gap_s`], else the truth interpolated between its neighbours: linearly for positions and
//! twists, by slerp for rotations) and reports in [`Metrics`]:
//!
//! - position RMSE (total and per camera axis) and maximum position error, in mm;
//! - rotation RMSE, the geodesic angle of `R_est⁻¹ R_true`, in degrees;
//! - with twists on both sides: linear velocity RMSE (mm/s), angular velocity RMSE (deg/s), and the velocity lag, the
//!   shift in estimator samples (and ms) maximising the normalized cross-correlation of estimated and true linear
//!   velocity, positive when the estimate lags behind the truth.

mod align;
mod error;
mod lag;
mod metrics;

use nalgebra::Vector3;
use roitrack_core::{PoseSample, TwistSample, so3};

pub use error::EvalError;
pub use metrics::Metrics;

use align::TruthIndex;

/// How estimates are matched with the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalOptions {
    /// An estimate within this many seconds of a truth sample is compared with that sample; otherwise with the truth
    /// interpolated at its time, which must then lie inside the truth's time span. Also the tolerance on twist times
    /// matching pose times. Default 1e-6 s.
    pub max_time_gap_s: f64,
    /// The velocity lag is searched in `-max_lag_samples..=max_lag_samples` estimator samples (and within half the
    /// series). Default 40.
    pub max_lag_samples: usize,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            max_time_gap_s: 1e-6,
            max_lag_samples: 40,
        }
    }
}

/// Compares estimated poses (and twists) with the truth; see the [crate documentation](crate) and [`Metrics`].
///
/// - `truth_poses`: ground truth, times strictly increasing; `truth_twists`, when given, at the same times.
/// - `est_poses`: the estimates, times strictly increasing and inside the truth's span; `est_twists`, when given, at
///   the same times. Velocity metrics need twists on both sides.
pub fn evaluate(
    truth_poses: &[PoseSample],
    truth_twists: Option<&[TwistSample]>,
    est_poses: &[PoseSample],
    est_twists: Option<&[TwistSample]>,
    opts: &EvalOptions,
) -> Result<Metrics, EvalError> {
    if !opts.max_time_gap_s.is_finite() || opts.max_time_gap_s < 0.0 {
        return Err(EvalError::InvalidOption {
            name: "max_time_gap_s",
            value: opts.max_time_gap_s,
            reason: "must be finite and non-negative",
        });
    }
    let gap = opts.max_time_gap_s;
    if truth_poses.is_empty() {
        return Err(EvalError::Empty {
            what: "truth poses",
        });
    }
    if est_poses.is_empty() {
        return Err(EvalError::Empty {
            what: "estimated poses",
        });
    }
    let truth_times: Vec<f64> = truth_poses.iter().map(|p| p.t_s).collect();
    let est_times: Vec<f64> = est_poses.iter().map(|p| p.t_s).collect();
    check_increasing("truth poses", &truth_times)?;
    check_increasing("estimated poses", &est_times)?;
    if let Some(twists) = truth_twists {
        check_twist_times("truth twists", &truth_times, twists, gap)?;
    }
    if let Some(twists) = est_twists {
        check_twist_times("estimated twists", &est_times, twists, gap)?;
    }

    let at: Vec<TruthIndex> = est_times
        .iter()
        .enumerate()
        .map(|(i, &t)| align::locate(&truth_times, i, t, gap))
        .collect::<Result<_, _>>()?;

    let count = est_poses.len();
    let estimator_period_s = median_period(&est_times);

    let mut position = MeanSquares::default();
    let mut rotation_sq_sum = 0.0;
    let mut max_position_error_m: f64 = 0.0;
    for (est, truth_at) in est_poses.iter().zip(&at) {
        let (truth_rotation, truth_translation) = truth_at.pose(truth_poses);
        let error = est.cam_from_obj.translation.vector - truth_translation;
        position.add(&error);
        max_position_error_m = max_position_error_m.max(error.norm());
        let angle = so3::angle_between(
            &est.cam_from_obj.rotation.to_rotation_matrix(),
            &truth_rotation.to_rotation_matrix(),
        );
        rotation_sq_sum += angle * angle;
    }

    let mut metrics = Metrics {
        count,
        duration_s: est_times[count - 1] - est_times[0],
        estimator_period_ms: estimator_period_s * 1e3,
        position_rmse_mm: position.rms_norm(count) * 1e3,
        position_rmse_xyz_mm: position.rms_axes(count).map(|v| v * 1e3),
        max_position_error_mm: max_position_error_m * 1e3,
        rotation_rmse_deg: (rotation_sq_sum / count as f64).sqrt().to_degrees(),
        velocity_rmse_mm_s: None,
        velocity_rmse_xyz_mm_s: None,
        angular_velocity_rmse_deg_s: None,
        velocity_lag_samples: None,
        velocity_lag_subsample: None,
        velocity_lag_ms: None,
    };

    if let (Some(truth_twists), Some(est_twists)) = (truth_twists, est_twists) {
        let mut velocity = MeanSquares::default();
        let mut angular = MeanSquares::default();
        let mut true_velocities = Vec::with_capacity(count);
        for (est, truth_at) in est_twists.iter().zip(&at) {
            let (truth_v, truth_w) = truth_at.twist(truth_twists);
            velocity.add(&(est.velocity_mps - truth_v));
            angular.add(&(est.angular_velocity_radps - truth_w));
            true_velocities.push(truth_v);
        }
        let est_velocities: Vec<Vector3<f64>> = est_twists.iter().map(|s| s.velocity_mps).collect();
        let lag = lag::velocity_lag(&est_velocities, &true_velocities, opts.max_lag_samples);

        metrics.velocity_rmse_mm_s = Some(velocity.rms_norm(count) * 1e3);
        metrics.velocity_rmse_xyz_mm_s = Some(velocity.rms_axes(count).map(|v| v * 1e3));
        metrics.angular_velocity_rmse_deg_s = Some(angular.rms_norm(count).to_degrees());
        metrics.velocity_lag_samples = Some(lag.samples);
        metrics.velocity_lag_subsample = Some(lag.subsample);
        metrics.velocity_lag_ms = Some(lag.samples as f64 * estimator_period_s * 1e3);
    }
    Ok(metrics)
}

/// Running sums of squared error components.
#[derive(Debug, Default)]
struct MeanSquares {
    sum: Vector3<f64>,
}

impl MeanSquares {
    fn add(&mut self, error: &Vector3<f64>) {
        self.sum += error.component_mul(error);
    }

    /// RMS of the error's norm over `count` samples.
    fn rms_norm(&self, count: usize) -> f64 {
        (self.sum.sum() / count as f64).sqrt()
    }

    /// RMS of each error component over `count` samples.
    fn rms_axes(&self, count: usize) -> [f64; 3] {
        (self.sum / count as f64).map(f64::sqrt).into()
    }
}

/// Checks that the times are finite and strictly increasing.
fn check_increasing(what: &'static str, times: &[f64]) -> Result<(), EvalError> {
    for (index, &t_s) in times.iter().enumerate() {
        if !t_s.is_finite() {
            return Err(EvalError::NonFiniteTime { what, index, t_s });
        }
        if index > 0 && t_s <= times[index - 1] {
            return Err(EvalError::NonIncreasingTime {
                what,
                index,
                previous_s: times[index - 1],
                t_s,
            });
        }
    }
    Ok(())
}

/// Checks that there is one twist per pose, each within `max_gap_s` of its pose's time.
fn check_twist_times(
    what: &'static str,
    pose_times: &[f64],
    twists: &[TwistSample],
    max_gap_s: f64,
) -> Result<(), EvalError> {
    if twists.len() != pose_times.len() {
        return Err(EvalError::TwistCountMismatch {
            what,
            poses: pose_times.len(),
            twists: twists.len(),
        });
    }
    match pose_times
        .iter()
        .zip(twists)
        .position(|(&t, twist)| twist.t_s.is_nan() || (twist.t_s - t).abs() > max_gap_s)
    {
        Some(index) => Err(EvalError::TwistTimeMismatch {
            what,
            index,
            pose_t_s: pose_times[index],
            twist_t_s: twists[index].t_s,
        }),
        None => Ok(()),
    }
}

/// The median interval between consecutive times (s); 0 with fewer than two.
fn median_period(times: &[f64]) -> f64 {
    let mut steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.is_empty() {
        return 0.0;
    }
    steps.sort_by(f64::total_cmp);
    let mid = steps.len() / 2;
    if steps.len() % 2 == 1 {
        steps[mid]
    } else {
        0.5 * (steps[mid - 1] + steps[mid])
    }
}
