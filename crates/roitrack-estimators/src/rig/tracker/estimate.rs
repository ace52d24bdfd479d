//! The fused estimates: one every `every` fused measurements, its status from the filter's own gate and from the
//! cameras' own tracks, against which each fused position is cross-checked.

use roitrack_core::Vector12;
use roitrack_core::stats::chi2_upper_quantile;

use super::{ClockEstimate, RigTracker};
use crate::{Estimate, Matrix12, TrackStatus};

/// One estimate of a [`RigTracker`]: the state is `rig_T_object` with its twist in the rig frame, its time on the
/// rig's clock; and every camera's clock as known then.
#[derive(Debug, Clone, PartialEq)]
pub struct RigEstimate {
    /// The fused estimate of `rig_T_object`, in the rig frame and on the rig's clock.
    pub estimate: Estimate,
    /// Every camera's clock at that time, in the rig's camera order.
    pub clocks: Vec<ClockEstimate>,
}

/// Measurements rejected in a row that dispute an estimate, and the normalised innovation squared beyond which one
/// rejection alone does (the single-camera filter's: 3 in a row happen by chance once in 700,000 good measurements;
/// 25 is 5 sigma).
const DISPUTED_AFTER_GATED_IN_A_ROW: usize = 3;
const DISPUTED_NIS: f64 = 25.0;
/// Estimates given as converging after a fused track starts.
const CONVERGING_ESTIMATES: usize = 3;

impl RigTracker {
    /// Whether nothing but the fused filter stands behind its position: each synced camera's own estimate (vouched
    /// for) nearest in time within [`CROSS_CHECK_SPAN_S`], carried to the fused time by its twist, refutes the fused
    /// position if their difference lies beyond the [`CROSS_CHECK_Z`] bound of its covariance (at most the sum of
    /// theirs, since they share measurements, plus the white acceleration's over the carry). The fused estimate is
    /// then disputed if no camera has such an estimate near it (on 30 Hz frames of a fast target a fused track ran 2 m
    /// off while the first camera's own track, restarted on every frame, vouched for nothing), if every camera
    /// compared refutes it, or if a camera whose clock is given (the first, or one the rig file times) does: a clock
    /// learnt wrong carries its camera's estimates with the fused track it pulls, and they agree, where the given
    /// clock's camera cannot be wrong in time. One camera with a learnt clock refuting it alone is the camera's own
    /// track gone astray (carried across an occlusion), not the fused one.
    fn contradicted_by_the_cameras(&self) -> bool {
        let Some(f) = &self.fused else {
            return false;
        };
        let bound = chi2_upper_quantile(3.0, CROSS_CHECK_Z);
        let fused_position = f.p.fixed_view::<3, 3>(0, 0).into_owned();
        let verdicts = (0..self.rig.len())
            .filter(|&c| self.synced[c])
            .filter_map(|c| {
                // In time order: the nearest is one of the two around the fused time (a search, not a scan: this
                // runs at every fused estimate).
                let recent = &self.recent_singles[c];
                let after = recent.partition_point(|e| e.t_ref_s < f.t_s);
                [after.checked_sub(1), Some(after)]
                    .into_iter()
                    .flatten()
                    .filter_map(|i| recent.get(i))
                    .filter(|e| (f.t_s - e.t_ref_s).abs() <= CROSS_CHECK_SPAN_S)
                    .min_by(|a, b| {
                        (a.t_ref_s - f.t_s)
                            .abs()
                            .total_cmp(&(b.t_ref_s - f.t_s).abs())
                    })
                    .map(|e| (c, e))
            })
            .filter_map(|(c, e)| {
                let p = e.covariance?;
                let dt = f.t_s - e.t_ref_s;
                // Position covariance carried by the constant twist over dt: P_pp + dt (P_pv + P_vp) + dt² P_vv,
                // plus the white acceleration's dt³/3 per axis.
                let pp = p.fixed_view::<3, 3>(0, 0).into_owned();
                let pv = p.fixed_view::<3, 3>(0, 6).into_owned();
                let vv = p.fixed_view::<3, 3>(6, 6).into_owned();
                let white = self.tuning.linear_accel_psd * dt.abs().powi(3) / 3.0;
                let carried = pp
                    + (pv + pv.transpose()) * dt
                    + vv * (dt * dt)
                    + nalgebra::Matrix3::identity() * white;
                let difference = f.state.cam_t_obj_m - e.state.predicted(dt).cam_t_obj_m;
                let s_inv = (carried + fused_position).try_inverse()?;
                let clock_given = self.clock_states[c].0.is_none();
                Some((
                    clock_given,
                    (difference.transpose() * s_inv * difference)[0] > bound,
                ))
            });
        // No camera's own track vouched for near it: nothing stands behind the fused estimate but the fused filter
        // itself (on 30 Hz frames of a fast target, a fused track 2 m off, the first camera's own track restarted
        // on every frame).
        let verdicts: Vec<(bool, bool)> = verdicts.collect();
        verdicts.is_empty()
            || verdicts.iter().all(|&(_, refuted)| refuted)
            || verdicts
                .iter()
                .any(|&(clock_given, refuted)| clock_given && refuted)
    }

