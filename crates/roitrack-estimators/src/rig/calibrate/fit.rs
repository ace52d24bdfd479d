//! The least squares of a camera's mount and clock: the normal equations, their weights, the step, the first mount.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6, Rotation3, SMatrix, Vector3};

use crate::rig::{CameraMount, ClockModel, MAX_DRIFT_PPM};
use roitrack_core::so3;

use super::placing::{Pair, Placed, Unknowns};
use super::track::UNSTATED_POSE_VARIANCE;

/// The partner's own uncertainty (translation, rotation, offset) carried to a camera of mount `mount` placed against
/// it: the partner mount's error turns with the relative rotation (a left error of the partner's camera_T_rig is
/// R_rel of it on this camera's), its offset adds.
pub(super) fn carried_from_partner(mount: &CameraMount, partner: &Placed) -> SMatrix<f64, 7, 7> {
    let relative = mount.camera_r_rig * partner.mount.camera_r_rig.inverse();
    let mut carry = SMatrix::<f64, 7, 7>::zeros();
    carry
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(relative.matrix());
    carry
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(relative.matrix());
    carry[(6, 6)] = 1.0;
    carry * partner.inherited * carry.transpose()
}

/// Where each of translation (3), rotation (3), offset and drift sits among the fit's columns, `None` when known.
pub(super) fn columns_of_unknowns(unknowns: Unknowns) -> [Option<usize>; 8] {
    let mut k = 0;
    let mut index = [None; 8];
    for (slot, unknown) in [
        (0, unknowns.mount),
        (6, unknowns.offset),
        (7, unknowns.drift),
    ] {
        if unknown {
            let width = if slot == 0 { 6 } else { 1 };
            for j in 0..width {
                index[slot + j] = Some(k + j);
            }
            k += width;
        }
    }
    index
}

/// The result of [`RigCalibrator::refine`].
pub(super) struct Fit {
    pub(super) mount: CameraMount,
    pub(super) clock: ClockModel,
    pub(super) covariance: DMatrix<f64>,
    pub(super) samples: usize,
    pub(super) rms_residual_m: f64,
}

/// The weighted normal equations `H δ = g` of the residuals at the current mount and clock, the Huber scale (the residuals' spread in units of their stated covariance),
/// and, with `batch_s`, the sandwich's middle `Σ_b g_b g_bᵀ` over contiguous batches of that length.
pub(super) struct System {
    pub(super) h: DMatrix<f64>,
    pub(super) g: DVector<f64>,
    pub(super) meat: DMatrix<f64>,
    pub(super) batches: usize,
    pub(super) scale: f64,
}

pub(super) fn normal_equations(
    pairs: &[Pair],
    points: &[Vector3<f64>],
    mount: &CameraMount,
    clock: &ClockModel,
    unknowns: Unknowns,
    weights: &Weights,
    batch_s: Option<f64>,
) -> System {
    let information = |pair: &Pair, point: &Vector3<f64>, r_x: &Rotation3<f64>| match weights {
        Weights::Stated => point_information(pair, point, r_x),
        Weights::Common(w) => *w,
    };
    let n = unknowns.count();
    let r_x = mount.camera_r_rig;
    let t_x = mount.camera_t_rig_m;
    // Per pair, the RMS over its points of the residual weighed by its covariance (both cameras' pose errors at
    // that point): the Huber scale is 1.48 times their median.
    let residual = |pair: &Pair, point: &Vector3<f64>| {
        let q = pair.rig.point_in_cam_at(point, 0.0);
        r_x * q + t_x - pair.camera.point_in_cam_at(point, 0.0)
    };
    let mut norms: Vec<f64> = pairs
        .iter()
        .map(|pair| {
            (points
                .iter()
                .map(|p| {
                    let r = residual(pair, p);
                    r.dot(&(information(pair, p, &r_x) * r))
                })
                .sum::<f64>()
                / points.len() as f64)
                .sqrt()
        })
        .collect();
    let norms_by_pair = norms.clone();
    norms.sort_by(f64::total_cmp);
    let median = norms.get(norms.len() / 2).copied().unwrap_or(0.0);
    let scale = (1.4826 * median).max(1e-12);
    let huber = 2.0 * scale;
    let mut h = DMatrix::zeros(n, n);
    let mut g = DVector::zeros(n);
    let mut meat = DMatrix::zeros(n, n);
    let mut batch_g = DVector::zeros(n);
    let mut batch_start: Option<f64> = None;
    let mut batches = 0usize;
    let mut row = nalgebra::Matrix3xX::<f64>::zeros(n);
    for (pair, norm) in pairs.iter().zip(&norms_by_pair) {
        if let Some(batch_s) = batch_s
            && batch_start.is_none_or(|s| pair.rig_s - s >= batch_s)
        {
            if batch_start.is_some() {
                meat += &batch_g * batch_g.transpose();
                batches += 1;
            }
            batch_g.fill(0.0);
            batch_start = Some(pair.rig_s);
        }
        let weight = if *norm <= huber { 1.0 } else { huber / norm };
        for point in points {
            let q = pair.rig.point_in_cam_at(point, 0.0);
            let r = r_x * q + t_x - pair.camera.point_in_cam_at(point, 0.0);
            let mut col = 0;
            if unknowns.mount {
                row.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&Matrix3::identity());
                row.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&(-so3::hat(&(r_x * q))));
                col = 6;
            }
            if unknowns.offset || unknowns.drift {
                // The point's velocity in the rig's frame, per second of rig time, seen in this camera's frame.
                let rotated = pair.rig.cam_r_obj * point;
                let dq_dt = pair.rig.angular_velocity_radps.cross(&rotated) + pair.rig.velocity_mps;
                let dr_dt = r_x * dq_dt * pair.rig_per_s;
                if unknowns.offset {
                    row.set_column(col, &dr_dt);
                    col += 1;
                }
                if unknowns.drift {
                    let rate = 1.0 + clock.drift_ppm * 1e-6;
                    row.set_column(col, &(dr_dt * (-pair.s * 1e-6 / (rate * rate))));
                }
            }
            let information = information(pair, point, &r_x) * weight;
            h += row.transpose() * information * &row;
            let contribution = -(row.transpose() * (information * r));
            g += &contribution;
            batch_g += &contribution;
        }
    }
    if batch_start.is_some() {
        meat += &batch_g * batch_g.transpose();
        batches += 1;
    }
    System {
        h,
        g,
        meat,
        batches,
        scale,
    }
}

