//! Whether an estimator's covariance tells the truth about its errors: the normalised estimation error squared (NEES)
//! of the position and of the velocity.
//!
//! For an estimate with covariance `P` (error-state order translation, rotation, velocity, angular velocity, as
//! [`Estimate::covariance`]) and the true state, the error is `δ = MotionState::difference(estimate, truth)` and the
//! NEES of a 3 x 3 block `b` (position: rows 0..3, velocity: rows 6..9) is `δ_bᵀ P_b⁻¹ δ_b`. If the errors are
//! zero-mean Gaussian with covariance `P`, each block's NEES is chi-square with 3 degrees of freedom: it averages 3,
//! and 99 % of the estimates lie below [`CHI2_3DOF_99`]. A mean well above 3 means an over-confident covariance, well
//! below 3 a timid one. Only estimates that are vouched for ([`roitrack_estimators::TrackStatus::is_vouched_for`]) and carry a covariance
//! are counted.
//!
//! ```
//! use nalgebra::Vector3;
//! use roitrack_core::{MotionState, Vector12};
//! use roitrack_estimators::{Estimate, Matrix12, TrackStatus};
//! use roitrack_eval::{CHI2_3DOF_99, Consistency, nees};
//!
//! let truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
//! let mut state = truth;
//! state.cam_t_obj_m.x += 2e-3; // 2 mm off along x
//! state.velocity_mps.y = 0.01; // 10 mm/s off along y
//! let estimate = Estimate {
//!     t_ref_s: 0.1,
//!     state,
//!     residual_rms_px: 0.1,
//!     inverse_condition: 0.3,
//!     measurements_used: 16,
//!     iterations: 1,
//!     status: TrackStatus::Tracking,
//!     // 1 mm and 10 mm/s standard deviations.
//!     covariance: Some(Matrix12::from_diagonal(&Vector12::from_fn(|i, _| if i < 3 { 1e-6 } else { 1e-4 }))),
//!     noise_px: 0.1,
//!     acceleration: None,
//! };
//! let n = nees(&estimate, &truth).unwrap();
//! assert!((n.position - 4.0).abs() < 1e-9 && (n.velocity - 1.0).abs() < 1e-9);
//! let summary = Consistency::of([(&estimate, truth)]);
//! assert_eq!(summary.count, 1);
//! assert!((summary.position_nees_per_dof - 4.0 / 3.0).abs() < 1e-9);
//! assert_eq!(summary.position_inside_99, 1.0); // 4 < 11.345
//! assert!(CHI2_3DOF_99 > 11.34 && CHI2_3DOF_99 < 11.35);
//! ```

use nalgebra::{Matrix3, Vector3};
use roitrack_core::{MotionState, PoseSample, TwistSample};
use roitrack_estimators::{Estimate, Matrix12};
use serde::Serialize;

use crate::{EvalError, EvalOptions, align, check_increasing, check_twist_times};

/// The 99 % quantile of the chi-square distribution with 3 degrees of freedom: 99 % of the NEES of a 3-vector whose
/// covariance is right lie below it.
///
/// ```
/// assert_eq!(roitrack_eval::CHI2_3DOF_99, 11.344866730144373);
/// ```
pub const CHI2_3DOF_99: f64 = 11.344_866_730_144_373;

/// The NEES of one estimate's position and velocity (each chi-square with 3 degrees of freedom when the covariance
/// is right).
///
/// ```
/// use roitrack_eval::BlockNees;
/// let n = BlockNees { t_s: 0.5, position: 2.0, velocity: 13.0 };
/// assert!(n.position < roitrack_eval::CHI2_3DOF_99 && n.velocity > roitrack_eval::CHI2_3DOF_99);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BlockNees {
    /// The estimate's time (s).
    pub t_s: f64,
    /// `δ_vᵀ P_vv⁻¹ δ_v`, position block (error-state rows 0..3).
    pub position: f64,
    /// `δ_Vᵀ P_VV⁻¹ δ_V`, velocity block (error-state rows 6..9).
    pub velocity: f64,
}

