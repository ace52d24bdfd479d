//! Random rigs: the targets, cameras, lenses, poses, motions, noise and model errors that users bring, drawn from
//! families, seeded and reproducible. Each rig holds the truth (the camera as it is, the target as it was made) and
//! the user's model of it (a calibration a little off, a target drawn to spec), so that what is tested is what a
//! user gets.
//!
//! The families split targets by what a pose solver sees: 3 points; 4-5 points on a plane or in depth; 6-40 points
//! on a plane, within 0.1-1 % or 1-10 % of their size off a plane, or spread in depth; and symmetric circle grids.
//! Every family draws the rest from the same ranges:
//!
//! - targets 1 cm to 1 m across (log-uniform), their origin on their first point;
//! - cameras of 300-3000 px focal length (log-uniform, within what the lens can see of the image), 320 x 240 to
//!   4096 x 3000, plumb_bob, rational_polynomial or equidistant (fisheye) lenses;
//! - poses 0.2-5 m away (log-uniform), the target's front tilted 0-70 degrees from the line of sight, at a distance
//!   redrawn until its image spans 5-90 % of the image's smaller side with every point inside;
//! - a constant twist that moves the target by up to a third of its distance a second, turning up to 1 rad/s, kept
//!   in view over the motion;
//! - centroid noise 0.03-1 px (log-uniform);
//! - the user's model: focal lengths and principal point off by up to 2 %, k1 off by up to 0.05, every target
//!   coordinate off by up to 0.5 mm.
//!
//! ```
//! use roitrack_sim::rigs::{Rig, RigFamily};
//!
//! let rig = Rig::random(RigFamily::Solid, 7);
//! assert_eq!(rig, Rig::random(RigFamily::Solid, 7)); // reproducible
//! assert!(rig.raw_pixels(&rig.state, 0.0).is_some()); // every point in view
//! ```

use nalgebra::{Rotation3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::camera::{Distortion, Equidistant, PlumbBob, RationalPolynomial};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, MotionState, PinholeIntrinsics, Target, TargetPoint};

/// The kinds of target a rig can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RigFamily {
    /// 3 points: up to four poses fit any view.
    ThreePoints,
    /// 4 or 5 points on a plane.
    FewPlanar,
    /// 4 or 5 points spread in depth.
    FewSolid,
    /// 6 to 40 points on a plane.
    Planar,
    /// 6 to 40 points off a plane by up to 0.1-1 % of the target's size.
    NearlyPlanar,
    /// 6 to 40 points off a plane by up to 1-10 % of the target's size.
    OffPlane,
    /// 6 to 40 points spread in depth (the box they fill at least 30 % as deep as it is wide).
    Solid,
    /// Square or hexagonal circle grids of 3 x 3 to 7 x 8, no point marked.
    SymmetricGrid,
}

impl RigFamily {
    /// Every family, from the fewest points to the symmetric grids.
    pub const ALL: [Self; 8] = [
        Self::ThreePoints,
        Self::FewPlanar,
        Self::FewSolid,
        Self::Planar,
        Self::NearlyPlanar,
        Self::OffPlane,
        Self::Solid,
        Self::SymmetricGrid,
    ];

    /// A short description of the family for tables (its point count and shape).
    pub fn name(&self) -> &'static str {
        match self {
            Self::ThreePoints => "3 points",
            Self::FewPlanar => "4-5 planar",
            Self::FewSolid => "4-5 3-D",
            Self::Planar => "6-40 planar",
            Self::NearlyPlanar => "6-40 off-plane 0.1-1%",
            Self::OffPlane => "6-40 off-plane 1-10%",
            Self::Solid => "6-40 3-D",
            Self::SymmetricGrid => "symmetric grids",
        }
    }
}

/// A camera, a target and their motion as they are, and the user's model of the camera and target.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    /// The family the rig was drawn from.
    pub family: RigFamily,
    /// The seed it was drawn from ([`Self::random`] gives the same rig again).
    pub seed: u64,
    /// The camera as it is.
    pub camera: CameraModel,
    /// The camera as the user's calibration file says.
    pub user_camera: CameraModel,
    /// The target as it was made.
    pub target: Target,
    /// The target as the user's file says (its drawing): the same ids, each coordinate a little off.
    pub user_target: Target,
    /// The true state at time 0: the pose and a constant twist (camera frame).
    pub state: MotionState,
    /// Centroid noise (px per coordinate, raw pixels).
    pub noise_px: f64,
}

