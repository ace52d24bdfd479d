//! The spatio-temporal projection model and its interaction matrix (docs/model.md; the paper's eqs. 1-3, 17-24).

use nalgebra::{Matrix2x3, Matrix3, Vector2, Vector3};

use crate::{CameraModel, Matrix2x12, MotionState, PinholeIntrinsics, so3};

/// The centre of a disk's image minus the image of its centre (raw px): the area centroid of the projected outline
/// (distortion included) against the projected centre. `None` if the disk is not wholly in front of the camera.
/// A disk's image is not centred on its centre's image once the disk is tilted to the line of sight (perspective)
/// or the lens distorts it; blob centres are corrected by this before they are compared with projected centres.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::projection::disk_centre_displacement_px;
/// use roitrack_core::{CameraModel, MotionState};
///
/// let camera = CameraModel::canonical();
/// let state = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
/// // A 10 mm disk facing the camera on its axis: its image is centred on its centre's image.
/// let on_axis = disk_centre_displacement_px(&camera, &state, &Vector3::zeros(), &Vector3::z(), 0.01).unwrap();
/// assert!(on_axis.norm() < 1e-3);
/// // The same disk 0.2 m to the side: its image's centre lies outward of its centre's image.
/// let side = Vector3::new(0.2, 0.0, 0.0);
/// let off_axis = disk_centre_displacement_px(&camera, &state, &side, &Vector3::z(), 0.01).unwrap();
/// assert!(off_axis.x.abs() > on_axis.x.abs());
/// ```
pub fn disk_centre_displacement_px(
    camera: &CameraModel,
    state: &MotionState,
    centre_in_obj_m: &Vector3<f64>,
    normal_in_obj: &Vector3<f64>,
    diameter_m: f64,
) -> Option<Vector2<f64>> {
    // 32 vertices: the polygon's centroid is the outline's to well under a thousandth of a pixel.
    const SAMPLES: usize = 32;
    let axis_u = normal_in_obj
        .cross(&Vector3::x())
        .try_normalize(1e-9)
        .or_else(|| normal_in_obj.cross(&Vector3::y()).try_normalize(1e-9))?;
    let axis_v = normal_in_obj.cross(&axis_u);
    let r = 0.5 * diameter_m;
    // The outline in the camera frame: the centre plus the rotated axes' combinations (no rotation per vertex).
    let centre_in_cam = state.point_in_cam_at(centre_in_obj_m, 0.0);
    let (axis_u, axis_v) = (
        state.cam_r_obj * (r * axis_u),
        state.cam_r_obj * (r * axis_v),
    );
    let mut outline = [Vector2::zeros(); SAMPLES];
    // The unit circle by rotation, one sine and cosine in all.
    let (step_sin, step_cos) = (std::f64::consts::TAU / SAMPLES as f64).sin_cos();
    let (mut cos, mut sin) = (1.0f64, 0.0f64);
    for o in outline.iter_mut() {
        let p = centre_in_cam + cos * axis_u + sin * axis_v;
        (cos, sin) = (
            cos * step_cos - sin * step_sin,
            sin * step_cos + cos * step_sin,
        );
        *o = camera.raw_pixel_from_cam(&p)?;
    }
    let centre = camera.raw_pixel_from_cam(&centre_in_cam)?;
    // Area centroid of the polygon (shoelace), relative to the centre for precision.
    let (mut area2, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for k in 0..SAMPLES {
        let (a, b) = (outline[k] - centre, outline[(k + 1) % SAMPLES] - centre);
        let cross = a.x * b.y - b.x * a.y;
        area2 += cross;
        cx += (a.x + b.x) * cross;
        cy += (a.y + b.y) * cross;
    }
    if area2.abs() < 1e-12 {
        return None;
    }
    Some(Vector2::new(cx, cy) / (3.0 * area2))
}

/// Which interaction matrix to build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum JacobianKind {
    /// The exact derivative of the projection w.r.t. the correction `δ` (default).
    #[default]
    Exact,
    /// The paper's first-order L_e2d (eqs. 17-24), faithful for reproduction.
    Paper,
}