/// The NEES of `estimate` against the true state at its time, or `None` when the estimate is not vouched for, has no
/// covariance, or a block of its covariance is not positive definite.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::MotionState;
/// use roitrack_estimators::{Estimate, Matrix12, TrackStatus};
/// use roitrack_eval::nees;
///
/// let truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
/// let mut estimate = Estimate {
///     t_ref_s: 0.0,
///     state: truth,
///     residual_rms_px: 0.1,
///     inverse_condition: 0.3,
///     measurements_used: 16,
///     iterations: 1,
///     status: TrackStatus::Tracking,
///     covariance: Some(Matrix12::identity() * 1e-6),
///     noise_px: 0.1,
///     acceleration: None,
/// };
/// estimate.state.cam_t_obj_m.z += 3e-3; // 3 mm off, 1 mm standard deviation: NEES 9
/// assert!((nees(&estimate, &truth).unwrap().position - 9.0).abs() < 1e-9);
/// estimate.status = TrackStatus::Degenerate;
/// assert!(nees(&estimate, &truth).is_none());
/// ```
pub fn nees(estimate: &Estimate, truth: &MotionState) -> Option<BlockNees> {
    if !estimate.status.is_vouched_for() {
        return None;
    }
    let covariance = estimate.covariance.as_ref()?;
    let delta = MotionState::difference(&estimate.state, truth);
    let block = |start: usize| {
        let error: Vector3<f64> = delta.fixed_rows::<3>(start).into_owned();
        block_nees(covariance, start, &error)
    };
    Some(BlockNees {
        t_s: estimate.t_ref_s,
        position: block(0)?,
        velocity: block(6)?,
    })
}

/// `eᵀ P_b⁻¹ e` for the 3 x 3 diagonal block of `covariance` starting at `start`; `None` unless that block is
/// symmetric positive definite and the result finite.
fn block_nees(covariance: &Matrix12, start: usize, error: &Vector3<f64>) -> Option<f64> {
    let block: Matrix3<f64> = covariance.fixed_view::<3, 3>(start, start).into_owned();
    let symmetric = (block + block.transpose()) * 0.5;
    let cholesky = symmetric.cholesky()?;
    let value = error.dot(&cholesky.solve(error));
    value.is_finite().then_some(value)
}

/// The NEES of a run's estimates summed up: the means per degree of freedom (1 when the covariance is right) and the
/// fractions inside the 99 % chi-square bound (0.99 when it is right). Every figure is NaN when no estimate counts.
///
/// ```
/// use roitrack_eval::Consistency;
/// let none = Consistency::of(std::iter::empty());
/// assert_eq!((none.count, none.skipped), (0, 0));
/// assert!(none.position_nees_per_dof.is_nan() && !none.is_calibrated());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Consistency {
    /// Estimates counted: vouched for, with a positive definite covariance.
    pub count: usize,
    /// Estimates left out: not vouched for, without a covariance, or with a covariance block that is not positive
    /// definite.
    pub skipped: usize,
    /// Mean position NEES divided by 3 (its degrees of freedom).
    pub position_nees_per_dof: f64,
    /// Mean velocity NEES divided by 3.
    pub velocity_nees_per_dof: f64,
    /// Fraction of the counted estimates whose position NEES is at most [`CHI2_3DOF_99`].
    pub position_inside_99: f64,
    /// Fraction of the counted estimates whose velocity NEES is at most [`CHI2_3DOF_99`].
    pub velocity_inside_99: f64,
}

