//! The error-state Kalman filter itself: its state covariance, prediction and the update by one centroid, and the
//! two motion models behind one type ([`Filter`]).

use super::*;

/// The covariance is made exactly symmetric again after this many updates (each leaves a round-off asymmetry of
/// about 1e-16 of its entries).
pub(super) const SYMMETRISE_EVERY_UPDATES: u64 = 16;

/// The filter's covariance and, with [`MotionModel::ConstantAcceleration`], its accelerations; the pose and the twist
/// live in the tracker. `N` is 12 (pose, twist) or 18 (pose, twist, linear and angular acceleration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ErrorStateKalman<const N: usize> {
    pub(super) covariance: SMatrix<f64, N, N>,
    /// The accelerations in the camera frame; zero and unused when `N` is 12.
    pub(super) acceleration: Acceleration,
    pub(super) tuning: KalmanTuning,
    /// Exponential average of the recent corrections of the pose and the twist (error-state units), and its largest
    /// weight per update (see [`Self::trend_rates`]).
    pub(super) trend: Vector12,
    pub(super) trend_rate: f64,
    /// The time step of the newest prediction that moved the filter (s): the trend's weights follow the filter's
    /// own time constant in seconds.
    pub(super) last_dt_s: f64,
    /// Updates applied, to symmetrise the covariance every [`SYMMETRISE_EVERY_UPDATES`].
    pub(super) updates: u64,
    /// The persistence of the newest innovation along the translational and the rotational part of the trend (see
    /// [`Self::update`]); 0 when there is no trend yet.
    pub(super) persistence: [f64; 2],
    /// The newest update's innovation (px), gated or not, and the part of its variance per axis that the state's
    /// uncertainty makes (px², `tr(H P Hᵀ) / 2`).
    pub(super) innovation_px: Vector2<f64>,
    pub(super) predicted_variance_px2: f64,
}

/// What one measurement update did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum UpdateOutcome {
    /// Used: the norm of its innovation (px) and its squared Mahalanobis distance (the normalised innovation
    /// squared, 2 dof).
    Accepted { norm_px: f64, nis: f64 },
    /// Rejected by the innovation gate: the norm of its innovation (px) and its squared Mahalanobis distance.
    Gated { norm_px: f64, nis: f64 },
    /// The point does not project (behind the camera) or the innovation covariance is singular.
    Invalid,
}

/// A centroid's noise as one update weighs and judges it.
///
/// Seen through the user's own camera and target files (nominal intrinsics, a target drawn to spec), a blob of a
/// frame sits off the best pose mostly by the model's error, a bias that changes slowly with the pose, and a little by
/// white noise, new at every frame. The bias is no error of the pose the frames show: a pose fitted to each frame on
/// the same files (the reference users compare with) carries it too, and averaging over frames cannot remove it. So
/// the gain weighs the white part only, while the gate, the Huber weight and every test of the innovations judge a
/// blob by both: how far it may lie from the prediction. Told the total as white noise, a filter trusted its motion
/// model over the frames and lagged them by a few tenths of a millimetre on a 4-dot plate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct CentroidNoise {
    /// Standard deviation per axis of the white part (px): the update's measurement noise.
    pub(super) white_px: f64,
    /// Standard deviation per axis of the model's error (px); 0 where none is told apart.
    pub(super) bias_px: f64,
}

impl CentroidNoise {
    /// Noise that is white through and through.
    pub(super) fn white(noise_px: f64) -> Self {
        Self {
            white_px: noise_px,
            bias_px: 0.0,
        }
    }

    /// The variance per axis of the white part and the bias together (px²).
    pub(super) fn total_px2(&self) -> f64 {
        self.white_px * self.white_px + self.bias_px * self.bias_px
    }
}

/// The standard deviations of the accelerations at the start of a track (linear in m/s², angular in rad/s²), and
/// the widening of a covariance reset (scaled as the pose's and twist's). Wider is not safer: a start knows the twist
/// only to 1 m/s and 10 rad/s, and with 10 m/s² and 30 rad/s² the first rolling-shutter frames could trade twist
/// for acceleration until the track was lost (measured in docs/results.md, "Design measurements behind the code").
pub(super) const ACCELERATION_PRIOR_SIGMAS: [f64; 2] = [3.0, 10.0];

