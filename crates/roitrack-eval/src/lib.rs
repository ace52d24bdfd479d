//! # roitrack-eval
//!
//! Accuracy of an estimated trajectory against ground truth (docs/evaluation.md), as pure computation on in-memory
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
#![deny(missing_docs)]

mod align;
pub mod consistency;
mod error;
mod lag;
mod metrics;
pub mod trajectory;

use nalgebra::Vector3;
use roitrack_core::{PoseSample, TwistSample, so3};
use roitrack_estimators::Estimate;

pub use consistency::{BlockNees, CHI2_3DOF_99, Consistency, consistency_of, nees};
pub use error::EvalError;
pub use metrics::{Metrics, PooledErrors};
pub use trajectory::{Alignment, SimilarityTransform, TimeOffset};

use align::TruthIndex;

/// How estimates are matched with the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalOptions {
    /// An estimate within this many seconds of a truth sample is compared with that sample; otherwise with the truth
    /// interpolated at its time, which must then lie inside the truth's time span. Also the tolerance on twist times
    /// matching pose times. Default 1e-6 s.
    pub max_time_gap_s: f64,
    /// The velocity lag is searched in `-max_lag_samples..=max_lag_samples` estimator samples (and within a quarter
    /// of the series), every shift scored on the same estimates: all but the first and the last `max_lag_samples`.
    /// Default 40.
    pub max_lag_samples: usize,
    /// The clock offset added to the estimates' times before they are paired with the truth, or
    /// [`TimeOffset::Auto`] to find it ([`trajectory::find_time_offset`]). Default 0.
    pub time_offset: TimeOffset,
    /// With [`TimeOffset::Auto`], the largest offset searched (s). Default 5.
    pub max_time_offset_s: f64,
    /// The transformation of the estimates onto the truth's frame, fitted to the paired positions
    /// ([`trajectory::umeyama`]). Default none.
    pub alignment: Alignment,
    /// Also the relative pose error over this interval (s) ([`trajectory::relative_errors`]). Default none.
    pub rpe_interval_s: Option<f64>,
    /// Leave out, and count, the estimates outside the truth's time span (after the offset) instead of refusing
    /// them. Default false.
    pub skip_outside_truth: bool,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            max_time_gap_s: 1e-6,
            max_lag_samples: 40,
            time_offset: TimeOffset::Fixed(0.0),
            max_time_offset_s: 5.0,
            alignment: Alignment::None,
            rpe_interval_s: None,
            skip_outside_truth: false,
        }
    }
}

/// The error of every estimate against the truth at its time (estimate minus truth, camera frame): what
/// [`evaluate`] sums into its metrics and what the figures plot.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateErrors {
    /// The estimates' times (s), on the truth's clock (the time offset added).
    pub t_s: Vec<f64>,
    /// The clock offset added to the estimates' times (s).
    pub time_offset_s: f64,
    /// The alignment asked for.
    pub alignment: Alignment,
    /// The transformation applied to the estimates (the identity without an alignment).
    pub transform: SimilarityTransform,
    /// Estimates left out for lying outside the truth's time span ([`EvalOptions::skip_outside_truth`]).
    pub skipped_outside_truth: usize,
    /// With [`EvalOptions::rpe_interval_s`], the relative pose errors.
    pub relative: Option<trajectory::RelativeErrors>,
    /// Position error of the object origin (m).
    pub position_m: Vec<Vector3<f64>>,
    /// Geodesic angle of `R_est⁻¹ R_true` (rad).
    pub rotation_rad: Vec<f64>,
    /// The rotation error as a rotation vector in the camera frame, `Log(R_est R_trueᵀ)` (rad): the negative of the
    /// left perturbation `w` of the covariance (`R_true = Exp(w) R_est`), so the covariance's rotation block is its
    /// covariance too. Its norm is [`Self::rotation_rad`].
    pub rotation_vector_rad: Vec<Vector3<f64>>,
    /// With twists on both sides: linear velocity errors (m/s).
    pub velocity_mps: Option<Vec<Vector3<f64>>>,
    /// With twists on both sides: angular velocity errors (rad/s).
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
    let (truth_times, est_times) =
        check_inputs(truth_poses, truth_twists, est_poses, est_twists, opts)?;
    let gap = opts.max_time_gap_s;
    let time_offset_s = clock_offset_s(opts, (truth_poses, &truth_times), (est_poses, &est_times))?;
    if let Some(interval) = opts.rpe_interval_s
        && !(interval.is_finite() && interval > 0.0)
    {
        return Err(EvalError::InvalidOption {
            name: "rpe_interval_s",
            value: interval,
            reason: "must be finite and positive",
        });
    }
    let kept = pair_with_truth(
        &truth_times,
        &est_times,
        time_offset_s,
        gap,
        opts.skip_outside_truth,
    )?;
    let skipped_outside_truth = est_times.len() - kept.len();
    let truth_at: Vec<PoseSample> = kept
        .iter()
        .map(|&(i, at)| {
            let (rotation, translation) = at.pose(truth_poses);
            PoseSample {
                t_s: est_times[i] + time_offset_s,
                cam_from_obj: nalgebra::Isometry3::from_parts(translation.into(), rotation),
            }
        })
        .collect();
    let transform = alignment(opts.alignment, est_poses, &kept, &truth_at)?;
    let aligned: Vec<PoseSample> = kept
        .iter()
        .zip(&truth_at)
        .map(|(&(i, _), truth)| {
            let mut pose = transform.pose(&est_poses[i]);
            pose.t_s = truth.t_s;
            pose
        })
        .collect();
    let (position_m, rotation_rad, rotation_vector_rad) = pose_errors(&aligned, &truth_at);
    let relative = opts
        .rpe_interval_s
        .map(|interval| trajectory::relative_errors(&truth_at, &aligned, interval));
    let mut errors = EstimateErrors {
        t_s: truth_at.iter().map(|p| p.t_s).collect(),
        time_offset_s,
        alignment: opts.alignment,
        transform,
        skipped_outside_truth,
        relative,
        position_m,
        rotation_rad,
        rotation_vector_rad,
        velocity_mps: None,
        angular_velocity_radps: None,
        true_velocity_mps: None,
        estimated_velocity_mps: None,
    };
    if let (Some(truth_twists), Some(est_twists)) = (truth_twists, est_twists) {
        add_twist_errors(&mut errors, &kept, truth_twists, est_twists);
    }
    Ok(errors)
}

