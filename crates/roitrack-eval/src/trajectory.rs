//! Bringing an estimated trajectory onto the truth's axes before it is compared: a time offset between the two
//! clocks (given, or found by correlating motion), a rigid or similar transformation between the two frames (Umeyama's
//! least-squares fit of the positions), and the relative pose error, which needs neither.
//!
//! Why they are needed: ground truth from a motion-capture system or a robot's kinematics is in its own frame and on
//! its own clock. roitrack's poses are camera_T_object; the truth may be world_T_object. The two differ by a constant
//! transformation (world_T_camera, and a scale if the target's size or the calibration is off), and their clocks by
//! an offset.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use roitrack_core::{PoseSample, TwistSample, so3};
use serde::{Deserialize, Serialize};

use crate::EvalError;

/// How the estimates are transformed onto the truth's frame before they are compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Alignment {
    /// As they are: both trajectories are in the same frame (the camera's, for simulated truth).
    #[default]
    None,
    /// A rotation and a translation, the least-squares fit of the estimated positions onto the true ones.
    Se3,
    /// A rotation, a translation and a scale (for a target file or calibration of the wrong size).
    Sim3,
}

impl Alignment {
    /// `"none"`, `"se3"` or `"sim3"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Se3 => "se3",
            Self::Sim3 => "sim3",
        }
    }
}

/// The offset between the estimates' clock and the truth's: an estimate at `t` is compared with the truth at
/// `t + offset`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum TimeOffset {
    /// Known (s).
    Fixed(f64),
    /// Found by [`find_time_offset`]: the shift that best lines up the angular and linear speeds of the two
    /// trajectories (speeds do not depend on the frames, so this works before any alignment).
    Auto,
}

impl Default for TimeOffset {
    fn default() -> Self {
        Self::Fixed(0.0)
    }
}

/// A similarity transformation `p -> scale * rotation * p + translation_m`, from the estimates' frame to the truth's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimilarityTransform {
    /// The rotation.
    pub rotation: Rotation3<f64>,
    /// The translation (m, truth frame).
    pub translation_m: Vector3<f64>,
    /// The scale (1 for a rigid transformation).
    pub scale: f64,
}

impl SimilarityTransform {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            rotation: Rotation3::identity(),
            translation_m: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// A pose moved into the truth's frame: position scaled, rotated and shifted; orientation rotated.
    pub fn pose(&self, p: &PoseSample) -> PoseSample {
        let rotation = UnitQuaternion::from_rotation_matrix(&self.rotation);
        let mut moved = *p;
        moved.cam_from_obj.translation.vector =
            self.scale * (self.rotation * p.cam_from_obj.translation.vector) + self.translation_m;
        moved.cam_from_obj.rotation = rotation * p.cam_from_obj.rotation;
        moved
    }

    /// A twist expressed in the truth's frame: velocity scaled and rotated, angular velocity rotated.
    pub fn twist(&self, t: &TwistSample) -> TwistSample {
        TwistSample {
            t_s: t.t_s,
            velocity_mps: self.scale * (self.rotation * t.velocity_mps),
            angular_velocity_radps: self.rotation * t.angular_velocity_radps,
        }
    }
}

