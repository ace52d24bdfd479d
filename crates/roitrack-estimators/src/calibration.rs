//! Calibration of the twist covariance a Kalman filter reports, against the track's own history.
//!
//! A white-acceleration motion model that follows manoeuvres without lag claims a velocity uncertainty that smooth
//! motions do not have: on the built-in scenes the velocity's mean NEES / 3 was 0.24-0.43, the covariance two to four
//! times too wide, even with the noise and the densities told. The filter needs that process noise for its gain, so
//! the reported covariance is corrected instead: each vouched estimate's twist is compared with the mean twist of
//! the poses around it (the central difference of the positions and the rotation between the two poses, over their
//! time apart), 8 estimates before and after it and 32 (40 and 160 ms at 400 Hz). The running mean of the normalised
//! squared differences `dᵀ P⁻¹ d / 3`, for the linear and the angular velocity separately, is the true one plus what
//! the reference's own error adds (the poses' noise over their time apart, the twist's change over it): the short
//! reference follows manoeuvres, the long one averages the poses' noise down on slow motion, and the smaller of the
//! two scales the twist's rows and columns of the reported covariance (by its square root on each side, so that the
//! cross-covariances with the pose keep the matrix positive semi-definite). It errs on the wide side. The filter
//! itself is not changed. On the built-in scenes at 0.03 to 1 px the velocity's mean NEES / 3 becomes 0.57-1.18.

use nalgebra::{Matrix3, Rotation3, Vector3};

use roitrack_core::{MotionState, so3};

use super::kalman::Matrix12;

/// Estimates on each side of the one checked, for the two references: `2 * h` estimates (40 and 160 ms at 400 Hz).
/// The short one follows manoeuvres, the long one averages the poses' noise down on slow motion; each scale is the
/// true one plus what its reference's own error adds, so the smaller of the two is reported.
const HALF_SPANS: [usize; 2] = [8, 32];
const SPAN: usize = 2 * HALF_SPANS[1] + 1;
/// Samples the running mean remembers (an exponential memory beyond them).
const MEMORY: f64 = 200.0;
/// The filter's own covariance (a scale of 1) counts as this many samples: a short run moves the scale only part
/// of the way, and few samples cannot narrow it much by chance.
const PRIOR_SAMPLES: f64 = 20.0;
/// One sample counts at most this much (NEES / 3): a manoeuvre the reference cannot follow must not blow the scale
/// up for the next hundred estimates.
const MAX_SAMPLE: f64 = 25.0;

#[derive(Debug, Clone, Copy)]
struct Entry {
    t_s: f64,
    cam_r_obj: Rotation3<f64>,
    cam_t_obj_m: Vector3<f64>,
    velocity_mps: Vector3<f64>,
    angular_velocity_radps: Vector3<f64>,
    velocity_cov: Matrix3<f64>,
    angular_velocity_cov: Matrix3<f64>,
    vouched: bool,
}

/// The running scales of the linear and the angular velocity covariance (see the module's documentation).
#[derive(Debug, Clone)]
pub(crate) struct TwistCalibration {
    ring: [Option<Entry>; SPAN],
    next: usize,
    /// Per reference: the running means of the normalised squared differences (NEES / 3), linear then angular, and
    /// the samples they hold.
    scale: [[f64; 2]; 2],
    samples: [f64; 2],
}

impl TwistCalibration {
    pub(crate) fn new() -> Self {
        Self {
            ring: [None; SPAN],
            next: 0,
            scale: [[1.0; 2]; 2],
            samples: [0.0; 2],
        }
    }

    /// Forgets the history (a new track) but keeps the scales learnt so far.
    pub(crate) fn restart(&mut self) {
        self.ring = [None; SPAN];
        self.next = 0;
    }

    /// Records an estimate (the state at `t_s` and the filter's covariance) and updates the scales from the estimate
    /// half a reference's span before it when it and the two ends of the span are vouched for.
    pub(crate) fn record(
        &mut self,
        t_s: f64,
        state: &MotionState,
        covariance: &Matrix12,
        vouched: bool,
    ) {
        self.ring[self.next] = Some(Entry {
            t_s,
            cam_r_obj: state.cam_r_obj,
            cam_t_obj_m: state.cam_t_obj_m,
            velocity_mps: state.velocity_mps,
            angular_velocity_radps: state.angular_velocity_radps,
            velocity_cov: covariance.fixed_view::<3, 3>(6, 6).into_owned(),
            angular_velocity_cov: covariance.fixed_view::<3, 3>(9, 9).into_owned(),
            vouched,
        });
        let newest = self.next;
        self.next = (self.next + 1) % SPAN;
        for (k, half) in HALF_SPANS.into_iter().enumerate() {
            let (Some(last), Some(middle), Some(first)) = (
                self.ring[newest],
                self.ring[(newest + SPAN - half) % SPAN],
                self.ring[(newest + SPAN - 2 * half) % SPAN],
            ) else {
                continue;
            };
            let span_s = last.t_s - first.t_s;
            if !(last.vouched && middle.vouched && first.vouched) || span_s <= 0.0 {
                continue;
            }
            let velocity_ref = (last.cam_t_obj_m - first.cam_t_obj_m) / span_s;
            let angular_ref = so3::log(&(last.cam_r_obj * first.cam_r_obj.inverse())) / span_s;
            let (Some(linear), Some(angular)) = (
                normalised_squared(&(middle.velocity_mps - velocity_ref), &middle.velocity_cov),
                normalised_squared(
                    &(middle.angular_velocity_radps - angular_ref),
                    &middle.angular_velocity_cov,
                ),
            ) else {
                continue;
            };
            self.samples[k] += 1.0;
            let weight = 1.0 / (self.samples[k] + PRIOR_SAMPLES).min(MEMORY);
            for (scale, sample) in self.scale[k].iter_mut().zip([linear, angular]) {
                *scale += weight * (sample.min(MAX_SAMPLE) - *scale);
            }
        }
    }