/// The prior variance of error-state entry `i` (12 to 17: the linear, then the angular acceleration).
pub(super) fn acceleration_prior_variance(i: usize) -> f64 {
    let sigma = ACCELERATION_PRIOR_SIGMAS[(i - 12) / 3];
    sigma * sigma
}

impl<const N: usize> ErrorStateKalman<N> {
    /// Whether the state carries the accelerations (known at compile time).
    pub(super) const WITH_ACCELERATION: bool = N == 18;

    /// A filter whose pose and twist have the covariance `pose_twist` (and, with accelerations, the acceleration
    /// prior, uncorrelated), accelerations zero.
    pub(super) fn new(pose_twist: Matrix12, tuning: KalmanTuning, trend_rate: f64) -> Self {
        let mut covariance = SMatrix::<f64, N, N>::zeros();
        covariance
            .fixed_view_mut::<12, 12>(0, 0)
            .copy_from(&pose_twist);
        for i in 12..N {
            covariance[(i, i)] = acceleration_prior_variance(i);
        }
        Self {
            covariance,
            acceleration: Acceleration {
                linear_mps2: Vector3::zeros(),
                angular_radps2: Vector3::zeros(),
            },
            tuning,
            trend: Vector12::zeros(),
            trend_rate,
            last_dt_s: 0.0,
            persistence: [0.0; 2],
            innovation_px: Vector2::zeros(),
            predicted_variance_px2: 0.0,
            updates: 0,
        }
    }

    /// The covariance of the pose and the twist.
    pub(super) fn pose_twist_covariance(&self) -> Matrix12 {
        self.covariance.fixed_view::<12, 12>(0, 0).into_owned()
    }

    /// Widens the covariance when one instant's blobs place the pose farther from the prediction than the two
    /// uncertainties allow, and returns by what factor (1: unchanged).
    ///
    /// `blobs` gives each blob's point, centroid (ideal px) and white noise variance (px²). Their fit of the pose
    /// alone, linearised at `state`, moves it by `x` with covariance `C = (Σ Jᵢᵀ Jᵢ / σᵢ²)⁻¹`; if the filter is right,
    /// `x ~ N(0, P_pose + C)` and `xᵀ (P_pose + C)⁻¹ x` is a chi-square of 6 degrees of freedom. Beyond
    /// `gate_chi2`, the prediction is surer of itself than the motion allows: frames weighed by the white part of
    /// their noise pin the pose, bias and all, and when the model's error moves with the pose (a plate turning
    /// through the direction four coplanar dots pin least), the prediction lags it. The whole covariance is then
    /// scaled by the `α` that makes `xᵀ (α P_pose + C)⁻¹ x` its expected 6 (a fading of the filter's memory by
    /// covariance matching), so that the frame's update follows its blobs instead of the motion model.
    pub(super) fn match_pose_innovation(
        &mut self,
        model: &SpatioTemporalModel,
        state: &MotionState,
        blobs: impl Iterator<Item = (Vector3<f64>, Vector2<f64>, f64)>,
        gate_chi2: f64,
    ) -> f64 {
        let (mut information, mut gradient) = (SMatrix::<f64, 6, 6>::zeros(), Vector6::zeros());
        for (point_in_obj_m, ideal_px, white_px2) in blobs {
            let Some(projected) =
                model.project_with_jacobian(JacobianKind::Exact, state, &point_in_obj_m, 0.0)
            else {
                continue;
            };
            let j = projected.jacobian.fixed_view::<2, 6>(0, 0).into_owned();
            information += j.transpose() * j / white_px2;
            gradient += j.transpose() * (ideal_px - projected.pixel) / white_px2;
        }
        let Some(fit_covariance) = information.try_inverse() else {
            return 1.0;
        };
        let x = fit_covariance * gradient;
        let pose = self.covariance.fixed_view::<6, 6>(0, 0).into_owned();
        let Some(alpha) = pose_matching_scale(&pose, &fit_covariance, &x, gate_chi2) else {
            return 1.0;
        };
        self.covariance *= alpha;
        alpha
    }