/// The least-squares similarity (or rigid transformation, `with_scale == false`) taking `from` onto `to`, paired by
/// index (Umeyama 1991): it minimises `Σ |to_i - (s R from_i + t)|²`.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_eval::trajectory::umeyama;
/// let rotation = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
/// let from: Vec<Vector3<f64>> = (0..10).map(|k| Vector3::new(k as f64, (k * k) as f64 * 0.1, (k % 3) as f64)).collect();
/// let to: Vec<Vector3<f64>> = from.iter().map(|p| 2.0 * (rotation * p) + Vector3::new(1.0, 2.0, 3.0)).collect();
/// let fit = umeyama(&from, &to, true).unwrap();
/// assert!((fit.scale - 2.0).abs() < 1e-12 && (fit.translation_m - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-10);
/// assert!((fit.rotation.matrix() - rotation.matrix()).norm() < 1e-12);
/// ```
pub fn umeyama(
    from: &[Vector3<f64>],
    to: &[Vector3<f64>],
    with_scale: bool,
) -> Result<SimilarityTransform, EvalError> {
    let n = from.len().min(to.len());
    let degenerate = |reason: &'static str| EvalError::DegenerateAlignment { points: n, reason };
    if n < 3 {
        return Err(degenerate("at least 3 positions are needed"));
    }
    let count = n as f64;
    let mean_from = from[..n].iter().sum::<Vector3<f64>>() / count;
    let mean_to = to[..n].iter().sum::<Vector3<f64>>() / count;
    let mut covariance = Matrix3::zeros();
    let mut spread_from = 0.0;
    for (a, b) in from[..n].iter().zip(&to[..n]) {
        let (a, b) = (a - mean_from, b - mean_to);
        covariance += b * a.transpose();
        spread_from += a.norm_squared();
    }
    covariance /= count;
    spread_from /= count;
    let svd = covariance.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(degenerate(
            "the positions' covariance could not be decomposed",
        ));
    };
    let mut singular = svd.singular_values;
    // Sort-independent check: the second largest singular value must stand out of rounding for the rotation to be
    // determined (positions on a line leave a turn about it free).
    let mut sorted = [singular[0], singular[1], singular[2]];
    sorted.sort_by(|a, b| b.total_cmp(a));
    if !(sorted[0] > 0.0 && sorted[1] > 1e-9 * sorted[0] && spread_from > 1e-18) {
        return Err(degenerate(
            "the positions do not span a plane (a still or straight-line trajectory leaves the rotation free)",
        ));
    }
    let mut sign = Matrix3::identity();
    if (u.determinant() * v_t.determinant()) < 0.0 {
        // A reflection is not a rotation: flip the axis of the smallest singular value.
        let smallest = (0..3)
            .min_by(|&a, &b| singular[a].total_cmp(&singular[b]))
            .unwrap_or(2);
        sign[(smallest, smallest)] = -1.0;
        singular[smallest] = -singular[smallest];
    }
    let rotation = Rotation3::from_matrix_unchecked(u * sign * v_t);
    let scale = if with_scale {
        singular.sum() / spread_from
    } else {
        1.0
    };
    Ok(SimilarityTransform {
        rotation,
        translation_m: mean_to - scale * (rotation * mean_from),
        scale,
    })
}

/// How many of the estimates' first speeds [`find_time_offset`] leaves out.
const CONVERGING_SPEEDS: usize = 10;

/// Angular speed (rad/s) and linear speed of the object's origin (m/s) between consecutive poses, at their midpoints:
/// figures that do not depend on the frame the poses are expressed in (nor on a clock offset).
fn speeds(poses: &[PoseSample]) -> Vec<(f64, f64, f64)> {
    poses
        .windows(2)
        .filter_map(|w| {
            let dt = w[1].t_s - w[0].t_s;
            (dt > 0.0).then(|| {
                let turn = so3::log_quaternion(
                    &(w[0].cam_from_obj.rotation.inverse() * w[1].cam_from_obj.rotation),
                );
                let moved =
                    w[1].cam_from_obj.translation.vector - w[0].cam_from_obj.translation.vector;
                (
                    0.5 * (w[0].t_s + w[1].t_s),
                    turn.norm() / dt,
                    moved.norm() / dt,
                )
            })
        })
        .collect()
}

