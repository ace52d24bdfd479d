//! Placing estimates on the truth's time axis, and interpolating the truth there.

use nalgebra::{UnitQuaternion, Vector3};
use roitrack_core::{PoseSample, TwistSample, so3};

use crate::EvalError;

/// Where an estimate's time falls among the truth samples: `fraction` of the way from sample `lower` to `lower + 1`.
///
/// `fraction == 0.0` means the truth sample `lower` itself (then `lower + 1` need not exist).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TruthIndex {
    pub lower: usize,
    pub fraction: f64,
}

/// Locates `t_s` (the time of estimate `index`) among the strictly increasing, non-empty `truth_times_s`.
///
/// A truth sample within `max_gap_s` is used as is; otherwise the truth is interpolated between its neighbours, and an
/// estimate outside the truth's span is an error.
pub(crate) fn locate(
    truth_times_s: &[f64],
    index: usize,
    t_s: f64,
    max_gap_s: f64,
) -> Result<TruthIndex, EvalError> {
    let n = truth_times_s.len();
    // First truth sample at or after t.
    let upper = truth_times_s.partition_point(|&s| s < t_s);
    let nearest = [upper.checked_sub(1), (upper < n).then_some(upper)]
        .into_iter()
        .flatten()
        .min_by(|&a, &b| {
            (truth_times_s[a] - t_s)
                .abs()
                .total_cmp(&(truth_times_s[b] - t_s).abs())
        });
    if let Some(i) = nearest
        && (truth_times_s[i] - t_s).abs() <= max_gap_s
    {
        return Ok(TruthIndex {
            lower: i,
            fraction: 0.0,
        });
    }
    if upper == 0 || upper == n {
        return Err(EvalError::OutsideTruthSpan {
            index,
            t_s,
            start_s: truth_times_s[0],
            end_s: truth_times_s[n - 1],
        });
    }
    let (t0, t1) = (truth_times_s[upper - 1], truth_times_s[upper]);
    Ok(TruthIndex {
        lower: upper - 1,
        fraction: (t_s - t0) / (t1 - t0),
    })
}

impl TruthIndex {
    /// The truth pose here: translation interpolated linearly, rotation by slerp (the shorter geodesic).
    pub fn pose(&self, truth: &[PoseSample]) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let a = &truth[self.lower].cam_from_obj;
        if self.fraction == 0.0 {
            return (a.rotation, a.translation.vector);
        }
        let b = &truth[self.lower + 1].cam_from_obj;
        let step = so3::log_quaternion(&(a.rotation.inverse() * b.rotation));
        let rotation = a.rotation * UnitQuaternion::from_scaled_axis(step * self.fraction);
        let translation = a
            .translation
            .vector
            .lerp(&b.translation.vector, self.fraction);
        (rotation, translation)
    }

    /// The truth twist here `(V, W)`, both interpolated linearly.
    pub fn twist(&self, truth: &[TwistSample]) -> (Vector3<f64>, Vector3<f64>) {
        let a = &truth[self.lower];
        if self.fraction == 0.0 {
            return (a.velocity_mps, a.angular_velocity_radps);
        }
        let b = &truth[self.lower + 1];
        (
            a.velocity_mps.lerp(&b.velocity_mps, self.fraction),
            a.angular_velocity_radps
                .lerp(&b.angular_velocity_radps, self.fraction),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TIMES: [f64; 4] = [0.0, 1.0, 2.0, 4.0];

    #[test]
    fn exact_and_near_times_use_the_sample() {
        for (t, expected) in [(0.0, 0), (1.0, 1), (2.0 + 1e-9, 2), (4.0 - 1e-9, 3)] {
            let at = locate(&TIMES, 0, t, 1e-6).unwrap();
            assert_eq!(
                at,
                TruthIndex {
                    lower: expected,
                    fraction: 0.0
                },
                "t = {t}"
            );
        }
    }

    #[test]
    fn times_between_samples_are_interpolated() {
        let at = locate(&TIMES, 0, 3.0, 1e-6).unwrap();
        assert_eq!(at.lower, 2);
        assert!((at.fraction - 0.5).abs() < 1e-15);
        let at = locate(&TIMES, 0, 0.25, 1e-6).unwrap();
        assert_eq!(at.lower, 0);
        assert!((at.fraction - 0.25).abs() < 1e-15);
    }

    #[test]
    fn times_outside_the_span_are_errors() {
        for t in [-1e-3, 4.0 + 1e-3] {
            let err = locate(&TIMES, 7, t, 1e-6).unwrap_err();
            assert_eq!(
                err,
                EvalError::OutsideTruthSpan {
                    index: 7,
                    t_s: t,
                    start_s: 0.0,
                    end_s: 4.0
                }
            );
        }
    }

    #[test]
    fn a_single_truth_sample_matches_only_its_own_time() {
        assert!(locate(&[1.0], 0, 1.0, 1e-6).is_ok());
        assert!(locate(&[1.0], 0, 1.1, 1e-6).is_err());
    }
}
