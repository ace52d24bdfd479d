//! The iterated update of a readout (the blobs of a frame, or a rolling-shutter frame's rows) fitted together
//! with the prior.

use super::*;

/// A measurement of one readout for [`ErrorStateKalman::refine`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ReadoutMeasurement {
    pub(super) point_index: usize,
    pub(super) point_in_obj_m: Vector3<f64>,
    pub(super) ideal_px: Vector2<f64>,
    /// Its time after the readout's first measurement.
    pub(super) dt_s: f64,
    /// Its variance per axis (px²), as the sequential update weighed it (Huber-inflated beyond `huber_sigma`).
    pub(super) variance_px2: f64,
    /// Whether the sequential update rejected it, and whether the refinement uses it.
    pub(super) gated: bool,
    pub(super) used: bool,
}

/// Fewest accepted blobs of a readout that are refined together: two blobs do not pin a pose, and their sequential
/// updates are the fit of so few.
pub(super) const MIN_READOUT_TO_REFINE: usize = 3;

/// Most Gauss-Newton steps of a readout's refinement; near a frame's blobs it converges in two or three, from a
/// prior far off in the twist in up to ten.
pub(super) const REFINE_MAX_ITERATIONS: usize = 10;

/// A refinement stops when no entry of the scaled correction (in prior standard deviations) moves more than this.
pub(super) const REFINE_TOLERANCE: f64 = 1e-6;

/// What a readout's refinement ([`ErrorStateKalman::refine`]) fits against, beside the filter, its prior and the
/// readout's measurements: the prior's state at the readout's first time, the readout's span after it, the camera
/// model, the centroid noise, and the process noise's scale for the move to the readout's last time.
#[derive(Debug, Clone, Copy)]
pub(super) struct ReadoutFit<'a> {
    pub(super) prior_state: &'a MotionState,
    pub(super) span_s: f64,
    pub(super) model: &'a SpatioTemporalModel,
    pub(super) noise: CentroidNoise,
    pub(super) process_scale: [f64; 2],
}

/// A readout's refined state at its first measurement time: the state, its accelerations, and their covariance.
pub(super) type Refined<const N: usize> = (MotionState, Acceleration, SMatrix<f64, N, N>);

impl<const N: usize> ErrorStateKalman<N> {
    /// [`Self::refine`] with a known acceleration `known` (a control input, [`KnownAcceleration`], and the
    /// readout's first time; without one, exactly [`Self::refine`]): the readout is fitted, and moved to its last
    /// time, with the sum of the filter's acceleration and the input in force at its first time, held over its span:
    /// a change of the input within one readout (a frame's few milliseconds) is not followed.
    pub(super) fn refine_known(
        &mut self,
        prior: &Self,
        fit: &ReadoutFit<'_>,
        state: &mut MotionState,
        readout: &mut [ReadoutMeasurement],
        known: Option<(f64, &KnownAcceleration)>,
    ) -> bool {
        let Some((first_s, known)) = known.filter(|(_, k)| !k.is_empty()) else {
            return self.refine(prior, fit, state, readout);
        };
        // The filter and its prior as if their own acceleration were the sum; the input taken back out after.
        let u = known.at(first_s);
        let mut shifted = *self;
        shifted.acceleration = known::sum(&self.acceleration, &u);
        let mut shifted_prior = *prior;
        shifted_prior.acceleration = known::sum(&prior.acceleration, &u);
        if !shifted.refine(&shifted_prior, fit, state, readout) {
            return false;
        }
        *self = shifted;
        self.acceleration = known::difference(&shifted.acceleration, &u);
        true
    }