/// How the residuals of a point are weighed.
pub(super) enum Weights {
    /// By the covariance the two tracks state.
    Stated,
    /// By one information matrix (m⁻²) for every point.
    Common(Matrix3<f64>),
}

/// The inverse of the covariance (m⁻²) of a pair's residual at model point `point`, in the camera's frame: the
/// camera's pose error at the point plus the placed camera's, turned by the mount's rotation `camera_r_rig`.
fn point_information(
    pair: &Pair,
    point: &Vector3<f64>,
    camera_r_rig: &Rotation3<f64>,
) -> Matrix3<f64> {
    let at = |rotated: Vector3<f64>| {
        let mut j = Matrix3x6::zeros();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-so3::hat(&rotated)));
        j
    };
    let j_camera = at(pair.camera.cam_r_obj * point);
    let j_rig = at(pair.rig.cam_r_obj * point);
    let r = camera_r_rig.matrix();
    let covariance = j_camera * pair.camera_covariance * j_camera.transpose()
        + r * (j_rig * pair.rig_covariance * j_rig.transpose()) * r.transpose();
    covariance
        .try_inverse()
        .unwrap_or_else(|| Matrix3::identity() / UNSTATED_POSE_VARIANCE)
}

/// The mount and clock after a Gauss-Newton step (translation, rotation on the left, offset, drift).
pub(super) fn apply_step(
    mount: &CameraMount,
    clock: &ClockModel,
    step: &DVector<f64>,
    unknowns: Unknowns,
) -> (CameraMount, ClockModel) {
    let mut mount = *mount;
    let mut clock = *clock;
    let mut k = 0;
    if unknowns.mount {
        let v = Vector3::new(step[0], step[1], step[2]);
        let w = Vector3::new(step[3], step[4], step[5]);
        mount = CameraMount::new(
            so3::orthonormalized(&(so3::exp(&w) * mount.camera_r_rig)),
            mount.camera_t_rig_m + v,
        );
        k = 6;
    }
    if unknowns.offset {
        clock.offset_s += step[k];
        k += 1;
    }
    if unknowns.drift {
        clock.drift_ppm = (clock.drift_ppm + step[k]).clamp(-MAX_DRIFT_PPM, MAX_DRIFT_PPM);
    }
    (mount, clock)
}

/// The mount that lays the pairs' rig-frame poses over the camera's: the chordal mean of the relative rotations, then
/// the translation that is best for it.
pub(super) fn mean_mount(pairs: &[Pair], points: &[Vector3<f64>]) -> CameraMount {
    let mut sum = Matrix3::zeros();
    for pair in pairs {
        sum += (pair.camera.cam_r_obj * pair.rig.cam_r_obj.inverse()).matrix();
    }
    let svd = sum.svd(true, true);
    let (u, v_t) = (svd.u.expect("asked for"), svd.v_t.expect("asked for"));
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = Rotation3::from_matrix_unchecked(u * d * v_t);
    let mut t = Vector3::zeros();
    let mut count = 0.0f64;
    for pair in pairs {
        for point in points {
            t += pair.camera.point_in_cam_at(point, 0.0)
                - rotation * pair.rig.point_in_cam_at(point, 0.0);
            count += 1.0;
        }
    }
    CameraMount::new(rotation, t / count.max(1.0))
}

/// The mean over pairs and points of the squared residual (m²).
pub(super) fn mean_square_residual(
    pairs: &[Pair],
    points: &[Vector3<f64>],
    mount: &CameraMount,
) -> f64 {
    let mut sum = 0.0;
    for pair in pairs {
        for point in points {
            let q = pair.rig.point_in_cam_at(point, 0.0);
            sum += (mount.camera_from_rig(&q) - pair.camera.point_in_cam_at(point, 0.0))
                .norm_squared();
        }
    }
    sum / (pairs.len() * points.len()).max(1) as f64
}

/// The largest distance (m) between the target's positions (rig frame) over the pairs: how far it moved.
pub(super) fn largest_distance_m(pairs: &[Pair]) -> f64 {
    let positions: Vec<Vector3<f64>> = pairs.iter().map(|p| p.rig.cam_t_obj_m).collect();
    let mean = positions.iter().sum::<Vector3<f64>>() / positions.len().max(1) as f64;
    2.0 * positions
        .iter()
        .map(|p| (p - mean).norm())
        .fold(0.0, f64::max)
}
