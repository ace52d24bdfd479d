//! The static pose (6 dof, velocity zero) from one set of correspondences: a closed form with no prior (planar
//! homography decomposition, or the DLT for non-planar targets) refined by Gauss-Newton on the reprojection error,
//! i.e. 6-dof virtual visual servoing to convergence.

use nalgebra::{DMatrix, Matrix3, Rotation3, SMatrix, Vector2, Vector3};
use thiserror::Error;

use super::normal_equations::NormalEquations;
use super::window::Observation;
use crate::{JacobianKind, MotionState, SpatioTemporalModel, Target};

#[derive(Debug, Clone, PartialEq, Error)]
pub enum InitError {
    #[error("a static pose needs at least {required} distinct points, got {actual}")]
    TooFewPoints { required: usize, actual: usize },
    #[error("the closed-form pose solver failed: {reason}")]
    Degenerate { reason: &'static str },
}

/// A fitted static pose and how well it fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseFit {
    /// Pose, velocity zero.
    pub state: MotionState,
    pub residual_rms_px: f64,
    pub inverse_condition: f64,
    pub iterations: usize,
    pub converged: bool,
}

/// Smallest eigenvector of `AᵀA`: the least-squares null vector of `A` (rows already normalised).
fn null_vector(a: &DMatrix<f64>) -> nalgebra::DVector<f64> {
    let ata = a.transpose() * a;
    let eig = ata.symmetric_eigen();
    let (imin, _) =
        eig.eigenvalues
            .iter()
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |(bi, bv), (i, &v)| if v < bv { (i, v) } else { (bi, bv) },
            );
    eig.eigenvectors.column(imin).into_owned()
}

/// The nearest rotation to `m` (polar decomposition by SVD).
fn nearest_rotation(m: &Matrix3<f64>) -> Option<Rotation3<f64>> {
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut r = u * v_t;
    if r.determinant() < 0.0 {
        let mut u = u;
        u.column_mut(2).neg_mut();
        r = u * v_t;
    }
    Some(Rotation3::from_matrix_unchecked(r))
}

/// Centroid and scale that bring points to zero mean and unit RMS distance.
fn normalisation<const D: usize>(
    points: &[nalgebra::SVector<f64, D>],
) -> (nalgebra::SVector<f64, D>, f64) {
    let n = points.len() as f64;
    let centroid = points.iter().sum::<nalgebra::SVector<f64, D>>() / n;
    let rms = (points
        .iter()
        .map(|p| (p - centroid).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    (centroid, if rms > 0.0 { 1.0 / rms } else { 1.0 })
}

/// Planar target: homography from the target plane to normalised image coordinates, decomposed into a pose.
fn planar_pose(
    target: &Target,
    obs: &[Observation],
    model: &SpatioTemporalModel,
) -> Result<MotionState, InitError> {
    // A proper frame on the target's plane: centroid, two in-plane axes, normal.
    let points: Vec<Vector3<f64>> = obs
        .iter()
        .map(|o| target.points()[o.point_index].point_in_obj_m)
        .collect();
    let all: Vec<Vector3<f64>> = target.points().iter().map(|p| p.point_in_obj_m).collect();
    let (centre, _) = normalisation(&all);
    let mut scatter = Matrix3::zeros();
    for p in &all {
        scatter += (p - centre) * (p - centre).transpose();
    }
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let e1 = eig.eigenvectors.column(order[0]).into_owned();
    let e2 = eig.eigenvectors.column(order[1]).into_owned();
    let obj_r_plane = Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]);

    let plane: Vec<Vector2<f64>> = points
        .iter()
        .map(|p| {
            let q = obj_r_plane.transpose() * (p - centre);
            Vector2::new(q.x, q.y)
        })
        .collect();
    let image: Vec<Vector2<f64>> = obs
        .iter()
        .map(|o| model.intrinsics.normalized_from_pixel(&o.ideal_px))
        .collect();
    let (pc, ps) = normalisation(&plane);
    let (ic, is) = normalisation(&image);
    let mut a = DMatrix::zeros(2 * obs.len(), 9);
    for (k, (p, m)) in plane.iter().zip(&image).enumerate() {
        let (x, y) = ((p.x - pc.x) * ps, (p.y - pc.y) * ps);
        let (u, v) = ((m.x - ic.x) * is, (m.y - ic.y) * is);
        a.row_mut(2 * k)
            .copy_from_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, -u]);
        a.row_mut(2 * k + 1)
            .copy_from_slice(&[0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, -v]);
    }
    let h = null_vector(&a);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let t_plane = Matrix3::new(ps, 0.0, -ps * pc.x, 0.0, ps, -ps * pc.y, 0.0, 0.0, 1.0);
    let t_image_inv = Matrix3::new(1.0 / is, 0.0, ic.x, 0.0, 1.0 / is, ic.y, 0.0, 0.0, 1.0);
    let hm = t_image_inv * hn * t_plane;
    let (h1, h2, h3) = (hm.column(0), hm.column(1), hm.column(2));
    let mut scale = 2.0 / (h1.norm() + h2.norm());
    if !scale.is_finite() {
        return Err(InitError::Degenerate {
            reason: "homography has no scale",
        });
    }
    // The target must be in front of the camera.
    if h3.z * scale < 0.0 {
        scale = -scale;
    }
    let r1 = h1 * scale;
    let r2 = h2 * scale;
    let cam_r_plane = nearest_rotation(&Matrix3::from_columns(&[r1, r2, r1.cross(&r2)])).ok_or(
        InitError::Degenerate {
            reason: "no rotation from the homography",
        },
    )?;
    let cam_t_plane = h3 * scale;
    let cam_r_obj = cam_r_plane * Rotation3::from_matrix_unchecked(obj_r_plane.transpose());
    Ok(MotionState::at_rest(
        cam_r_obj,
        cam_t_plane - cam_r_obj * centre,
    ))
}