/// Rigs redrawn at most this many times before giving up (never reached in practice: a few draws suffice).
const MAX_DRAWS: usize = 1000;

impl Rig {
    /// The rig of `family` drawn from `seed` (see the module's docs for the ranges).
    pub fn random(family: RigFamily, seed: u64) -> Self {
        let mut rng =
            ChaCha8Rng::seed_from_u64(seed ^ (family as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        for _ in 0..MAX_DRAWS {
            if let Some(rig) = Self::draw(family, seed, &mut rng) {
                return rig;
            }
        }
        panic!(
            "no rig of family {} from seed {seed} in {MAX_DRAWS} draws",
            family.name()
        );
    }

    fn draw(family: RigFamily, seed: u64, rng: &mut ChaCha8Rng) -> Option<Self> {
        let target = random_target(family, rng)?;
        let camera = random_camera(rng)?;
        let state = random_state(&target, &camera, rng)?;
        let noise_px = log_uniform(rng, 0.03, 1.0);
        let user_camera = user_camera(&camera, rng)?;
        let user_target = user_target(&target, rng)?;
        Some(Self {
            family,
            seed,
            camera,
            user_camera,
            target,
            user_target,
            state,
            noise_px,
        })
    }

    /// The raw pixel of every target point at `d_s` seconds after time 0, if every one is in front of the camera and
    /// inside the image (2 px from its edge).
    pub fn raw_pixels(&self, state: &MotionState, d_s: f64) -> Option<Vec<Vector2<f64>>> {
        raw_pixels_in(&self.camera, &self.target, state, d_s, 2.0)
    }
}

fn raw_pixels_in(
    camera: &CameraModel,
    target: &Target,
    state: &MotionState,
    d_s: f64,
    margin_px: f64,
) -> Option<Vec<Vector2<f64>>> {
    target
        .points()
        .iter()
        .map(|p| {
            let in_cam = state.point_in_cam_at(&p.point_in_obj_m, d_s);
            let px = camera.raw_pixel_from_cam(&in_cam)?;
            let inside = px.x >= margin_px
                && px.y >= margin_px
                && px.x <= f64::from(camera.width_px) - 1.0 - margin_px
                && px.y <= f64::from(camera.height_px) - 1.0 - margin_px;
            (in_cam.z > 0.0 && inside).then_some(px)
        })
        .collect()
}

fn log_uniform(rng: &mut ChaCha8Rng, low: f64, high: f64) -> f64 {
    (rng.random_range(low.ln()..high.ln())).exp()
}

fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

/// `count` points in the unit square at least `min_gap` apart, no three nearly on a line (their triangle's height at
/// least `min_gap / 2`), or `None` if the draw failed.
fn scattered_in_square(
    rng: &mut ChaCha8Rng,
    count: usize,
    min_gap: f64,
) -> Option<Vec<Vector2<f64>>> {
    let mut points: Vec<Vector2<f64>> = Vec::with_capacity(count);
    for _ in 0..200 * count {
        if points.len() == count {
            break;
        }
        let p = Vector2::new(rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
        let far = points.iter().all(|q| (q - p).norm() >= min_gap);
        // Small layouts are the ones a near-line of points spoils: check every pair with the new point.
        let spread = count > 5
            || points.iter().enumerate().all(|(i, a)| {
                points[i + 1..].iter().all(|b| {
                    let (e1, e2) = (b - a, p - a);
                    (e1.x * e2.y - e1.y * e2.x).abs() / e1.norm().max(e2.norm()) >= 0.5 * min_gap
                })
            });
        if far && spread {
            points.push(p);
        }
    }
    (points.len() == count).then_some(points)
}

fn random_target(family: RigFamily, rng: &mut ChaCha8Rng) -> Option<Target> {
    let size_m = log_uniform(rng, 0.01, 1.0);
    let in_plane = |rng: &mut ChaCha8Rng, count: usize, depth: f64| -> Option<Vec<Vector3<f64>>> {
        let gap = 0.5 / (count as f64).sqrt();
        Some(
            scattered_in_square(rng, count, gap)?
                .into_iter()
                .map(|p| Vector3::new(p.x, p.y, depth * rng.random_range(-1.0..1.0)))
                .collect(),
        )
    };
    let solid = |rng: &mut ChaCha8Rng, count: usize| -> Vec<Vector3<f64>> {
        // A box at least 30 % as deep as wide: each point's depth from the box.
        let depth = rng.random_range(0.3..1.0);
        let gap = 0.4 / (count as f64).cbrt();
        let mut points: Vec<Vector3<f64>> = Vec::with_capacity(count);
        while points.len() < count {
            let p = Vector3::new(
                rng.random_range(0.0..1.0),
                rng.random_range(0.0..1.0),
                depth * rng.random_range(0.0..1.0),
            );
            if points.iter().all(|q| (q - p).norm() >= gap) {
                points.push(p);
            }
        }
        points
    };
    let unit_points: Vec<Vector3<f64>> = match family {
        RigFamily::ThreePoints => in_plane(rng, 3, 0.0)?,
        RigFamily::FewPlanar => {
            let count = rng.random_range(4..=5);
            in_plane(rng, count, 0.0)?
        }
        RigFamily::FewSolid => {
            let count = rng.random_range(4..=5);
            solid(rng, count)
        }
        RigFamily::Planar => {
            let count = rng.random_range(6..=40);
            in_plane(rng, count, 0.0)?
        }
        RigFamily::NearlyPlanar => {
            let (count, depth) = (rng.random_range(6..=40), log_uniform(rng, 0.001, 0.01));
            in_plane(rng, count, depth)?
        }
        RigFamily::OffPlane => {
            let (count, depth) = (rng.random_range(6..=40), log_uniform(rng, 0.01, 0.1));
            in_plane(rng, count, depth)?
        }
        RigFamily::Solid => {
            let count = rng.random_range(6..=40);
            solid(rng, count)
        }
        RigFamily::SymmetricGrid => {
            let (rows, cols) = (rng.random_range(3..=7u32), rng.random_range(3..=8u32));
            let layout = if rng.random_bool(0.5) {
                GridLayout::Square
            } else {
                GridLayout::Hexagonal
            };
            let spacing = 1.0 / f64::from(rows.max(cols));
            let grid = Target::circle_grid(&CircleGrid {
                rows,
                cols,
                spacing_m: spacing,
                diameter_m: 0.4 * spacing,
                layout,
            })
            .ok()?;
            grid.points().iter().map(|p| p.point_in_obj_m).collect()
        }
    };
    // Scaled to the target's size, its origin on its first point.
    let extent = unit_points
        .iter()
        .flat_map(|p| unit_points.iter().map(move |q| (p - q).norm()))
        .fold(0.0, f64::max);
    let origin = unit_points[0];
    let points = unit_points
        .iter()
        .enumerate()
        .map(|(i, p)| TargetPoint {
            id: i as u32,
            point_in_obj_m: (p - origin) * (size_m / extent),
            diameter_m: None,
        })
        .collect();
    let target = Target::new(points).ok()?;
    // Points spread in depth: the thinnest spread at least a tenth of the widest (a few random points can fall near
    // a plane).
    let [widest, _, thinnest] = target.principal_spreads_m();
    let solid = matches!(family, RigFamily::Solid | RigFamily::FewSolid);
    (!solid || thinnest >= 0.1 * widest).then_some(target)
}

fn random_camera(rng: &mut ChaCha8Rng) -> Option<CameraModel> {
    const SIZES: [(u32, u32); 7] = [
        (320, 240),
        (640, 480),
        (800, 600),
        (1280, 960),
        (1920, 1080),
        (2448, 2048),
        (4096, 3000),
    ];
    let (width_px, height_px) = SIZES[rng.random_range(0..SIZES.len())];
    let lens = rng.random_range(0..3);
    // What the lens sees of the image: a perspective lens up to 60 degrees off axis at the image's corner, a fisheye up
    // to 80.
    let max_angle_deg: f64 = if lens == 2 { 80.0 } else { 60.0 };
    let half_diagonal_px = 0.5 * f64::from(width_px).hypot(f64::from(height_px));
    let min_focal_px = (half_diagonal_px / max_angle_deg.to_radians().tan()).max(300.0);
    if min_focal_px >= 3000.0 {
        return None;
    }
    let fx_px = log_uniform(rng, min_focal_px, 3000.0);
    let intrinsics = PinholeIntrinsics {
        fx_px,
        fy_px: fx_px * rng.random_range(0.98..1.02),
        skew_px: 0.0,
        cx_px: f64::from(width_px) * (0.5 + rng.random_range(-0.05..0.05)),
        cy_px: f64::from(height_px) * (0.5 + rng.random_range(-0.05..0.05)),
    };
    let tangential = |rng: &mut ChaCha8Rng| rng.random_range(-1e-3..1e-3);
    let distortion: Distortion = match lens {
        0 => PlumbBob::from_coefficients([
            rng.random_range(-0.3..0.1),
            rng.random_range(-0.05..0.05),
            tangential(rng),
            tangential(rng),
            0.0,
        ])
        .into(),
        1 => RationalPolynomial::from_coefficients([
            rng.random_range(-0.3..0.1),
            rng.random_range(-0.05..0.05),
            tangential(rng),
            tangential(rng),
            0.0,
            rng.random_range(-0.1..0.1),
            0.0,
            0.0,
        ])
        .into(),
        _ => Equidistant::from_coefficients([
            rng.random_range(-0.05..0.05),
            rng.random_range(-0.01..0.01),
            0.0,
            0.0,
        ])
        .into(),
    };
    let camera = CameraModel::new("random", width_px, height_px, intrinsics, distortion).ok()?;
    invertible_over_image(&camera).then_some(camera)
}

/// Whether the camera's distortion can be undistorted all over its image (edges and corners included) and back: a
/// lens whose polynomial folds over inside the image is no real lens.
fn invertible_over_image(camera: &CameraModel) -> bool {
    let (w, h) = (
        f64::from(camera.width_px - 1),
        f64::from(camera.height_px - 1),
    );
    (0..=8).all(|i| {
        (0..=8).all(|j| {
            let raw = Vector2::new(w * f64::from(i) / 8.0, h * f64::from(j) / 8.0);
            camera
                .undistort_pixel(&raw)
                .is_ok_and(|ideal| (camera.distort_pixel(&ideal) - raw).norm() < 1e-6)
        })
    })
}

/// The pose (target front tilted up to 70 degrees from the line of sight, at a distance that puts its image at 5-90 %
/// of the image's smaller side) and a twist that keeps every point in view for a second's motion scaled to the run.
fn random_state(
    target: &Target,
    camera: &CameraModel,
    rng: &mut ChaCha8Rng,
) -> Option<MotionState> {
    let points: Vec<Vector3<f64>> = target.points().iter().map(|p| p.point_in_obj_m).collect();
    let centre = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    // The front: the normal of the points' best plane, its -z side (a printed target's side), or any direction.
    let front = target
        .plane()
        .map(|plane| {
            let n: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
            if n.z > 0.0 { -n } else { n }
        })
        .unwrap_or_else(|| random_unit(rng));
    let smaller_side_px = f64::from(camera.width_px.min(camera.height_px));
    for _ in 0..50 {
        // The direction of the target's centre: within 60 % of the half field of view.
        let half_w = 0.5 * f64::from(camera.width_px) / camera.intrinsics.fx_px;
        let half_h = 0.5 * f64::from(camera.height_px) / camera.intrinsics.fy_px;
        let ray = Vector3::new(
            0.6 * half_w * rng.random_range(-1.0..1.0),
            0.6 * half_h * rng.random_range(-1.0..1.0),
            1.0,
        )
        .normalize();
        // The front turned towards the camera (towards -ray), then tilted and rolled.
        let towards = Rotation3::rotation_between(&front, &-ray).unwrap_or_else(|| {
            Rotation3::from_axis_angle(
                &nalgebra::Unit::new_normalize(random_unit(rng).cross(&front)),
                std::f64::consts::PI,
            )
        });
        let tilt_axis = nalgebra::Unit::new_normalize(ray.cross(&random_unit(rng)));
        let tilt =
            Rotation3::from_axis_angle(&tilt_axis, rng.random_range(0.0..70f64.to_radians()));
        let roll = Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(-ray),
            rng.random_range(0.0..std::f64::consts::TAU),
        );
        let cam_r_obj = tilt * roll * towards;
        let distance_m = log_uniform(rng, 0.2, 5.0);
        let cam_t_obj_m = ray * distance_m - cam_r_obj * centre;
        let at_rest = MotionState::at_rest(cam_r_obj, cam_t_obj_m);
        let Some(pixels) = raw_pixels_in(camera, target, &at_rest, 0.0, 2.0) else {
            continue;
        };
        let extent_px = pixels
            .iter()
            .flat_map(|p| pixels.iter().map(move |q| (p - q).norm()))
            .fold(0.0, f64::max);
        if !(0.05 * smaller_side_px..=0.9 * smaller_side_px).contains(&extent_px) {
            continue;
        }
        // A twist: up to a third of the distance a second, up to 1 rad/s about the target's centre; halved until
        // every point stays in view for 0.2 s.
        let mut scale = 1.0;
        let velocity = random_unit(rng) * distance_m * rng.random_range(0.0..0.33);
        let angular = random_unit(rng) * rng.random_range(0.0..1.0);
        for _ in 0..8 {
            let w = angular * scale;
            // The velocity of the origin that moves the centre at `velocity`: v_origin = v_centre - w x (R c).
            let v = velocity * scale - w.cross(&(cam_r_obj * centre));
            let state = MotionState {
                velocity_mps: v,
                angular_velocity_radps: w,
                ..at_rest
            };
            let in_view = (0..=4)
                .all(|k| raw_pixels_in(camera, target, &state, 0.05 * f64::from(k), 2.0).is_some());
            if in_view {
                return Some(state);
            }
            scale *= 0.5;
        }
        return Some(at_rest);
    }
    None
}

fn user_camera(camera: &CameraModel, rng: &mut ChaCha8Rng) -> Option<CameraModel> {
    let k = camera.intrinsics;
    let (w, h) = (f64::from(camera.width_px), f64::from(camera.height_px));
    let mut off = |x: f64| x * (1.0 + rng.random_range(-0.02..0.02));
    let intrinsics = PinholeIntrinsics {
        fx_px: off(k.fx_px),
        fy_px: off(k.fy_px),
        skew_px: 0.0,
        cx_px: k.cx_px + w * rng.random_range(-0.02..0.02),
        cy_px: k.cy_px + h * rng.random_range(-0.02..0.02),
    };
    let dk1 = rng.random_range(-0.05..0.05);
    let distortion = {
        let mut c = camera.distortion.coefficients();
        if let Some(k1) = c.first_mut() {
            *k1 += dk1;
        }
        camera.distortion.with_coefficients(&c)
    };
    let user = CameraModel::new(
        "user",
        camera.width_px,
        camera.height_px,
        intrinsics,
        distortion,
    )
    .ok()?;
    invertible_over_image(&user).then_some(user)
}

fn user_target(target: &Target, rng: &mut ChaCha8Rng) -> Option<Target> {
    let points = target
        .points()
        .iter()
        .map(|p| TargetPoint {
            point_in_obj_m: p.point_in_obj_m
                + Vector3::new(
                    rng.random_range(-5e-4..5e-4),
                    rng.random_range(-5e-4..5e-4),
                    rng.random_range(-5e-4..5e-4),
                ),
            ..*p
        })
        .collect();
    Target::new(points).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigs_cover_their_ranges() {
        for family in RigFamily::ALL {
            for seed in 0..20 {
                let rig = Rig::random(family, seed);
                assert!(rig.raw_pixels(&rig.state, 0.0).is_some());
                let distance = rig.state.cam_t_obj_m.norm();
                assert!(distance > 0.1 && distance < 6.5, "{distance}");
                assert!((0.03..=1.0).contains(&rig.noise_px));
                let n = rig.target.len();
                let planar = rig.target.is_planar();
                match family {
                    RigFamily::ThreePoints => assert_eq!(n, 3),
                    RigFamily::FewPlanar => assert!((4..=5).contains(&n) && planar),
                    RigFamily::FewSolid => assert!((4..=5).contains(&n) && !planar),
                    RigFamily::Planar => assert!((6..=40).contains(&n) && planar),
                    RigFamily::NearlyPlanar | RigFamily::OffPlane | RigFamily::Solid => {
                        assert!((6..=40).contains(&n) && !planar);
                    }
                    RigFamily::SymmetricGrid => assert!(planar && n >= 5),
                }
                let [a, _, c] = rig.target.principal_spreads_m();
                match family {
                    RigFamily::NearlyPlanar => assert!(c < 0.02 * a, "{c} {a}"),
                    RigFamily::Solid | RigFamily::FewSolid => assert!(c > 0.05 * a, "{c} {a}"),
                    _ => {}
                }
                assert_eq!(rig.user_target.len(), n);
            }
        }
    }
}