/// Linear interpolation of `(t, a, b)` samples (times increasing) at `t`; `None` outside them.
fn interpolate(samples: &[(f64, f64, f64)], t: f64) -> Option<(f64, f64)> {
    let upper = samples.partition_point(|s| s.0 < t);
    if upper == 0 || upper == samples.len() {
        return (upper < samples.len() && samples[upper].0 == t)
            .then(|| (samples[upper].1, samples[upper].2));
    }
    let (a, b) = (samples[upper - 1], samples[upper]);
    let f = (t - a.0) / (b.0 - a.0);
    Some((a.1 + f * (b.1 - a.1), a.2 + f * (b.2 - a.2)))
}

/// Pearson correlation of two equally long series; 0 when either is constant.
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    if a.len() < 3 {
        return 0.0;
    }
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma) * (x - ma);
        bb += (y - mb) * (y - mb);
    }
    if aa <= 0.0 || bb <= 0.0 {
        0.0
    } else {
        ab / (aa * bb).sqrt()
    }
}

/// The clock offset (s) to add to the estimates' times to put them on the truth's clock: the shift that maximises
/// the correlation of the two trajectories' angular and linear speeds (their sum), searched on a grid of the
/// estimates' median period over ± `max_offset_s` (at most half of either trajectory's duration), then refined by a
/// parabola through the peak.
///
/// The estimates' first 10 speeds are left out when there are at least 100: a tracker's first poses converge from its
/// initial fit, and their jumps are large against the noise. Which of them a shift keeps inside the truth's span
/// changed the correlation enough to move the peak by several periods (measured in docs/results.md, "Design
/// measurements behind the code").
///
/// ```
/// use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
/// use roitrack_core::PoseSample;
/// use roitrack_eval::trajectory::find_time_offset;
/// // A target that turns and moves in bursts; the estimates' clock is 0.25 s behind the truth's.
/// let pose = |t_s: f64, t_true: f64| {
///     let s = (1.3 * t_true).sin() + 0.5 * (3.1 * t_true).sin();
///     PoseSample {
///         t_s,
///         cam_from_obj: Isometry3::from_parts(
///             Translation3::new(0.1 * s, 0.05 * s * s, 0.6),
///             UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.8 * s)),
///         ),
///     }
/// };
/// let truth: Vec<_> = (0..2000).map(|k| pose(k as f64 * 0.005, k as f64 * 0.005)).collect();
/// let estimates: Vec<_> = (0..1500).map(|k| pose(k as f64 * 0.005, k as f64 * 0.005 + 0.25)).collect();
/// let offset = find_time_offset(&truth, &estimates, 2.0).unwrap();
/// assert!((offset - 0.25).abs() < 0.002, "{offset}");
/// ```
pub fn find_time_offset(
    truth: &[PoseSample],
    estimates: &[PoseSample],
    max_offset_s: f64,
) -> Result<f64, EvalError> {
    let (truth_speeds, mut est_speeds) = (speeds(truth), speeds(estimates));
    if est_speeds.len() >= 10 * CONVERGING_SPEEDS {
        est_speeds.drain(..CONVERGING_SPEEDS);
    }
    let too_short = EvalError::TimeOffsetNotFound {
        reason: "each trajectory needs at least 8 poses",
    };
    if truth_speeds.len() < 7 || est_speeds.len() < 7 {
        return Err(too_short);
    }
    let mut periods: Vec<f64> = est_speeds.windows(2).map(|w| w[1].0 - w[0].0).collect();
    periods.sort_by(f64::total_cmp);
    let step = periods[periods.len() / 2];
    let span = |s: &[(f64, f64, f64)]| s[s.len() - 1].0 - s[0].0;
    let reach = max_offset_s
        .min(0.5 * span(&truth_speeds))
        .min(0.5 * span(&est_speeds));
    if !(step > 0.0 && reach.is_finite() && reach > 0.0) {
        return Err(EvalError::TimeOffsetNotFound {
            reason: "the trajectories are too short to search an offset",
        });
    }
    let shifts = (reach / step).floor() as i64;
    // At most 4,000 estimate samples are compared per shift: a fixed, even subsample of a long run.
    let stride = (est_speeds.len() / 4000).max(1);
    let score = |shift: f64| -> f64 {
        let (mut ea, mut ta, mut el, mut tl) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for &(t, angular, linear) in est_speeds.iter().step_by(stride) {
            if let Some((true_angular, true_linear)) = interpolate(&truth_speeds, t + shift) {
                ea.push(angular);
                ta.push(true_angular);
                el.push(linear);
                tl.push(true_linear);
            }
        }
        // Overlap too small to judge: no score.
        if ea.len() < 8 {
            return f64::NEG_INFINITY;
        }
        correlation(&ea, &ta) + correlation(&el, &tl)
    };
    let scores: Vec<f64> = (-shifts..=shifts).map(|k| score(k as f64 * step)).collect();
    let (best, &peak) = scores
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .ok_or(too_short)?;
    if !(peak.is_finite() && peak > 0.2) {
        return Err(EvalError::TimeOffsetNotFound {
            reason: "the two trajectories' speeds do not correlate at any offset (too little motion?)",
        });
    }
    let mut offset = (best as i64 - shifts) as f64 * step;
    if best > 0 && best + 1 < scores.len() {
        let (a, b, c) = (scores[best - 1], peak, scores[best + 1]);
        let curvature = a - 2.0 * b + c;
        if curvature < 0.0 && a.is_finite() && c.is_finite() {
            offset += 0.5 * (a - c) / curvature * step;
        }
    }
    Ok(offset)
}

