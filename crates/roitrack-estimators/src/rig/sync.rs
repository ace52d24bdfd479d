//! The coarse search of a camera's clock offset: the shift that best lays its own track of the target (in the rig
//! frame) over the reference camera's. The filter then refines the offset, and learns the drift, from the centroids.

use nalgebra::{Matrix3, Vector3};

/// What [`search_offset_s`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetSearch {
    /// The offset (s): `t_rig ≈ offset_s + t_camera`.
    pub offset_s: f64,
    /// The RMS distance (m) between the two tracks at that offset.
    pub rms_m: f64,
    /// The RMS distance (m) at the worst offset searched: how much the offset matters on this stretch of motion.
    pub worst_rms_m: f64,
    /// Whether the best offset is at the edge of the search (the true one may lie beyond).
    pub at_edge: bool,
}

/// The reference track's position at `t_s` by linear interpolation; `None` outside it.
fn interpolate(reference: &[(f64, Vector3<f64>)], t_s: f64) -> Option<Vector3<f64>> {
    let first = reference.first()?;
    let last = reference.last()?;
    if t_s < first.0 || t_s > last.0 {
        return None;
    }
    let i = reference.partition_point(|(t, _)| *t <= t_s);
    if i == 0 {
        return Some(first.1);
    }
    if i >= reference.len() {
        return Some(last.1);
    }
    let (t0, p0) = reference[i - 1];
    let (t1, p1) = reference[i];
    let w = if t1 > t0 { (t_s - t0) / (t1 - t0) } else { 0.0 };
    Some(p0 + (p1 - p0) * w)
}

/// The mean squared distance between `camera`'s positions shifted by `offset_s` and the reference's at those times,
/// over the samples that overlap it; `None` if fewer than half do.
fn cost_m2(
    reference: &[(f64, Vector3<f64>)],
    camera: &[(f64, Vector3<f64>)],
    offset_s: f64,
) -> Option<f64> {
    let (mut sum, mut n) = (0.0, 0usize);
    for (t, p) in camera {
        if let Some(q) = interpolate(reference, t + offset_s) {
            sum += (p - q).norm_squared();
            n += 1;
        }
    }
    (n > 0 && 2 * n >= camera.len()).then(|| sum / n as f64)
}

/// The clock offset within `±max_offset_s` that lays `camera`'s track (its times on its own clock, positions in the
/// rig frame) best over `reference`'s (rig clock): a grid of `step_s`, then one of a twentieth of it around the best,
/// then a parabola through the three best. `None` if no offset overlaps half of the camera's samples.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_estimators::rig::search_offset_s;
///
/// let track = |t: f64| Vector3::new((3.0 * t).sin() * 0.05, (2.0 * t).cos() * 0.03, 0.6);
/// let reference: Vec<_> = (0..400).map(|k| { let t = k as f64 * 2.5e-3; (t, track(t)) }).collect();
/// // The camera's clock is 17.3 ms behind the rig's: t_rig = 0.0173 + t_camera.
/// let camera: Vec<_> = (0..300).map(|k| { let t = 0.05 + k as f64 * 2.5e-3; (t, track(t + 0.0173)) }).collect();
/// let found = search_offset_s(&reference, &camera, 0.1, 0.5e-3).unwrap();
/// assert!((found.offset_s - 0.0173).abs() < 20e-6, "{found:?}");
/// ```
pub fn search_offset_s(
    reference: &[(f64, Vector3<f64>)],
    camera: &[(f64, Vector3<f64>)],
    max_offset_s: f64,
    step_s: f64,
) -> Option<OffsetSearch> {
    let steps = (max_offset_s / step_s).ceil() as i64;
    let mut best: Option<(f64, f64)> = None;
    let mut worst = 0.0f64;
    for k in -steps..=steps {
        let offset_s = k as f64 * step_s;
        if let Some(c) = cost_m2(reference, camera, offset_s) {
            worst = worst.max(c);
            if best.is_none_or(|(_, b)| c < b) {
                best = Some((offset_s, c));
            }
        }
    }
    let (coarse_s, _) = best?;
    let at_edge = coarse_s.abs() >= steps as f64 * step_s - 0.5 * step_s;
    // A finer grid around the best, then a parabola through the best and its neighbours.
    let fine_step_s = step_s / 20.0;
    let mut fine: Vec<(f64, f64)> = (-20..=20)
        .filter_map(|k| {
            let offset_s = coarse_s + k as f64 * fine_step_s;
            cost_m2(reference, camera, offset_s).map(|c| (offset_s, c))
        })
        .collect();
    if fine.is_empty() {
        fine.push(best?);
    }
    let i = (0..fine.len())
        .min_by(|&a, &b| fine[a].1.total_cmp(&fine[b].1))
        .unwrap_or(0);
    let (mut offset_s, mut cost) = fine[i];
    if i > 0 && i + 1 < fine.len() {
        let (c0, c1, c2) = (fine[i - 1].1, fine[i].1, fine[i + 1].1);
        let curvature = c0 - 2.0 * c1 + c2;
        if curvature > 0.0 {
            let shift = 0.5 * (c0 - c2) / curvature;
            offset_s += shift * fine_step_s;
            cost = cost_m2(reference, camera, offset_s).unwrap_or(cost);
        }
    }
    Some(OffsetSearch {
        offset_s,
        rms_m: cost.max(0.0).sqrt(),
        worst_rms_m: worst.sqrt(),
        at_edge,
    })
}