/// The bounds of a calibrated covariance (the sweep's): each block's mean NEES per degree of freedom within
/// `[MIN_NEES_PER_DOF, MAX_NEES_PER_DOF]`, and at least [`MIN_INSIDE_99`] of the estimates inside the 99 % bound.
///
/// ```
/// use roitrack_eval::consistency::{MAX_NEES_PER_DOF, MIN_INSIDE_99, MIN_NEES_PER_DOF};
/// assert_eq!((MIN_NEES_PER_DOF, MAX_NEES_PER_DOF, MIN_INSIDE_99), (0.5, 2.0, 0.95));
/// ```
pub const MIN_NEES_PER_DOF: f64 = 0.5;
/// See [`MIN_NEES_PER_DOF`].
pub const MAX_NEES_PER_DOF: f64 = 2.0;
/// See [`MIN_NEES_PER_DOF`].
pub const MIN_INSIDE_99: f64 = 0.95;

impl Consistency {
    /// Sums up the NEES of every estimate against the true state at its time (see [`nees`] for which count).
    ///
    /// ```
    /// use nalgebra::Vector3;
    /// use roitrack_core::MotionState;
    /// use roitrack_estimators::{Estimate, Matrix12, TrackStatus};
    /// use roitrack_eval::Consistency;
    ///
    /// let truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
    /// let estimate = |x_mm: f64, covariance| {
    ///     let mut state = truth;
    ///     state.cam_t_obj_m.x += x_mm * 1e-3;
    ///     Estimate {
    ///         t_ref_s: 0.0, state, residual_rms_px: 0.1, inverse_condition: 0.3, measurements_used: 16,
    ///         iterations: 1, status: TrackStatus::Tracking, covariance, noise_px: 0.1, acceleration: None,
    ///     }
    /// };
    /// let one_mm = Some(Matrix12::identity() * 1e-6);
    /// let estimates = [estimate(1.0, one_mm), estimate(5.0, one_mm), estimate(0.0, None)];
    /// let summary = Consistency::of(estimates.iter().map(|e| (e, truth)));
    /// assert_eq!((summary.count, summary.skipped), (2, 1));
    /// assert!((summary.position_nees_per_dof - (1.0 + 25.0) / 2.0 / 3.0).abs() < 1e-9);
    /// assert_eq!(summary.position_inside_99, 0.5); // 25 > 11.345
    /// ```
    pub fn of<'a>(pairs: impl IntoIterator<Item = (&'a Estimate, MotionState)>) -> Self {
        let mut skipped = 0;
        let samples: Vec<BlockNees> = pairs
            .into_iter()
            .filter_map(|(estimate, truth)| {
                let n = nees(estimate, &truth);
                skipped += usize::from(n.is_none());
                n
            })
            .collect();
        Self::of_samples(&samples, skipped)
    }

    /// Sums up NEES samples already computed; `skipped` estimates were left out.
    ///
    /// ```
    /// use roitrack_eval::{BlockNees, Consistency};
    /// let samples = [BlockNees { t_s: 0.0, position: 3.0, velocity: 6.0 }, BlockNees { t_s: 0.1, position: 3.0, velocity: 30.0 }];
    /// let summary = Consistency::of_samples(&samples, 0);
    /// assert_eq!((summary.position_nees_per_dof, summary.velocity_nees_per_dof), (1.0, 6.0));
    /// assert_eq!((summary.position_inside_99, summary.velocity_inside_99), (1.0, 0.5));
    /// ```
    pub fn of_samples(samples: &[BlockNees], skipped: usize) -> Self {
        let count = samples.len();
        let n = count as f64;
        let mean_per_dof = |f: fn(&BlockNees) -> f64| samples.iter().map(f).sum::<f64>() / n / 3.0;
        let inside = |f: fn(&BlockNees) -> f64| {
            samples.iter().filter(|s| f(s) <= CHI2_3DOF_99).count() as f64 / n
        };
        let position: fn(&BlockNees) -> f64 = |s| s.position;
        let velocity: fn(&BlockNees) -> f64 = |s| s.velocity;
        Self {
            count,
            skipped,
            position_nees_per_dof: mean_per_dof(position),
            velocity_nees_per_dof: mean_per_dof(velocity),
            position_inside_99: inside(position),
            velocity_inside_99: inside(velocity),
        }
    }

    /// Summaries of several runs pooled: the means and fractions of all their counted estimates together (each
    /// weighted by its count).
    ///
    /// ```
    /// use roitrack_eval::{BlockNees, Consistency};
    /// let at = |position| BlockNees { t_s: 0.0, position, velocity: 3.0 };
    /// let one = Consistency::of_samples(&[at(3.0)], 1);
    /// let three = Consistency::of_samples(&[at(6.0), at(6.0), at(6.0)], 0);
    /// let pooled = Consistency::pooled(&[one, three]);
    /// assert_eq!((pooled.count, pooled.skipped), (4, 1));
    /// assert!((pooled.position_nees_per_dof - (3.0 + 18.0) / 4.0 / 3.0).abs() < 1e-12);
    /// ```
    pub fn pooled(parts: &[Consistency]) -> Self {
        let count: usize = parts.iter().map(|c| c.count).sum();
        let weighted = |f: fn(&Consistency) -> f64| {
            parts
                .iter()
                .filter(|c| c.count > 0)
                .map(|c| f(c) * c.count as f64)
                .sum::<f64>()
                / count as f64
        };
        Self {
            count,
            skipped: parts.iter().map(|c| c.skipped).sum(),
            position_nees_per_dof: weighted(|c| c.position_nees_per_dof),
            velocity_nees_per_dof: weighted(|c| c.velocity_nees_per_dof),
            position_inside_99: weighted(|c| c.position_inside_99),
            velocity_inside_99: weighted(|c| c.velocity_inside_99),
        }
    }

    /// Whether the covariance is calibrated (the sweep's): the mean NEES per degree of freedom of the position and of
    /// the velocity from [`MIN_NEES_PER_DOF`] to [`MAX_NEES_PER_DOF`] and at least [`MIN_INSIDE_99`] of the
    /// estimates inside the 99 % bound, for both. False when no estimate counts.
    ///
    /// ```
    /// use roitrack_eval::{BlockNees, Consistency};
    /// let at = |position| BlockNees { t_s: 0.0, position, velocity: 3.0 };
    /// assert!(Consistency::of_samples(&[at(2.0), at(4.0)], 0).is_calibrated());
    /// // Over-confident: the position NEES averages 4 x its dimension.
    /// assert!(!Consistency::of_samples(&[at(12.0), at(10.0)], 0).is_calibrated());
    /// ```
    pub fn is_calibrated(&self) -> bool {
        let mean_ok = |x: f64| (MIN_NEES_PER_DOF..=MAX_NEES_PER_DOF).contains(&x);
        self.count > 0
            && mean_ok(self.position_nees_per_dof)
            && mean_ok(self.velocity_nees_per_dof)
            && self.position_inside_99 >= MIN_INSIDE_99
            && self.velocity_inside_99 >= MIN_INSIDE_99
    }
}