/// Non-planar target: the direct linear transform of the 3 x 4 projection matrix (at least 6 points).
fn dlt_pose(
    target: &Target,
    obs: &[Observation],
    model: &SpatioTemporalModel,
) -> Result<MotionState, InitError> {
    let points: Vec<Vector3<f64>> = obs
        .iter()
        .map(|o| target.points()[o.point_index].point_in_obj_m)
        .collect();
    let image: Vec<Vector2<f64>> = obs
        .iter()
        .map(|o| model.intrinsics.normalized_from_pixel(&o.ideal_px))
        .collect();
    let (pc, ps) = normalisation(&points);
    let mut a = DMatrix::zeros(2 * obs.len(), 12);
    for (k, (p, m)) in points.iter().zip(&image).enumerate() {
        let q = (p - pc) * ps;
        let (x, y, z) = (q.x, q.y, q.z);
        a.row_mut(2 * k).copy_from_slice(&[
            x,
            y,
            z,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            -m.x * x,
            -m.x * y,
            -m.x * z,
            -m.x,
        ]);
        a.row_mut(2 * k + 1).copy_from_slice(&[
            0.0,
            0.0,
            0.0,
            0.0,
            x,
            y,
            z,
            1.0,
            -m.y * x,
            -m.y * y,
            -m.y * z,
            -m.y,
        ]);
    }
    let v = null_vector(&a);
    let mut p = SMatrix::<f64, 3, 4>::from_row_slice(v.as_slice());
    // Undo the point normalisation: q = s (X - c), so P_X = [s M | p4 - s M c].
    let m = p.fixed_view::<3, 3>(0, 0) * ps;
    let p4 = p.column(3) - m * pc;
    p.fixed_view_mut::<3, 3>(0, 0).copy_from(&m);
    p.set_column(3, &p4);
    let mut m = p.fixed_view::<3, 3>(0, 0).into_owned();
    let mut p4 = p.column(3).into_owned();
    if m.determinant() < 0.0 {
        m = -m;
        p4 = -p4;
    }
    let scale = m.singular_values().mean();
    let r = nearest_rotation(&(m / scale)).ok_or(InitError::Degenerate {
        reason: "no rotation from the DLT",
    })?;
    let t = p4 / scale;
    Ok(MotionState::at_rest(r, t))
}

/// Gauss-Newton (with Levenberg-Marquardt safeguarding) on the 6-dof pose, all observations taken as simultaneous.
pub fn refine_static_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
    initial: &MotionState,
    max_iterations: usize,
) -> PoseFit {
    let points = target.points();
    let accumulate = |state: &MotionState| {
        let mut ne = NormalEquations::<6>::default();
        for o in obs {
            let p = &points[o.point_index].point_in_obj_m;
            match model.project_with_jacobian(JacobianKind::Exact, state, p, 0.0) {
                Some(pp) => {
                    let j: SMatrix<f64, 2, 6> = pp.jacobian.fixed_columns::<6>(0).into_owned();
                    ne.add(&j, &(pp.pixel - o.ideal_px), 1.0);
                }
                // A point behind the camera: an infinite cost makes the step be rejected.
                None => ne.cost = f64::INFINITY,
            }
        }
        ne
    };
    let mut state = MotionState::at_rest(initial.cam_r_obj, initial.cam_t_obj_m);
    let mut ne = accumulate(&state);
    let mut damping = 1e-6;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < max_iterations && ne.cost.is_finite() {
        iterations += 1;
        let Some(step) = ne.solve(damping) else { break };
        let mut delta = crate::Vector12::zeros();
        delta.fixed_rows_mut::<6>(0).copy_from(&step);
        let candidate = state.corrected(&delta);
        let candidate_ne = accumulate(&candidate);
        if candidate_ne.cost <= ne.cost {
            let small =
                step.fixed_rows::<3>(0).norm() < 1e-13 && step.fixed_rows::<3>(3).norm() < 1e-13;
            state = candidate;
            ne = candidate_ne;
            damping = (damping * 0.1).max(1e-9);
            if small {
                converged = true;
                break;
            }
        } else {
            damping *= 10.0;
            if damping > 1e6 {
                // No descent direction left: at a minimum to machine precision.
                converged = true;
                break;
            }
        }
    }
    PoseFit {
        state,
        residual_rms_px: ne.residual_rms_px(),
        inverse_condition: ne.inverse_condition(),
        iterations,
        converged,
    }
}