    /// Adds `scale` times `prior` (of the pose and the twist) and of the acceleration prior: a covariance reset.
    pub(super) fn widen(&mut self, prior: &Matrix12, scale: f64) {
        let mut block = self.covariance.fixed_view_mut::<12, 12>(0, 0);
        block += prior * scale;
        for i in 12..N {
            self.covariance[(i, i)] += acceleration_prior_variance(i) * scale;
        }
    }

    /// Moves the state `dt_s` ahead and grows the covariance, with the process densities scaled by `process_scale`.
    pub(super) fn predict(&mut self, state: &mut MotionState, dt_s: f64, process_scale: [f64; 2]) {
        let acceleration = self.acceleration;
        self.predict_with(state, dt_s, process_scale, &acceleration);
    }

    /// [`Self::predict`] from `t_s`, with the known acceleration `known` on top of the filter's own (a control
    /// input, `x' = F x + B u`): the interval is cut where the known acceleration changes, and each piece predicted
    /// with the sum ([`KnownAcceleration`]). Without any input given, exactly [`Self::predict`].
    pub(super) fn predict_known(
        &mut self,
        state: &mut MotionState,
        t_s: f64,
        dt_s: f64,
        process_scale: [f64; 2],
        known: &KnownAcceleration,
    ) {
        if known.is_empty() {
            return self.predict(state, dt_s, process_scale);
        }
        if dt_s == 0.0 {
            return;
        }
        let own = self.acceleration;
        known.for_each_piece(t_s, dt_s, |piece_s, u| {
            self.predict_with(state, piece_s, process_scale, &known::sum(&own, u));
        });
        // The trend's weights follow the whole step, however it was cut.
        self.last_dt_s = dt_s.abs();
    }

    /// [`Self::predict`] with the target's acceleration over `dt_s` taken as `acceleration` (the filter's own, plus
    /// any known input). `F` depends on it through the rotation increment only (`Transition`): a linear input
    /// leaves the covariance's propagation as it is.
    fn predict_with(
        &mut self,
        state: &mut MotionState,
        dt_s: f64,
        process_scale: [f64; 2],
        acceleration: &Acceleration,
    ) {
        if dt_s == 0.0 {
            return;
        }
        self.last_dt_s = dt_s.abs();
        let transition = Transition::new(state, acceleration, dt_s);
        // F P Fᵀ: F applied to every column, then Fᵀ from the right, by whole columns. F is sparse (a few 3 x 3
        // blocks beside the identity), so this is a fraction of a dense product's work, in place.
        for column in self.covariance.as_mut_slice().chunks_exact_mut(N) {
            transition.apply::<N>(column);
        }
        transition.apply_from_the_right::<N>(self.covariance.as_mut_slice());
        self.add_process_noise(dt_s, process_scale);
        // The state's own prediction (`MotionState::predicted` when there is no acceleration), with the rotation
        // increment already at hand.
        let Acceleration {
            linear_mps2,
            angular_radps2,
        } = *acceleration;
        state.cam_r_obj = Rotation3::from_matrix_unchecked(transition.e) * state.cam_r_obj;
        state.cam_t_obj_m += state.velocity_mps * dt_s + linear_mps2 * transition.half_dt2;
        state.velocity_mps += linear_mps2 * dt_s;
        state.angular_velocity_radps += angular_radps2 * dt_s;
    }