/// Refuses a negative or non-finite time gap, empty poses, times that do not increase and twists at other times
/// than their poses; returns the times of the truth's poses and of the estimates.
fn check_inputs(
    truth_poses: &[PoseSample],
    truth_twists: Option<&[TwistSample]>,
    est_poses: &[PoseSample],
    est_twists: Option<&[TwistSample]>,
    opts: &EvalOptions,
) -> Result<(Vec<f64>, Vec<f64>), EvalError> {
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
    Ok((truth_times, est_times))
}

/// The estimates' clock offset to the truth's: the given one, or the one found by matching the trajectories and
/// refined.
fn clock_offset_s(
    opts: &EvalOptions,
    (truth_poses, truth_times): (&[PoseSample], &[f64]),
    (est_poses, est_times): (&[PoseSample], &[f64]),
) -> Result<f64, EvalError> {
    Ok(match opts.time_offset {
        TimeOffset::Fixed(offset) if offset.is_finite() => offset,
        TimeOffset::Fixed(offset) => {
            return Err(EvalError::InvalidOption {
                name: "time_offset",
                value: offset,
                reason: "must be finite",
            });
        }
        TimeOffset::Auto => {
            let coarse =
                trajectory::find_time_offset(truth_poses, est_poses, opts.max_time_offset_s)?;
            refine_time_offset(
                (truth_poses, truth_times),
                (est_poses, est_times),
                coarse,
                opts.alignment,
            )
        }
    })
}

/// Each estimate on the truth's clock (shifted by `time_offset_s`) with where the truth is there; estimates outside
/// the truth's span are left out with `skip_outside_truth`, refused otherwise.
fn pair_with_truth(
    truth_times: &[f64],
    est_times: &[f64],
    time_offset_s: f64,
    gap: f64,
    skip_outside_truth: bool,
) -> Result<Vec<(usize, TruthIndex)>, EvalError> {
    let mut kept: Vec<(usize, TruthIndex)> = Vec::with_capacity(est_times.len());
    for (i, &t) in est_times.iter().enumerate() {
        match align::locate(truth_times, i, t + time_offset_s, gap) {
            Ok(at) => kept.push((i, at)),
            Err(EvalError::OutsideTruthSpan { .. }) if skip_outside_truth => {}
            Err(error) => return Err(error),
        }
    }
    if kept.is_empty() {
        return Err(EvalError::Empty {
            what: "estimates inside the truth's time span",
        });
    }
    Ok(kept)
}

/// The transform that aligns the kept estimates' positions onto the truth's (`Alignment::None`: the identity).
fn alignment(
    alignment: Alignment,
    est_poses: &[PoseSample],
    kept: &[(usize, TruthIndex)],
    truth_at: &[PoseSample],
) -> Result<SimilarityTransform, EvalError> {
    Ok(match alignment {
        Alignment::None => SimilarityTransform::identity(),
        kind => {
            let from: Vec<Vector3<f64>> = kept
                .iter()
                .map(|&(i, _)| est_poses[i].cam_from_obj.translation.vector)
                .collect();
            let to: Vec<Vector3<f64>> = truth_at
                .iter()
                .map(|p| p.cam_from_obj.translation.vector)
                .collect();
            trajectory::umeyama(&from, &to, kind == Alignment::Sim3)?
        }
    })
}