/// Projection of model points seen at their own times, in ideal (undistorted) pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatioTemporalModel {
    /// The camera matrix that turns camera-frame points into ideal pixels (the lens is undone before, on the
    /// measurements).
    pub intrinsics: PinholeIntrinsics,
}

/// A projected point with its 2 x 12 interaction matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedPoint {
    /// Ideal pixel (u, v).
    pub pixel: Vector2<f64>,
    /// d(u, v)/dδ for δ = (v, w, dV, dW).
    pub jacobian: Matrix2x12,
    /// The point in the camera frame at its time.
    pub point_in_cam_m: Vector3<f64>,
}

impl SpatioTemporalModel {
    /// The model of a camera with these intrinsics.
    pub fn new(intrinsics: PinholeIntrinsics) -> Self {
        Self { intrinsics }
    }

    /// Ideal pixel of `point_in_obj_m` seen `d_s` seconds after the state's reference time; `None` if it is not in
    /// front of the camera.
    #[inline]
    pub fn project(
        &self,
        state: &MotionState,
        point_in_obj_m: &Vector3<f64>,
        d_s: f64,
    ) -> Option<Vector2<f64>> {
        self.intrinsics
            .pixel_from_cam(&state.point_in_cam_at(point_in_obj_m, d_s))
    }

    /// The projection and its interaction matrix; `None` if the point is not in front of the camera.
    ///
    /// With `E = Exp(W d)` and `OP = E R p` (the point relative to the origin, at its time), the exact rows are
    /// `d(u,v)/dP · [I, -[OP]× E, d I, -[OP]× J_l(W d) d]`. The paper's rows replace the bracket by
    /// `[L3d + d H3d, d L3d]` with `L3d = [I, -[OP₀]×]`, `H3d = [2[W]×, [[OP₀]× W]×]`, `OP₀ = R p` at the reference
    /// time: a first-order approximation in `|W| d`.
    #[inline]
    pub fn project_with_jacobian(
        &self,
        kind: JacobianKind,
        state: &MotionState,
        point_in_obj_m: &Vector3<f64>,
        d_s: f64,
    ) -> Option<ProjectedPoint> {
        let increment = so3::RotationIncrement::new(&(state.angular_velocity_radps * d_s));
        let op0 = state.cam_r_obj * point_in_obj_m;
        let op = increment.rotate(&op0);
        let point_in_cam_m = op + state.cam_t_obj_m + state.velocity_mps * d_s;
        let pixel = self.intrinsics.pixel_from_cam(&point_in_cam_m)?;
        let dm_dp: Matrix2x3<f64> = self.intrinsics.pixel_jacobian_wrt_cam(&point_in_cam_m);
        let mut jacobian = Matrix2x12::zeros();
        match kind {
            JacobianKind::Exact => {
                // dm/dP [I, -[OP]x E, d I, -[OP]x J_l d]. For a row a of dm/dP, (a [OP]x)ᵀ = a × OP, and the products
                // of that row with E and J_l are taken by cross products (no 3 x 3 matrices).
                for r in 0..2 {
                    let a = dm_dp.row(r).transpose();
                    let (a_op_e, a_op_j) = increment.row_times_exp_and_left_jacobian(&a.cross(&op));
                    for c in 0..3 {
                        jacobian[(r, c)] = a[c];
                        jacobian[(r, 3 + c)] = -a_op_e[c];
                        jacobian[(r, 6 + c)] = a[c] * d_s;
                        jacobian[(r, 9 + c)] = -a_op_j[c] * d_s;
                    }
                }
            }
            JacobianKind::Paper => {
                let w = &state.angular_velocity_radps;
                let op0_hat = so3::hat(&op0);
                let h_trans = so3::hat(w) * 2.0;
                let h_rot = so3::hat(&(op0_hat * w));
                let blocks: [Matrix3<f64>; 4] = [
                    Matrix3::identity() + h_trans * d_s,
                    -op0_hat + h_rot * d_s,
                    Matrix3::identity() * d_s,
                    -op0_hat * d_s,
                ];
                for (k, block) in blocks.iter().enumerate() {
                    jacobian
                        .fixed_view_mut::<2, 3>(0, 3 * k)
                        .copy_from(&(dm_dp * block));
                }
            }
        }
        Some(ProjectedPoint {
            pixel,
            jacobian,
            point_in_cam_m,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CameraModel, Target, Vector12};
    use nalgebra::Rotation3;

    fn model() -> SpatioTemporalModel {
        let mut k = CameraModel::canonical().intrinsics;
        k.skew_px = 2.5; // exercise the skew term
        SpatioTemporalModel::new(k)
    }

    /// The exact Jacobian against central differences, at a state, a point of the grid and a time offset `d` up to
    /// 8 ms before the reference. Velocity columns act through `d`: their scale, 100 m/s and rad/s, moves the point
    /// at the largest `d` about as much as the pose's unit steps do.
    #[test]
    fn exact_jacobian_matches_central_differences() {
        use rand::Rng;
        let m = model();
        let points = Target::grid4x4()
            .points()
            .iter()
            .map(|p| p.point_in_obj_m)
            .collect::<Vec<_>>();
        let mut scale = Vector12::repeat(1.0);
        scale.fixed_rows_mut::<6>(6).fill(100.0);
        roitrack_testkit::check_jacobian(
            "exact projection Jacobian",
            (
                MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6)),
                points[0],
                -4e-3,
            ),
            |rng, spread| {
                let point = points[rng.random_range(0..points.len())];
                (
                    crate::test_support::drawn_state(rng, spread),
                    point,
                    rng.random_range(-0.008..0.0),
                )
            },
            &scale,
            |(s, p, d), delta| m.project(&s.corrected(delta), p, *d).unwrap(),
            |(s, p, d)| {
                let analytic = m
                    .project_with_jacobian(JacobianKind::Exact, s, p, *d)
                    .unwrap();
                assert!((analytic.pixel - m.project(s, p, *d).unwrap()).norm() < 1e-9);
                analytic.jacobian
            },
        );
    }