    /// An estimate when `every` fused measurements have come since the previous one.
    pub(super) fn estimate_if_due(&mut self) -> Option<RigEstimate> {
        let f = self.fused.as_ref()?;
        if self.since_estimate < self.config.tracker.every || f.t_s <= self.last_emitted_s {
            return None;
        }
        let contradicted = self.contradicted_by_the_cameras();
        let f = self.fused.as_mut()?;
        self.since_estimate = 0;
        let covariance: Matrix12 = Matrix12::from_fn(|i, j| f.p[(i, j)]);
        // Disputed as the single-camera filter's estimates are: a run of rejections, a newest one far beyond the gate,
        // or half the measurements since the last estimate rejected (one rejection alone happens once in 90 good
        // measurements).
        let disputed = f.gated_in_a_row >= DISPUTED_AFTER_GATED_IN_A_ROW
            || (f.newest_gated && f.newest_nis > DISPUTED_NIS)
            || 2 * f.gated_since_estimate >= f.count.max(2);
        f.gated_since_estimate = 0;
        let status = if disputed || contradicted {
            TrackStatus::Disputed
        } else if f.estimates < CONVERGING_ESTIMATES {
            TrackStatus::Converging
        } else {
            TrackStatus::Tracking
        };
        let residual_rms_px = if f.count > 0 {
            (f.sum_squares_px2 / (2 * f.count) as f64).sqrt()
        } else {
            0.0
        };
        let measurements_used = f.count;
        f.sum_squares_px2 = 0.0;
        f.count = 0;
        f.estimates += 1;
        self.last_emitted_s = f.t_s;
        let noise_px = self.noise_px.iter().copied().fold(f64::INFINITY, f64::min);
        let estimate = Estimate {
            t_ref_s: f.t_s,
            state: f.state,
            residual_rms_px,
            inverse_condition: inverse_condition(&covariance),
            measurements_used,
            iterations: measurements_used,
            status,
            covariance: Some(covariance),
            noise_px,
            acceleration: None,
        };
        self.report.estimates += 1;
        Some(RigEstimate {
            estimate,
            clocks: self.clocks(),
        })
    }
}

/// How far (s, rig time) a camera's own vouched estimate may lie from a fused one to be compared with it.
pub(super) const CROSS_CHECK_SPAN_S: f64 = 0.05;

/// The cross-check's bound, in standard deviations of one Gaussian error (a false alarm once in 3.5 million checks):
/// every fused estimate is checked against every synced camera, thousands a second at kHz rates, and what the check
/// is for, a fused track gone astray by millimetres to metres, lies far beyond it.
const CROSS_CHECK_Z: f64 = 5.0;

/// The most own estimates kept per camera for the cross-check (a bound on memory whatever the estimate rate).
pub(super) const CROSS_CHECK_CAPACITY: usize = 512;

/// The reciprocal condition number of a covariance's correlation matrix (1: its errors uncorrelated, 0: one of them
/// a combination of the others): the conditioning figure of a fused estimate.
fn inverse_condition(covariance: &Matrix12) -> f64 {
    let d = Vector12::from_fn(|i, _| 1.0 / covariance[(i, i)].max(1e-300).sqrt());
    let correlation = Matrix12::from_fn(|i, j| covariance[(i, j)] * d[i] * d[j]);
    let eigen = correlation.symmetric_eigenvalues();
    let (min, max) = eigen.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| {
        (lo.min(e), hi.max(e))
    });
    if max > 0.0 && min.is_finite() {
        (min / max).clamp(0.0, 1.0)
    } else {
        0.0
    }
}