/// How closely an offset lays a camera's track over the reference's against what their own errors allow: the sum over
/// the camera's samples that the reference spans of the distance to the reference interpolated at the shifted time,
/// squared in the metric of its covariance (both samples' stated covariances, and the linear interpolation's error,
/// which the reference's own curvature bounds), with its degrees of freedom (3 a sample, less the offset fitted). Samples
/// are (time, position in the rig frame, its covariance, m²); the camera's times on its own clock scaled by
/// `scale` (its drift as known), the reference's on the rig's. `None` if no sample overlaps.
///
/// ```
/// use nalgebra::{Matrix3, Vector3};
/// use roitrack_estimators::rig::offset_chi2;
/// use roitrack_core::stats::chi2_upper_0_1_percent;
///
/// let track = |t: f64| Vector3::new((3.0 * t).sin() * 0.05, (2.0 * t).cos() * 0.03, 0.6);
/// let c = Matrix3::identity() * 1e-8;
/// let reference: Vec<_> = (0..100).map(|k| { let t = k as f64 * 0.01; (t, track(t), c) }).collect();
/// let camera: Vec<_> = (0..50).map(|k| { let t = 0.2 + k as f64 * 0.01; (t, track(t + 0.0173), c) }).collect();
/// let (right, dof) = offset_chi2(&reference, &camera, 0.0173, 1.0).unwrap();
/// let (wrong, _) = offset_chi2(&reference, &camera, 0.0100, 1.0).unwrap();
/// // Taken at its 99.9 % point: the right offset, not one 7.3 ms off.
/// let limit = chi2_upper_0_1_percent(dof);
/// assert!(right < limit && wrong > limit, "{right} {wrong} {limit}");
/// ```
pub fn offset_chi2(
    reference: &[(f64, Vector3<f64>, Matrix3<f64>)],
    camera: &[(f64, Vector3<f64>, Matrix3<f64>)],
    offset_s: f64,
    scale: f64,
) -> Option<(f64, f64)> {
    let (mut chi2, mut n) = (0.0, 0usize);
    for &(t, p, covariance_m2) in camera {
        let t_ref = t * scale + offset_s;
        let i = reference.partition_point(|(tr, _, _)| *tr <= t_ref);
        if i == 0 || i >= reference.len() {
            continue;
        }
        let ((t0, p0, v0), (t1, p1, v1)) = (reference[i - 1], reference[i]);
        if t1 <= t0 {
            continue;
        }
        let w = (t_ref - t0) / (t1 - t0);
        let q = p0 + (p1 - p0) * w;
        // The linear interpolation is off by at most a (t1 - t0)² / 8 for an acceleration a, which the second
        // difference of the reference's neighbouring samples gives.
        let curvature_m = [
            i.checked_sub(2).map(|k| (k, k + 1, k + 2)),
            (i + 1 < reference.len()).then_some((i - 1, i, i + 1)),
        ]
        .into_iter()
        .flatten()
        .filter(|&(a, b, c)| reference[a].0 < reference[b].0 && reference[b].0 < reference[c].0)
        .map(|(a, b, c)| {
            let ((ta, pa, _), (tb, pb, _), (tc, pc, _)) =
                (reference[a], reference[b], reference[c]);
            let acceleration = ((pc - pb) / (tc - tb) - (pb - pa) / (tb - ta)) * (2.0 / (tc - ta));
            acceleration.norm() * (t1 - t0).powi(2) / 8.0
        })
        .fold(0.0, f64::max);
        let covariance = covariance_m2
            + v0 * (1.0 - w).powi(2)
            + v1 * (w * w)
            + Matrix3::identity() * (curvature_m * curvature_m);
        let Some(information) = covariance.try_inverse() else {
            continue;
        };
        let d = p - q;
        chi2 += d.dot(&(information * d));
        n += 1;
    }
    (n > 0).then(|| (chi2, (3 * n) as f64 - 1.0))
}