    #[test]
    fn paper_velocity_block_agrees_to_second_order() {
        let m = model();
        let s = MotionState {
            cam_r_obj: Rotation3::from_euler_angles(0.17, -0.26, 0.09),
            cam_t_obj_m: Vector3::new(0.02, -0.01, 0.6),
            velocity_mps: Vector3::new(0.4, -0.2, 0.1),
            angular_velocity_radps: Vector3::new(3.0, -4.0, 2.0),
        };
        let p = Vector3::new(0.03, -0.01, 0.0);
        let block_gap = |d: f64| {
            let e = m
                .project_with_jacobian(JacobianKind::Exact, &s, &p, d)
                .unwrap()
                .jacobian;
            let q = m
                .project_with_jacobian(JacobianKind::Paper, &s, &p, d)
                .unwrap()
                .jacobian;
            ((e - q).columns(6, 6).norm(), (e - q).columns(0, 6).norm())
        };
        let mut d = 0.004;
        let (mut vel_prev, mut pose_prev) = block_gap(d);
        for _ in 0..4 {
            d /= 2.0;
            let (vel, pose) = block_gap(d);
            // Velocity block O(d²): halving d divides the gap by 4. Pose block O(d): by 2.
            let vel_ratio = vel_prev / vel;
            let pose_ratio = pose_prev / pose;
            assert!(
                (vel_ratio - 4.0).abs() < 0.2,
                "velocity block ratio {vel_ratio}"
            );
            assert!(
                (pose_ratio - 2.0).abs() < 0.1,
                "pose block ratio {pose_ratio}"
            );
            (vel_prev, pose_prev) = (vel, pose);
        }
        // At d = 0 both reduce to the classical point interaction matrix.
        let e = m
            .project_with_jacobian(JacobianKind::Exact, &s, &p, 0.0)
            .unwrap()
            .jacobian;
        let q = m
            .project_with_jacobian(JacobianKind::Paper, &s, &p, 0.0)
            .unwrap()
            .jacobian;
        assert!((e - q).norm() < 1e-12 * e.norm());
    }

    #[test]
    fn points_behind_the_camera_have_no_projection() {
        let s = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, -0.5));
        assert!(
            model()
                .project_with_jacobian(JacobianKind::Exact, &s, &Vector3::zeros(), 0.0)
                .is_none()
        );
    }
}