/// Relative pose errors over an interval: for each estimate `i`, the estimate `j` nearest to `t_i + interval` (within
/// 5 % of the interval), and the error of the estimated motion of the object from `i` to `j` (in the object's frame at
/// `i`) against the true one. Depends on neither the frames nor a constant error of the pose: it measures drift and
/// jitter over that interval.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RelativeErrors {
    /// The interval the pairs span (s).
    pub interval_s: f64,
    /// Translation error of each pair (m).
    pub translation_m: Vec<f64>,
    /// Rotation error angle of each pair (rad).
    pub rotation_rad: Vec<f64>,
}

/// [`RelativeErrors`] of estimates against the truth at the same times (`truth[i]` at `estimates[i]`'s time).
pub fn relative_errors(
    truth: &[PoseSample],
    estimates: &[PoseSample],
    interval_s: f64,
) -> RelativeErrors {
    let mut errors = RelativeErrors {
        interval_s,
        ..RelativeErrors::default()
    };
    let times: Vec<f64> = estimates.iter().map(|p| p.t_s).collect();
    for i in 0..estimates.len() {
        let goal = times[i] + interval_s;
        let upper = times.partition_point(|&t| t < goal);
        let j = [upper.checked_sub(1), (upper < times.len()).then_some(upper)]
            .into_iter()
            .flatten()
            .filter(|&j| j > i)
            .min_by(|&a, &b| (times[a] - goal).abs().total_cmp(&(times[b] - goal).abs()));
        let Some(j) = j.filter(|&j| (times[j] - goal).abs() <= 0.05 * interval_s) else {
            continue;
        };
        let motion = |p: &[PoseSample]| p[i].cam_from_obj.inverse() * p[j].cam_from_obj;
        let error = motion(truth).inverse() * motion(estimates);
        errors.translation_m.push(error.translation.vector.norm());
        errors.rotation_rad.push(error.rotation.angle());
    }
    errors
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3};

    fn pose(t_s: f64, x: f64, y: f64, z: f64, turn: f64) -> PoseSample {
        PoseSample {
            t_s,
            cam_from_obj: Isometry3::from_parts(
                Translation3::new(x, y, z),
                UnitQuaternion::from_scaled_axis(Vector3::new(0.1 * turn, 0.2, turn)),
            ),
        }
    }

    #[test]
    fn umeyama_undoes_a_similarity_and_refuses_a_line() {
        let rotation = Rotation3::from_euler_angles(-0.7, 0.4, 2.9);
        let from: Vec<Vector3<f64>> = (0..20)
            .map(|k| {
                let t = f64::from(k) * 0.3;
                Vector3::new(t.cos(), (2.0 * t).sin(), 0.2 * t)
            })
            .collect();
        let to: Vec<Vector3<f64>> = from
            .iter()
            .map(|p| 0.7 * (rotation * p) + Vector3::new(-1.0, 0.5, 2.0))
            .collect();
        let rigid = umeyama(&from, &to, false).unwrap();
        assert_eq!(rigid.scale, 1.0);
        let similar = umeyama(&from, &to, true).unwrap();
        assert!((similar.scale - 0.7).abs() < 1e-12);
        assert!((similar.rotation.matrix() - rotation.matrix()).norm() < 1e-12);
        for (a, b) in from.iter().zip(&to) {
            assert!(
                (similar.scale * (similar.rotation * a) + similar.translation_m - b).norm() < 1e-12
            );
        }
        // A mirror image is not fitted by a reflection.
        let mirrored: Vec<Vector3<f64>> = to.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        let fit = umeyama(&from, &mirrored, false).unwrap();
        assert!((fit.rotation.matrix().determinant() - 1.0).abs() < 1e-12);
        let line: Vec<Vector3<f64>> = (0..10)
            .map(|k| Vector3::new(f64::from(k), 0.0, 0.0))
            .collect();
        assert!(matches!(
            umeyama(&line, &line, false),
            Err(EvalError::DegenerateAlignment { .. })
        ));
        assert!(umeyama(&line[..2], &line[..2], false).is_err());
    }

    #[test]
    fn relative_errors_ignore_the_frame_and_see_drift() {
        let truth: Vec<PoseSample> = (0..100)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                pose(t, 0.1 * t.sin(), 0.02 * t, 0.6, 0.5 * t)
            })
            .collect();
        // The same motion seen from another frame: no relative error.
        let frame = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 1.0),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.4, -0.1, 0.9)),
        );
        let moved: Vec<PoseSample> = truth
            .iter()
            .map(|p| PoseSample {
                t_s: p.t_s,
                cam_from_obj: frame * p.cam_from_obj,
            })
            .collect();
        let same = relative_errors(&truth, &moved, 0.1);
        assert_eq!(same.translation_m.len(), 90);
        assert!(same.translation_m.iter().all(|&e| e < 1e-12));
        assert!(same.rotation_rad.iter().all(|&e| e < 1e-9));
        // A drift of 1 mm per 0.1 s along the object's x, on a target that moves without turning: 1 mm over each
        // interval.
        let sliding: Vec<PoseSample> = (0..100)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                pose(t, 0.1 * t.sin(), 0.02 * t, 0.6, 0.3)
            })
            .collect();
        let drifting: Vec<PoseSample> = sliding
            .iter()
            .map(|p| {
                let mut q = *p;
                let drift = Isometry3::translation(0.01 * p.t_s, 0.0, 0.0);
                q.cam_from_obj = p.cam_from_obj * drift;
                q
            })
            .collect();
        let drift = relative_errors(&sliding, &drifting, 0.1);
        assert!(
            drift
                .translation_m
                .iter()
                .all(|&e| (e - 0.001).abs() < 1e-9),
            "{:?}",
            &drift.translation_m[..3]
        );
    }

    #[test]
    fn a_still_trajectory_has_no_time_offset() {
        let still: Vec<PoseSample> = (0..100)
            .map(|k| pose(f64::from(k) * 0.01, 0.0, 0.0, 0.6, 0.0))
            .collect();
        assert!(matches!(
            find_time_offset(&still, &still, 1.0),
            Err(EvalError::TimeOffsetNotFound { .. })
        ));
        assert!(find_time_offset(&still[..5], &still[..5], 1.0).is_err());
    }
}
