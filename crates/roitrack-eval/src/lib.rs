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
//!
//! [`estimate_errors`] gives the error of every estimate, which the figures plot; [`evaluate_estimates`] takes a
//! tracker's estimates directly. [`consistency`] tells whether an estimator's covariance matches its errors (the NEES
//! of position and velocity, [`consistency_of`]). Every metric of roitrack's tables and figures is defined here, once.

mod align;
pub mod consistency;
mod error;
mod lag;
mod metrics;

use nalgebra::Vector3;
use roitrack_core::estimator::Estimate;
use roitrack_core::{PoseSample, TwistSample, so3};

pub use consistency::{BlockNees, CHI2_3DOF_99, Consistency, consistency_of, nees};
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

/// The error of every estimate against the truth at its time (estimate minus truth, camera frame): what
/// [`evaluate`] sums into its metrics and what the figures plot.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateErrors {
    /// The estimates' times (s).
    pub t_s: Vec<f64>,
    /// Position error of the object origin (m).
    pub position_m: Vec<Vector3<f64>>,
    /// Geodesic angle of `R_est⁻¹ R_true` (rad).
    pub rotation_rad: Vec<f64>,
    /// With twists on both sides: linear and angular velocity errors (m/s, rad/s).
    pub velocity_mps: Option<Vec<Vector3<f64>>>,
    pub angular_velocity_radps: Option<Vec<Vector3<f64>>>,
    /// The true linear velocity at each estimate (m/s), for the velocity lag.
    true_velocity_mps: Option<Vec<Vector3<f64>>>,
    estimated_velocity_mps: Option<Vec<Vector3<f64>>>,
}

/// Pairs each estimate with the truth at its time (see the [crate documentation](crate)) and returns the errors.
/// Takes the same arguments, and makes the same checks, as [`evaluate`].
///
/// ```
/// use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
/// use roitrack_core::PoseSample;
/// use roitrack_eval::{EvalOptions, estimate_errors};
///
/// let at = |t_s: f64, x: f64| PoseSample {
///     t_s,
///     cam_from_obj: Isometry3::from_parts(Translation3::new(x, 0.0, 0.6), UnitQuaternion::identity()),
/// };
/// let truth = [at(0.0, 0.0), at(1.0, 0.1)];
/// // An estimate half-way, 1 mm to the right of the interpolated truth.
/// let errors = estimate_errors(&truth, None, &[at(0.5, 0.051)], None, &EvalOptions::default()).unwrap();
/// assert!((errors.position_m[0] - Vector3::new(0.001, 0.0, 0.0)).norm() < 1e-12);
/// assert!(errors.velocity_mps.is_none());
/// ```
pub fn estimate_errors(
    truth_poses: &[PoseSample],
    truth_twists: Option<&[TwistSample]>,
    est_poses: &[PoseSample],
    est_twists: Option<&[TwistSample]>,
    opts: &EvalOptions,
) -> Result<EstimateErrors, EvalError> {
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

    let (position_m, rotation_rad) = est_poses
        .iter()
        .zip(&at)
        .map(|(est, truth_at)| {
            let (truth_rotation, truth_translation) = truth_at.pose(truth_poses);
            let angle = so3::angle_between(
                &est.cam_from_obj.rotation.to_rotation_matrix(),
                &truth_rotation.to_rotation_matrix(),
            );
            (
                est.cam_from_obj.translation.vector - truth_translation,
                angle,
            )
        })
        .unzip();
    let mut errors = EstimateErrors {
        t_s: est_times,
        position_m,
        rotation_rad,
        velocity_mps: None,
        angular_velocity_radps: None,
        true_velocity_mps: None,
        estimated_velocity_mps: None,
    };
    if let (Some(truth_twists), Some(est_twists)) = (truth_twists, est_twists) {
        let count = est_twists.len();
        let (mut velocity, mut angular, mut truth_v) = (
            Vec::with_capacity(count),
            Vec::with_capacity(count),
            Vec::with_capacity(count),
        );
        for (est, truth_at) in est_twists.iter().zip(&at) {
            let (true_v, true_w) = truth_at.twist(truth_twists);
            velocity.push(est.velocity_mps - true_v);
            angular.push(est.angular_velocity_radps - true_w);
            truth_v.push(true_v);
        }
        errors.velocity_mps = Some(velocity);
        errors.angular_velocity_radps = Some(angular);
        errors.true_velocity_mps = Some(truth_v);
        errors.estimated_velocity_mps = Some(est_twists.iter().map(|s| s.velocity_mps).collect());
    }
    Ok(errors)
}