    /// Adds the process noise of `dt_s` (its absolute value) to the covariance, with the densities scaled by
    /// `process_scale`: what the motion's random walk adds over that time.
    pub(super) fn add_process_noise(&mut self, dt_s: f64, process_scale: [f64; 2]) {
        let dt = dt_s.abs();
        let p = &mut self.covariance;
        match self.tuning.motion_model {
            MotionModel::ConstantVelocity => {
                // Q of white acceleration: per axis [dt³/3 dt²/2; dt²/2 dt] times the density.
                for (pos, vel, psd) in [
                    (0, 6, self.tuning.linear_accel_psd * process_scale[0]),
                    (3, 9, self.tuning.angular_accel_psd * process_scale[1]),
                ] {
                    let (qpp, qpv, qvv) = (psd * dt * dt * dt / 3.0, psd * dt * dt / 2.0, psd * dt);
                    for i in 0..3 {
                        p[(pos + i, pos + i)] += qpp;
                        p[(pos + i, vel + i)] += qpv;
                        p[(vel + i, pos + i)] += qpv;
                        p[(vel + i, vel + i)] += qvv;
                    }
                }
            }
            MotionModel::ConstantAcceleration {
                linear_jerk_psd,
                angular_jerk_psd,
            } if Self::WITH_ACCELERATION => {
                // Q of white jerk: per axis, over (pose, twist, acceleration), the density times
                // [dt⁵/20 dt⁴/8 dt³/6; dt⁴/8 dt³/3 dt²/2; dt³/6 dt²/2 dt].
                let (dt2, dt3) = (dt * dt, dt * dt * dt);
                let q = [
                    [dt2 * dt3 / 20.0, dt2 * dt2 / 8.0, dt3 / 6.0],
                    [dt2 * dt2 / 8.0, dt3 / 3.0, dt2 / 2.0],
                    [dt3 / 6.0, dt2 / 2.0, dt],
                ];
                for (offset, psd) in [
                    (0, linear_jerk_psd * process_scale[0]),
                    (3, angular_jerk_psd * process_scale[1]),
                ] {
                    for axis in 0..3 {
                        for (r, q_row) in q.iter().enumerate() {
                            for (c, q_rc) in q_row.iter().enumerate() {
                                p[(offset + 6 * r + axis, offset + 6 * c + axis)] += psd * q_rc;
                            }
                        }
                    }
                }
            }
            MotionModel::ConstantAcceleration { .. } => {
                unreachable!("a constant-acceleration model has an 18-state filter")
            }
        }
    }

    /// The trend's weight per update for its translational and its rotational part: the step over the filter's own
    /// time constant for that part, `sqrt(tr P_pose / tr P_twist)` (the `1 / ω` of a constant-velocity filter, whose
    /// pose and twist variances are `√2 r^¾ q^¼` and `√2 r^¼ q^¾` for measurement and process densities `r` and
    /// `q`), but never more than [`Self::trend_rate`] (two cycles of the target's points, and at least
    /// [`TREND_MIN_UPDATES`] updates). A lagging filter's innovations stay correlated over its time constant (for the
    /// translation at 1 px, 12 to 35 ms on the built-in scenes), and a trend of two cycles (8 ms at 4 kHz with 16
    /// points) missed most of its lag (random motion at 1 px: 94.6 % of the positions inside their 99 % bound, 96.3 %
    /// with this).
    pub(super) fn trend_rates(&self) -> [f64; 2] {
        let p = &self.covariance;
        [0, 3].map(|first| {
            let pose: f64 = (first..first + 3).map(|i| p[(i, i)]).sum();
            let twist: f64 = (first + 6..first + 9).map(|i| p[(i, i)]).sum();
            let rate = self.last_dt_s / (pose / twist).sqrt();
            // No step yet, or no twist uncertainty: nothing to scale by.
            if rate.is_finite() && rate > 0.0 {
                rate.min(self.trend_rate)
            } else {
                self.trend_rate
            }
        })
    }

    /// The squared Mahalanobis distance of a centroid (ideal pixel) of `point_in_obj_m` from this filter's
    /// prediction, against the whole of `noise`; `None` if the point does not project.
    pub(super) fn prediction_nis(
        &self,
        model: &SpatioTemporalModel,
        state: &MotionState,
        point_in_obj_m: &Vector3<f64>,
        ideal_px: &Vector2<f64>,
        noise: CentroidNoise,
    ) -> Option<f64> {
        let projected =
            model.project_with_jacobian(JacobianKind::Exact, state, point_in_obj_m, 0.0)?;
        let h = projected.jacobian;
        let s = h * self.covariance.fixed_view::<12, 12>(0, 0) * h.transpose()
            + Matrix2::identity() * noise.total_px2();
        let innovation = ideal_px - projected.pixel;
        let nis = (innovation.transpose() * s.try_inverse()? * innovation)[0];
        nis.is_finite().then_some(nis)
    }

