//! An error-state extended Kalman filter on the 12-dof state with a constant-velocity process model: every centroid
//! updates the state once, at its own time.
//!
//! The error state is the correction `δ = (v, w, dV, dW)` of [`MotionState::corrected`]. Between measurements the
//! state moves with its twist; the twist drifts as a random walk driven by white linear and angular acceleration of
//! spectral densities `q_a` ((m/s²)²/Hz) and `q_α` ((rad/s²)²/Hz).

use nalgebra::{Matrix2, Matrix3, SMatrix, Vector2, Vector3};

use crate::{JacobianKind, MotionState, SpatioTemporalModel, so3};

pub type Matrix12 = SMatrix<f64, 12, 12>;

/// Tuning of the recursive estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanTuning {
    /// White linear acceleration spectral density q_a ((m/s²)²/Hz). Larger: less lag, more noise.
    pub linear_accel_psd: f64,
    /// White angular acceleration spectral density q_α ((rad/s²)²/Hz).
    pub angular_accel_psd: f64,
    /// Innovations beyond this many standard deviations (Mahalanobis, 2 dof) are rejected as outliers. Default 3:
    /// it rejects exp(-9/2) = 1.1 % of good measurements. Measured with `roitrack faults` (3 runs each): against 6,
    /// it costs 0.9 % of position RMSE on clean measurements (0.2647 against 0.2623 mm on orthoglide), and with 10 %
    /// of rendered ROIs carrying a reflection it keeps the error at 1.4-3.6x the clean image run instead of 1.9-21x
    /// (a reflection merged with the blob biases its centroid by a fraction of a pixel, well inside 6 σ of the
    /// prediction); 3.5 left up to 30x.
    pub gate_sigma: f64,
    /// Huber threshold (standard deviations, Mahalanobis): a larger innovation gets its measurement noise inflated
    /// by `distance / huber_sigma` (the Huber weight), so a moderate outlier pulls less; `f64::INFINITY` turns it off.
    pub huber_sigma: f64,
}

impl Default for KalmanTuning {
    fn default() -> Self {
        Self {
            linear_accel_psd: 1.0,
            angular_accel_psd: 10.0,
            gate_sigma: 3.0,
            huber_sigma: 2.5,
        }
    }
}

/// The filter's covariance; the state itself lives in the tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStateKalman {
    pub covariance: Matrix12,
    pub tuning: KalmanTuning,
}

/// What one measurement update did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpdateOutcome {
    Accepted,
    /// Rejected by the innovation gate.
    Gated,
    /// The point does not project (behind the camera) or the innovation covariance is singular.
    Invalid,
}

impl ErrorStateKalman {
    pub fn new(covariance: Matrix12, tuning: KalmanTuning) -> Self {
        Self { covariance, tuning }
    }

    /// Moves the state `dt_s` ahead and grows the covariance.
    pub fn predict(&mut self, state: &mut MotionState, dt_s: f64) {
        if dt_s == 0.0 {
            return;
        }
        let rotation_increment = state.angular_velocity_radps * dt_s;
        let mut f = Matrix12::identity();
        f.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&(Matrix3::identity() * dt_s));
        f.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(so3::exp(&rotation_increment).matrix());
        f.fixed_view_mut::<3, 3>(3, 9)
            .copy_from(&(so3::left_jacobian(&rotation_increment) * dt_s));
        let dt = dt_s.abs();
        let mut q = Matrix12::zeros();
        for (pos, vel, psd) in [
            (0, 6, self.tuning.linear_accel_psd),
            (3, 9, self.tuning.angular_accel_psd),
        ] {
            let i3 = Matrix3::identity();
            q.fixed_view_mut::<3, 3>(pos, pos)
                .copy_from(&(i3 * (psd * dt * dt * dt / 3.0)));
            q.fixed_view_mut::<3, 3>(pos, vel)
                .copy_from(&(i3 * (psd * dt * dt / 2.0)));
            q.fixed_view_mut::<3, 3>(vel, pos)
                .copy_from(&(i3 * (psd * dt * dt / 2.0)));
            q.fixed_view_mut::<3, 3>(vel, vel)
                .copy_from(&(i3 * (psd * dt)));
        }
        self.covariance = f * self.covariance * f.transpose() + q;
        *state = state.predicted(dt_s);
    }

    /// Updates with one centroid (ideal pixel) of `point_in_obj_m`, observed at the state's reference time.
    pub fn update(
        &mut self,
        model: &SpatioTemporalModel,
        state: &mut MotionState,
        point_in_obj_m: &Vector3<f64>,
        ideal_px: &Vector2<f64>,
        sigma_px: f64,
    ) -> UpdateOutcome {
        let Some(projected) =
            model.project_with_jacobian(JacobianKind::Exact, state, point_in_obj_m, 0.0)
        else {
            return UpdateOutcome::Invalid;
        };
        let h = projected.jacobian;
        let innovation = ideal_px - projected.pixel;
        let ph_t: SMatrix<f64, 12, 2> = self.covariance * h.transpose();
        let s = h * ph_t + Matrix2::identity() * (sigma_px * sigma_px);
        let Some(s_inv) = s.try_inverse() else {
            return UpdateOutcome::Invalid;
        };
        let mahalanobis2 = (innovation.transpose() * s_inv * innovation)[0];
        if !mahalanobis2.is_finite() {
            return UpdateOutcome::Invalid;
        }
        if mahalanobis2 > self.tuning.gate_sigma * self.tuning.gate_sigma {
            return UpdateOutcome::Gated;
        }
        let distance = mahalanobis2.sqrt();
        let (sigma2, s_inv) = if distance > self.tuning.huber_sigma {
            let inflated = sigma_px * sigma_px * distance / self.tuning.huber_sigma;
            match (h * ph_t + Matrix2::identity() * inflated).try_inverse() {
                Some(inv) => (inflated, inv),
                None => return UpdateOutcome::Invalid,
            }
        } else {
            (sigma_px * sigma_px, s_inv)
        };
        let gain = ph_t * s_inv;
        let correction = gain * innovation;
        let corrected = state.corrected(&correction);
        if !corrected.is_finite() {
            return UpdateOutcome::Invalid;
        }
        *state = corrected;
        // Joseph form: stays symmetric positive definite in floating point.
        let i_kh = Matrix12::identity() - gain * h;
        self.covariance =
            i_kh * self.covariance * i_kh.transpose() + gain * gain.transpose() * sigma2;
        UpdateOutcome::Accepted
    }
}