    /// The iterated update of a readout (the blobs of a frame), from this filter after its sequential updates, whose
    /// state is `state`, `fit.span_s` after the readout's first measurement; `prior` and `fit.prior_state` are the
    /// filter before them, at that first time.
    ///
    /// 1. The state that best fits both the prior and every blob the sequential updates used, at once
    ///    ([`Self::refined`]).
    /// 2. The blobs they rejected are judged again against that state's prediction and its covariance; those inside
    ///    the gate are used after all (marked in `readout`), and the fit is made again with them.
    /// 3. The filter takes the result, moved to the readout's last time.
    ///
    /// Why: the sequential updates linearise each blob at the state the blobs before it left, so when the prior is
    /// wide (the frame after a new track, or one the target crossed faster than predicted) the first blobs move the
    /// state far along directions they do not pin (depth, with four dots), the later blobs are linearised there, and
    /// the result stops short of the frame by pixels; a later blob may even be rejected as an outlier although the
    /// fit of all of them puts it within a hundredth of a pixel. Returns whether the filter was refined; it is left
    /// as it was when the sequential updates were [linear enough](Self::linear_enough), a point does not project,
    /// the information is not positive definite, or the fit is worse than the sequential result (`readout`'s marks
    /// may then say recovered blobs that were not used).
    ///
    /// Two approximations, standard for an iterated extended Kalman update: a blob read after the first time is a
    /// function of the state at that time without the process noise between (over a rolling shutter's readout of the
    /// target, 4.5 ms, a few hundredths of a pixel with the rolling-shutter jerk densities; the noise over the span is
    /// added once, at the end), and the Jacobians at the iterate are used for corrections from the prior, without the
    /// left Jacobian of the rotation's correction (1.5 % on the rotation's columns at 0.03 rad).
    pub(super) fn refine(
        &mut self,
        prior: &Self,
        fit: &ReadoutFit<'_>,
        state: &mut MotionState,
        readout: &mut [ReadoutMeasurement],
    ) -> bool {
        let ReadoutFit {
            prior_state,
            span_s,
            model,
            noise,
            process_scale,
        } = *fit;
        let start = (
            self.acceleration.predicted(state, -span_s),
            self.acceleration,
        );
        if Self::linear_enough(prior_state, &start.0, model, readout, noise.white_px) {
            return false;
        }
        let Some(mut fit) = Self::refined(prior, prior_state, start, model, readout) else {
            return false;
        };
        let gate2 = self.tuning.gate_sigma * self.tuning.gate_sigma;
        let mut recovered = false;
        for m in readout.iter_mut().filter(|m| m.gated) {
            let judged = ReadoutMeasurement {
                variance_px2: noise.total_px2(),
                ..*m
            };
            if Self::normalised_innovation2(&fit, model, &judged).is_some_and(|nis| nis <= gate2) {
                *m = ReadoutMeasurement {
                    used: true,
                    variance_px2: noise.white_px * noise.white_px,
                    ..*m
                };
                recovered = true;
            }
        }
        if recovered {
            match Self::refined(prior, prior_state, (fit.0, fit.1), model, readout) {
                Some(again) => fit = again,
                None => return false,
            }
        }
        (*state, self.acceleration, self.covariance) = fit;
        self.predict(state, span_s, process_scale);
        true
    }

    /// Whether the sequential updates moved the state from the prior (`prior_state`) to `start` (both at the
    /// readout's first time) so little that their linearisation is exact to a tenth of the noise, and no blob was
    /// rejected: then a refinement would change nothing. A projection's second-order term after a correction of the
    /// rotation by `w` (rad) and of the translation by `v` at depth `z` is at most about `f (|w| + |v|/z)² / 2`
    /// pixels, `f` the focal length. This is the common case of a track that follows its target, and skipping the
    /// refinement there saves about a third of the frame's work (measured in docs/results.md, "Design measurements
    /// behind the code").
    pub(super) fn linear_enough(
        prior_state: &MotionState,
        start: &MotionState,
        model: &SpatioTemporalModel,
        readout: &[ReadoutMeasurement],
        noise_px: f64,
    ) -> bool {
        if readout.iter().any(|m| m.gated) {
            return false;
        }
        let moved = MotionState::difference(prior_state, start);
        let depth_m = prior_state.cam_t_obj_m.z.abs().max(1e-3);
        let angle = moved.fixed_rows::<3>(3).norm() + moved.fixed_rows::<3>(0).norm() / depth_m;
        let focal_px = model
            .intrinsics
            .fx_px
            .abs()
            .max(model.intrinsics.fy_px.abs());
        0.5 * focal_px * angle * angle < 0.1 * noise_px
    }