    /// Updates with one centroid (ideal pixel) of `point_in_obj_m`, observed at the state's reference time, weighed
    /// by the white part of `noise` and judged (gate, Huber weight, persistence) by the whole of it: by its squared
    /// Mahalanobis distance from this filter's prediction, or by `judged_nis` when it was judged before (against the
    /// prediction before the other blobs of its frame: see [`KalmanLaw::take_readout`]).
    pub(super) fn update(
        &mut self,
        model: &SpatioTemporalModel,
        state: &mut MotionState,
        point_in_obj_m: &Vector3<f64>,
        ideal_px: &Vector2<f64>,
        noise: CentroidNoise,
        judged_nis: Option<f64>,
    ) -> UpdateOutcome {
        let Some(projected) =
            model.project_with_jacobian(JacobianKind::Exact, state, point_in_obj_m, 0.0)
        else {
            return UpdateOutcome::Invalid;
        };
        // The centroid depends on the pose alone (at its own time); the accelerations' columns of H are zero.
        let h = projected.jacobian;
        let innovation = ideal_px - projected.pixel;
        self.innovation_px = innovation;
        // P Hᵀ over the pose's and twist's columns, by whole columns of P (a strided view's product is slower).
        let mut ph_t = SMatrix::<f64, N, 2>::zeros();
        for (j, column) in self
            .covariance
            .as_slice()
            .chunks_exact(N)
            .take(12)
            .enumerate()
        {
            let (h0, h1) = (h[(0, j)], h[(1, j)]);
            for (i, entry) in column.iter().enumerate() {
                ph_t[(i, 0)] += entry * h0;
                ph_t[(i, 1)] += entry * h1;
            }
        }
        let hph_t = h * ph_t.fixed_rows::<12>(0);
        self.predicted_variance_px2 = 0.5 * (hph_t[(0, 0)] + hph_t[(1, 1)]);
        let s = hph_t + Matrix2::identity() * noise.total_px2();
        let Some(s_inv) = s.try_inverse() else {
            return UpdateOutcome::Invalid;
        };
        let mahalanobis2 = judged_nis.unwrap_or((innovation.transpose() * s_inv * innovation)[0]);
        if !mahalanobis2.is_finite() {
            return UpdateOutcome::Invalid;
        }
        // Persistence: the innovation along the displacement that the recent corrections predict for this point,
        // normalised. An optimal filter's innovations are white, so this is N(0, 1); it is positive on average when
        // the corrections keep going one way (the filter lags the motion) and negative when they undo each other
        // (the filter chases the noise).
        for (part, rows) in [(0, [0, 6]), (1, [3, 9])] {
            let expected: Vector2<f64> = rows
                .iter()
                .map(|&r| h.fixed_columns::<3>(r) * self.trend.fixed_rows::<3>(r))
                .sum();
            let spread2 = (expected.transpose() * s_inv * expected)[0];
            self.persistence[part] = if spread2 > 0.0 {
                (innovation.transpose() * s_inv * expected)[0] / spread2.sqrt()
            } else {
                0.0
            };
        }
        if mahalanobis2 > self.tuning.gate_sigma * self.tuning.gate_sigma {
            return UpdateOutcome::Gated {
                norm_px: innovation.norm(),
                nis: mahalanobis2,
            };
        }
        let distance = mahalanobis2.sqrt();
        let white2 = noise.white_px * noise.white_px;
        let (sigma2, s_inv) = if distance > self.tuning.huber_sigma {
            let inflated = white2 * distance / self.tuning.huber_sigma;
            match (hph_t + Matrix2::identity() * inflated).try_inverse() {
                Some(inv) => (inflated, inv),
                None => return UpdateOutcome::Invalid,
            }
        } else if noise.bias_px == 0.0 {
            (white2, s_inv)
        } else {
            match (hph_t + Matrix2::identity() * white2).try_inverse() {
                Some(inv) => (white2, inv),
                None => return UpdateOutcome::Invalid,
            }
        };
        let gain = ph_t * s_inv;
        let correction = gain * innovation;
        let pose_twist_correction: Vector12 = correction.fixed_rows::<12>(0).into_owned();
        let corrected = state.corrected(&pose_twist_correction);
        if !corrected.is_finite() {
            return UpdateOutcome::Invalid;
        }
        *state = corrected;
        if Self::WITH_ACCELERATION {
            self.acceleration.linear_mps2 += correction.fixed_rows::<3>(12);
            self.acceleration.angular_radps2 += correction.fixed_rows::<3>(15);
        }
        let rates = self.trend_rates();
        for (row, (trend, correction)) in self
            .trend
            .iter_mut()
            .zip(&pose_twist_correction)
            .enumerate()
        {
            // Rows 0-2 and 6-8 are the translation and the linear velocity, 3-5 and 9-11 their angular partners.
            *trend += (correction - *trend) * rates[usize::from(row % 6 >= 3)];
        }
        // P - K S Kᵀ = P - (P Hᵀ) S⁻¹ (P Hᵀ)ᵀ with the gain that is optimal for S (the Huber-inflated one included):
        // a twelfth of the Joseph form's work, as a rank-2 downdate in place, symmetrised every few updates against
        // round-off. Should rounding ever leave a variance that is not positive, the Joseph form takes over.
        for (j, column) in self
            .covariance
            .as_mut_slice()
            .chunks_exact_mut(N)
            .enumerate()
        {
            let (a, b) = (ph_t[(j, 0)], ph_t[(j, 1)]);
            for (i, entry) in column.iter_mut().enumerate() {
                *entry -= gain[(i, 0)] * a + gain[(i, 1)] * b;
            }
        }
        self.updates += 1;
        if self.updates.is_multiple_of(SYMMETRISE_EVERY_UPDATES) {
            self.covariance = (self.covariance + self.covariance.transpose()) * 0.5;
        }
        if (0..N).any(|i| self.covariance[(i, i)] <= 0.0) {
            let before = self.covariance + gain * ph_t.transpose();
            let mut h_full = SMatrix::<f64, 2, N>::zeros();
            h_full.fixed_columns_mut::<12>(0).copy_from(&h);
            let i_kh = SMatrix::<f64, N, N>::identity() - gain * h_full;
            self.covariance = i_kh * before * i_kh.transpose() + gain * gain.transpose() * sigma2;
        }
        UpdateOutcome::Accepted {
            norm_px: innovation.norm(),
            nis: mahalanobis2,
        }
    }
}