/// The [`Consistency`] of a tracker's estimates against the truth's poses and twists (each estimate paired with the
/// truth at its time as [`estimate_errors`](crate::estimate_errors) pairs them: the truth sample within
/// [`EvalOptions::max_time_gap_s`], else the truth interpolated). The truth's times must increase strictly, its twists
/// be at the poses' times, and every estimate lie inside its span.
///
/// ```
/// use roitrack_estimators::{TrackerConfig, track_all};
/// use roitrack_eval::{EvalOptions, consistency_of};
/// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
///
/// let run = simulate(&Scenario::new(ScenarioKind::Static, 1), &SimulationOptions::default()).unwrap();
/// let (estimates, _) = track_all(&run.camera, &run.target, TrackerConfig::default(), &run.measurements).unwrap();
/// let summary = consistency_of(&run.truth_poses, &run.truth_twists, &estimates, &EvalOptions::default()).unwrap();
/// assert_eq!(summary.count + summary.skipped, estimates.len());
/// assert!(summary.position_nees_per_dof > 0.0);
/// ```
pub fn consistency_of(
    truth_poses: &[PoseSample],
    truth_twists: &[TwistSample],
    estimates: &[Estimate],
    opts: &EvalOptions,
) -> Result<Consistency, EvalError> {
    if !opts.max_time_gap_s.is_finite() || opts.max_time_gap_s < 0.0 {
        return Err(EvalError::InvalidOption {
            name: "max_time_gap_s",
            value: opts.max_time_gap_s,
            reason: "must be finite and non-negative",
        });
    }
    if truth_poses.is_empty() {
        return Err(EvalError::Empty {
            what: "truth poses",
        });
    }
    let truth_times: Vec<f64> = truth_poses.iter().map(|p| p.t_s).collect();
    check_increasing("truth poses", &truth_times)?;
    check_twist_times(
        "truth twists",
        &truth_times,
        truth_twists,
        opts.max_time_gap_s,
    )?;
    let mut pairs = Vec::with_capacity(estimates.len());
    for (index, estimate) in estimates.iter().enumerate() {
        let at = align::locate(&truth_times, index, estimate.t_ref_s, opts.max_time_gap_s)?;
        let (rotation, translation) = at.pose(truth_poses);
        let (velocity, angular_velocity) = at.twist(truth_twists);
        let truth = MotionState {
            cam_r_obj: rotation.to_rotation_matrix(),
            cam_t_obj_m: translation,
            velocity_mps: velocity,
            angular_velocity_radps: angular_velocity,
        };
        pairs.push((estimate, truth));
    }
    Ok(Consistency::of(pairs))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooled_consistency_weighs_by_count() {
        let a = Consistency {
            count: 1,
            skipped: 0,
            position_nees_per_dof: 1.0,
            velocity_nees_per_dof: 2.0,
            position_inside_99: 1.0,
            velocity_inside_99: 0.0,
        };
        let b = Consistency {
            count: 3,
            skipped: 2,
            position_nees_per_dof: 3.0,
            velocity_nees_per_dof: 2.0,
            position_inside_99: 0.0,
            velocity_inside_99: 1.0,
        };
        let p = Consistency::pooled(&[a, b]);
        assert_eq!((p.count, p.skipped), (4, 2));
        assert_eq!(p.position_nees_per_dof, 2.5);
        assert_eq!(p.velocity_nees_per_dof, 2.0);
        assert_eq!((p.position_inside_99, p.velocity_inside_99), (0.25, 0.75));
    }

    use nalgebra::SMatrix;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};
    use roitrack_core::Vector12;
    use roitrack_estimators::TrackStatus;

    /// A random symmetric positive definite covariance with standard deviations of a few mm, mrad, mm/s, mrad/s and
    /// correlations between every component.
    fn random_covariance(rng: &mut ChaCha8Rng) -> Matrix12 {
        let a = SMatrix::<f64, 12, 12>::from_fn(|_, _| StandardNormal.sample(rng));
        let scale = Matrix12::from_diagonal(&Vector12::from_fn(|i, _| match i / 3 {
            0 => 1e-3,
            1 => 2e-3,
            2 => 1e-2,
            _ => 3e-2,
        }));
        scale * (a * a.transpose() / 12.0 + Matrix12::identity() * 0.2) * scale
    }

    /// `count` estimates whose errors are drawn from their own stated covariance, and the truth of each; the
    /// covariance each estimate reports is the drawn one times `reported_scale`.
    fn sample(count: usize, reported_scale: f64) -> Vec<(Estimate, MotionState)> {
        let mut rng = ChaCha8Rng::seed_from_u64(15);
        let estimate_state =
            MotionState::at_rest(Default::default(), Vector3::new(0.01, 0.02, 0.6));
        (0..count)
            .map(|k| {
                let covariance = random_covariance(&mut rng);
                let cholesky = covariance.cholesky().expect("positive definite").l();
                let z = Vector12::from_fn(|_, _| StandardNormal.sample(&mut rng));
                let truth = estimate_state.corrected(&(cholesky * z));
                let estimate = Estimate {
                    t_ref_s: k as f64 * 1e-3,
                    state: estimate_state,
                    residual_rms_px: 0.1,
                    inverse_condition: 0.3,
                    measurements_used: 16,
                    iterations: 1,
                    status: TrackStatus::Tracking,
                    covariance: Some(covariance * reported_scale),
                    noise_px: 0.1,
                    acceleration: None,
                };
                (estimate, truth)
            })
            .collect()
    }

    #[test]
    fn errors_drawn_from_the_stated_covariance_are_calibrated() {
        let pairs = sample(20_000, 1.0);
        let summary = Consistency::of(pairs.iter().map(|(e, t)| (e, *t)));
        assert_eq!((summary.count, summary.skipped), (20_000, 0));
        // chi-square(3) / 3 has standard deviation sqrt(2/3): the mean of 20,000 is within 0.006 (1 sigma).
        for mean in [summary.position_nees_per_dof, summary.velocity_nees_per_dof] {
            assert!((mean - 1.0).abs() < 0.025, "{summary:?}");
        }
        for inside in [summary.position_inside_99, summary.velocity_inside_99] {
            assert!((inside - 0.99).abs() < 0.003, "{summary:?}");
        }
        assert!(summary.is_calibrated());
    }

    #[test]
    fn a_covariance_four_times_too_small_shows() {
        let pairs = sample(20_000, 0.25);
        let summary = Consistency::of(pairs.iter().map(|(e, t)| (e, *t)));
        // The NEES averages 12 (4 x its dimension): 4 per degree of freedom.
        for mean in [summary.position_nees_per_dof, summary.velocity_nees_per_dof] {
            assert!((mean - 4.0).abs() < 0.1, "{summary:?}");
        }
        // P(chi-square(3) <= 11.345 / 4 = 2.84) = 0.583.
        for inside in [summary.position_inside_99, summary.velocity_inside_99] {
            assert!((inside - 0.583).abs() < 0.02, "{summary:?}");
        }
        assert!(!summary.is_calibrated());
    }

    #[test]
    fn unvouched_estimates_and_broken_covariances_are_left_out() {
        let mut pairs = sample(4, 1.0);
        pairs[0].0.status = TrackStatus::Disputed;
        pairs[1].0.covariance = None;
        pairs[2].0.covariance = Some(Matrix12::zeros());
        let summary = Consistency::of(pairs.iter().map(|(e, t)| (e, *t)));
        assert_eq!((summary.count, summary.skipped), (1, 3));
        let n = nees(&pairs[3].0, &pairs[3].1).unwrap();
        assert_eq!(summary.position_nees_per_dof, n.position / 3.0);
    }

    #[test]
    fn consistency_of_pairs_estimates_with_the_truth_at_their_times() {
        let pairs = sample(50, 1.0);
        let truth_poses: Vec<PoseSample> = pairs
            .iter()
            .map(|(e, t)| PoseSample::from_state(e.t_ref_s, t))
            .collect();
        let truth_twists: Vec<TwistSample> = pairs
            .iter()
            .map(|(e, t)| TwistSample::from_state(e.t_ref_s, t))
            .collect();
        let estimates: Vec<Estimate> = pairs.iter().map(|(e, _)| *e).collect();
        let direct = Consistency::of(pairs.iter().map(|(e, t)| (e, *t)));
        let aligned = consistency_of(
            &truth_poses,
            &truth_twists,
            &estimates,
            &EvalOptions::default(),
        )
        .unwrap();
        assert_eq!(aligned.count, direct.count);
        assert!((aligned.position_nees_per_dof - direct.position_nees_per_dof).abs() < 1e-6);
        assert!((aligned.velocity_nees_per_dof - direct.velocity_nees_per_dof).abs() < 1e-6);
        // An estimate after the truth's end is refused.
        let mut late = estimates.clone();
        late[0].t_ref_s = 10.0;
        assert!(matches!(
            consistency_of(&truth_poses, &truth_twists, &late, &EvalOptions::default()),
            Err(EvalError::OutsideTruthSpan { index: 0, .. })
        ));
    }
}