/// The position error (m), rotation angle (rad) and rotation vector (rad) of each aligned estimate against the truth.
fn pose_errors(
    aligned: &[PoseSample],
    truth_at: &[PoseSample],
) -> (Vec<Vector3<f64>>, Vec<f64>, Vec<Vector3<f64>>) {
    let (position_m, (rotation_rad, rotation_vector_rad)): (Vec<_>, (Vec<_>, Vec<_>)) = aligned
        .iter()
        .zip(truth_at)
        .map(|(est, truth)| {
            let angle = so3::angle_between(
                &est.cam_from_obj.rotation.to_rotation_matrix(),
                &truth.cam_from_obj.rotation.to_rotation_matrix(),
            );
            let vector = so3::log_quaternion(
                &(est.cam_from_obj.rotation * truth.cam_from_obj.rotation.inverse()),
            );
            (
                est.cam_from_obj.translation.vector - truth.cam_from_obj.translation.vector,
                (angle, vector),
            )
        })
        .unzip();
    (position_m, rotation_rad, rotation_vector_rad)
}

/// The velocity and angular velocity errors of the kept estimates (their twists through the alignment), and the
/// true and estimated velocities the velocity lag is measured on.
fn add_twist_errors(
    errors: &mut EstimateErrors,
    kept: &[(usize, TruthIndex)],
    truth_twists: &[TwistSample],
    est_twists: &[TwistSample],
) {
    let transform = errors.transform;
    let count = kept.len();
    let (mut velocity, mut angular, mut truth_v, mut est_v) = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
    );
    for &(i, truth_at) in kept {
        let (true_v, true_w) = truth_at.twist(truth_twists);
        let est = transform.twist(&est_twists[i]);
        velocity.push(est.velocity_mps - true_v);
        angular.push(est.angular_velocity_radps - true_w);
        truth_v.push(true_v);
        est_v.push(est.velocity_mps);
    }
    errors.velocity_mps = Some(velocity);
    errors.angular_velocity_radps = Some(angular);
    errors.true_velocity_mps = Some(truth_v);
    errors.estimated_velocity_mps = Some(est_v);
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
            time_offset_s: self.time_offset_s,
            alignment: self.alignment,
            alignment_scale: self.transform.scale,
            alignment_rotation_deg: self.transform.rotation.angle().to_degrees(),
            alignment_translation_mm: (self.transform.translation_m * 1e3).into(),
            skipped_outside_truth: self.skipped_outside_truth,
            rpe_interval_s: None,
            rpe_pairs: None,
            rpe_translation_rmse_mm: None,
            rpe_rotation_rmse_deg: None,
        };
        if let Some(relative) = &self.relative {
            let rms = |values: &[f64]| {
                (values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64).sqrt()
            };
            metrics.rpe_interval_s = Some(relative.interval_s);
            metrics.rpe_pairs = Some(relative.translation_m.len());
            if !relative.translation_m.is_empty() {
                metrics.rpe_translation_rmse_mm = Some(rms(&relative.translation_m) * 1e3);
                metrics.rpe_rotation_rmse_deg = Some(rms(&relative.rotation_rad).to_degrees());
            }
        }
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
/// use roitrack_estimators::{TrackerConfig, track_all};
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
/// use roitrack_estimators::{TrackerConfig, track_all};
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
/// use roitrack_estimators::{Estimate, TrackStatus};
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
///     acceleration: None,
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

/// The clock offset near `coarse` (within three estimate periods) that minimises the RMS position error after the
/// alignment asked for (a rigid one when none is: the search must not depend on a frame it cannot know). Speeds
/// correlate broadly and place the offset within a few periods; positions, which a moving target changes by
/// millimetres a millisecond, pin it down. Golden-section search.
fn refine_time_offset(
    (truth_poses, truth_times): (&[PoseSample], &[f64]),
    (est_poses, est_times): (&[PoseSample], &[f64]),
    coarse: f64,
    alignment: Alignment,
) -> f64 {
    let period = median_period(est_times);
    let cost = |offset: f64| -> f64 {
        let (mut from, mut to) = (Vec::new(), Vec::new());
        for (i, &t) in est_times.iter().enumerate() {
            if let Ok(at) = align::locate(truth_times, i, t + offset, 0.0) {
                from.push(est_poses[i].cam_from_obj.translation.vector);
                to.push(at.pose(truth_poses).1);
            }
        }
        let transform = match alignment {
            Alignment::Sim3 => trajectory::umeyama(&from, &to, true),
            _ => trajectory::umeyama(&from, &to, false),
        };
        let Ok(transform) = transform else {
            return f64::INFINITY;
        };
        let sum: f64 = from
            .iter()
            .zip(&to)
            .map(|(a, b)| {
                (transform.scale * (transform.rotation * a) + transform.translation_m - b)
                    .norm_squared()
            })
            .sum();
        if from.is_empty() {
            f64::INFINITY
        } else {
            sum / from.len() as f64
        }
    };
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (coarse - 3.0 * period, coarse + 3.0 * period);
    let (mut x1, mut x2) = (b - ratio * (b - a), a + ratio * (b - a));
    let (mut f1, mut f2) = (cost(x1), cost(x2));
    if !(f1.is_finite() || f2.is_finite()) {
        return coarse;
    }
    for _ in 0..40 {
        if f1 <= f2 {
            (b, x2, f2) = (x2, x1, f1);
            x1 = b - ratio * (b - a);
            f1 = cost(x1);
        } else {
            (a, x1, f1) = (x1, x2, f2);
            x2 = a + ratio * (b - a);
            f2 = cost(x2);
        }
    }
    0.5 * (a + b)
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