    /// The Gauss-Newton fit of the prior (`prior`, `prior_state`) and the used blobs of `readout`, from `start`:
    /// the state, accelerations and covariance at the readout's first time; `None` if a point does not project, the
    /// information is not positive definite, or the steps ended where the cost is higher than at `start`.
    ///
    /// Solved in information form, scaled by the prior's standard deviations (the pose's variances are 1e-10 m² and
    /// the accelerations' 100 (rad/s²)²: unscaled, the prior's inverse would lose the pose's digits), so the work
    /// does not grow with the number of blobs beyond their Jacobians: an `N x N` factorisation per step.
    pub(super) fn refined(
        prior: &Self,
        prior_state: &MotionState,
        start: (MotionState, Acceleration),
        model: &SpatioTemporalModel,
        readout: &[ReadoutMeasurement],
    ) -> Option<Refined<N>> {
        let scale = SVector::<f64, N>::from_fn(|i, _| prior.covariance[(i, i)].max(0.0).sqrt());
        if scale.iter().any(|&s| !(s > 0.0 && s.is_finite())) {
            return None;
        }
        let scaled_prior =
            SMatrix::<f64, N, N>::from_fn(|i, j| prior.covariance[(i, j)] / (scale[i] * scale[j]));
        let prior_information = scaled_prior.cholesky()?.inverse();
        let mut iterate = start;
        let mut information = prior_information;
        // The cost (prior term plus weighted squared residuals) at `start` and at the newest iterate: a fit that ends
        // above where it started (a Gauss-Newton step too long for the curvature) is not taken. Steps that have not
        // converged after the last iteration end at the iterate before them (improved, if not optimal).
        let (mut start_cost, mut cost) = (None, 0.0);
        let (mut converged, mut linearised_at) = (false, start);
        for _ in 0..REFINE_MAX_ITERATIONS {
            linearised_at = iterate;
            let (at, acceleration) = &iterate;
            // The iterate's correction from the prior, scaled.
            let mut from_prior = SVector::<f64, N>::zeros();
            from_prior
                .fixed_rows_mut::<12>(0)
                .copy_from(&MotionState::difference(prior_state, at));
            if Self::WITH_ACCELERATION {
                from_prior
                    .fixed_rows_mut::<3>(12)
                    .copy_from(&(acceleration.linear_mps2 - prior.acceleration.linear_mps2));
                from_prior
                    .fixed_rows_mut::<3>(15)
                    .copy_from(&(acceleration.angular_radps2 - prior.acceleration.angular_radps2));
            }
            let from_prior = from_prior.component_div(&scale);
            information = prior_information;
            cost = from_prior.dot(&(prior_information * from_prior));
            let mut gradient = SVector::<f64, N>::zeros();
            for m in readout.iter().filter(|m| m.used) {
                let (pixel, h) = readout_projection::<N>(model, at, acceleration, m)?;
                let h = SMatrix::<f64, 2, N>::from_fn(|r, c| h[(r, c)] * scale[c]);
                let weight = 1.0 / m.variance_px2;
                cost += (m.ideal_px - pixel).norm_squared() * weight;
                let residual = m.ideal_px - pixel + h * from_prior;
                if m.dt_s == 0.0 {
                    // A blob at the readout's first time does not see the accelerations: their columns are zero
                    // (half the work with them, on global-shutter frames).
                    let h = h.fixed_columns::<12>(0);
                    let mut block = information.fixed_view_mut::<12, 12>(0, 0);
                    block += h.transpose() * h * weight;
                    let mut rows = gradient.fixed_rows_mut::<12>(0);
                    rows += h.transpose() * residual * weight;
                } else {
                    information += h.transpose() * h * weight;
                    gradient += h.transpose() * residual * weight;
                }
            }
            start_cost.get_or_insert(cost);
            let correction = information.cholesky()?.solve(&gradient);
            let unscaled = correction.component_mul(&scale);
            let moved = (correction - from_prior).amax();
            let corrected = prior_state.corrected(&unscaled.fixed_rows::<12>(0).into_owned());
            let mut corrected_acceleration = prior.acceleration;
            if Self::WITH_ACCELERATION {
                corrected_acceleration.linear_mps2 += unscaled.fixed_rows::<3>(12);
                corrected_acceleration.angular_radps2 += unscaled.fixed_rows::<3>(15);
            }
            if !corrected.is_finite() {
                return None;
            }
            iterate = (corrected, corrected_acceleration);
            if moved < REFINE_TOLERANCE {
                converged = true;
                break;
            }
        }
        if !converged {
            // The newest iterate whose cost is known, and at which the information was taken.
            iterate = linearised_at;
        }
        if start_cost.is_none_or(|start| cost > start * (1.0 + 1e-9)) {
            return None;
        }
        let scaled_covariance = information.cholesky()?.inverse();
        let covariance = SMatrix::<f64, N, N>::from_fn(|i, j| {
            0.5 * (scaled_covariance[(i, j)] + scaled_covariance[(j, i)]) * scale[i] * scale[j]
        });
        Some((iterate.0, iterate.1, covariance))
    }