    /// The scales applied, linear and angular: the smaller of the two references'.
    fn applied_scale(&self) -> [f64; 2] {
        [0, 1].map(|i| self.scale[0][i].min(self.scale[1][i]))
    }

    /// The filter's covariance with the twist's rows and columns scaled.
    pub(crate) fn apply(&self, covariance: &Matrix12) -> Matrix12 {
        let scale = self.applied_scale();
        let mut factors = [1.0; 12];
        for (k, factor) in factors.iter_mut().enumerate().skip(6) {
            *factor = scale[(k - 6) / 3].sqrt();
        }
        Matrix12::from_fn(|i, j| covariance[(i, j)] * factors[i] * factors[j])
    }
}

/// `dᵀ P⁻¹ d / 3`, or `None` when `P` is not positive definite.
fn normalised_squared(d: &Vector3<f64>, p: &Matrix3<f64>) -> Option<f64> {
    let cholesky = p.cholesky()?;
    Some(d.dot(&cholesky.solve(d)) / 3.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight run at 1 m/s sampled every 2.5 ms, whose reported velocity errs by `error_mps` (alternating sign)
    /// with a claimed standard deviation of `claimed_mps` on each axis.
    fn run(error_mps: f64, claimed_mps: f64) -> TwistCalibration {
        let mut calibration = TwistCalibration::new();
        let mut covariance = Matrix12::identity() * 1e-8;
        for k in 6..12 {
            covariance[(k, k)] = claimed_mps * claimed_mps;
        }
        for k in 0..3000 {
            let t_s = k as f64 * 0.0025;
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            let state = MotionState {
                cam_r_obj: Rotation3::identity(),
                cam_t_obj_m: Vector3::new(t_s, 0.0, 0.6),
                velocity_mps: Vector3::new(1.0 + sign * error_mps, 0.0, 0.0),
                angular_velocity_radps: Vector3::zeros(),
            };
            calibration.record(t_s, &state, &covariance, true);
        }
        calibration
    }

    #[test]
    fn a_covariance_too_wide_is_narrowed_and_a_right_one_kept() {
        // Errors of 0.01 m/s along x only: NEES / 3 = (0.01 / claimed)² / 3.
        let wide = run(0.01, 0.03);
        // After thousands of samples the prior (a scale of 1) is forgotten.
        assert!(
            (wide.scale[0][0] - 1.0 / 27.0).abs() < 1e-5,
            "{:?}",
            wide.scale
        );
        let right = run(0.01, 0.01 / 3f64.sqrt());
        assert!((right.scale[0][0] - 1.0).abs() < 1e-9, "{:?}", right.scale);
        // The angular part had no error at all.
        assert!(wide.scale[0][1] < 1e-5 && wide.scale[1][1] < 1e-5);
        // Applied: the velocity block is scaled, the pose block kept, the matrix stays symmetric.
        let mut covariance = Matrix12::identity() * 1e-8;
        for k in 6..12 {
            covariance[(k, k)] = 0.03 * 0.03;
        }
        covariance[(0, 6)] = 1e-6;
        covariance[(6, 0)] = 1e-6;
        let applied = wide.apply(&covariance);
        let scale = wide.applied_scale()[0];
        assert!((scale * 27.0 - 1.0).abs() < 1e-3, "{scale}");
        assert!((applied[(6, 6)] - 0.03 * 0.03 * scale).abs() < 1e-15);
        assert_eq!(applied[(0, 0)], covariance[(0, 0)]);
        assert!((applied[(0, 6)] - 1e-6 * scale.sqrt()).abs() < 1e-15);
        assert_eq!(applied, applied.transpose());
    }

    #[test]
    fn nothing_is_scaled_without_vouched_estimates() {
        let mut calibration = TwistCalibration::new();
        let covariance = Matrix12::identity() * 1e-4;
        let state = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6));
        for k in 0..100 {
            calibration.record(k as f64 * 0.0025, &state, &covariance, false);
        }
        assert_eq!(calibration.apply(&covariance), covariance);
    }
}