/// The Kalman filter of one motion model.
// Unboxed: the filter lives in its track and is not moved per measurement; a box would cost an allocation at every
// track start and an indirection at every update.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Filter {
    ConstantVelocity(ErrorStateKalman<12>),
    ConstantAcceleration(ErrorStateKalman<18>),
}

/// `$body` with `$f` bound to the filter, whichever its motion model.
macro_rules! with_filter {
    ($filter:expr, $f:ident => $body:expr) => {
        match $filter {
            Filter::ConstantVelocity($f) => $body,
            Filter::ConstantAcceleration($f) => $body,
        }
    };
}

impl Filter {
    pub(super) fn new(pose_twist: Matrix12, tuning: KalmanTuning, trend_rate: f64) -> Self {
        match tuning.motion_model {
            MotionModel::ConstantVelocity => {
                Self::ConstantVelocity(ErrorStateKalman::new(pose_twist, tuning, trend_rate))
            }
            MotionModel::ConstantAcceleration { .. } => {
                Self::ConstantAcceleration(ErrorStateKalman::new(pose_twist, tuning, trend_rate))
            }
        }
    }

    pub(super) fn tuning(&self) -> &KalmanTuning {
        with_filter!(self, f => &f.tuning)
    }

    pub(super) fn persistence(&self) -> [f64; 2] {
        with_filter!(self, f => f.persistence)
    }

    /// The newest update's innovation (px) and the part of its variance per axis the state's uncertainty makes (px²).
    pub(super) fn newest_innovation(&self) -> (Vector2<f64>, f64) {
        with_filter!(self, f => (f.innovation_px, f.predicted_variance_px2))
    }

    pub(super) fn pose_twist_covariance(&self) -> Matrix12 {
        with_filter!(self, f => f.pose_twist_covariance())
    }