impl EstimateErrors {
    /// The metrics of these errors ([`Metrics`]): RMS, maximum and velocity lag.
    pub fn metrics(&self, opts: &EvalOptions) -> Metrics {
        let count = self.t_s.len();
        let estimator_period_s = median_period(&self.t_s);
        let mut position = MeanSquares::default();
        let mut rotation_sq_sum = 0.0;
        let mut max_position_error_m: f64 = 0.0;
        for (error, angle) in self.position_m.iter().zip(&self.rotation_rad) {
            position.add(error);
            max_position_error_m = max_position_error_m.max(error.norm());
            rotation_sq_sum += angle * angle;
        }
        let mut metrics = Metrics {
            count,
            duration_s: self.t_s[count - 1] - self.t_s[0],
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
        if let (Some(velocity_errors), Some(angular_errors), Some(truth_v), Some(est_v)) = (
            &self.velocity_mps,
            &self.angular_velocity_radps,
            &self.true_velocity_mps,
            &self.estimated_velocity_mps,
        ) {
            let mut velocity = MeanSquares::default();
            let mut angular = MeanSquares::default();
            for (v, w) in velocity_errors.iter().zip(angular_errors) {
                velocity.add(v);
                angular.add(w);
            }
            let lag = lag::velocity_lag(est_v, truth_v, opts.max_lag_samples);
            metrics.velocity_rmse_mm_s = Some(velocity.rms_norm(count) * 1e3);
            metrics.velocity_rmse_xyz_mm_s = Some(velocity.rms_axes(count).map(|v| v * 1e3));
            metrics.angular_velocity_rmse_deg_s = Some(angular.rms_norm(count).to_degrees());
            metrics.velocity_lag_samples = Some(lag.samples);
            metrics.velocity_lag_subsample = Some(lag.subsample);
            metrics.velocity_lag_ms = Some(lag.samples as f64 * estimator_period_s * 1e3);
        }
        metrics
    }
}

/// Compares estimated poses (and twists) with the truth; see the [crate documentation](crate) and [`Metrics`].
///
/// - `truth_poses`: ground truth, times strictly increasing; `truth_twists`, when given, at the same times.
/// - `est_poses`: the estimates, times strictly increasing and inside the truth's span; `est_twists`, when given, at
///   the same times. Velocity metrics need twists on both sides.
///
/// ```
/// use nalgebra::{Isometry3, Translation3, UnitQuaternion};
/// use roitrack_core::PoseSample;
/// use roitrack_eval::{EvalOptions, evaluate};
///
/// let at = |t_s: f64, x: f64| PoseSample {
///     t_s,
///     cam_from_obj: Isometry3::from_parts(Translation3::new(x, 0.0, 0.6), UnitQuaternion::identity()),
/// };
/// let truth: Vec<_> = (0..10).map(|k| at(k as f64, 0.0)).collect();
/// let estimate: Vec<_> = (0..10).map(|k| at(k as f64, if k % 2 == 0 { 0.001 } else { -0.001 })).collect();
/// let metrics = evaluate(&truth, None, &estimate, None, &EvalOptions::default()).unwrap();
/// assert!((metrics.position_rmse_mm - 1.0).abs() < 1e-9);
/// assert_eq!(metrics.velocity_rmse_mm_s, None);
/// ```
pub fn evaluate(
    truth_poses: &[PoseSample],
    truth_twists: Option<&[TwistSample]>,
    est_poses: &[PoseSample],
    est_twists: Option<&[TwistSample]>,
    opts: &EvalOptions,
) -> Result<Metrics, EvalError> {
    estimate_errors(truth_poses, truth_twists, est_poses, est_twists, opts).map(|e| e.metrics(opts))
}

/// [`estimate_errors`] of a tracker's estimates (their poses and twists).
///
/// ```
/// use roitrack_core::estimator::{TrackerConfig, track_all};
/// use roitrack_eval::{EvalOptions, estimate_errors_of};
/// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
///
/// let run = simulate(&Scenario::new(ScenarioKind::Static, 1), &SimulationOptions::default()).unwrap();
/// let (estimates, _) = track_all(&run.camera, &run.target, TrackerConfig::default(), &run.measurements).unwrap();
/// let errors = estimate_errors_of(&run.truth_poses, &run.truth_twists, &estimates, &EvalOptions::default()).unwrap();
/// assert_eq!(errors.position_m.len(), estimates.len());
/// assert!(errors.position_m.iter().all(|e| e.norm() < 2e-3));
/// ```
pub fn estimate_errors_of(
    truth_poses: &[PoseSample],
    truth_twists: &[TwistSample],
    estimates: &[Estimate],
    opts: &EvalOptions,
) -> Result<EstimateErrors, EvalError> {
    let (poses, twists) = samples_of(estimates);
    estimate_errors(truth_poses, Some(truth_twists), &poses, Some(&twists), opts)
}

/// [`evaluate`] of a tracker's estimates (their poses and twists) against the truth's poses and twists.
///
/// ```
/// use roitrack_core::estimator::{TrackerConfig, track_all};
/// use roitrack_eval::{EvalOptions, evaluate_estimates};
/// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
///
/// let run = simulate(&Scenario::new(ScenarioKind::Static, 1), &SimulationOptions::default()).unwrap();
/// let (estimates, _) = track_all(&run.camera, &run.target, TrackerConfig::default(), &run.measurements).unwrap();
/// let metrics = evaluate_estimates(&run.truth_poses, &run.truth_twists, &estimates, &EvalOptions::default()).unwrap();
/// assert!(metrics.position_rmse_mm < 0.5, "{metrics:?}");
/// ```
pub fn evaluate_estimates(
    truth_poses: &[PoseSample],
    truth_twists: &[TwistSample],
    estimates: &[Estimate],
    opts: &EvalOptions,
) -> Result<Metrics, EvalError> {
    estimate_errors_of(truth_poses, truth_twists, estimates, opts).map(|e| e.metrics(opts))
}

/// The poses and twists of estimates, as written to files.
///
/// ```
/// use roitrack_core::estimator::{Estimate, TrackStatus};
/// use roitrack_core::MotionState;
/// use roitrack_eval::samples_of;
/// let e = Estimate {
///     t_ref_s: 0.5,
///     state: MotionState::at_rest(Default::default(), nalgebra::Vector3::new(0.0, 0.0, 0.6)),
///     residual_rms_px: 0.1,
///     inverse_condition: 0.2,
///     measurements_used: 16,
///     iterations: 1,
///     status: TrackStatus::Tracking,
///     covariance: None,
///     noise_px: 0.1,
/// };
/// let (poses, twists) = samples_of(&[e]);
/// assert_eq!((poses[0].t_s, twists[0].t_s), (0.5, 0.5));
/// assert_eq!(poses[0].cam_from_obj.translation.vector.z, 0.6);
/// ```
pub fn samples_of(estimates: &[Estimate]) -> (Vec<PoseSample>, Vec<TwistSample>) {
    estimates
        .iter()
        .map(|e| {
            (
                PoseSample::from_state(e.t_ref_s, &e.state),
                TwistSample::from_state(e.t_ref_s, &e.state),
            )
        })
        .unzip()
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
    let steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.is_empty() {
        return 0.0;
    }
    roitrack_core::stats::median(&steps)
}