/// The static pose from scratch: closed form (homography for planar targets, DLT otherwise) then refinement.
/// Observation times are ignored (as if simultaneous); each point should appear once.
pub fn solve_static_pose(
    model: &SpatioTemporalModel,
    target: &Target,
    obs: &[Observation],
) -> Result<PoseFit, InitError> {
    let planar = target.is_planar();
    let required = if planar { 4 } else { 6 };
    if obs.len() < required {
        return Err(InitError::TooFewPoints {
            required,
            actual: obs.len(),
        });
    }
    let initial = if planar {
        planar_pose(target, obs, model)?
    } else {
        dlt_pose(target, obs, model)?
    };
    if !initial.is_finite() {
        return Err(InitError::Degenerate {
            reason: "closed-form pose is not finite",
        });
    }
    Ok(refine_static_pose(model, target, obs, &initial, 50))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CameraModel, TargetPoint};

    fn bench() -> MotionState {
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 5f64.to_radians())
            * Rotation3::from_axis_angle(&Vector3::y_axis(), (-15f64).to_radians())
            * Rotation3::from_axis_angle(&Vector3::x_axis(), 10f64.to_radians());
        MotionState::at_rest(r, Vector3::new(0.02, -0.01, 0.6))
    }

    fn observe(
        model: &SpatioTemporalModel,
        target: &Target,
        state: &MotionState,
    ) -> Vec<Observation> {
        target
            .points()
            .iter()
            .enumerate()
            .map(|(i, p)| Observation {
                t_s: 0.0,
                point_index: i,
                ideal_px: model.project(state, &p.point_in_obj_m, 0.0).unwrap(),
            })
            .collect()
    }

    fn assert_recovers(target: &Target, truth: &MotionState) {
        let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
        let fit = solve_static_pose(&model, target, &observe(&model, target, truth)).unwrap();
        let dt = (fit.state.cam_t_obj_m - truth.cam_t_obj_m).norm();
        let dr = crate::so3::angle_between(&fit.state.cam_r_obj, &truth.cam_r_obj);
        assert!(dt < 1e-9 && dr < 1e-9, "dt {dt} m, dr {dr} rad");
        assert!(fit.residual_rms_px < 1e-8);
    }

    #[test]
    fn planar_grid_from_scratch_to_1e9() {
        let target = Target::grid4x4();
        assert_recovers(&target, &bench());
        // Any in-plane rotation, and a strong tilt.
        for angle_deg in [0.0, 90.0, 180.0, 270.0, 33.0] {
            let mut s = bench();
            s.cam_r_obj *=
                Rotation3::from_axis_angle(&Vector3::z_axis(), f64::to_radians(angle_deg));
            assert_recovers(&target, &s);
        }
        let mut s = bench();
        s.cam_r_obj = Rotation3::from_euler_angles(0.9, -0.4, 2.0);
        assert_recovers(&target, &s);
    }

    #[test]
    fn non_planar_target_from_scratch() {
        let points = (0..8)
            .map(|i| TargetPoint {
                id: i,
                point_in_obj_m: Vector3::new(
                    0.03 * ((i & 1) as f64 - 0.5),
                    0.03 * (((i >> 1) & 1) as f64 - 0.5),
                    0.02 * (((i >> 2) & 1) as f64) + 0.001 * i as f64,
                ),
                diameter_m: None,
            })
            .collect();
        let target = Target::new(points).unwrap();
        assert_recovers(&target, &bench());
    }

    #[test]
    fn too_few_points() {
        let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
        let target = Target::grid4x4();
        let obs = observe(&model, &target, &bench());
        assert!(matches!(
            solve_static_pose(&model, &target, &obs[..3]),
            Err(InitError::TooFewPoints {
                required: 4,
                actual: 3
            })
        ));
    }
}