    pub(super) fn acceleration(&self) -> Option<Acceleration> {
        match self {
            Self::ConstantVelocity(_) => None,
            Self::ConstantAcceleration(f) => Some(f.acceleration),
        }
    }

    pub(super) fn widen(&mut self, prior: &Matrix12, scale: f64) {
        with_filter!(self, f => f.widen(prior, scale))
    }

    pub(super) fn match_pose_innovation(
        &mut self,
        model: &SpatioTemporalModel,
        state: &MotionState,
        blobs: impl Iterator<Item = (Vector3<f64>, Vector2<f64>, f64)>,
        gate_chi2: f64,
    ) -> f64 {
        with_filter!(self, f => f.match_pose_innovation(model, state, blobs, gate_chi2))
    }

    pub(super) fn predict_known(
        &mut self,
        state: &mut MotionState,
        t_s: f64,
        dt_s: f64,
        process_scale: [f64; 2],
        known: &KnownAcceleration,
    ) {
        with_filter!(self, f => f.predict_known(state, t_s, dt_s, process_scale, known))
    }

    pub(super) fn add_process_noise(&mut self, dt_s: f64, process_scale: [f64; 2]) {
        with_filter!(self, f => f.add_process_noise(dt_s, process_scale))
    }

    pub(super) fn update(
        &mut self,
        model: &SpatioTemporalModel,
        state: &mut MotionState,
        point_in_obj_m: &Vector3<f64>,
        ideal_px: &Vector2<f64>,
        noise: CentroidNoise,
        judged_nis: Option<f64>,
    ) -> UpdateOutcome {
        with_filter!(self, f => f.update(model, state, point_in_obj_m, ideal_px, noise, judged_nis))
    }

    pub(super) fn prediction_nis(
        &self,
        model: &SpatioTemporalModel,
        state: &MotionState,
        point_in_obj_m: &Vector3<f64>,
        ideal_px: &Vector2<f64>,
        noise: CentroidNoise,
    ) -> Option<f64> {
        with_filter!(self, f => f.prediction_nis(model, state, point_in_obj_m, ideal_px, noise))
    }

    /// [`ErrorStateKalman::refine`] from `prior`, a copy of this filter before the readout (`false` if it is of
    /// the other motion model, which no filter changes into).
    pub(super) fn refine(
        &mut self,
        prior: &Self,
        fit: &ReadoutFit<'_>,
        state: &mut MotionState,
        readout: &mut [ReadoutMeasurement],
        known: Option<(f64, &KnownAcceleration)>,
    ) -> bool {
        match (self, prior) {
            (Self::ConstantVelocity(f), Self::ConstantVelocity(p)) => {
                f.refine_known(p, fit, state, readout, known)
            }
            (Self::ConstantAcceleration(f), Self::ConstantAcceleration(p)) => {
                f.refine_known(p, fit, state, readout, known)
            }
            _ => false,
        }
    }
}

/// Covariance matching of a pose innovation: when a fit of the pose alone moves the prediction by `x` (covariance
/// `fit_covariance`) beyond `gate_chi2` of `xᵀ (P_pose + C)⁻¹ x`, a chi-square of 6 degrees of freedom if the
/// prediction is right, the factor `α` on `P_pose` that makes it its expected 6; `None` within the gate.
pub(crate) fn pose_matching_scale(
    pose_covariance: &SMatrix<f64, 6, 6>,
    fit_covariance: &SMatrix<f64, 6, 6>,
    x: &Vector6<f64>,
    gate_chi2: f64,
) -> Option<f64> {
    let nis = |alpha: f64| {
        (pose_covariance * alpha + fit_covariance)
            .cholesky()
            .map(|c| x.dot(&c.solve(x)))
    };
    match nis(1.0) {
        Some(v) if v.is_finite() && v > gate_chi2 => {}
        _ => return None,
    }
    // The normalised innovation falls as α grows: bisect in its logarithm for the expected 6.
    let (mut low, mut high) = (1.0_f64, 1e8_f64);
    for _ in 0..40 {
        let mid = (low * high).sqrt();
        match nis(mid) {
            Some(v) if v > 6.0 => low = mid,
            _ => high = mid,
        }
    }
    Some(high)
}