    /// The squared Mahalanobis distance of `m`'s innovation at the refined state `fit`: against the covariance of its
    /// prediction plus its own variance.
    pub(super) fn normalised_innovation2(
        fit: &Refined<N>,
        model: &SpatioTemporalModel,
        m: &ReadoutMeasurement,
    ) -> Option<f64> {
        let (pixel, h) = readout_projection::<N>(model, &fit.0, &fit.1, m)?;
        let s = h * fit.2 * h.transpose() + Matrix2::identity() * m.variance_px2;
        let innovation = m.ideal_px - pixel;
        Some((innovation.transpose() * s.try_inverse()? * innovation)[0])
    }
}

/// The ideal pixel of a readout's measurement `m` and its Jacobian with respect to the error state at the readout's
/// first time, where the state is `at` with `acceleration`: the projection at the measurement's own time, times the
/// transition to it (`H F`).
pub(super) fn readout_projection<const N: usize>(
    model: &SpatioTemporalModel,
    at: &MotionState,
    acceleration: &Acceleration,
    m: &ReadoutMeasurement,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, N>)> {
    let moved = acceleration.predicted(at, m.dt_s);
    let projected =
        model.project_with_jacobian(JacobianKind::Exact, &moved, &m.point_in_obj_m, 0.0)?;
    let h = projected.jacobian;
    let mut h_at_first = SMatrix::<f64, 2, N>::zeros();
    h_at_first.fixed_columns_mut::<12>(0).copy_from(&h);
    if m.dt_s != 0.0 {
        // Row by row, H F with F's blocks (see [`Transition`]).
        let transition = Transition::new(at, acceleration, m.dt_s);
        let (h_v, h_w) = (h.fixed_columns::<3>(0), h.fixed_columns::<3>(3));
        let (h_dv, h_dw) = (h.fixed_columns::<3>(6), h.fixed_columns::<3>(9));
        h_at_first
            .fixed_columns_mut::<3>(3)
            .copy_from(&(h_w * transition.e));
        h_at_first
            .fixed_columns_mut::<3>(6)
            .copy_from(&(h_v * transition.dt_s + h_dv));
        h_at_first
            .fixed_columns_mut::<3>(9)
            .copy_from(&(h_w * transition.b + h_dw));
        if N == 18 {
            h_at_first
                .fixed_columns_mut::<3>(12)
                .copy_from(&(h_v * transition.half_dt2 + h_dv * transition.dt_s));
            h_at_first
                .fixed_columns_mut::<3>(15)
                .copy_from(&(h_w * transition.b_half_dt + h_dw * transition.dt_s));
        }
    }
    Some((projected.pixel, h_at_first))
}
