//! The target found and identified in synthetic photographs ([`roitrack_sim::photo`]): square, hexagonal, keyed and
//! sparse targets under tilt, lens distortion, blur, noise, uneven light, shadow, clutter, both polarities and 8 to
//! 16 bits; the accuracy of the centres; partial views (right or refused, never wrong); failures as errors.
//!
//! Every result is checked against the truth: each returned point within a pixel of the truth centre of the same id
//! and the pose near the truth, or, when the result says the labelling is ambiguous, the labelling equal to the truth
//! up to a rotation of the target onto itself (and the pose the truth composed with that rotation).

use std::time::Instant;

use nalgebra::{Rotation3, Vector2, Vector3};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, Target, TargetPoint, so3};
use roitrack_detect::detect_target;
use roitrack_detect::photo::{PhotoDetection, PhotoError, PhotoOptions, PolarityChoice};
use roitrack_image::{Frame, Polarity};
use roitrack_sim::photo::{
    Background, CircleShade, Clutter, Illumination, PhotoScene, RenderedPhoto, Shadow, render_photo,
};

// ---------------------------------------------------------------------------------------------------------------
// Targets and scenes

fn grid(rows: u32, cols: u32, spacing_m: f64, diameter_m: f64, layout: GridLayout) -> Target {
    Target::circle_grid(&CircleGrid {
        rows,
        cols,
        spacing_m,
        diameter_m,
        layout,
    })
    .unwrap()
}

/// Five circles in no symmetric layout (no rotation of the plane takes it onto itself), one of them larger.
fn sparse5() -> Target {
    let xy = [
        (0.0, 0.0, 0.014),
        (0.075, 0.005, 0.014),
        (0.115, 0.06, 0.014),
        (0.03, 0.085, 0.014),
        (0.06, 0.04, 0.02),
    ];
    Target::new(
        xy.iter()
            .enumerate()
            .map(|(i, &(x, y, d))| TargetPoint {
                id: 10 + i as u32,
                point_in_obj_m: Vector3::new(x, y, 0.0),
                diameter_m: Some(d),
            })
            .collect(),
    )
    .unwrap()
}

/// A tilt of `deg` degrees about the in-image axis at `axis_deg` from the camera's x axis, then a turn of `roll_deg`
/// about the optical axis.
fn tilt(deg: f64, axis_deg: f64, roll_deg: f64) -> Rotation3<f64> {
    let a = axis_deg.to_radians();
    let axis = nalgebra::Unit::new_normalize(Vector3::new(a.cos(), a.sin(), 0.0));
    Rotation3::from_axis_angle(&axis, deg.to_radians())
        * Rotation3::from_axis_angle(&Vector3::z_axis(), roll_deg.to_radians())
}

/// A 1024 x 768 camera without distortion (fx = fy = 1100 px).
fn camera_xga() -> CameraModel {
    CameraModel::new(
        "xga",
        1024,
        768,
        roitrack_core::camera::PinholeIntrinsics {
            fx_px: 1100.0,
            fy_px: 1100.0,
            skew_px: 0.0,
            cx_px: 511.5,
            cy_px: 383.5,
        },
        roitrack_core::camera::PlumbBob::default(),
    )
    .unwrap()
}

/// Uneven light without clutter: a gradient down to 0.55, strong vignetting and a shadow (light `light`, a penumbra
/// `softness_px` wide) across the middle of the image.
fn shaded(mut scene: PhotoScene, light: f64, softness_px: f64) -> PhotoScene {
    let (w, h) = (
        f64::from(scene.camera.width_px),
        f64::from(scene.camera.height_px),
    );
    scene.illumination = Illumination {
        gradient_min: 0.55,
        gradient_angle_rad: 2.2,
        vignetting: 0.5,
        shadow: Some(Shadow::half_plane(
            Vector2::new(0.5 * w, 0.5 * h),
            Vector2::new(0.8, 0.6),
            light,
            softness_px,
        )),
        glare: None,
    };
    scene
}

// ---------------------------------------------------------------------------------------------------------------
// Checking a result against the truth

/// The rotations of the target's plane that take the target onto itself (points onto points of the same diameter),
/// as permutations of the point indices (the identity included). A target seen from its front can only be
/// relabelled by these; a mirror image shows the back.
fn symmetries(target: &Target) -> Vec<Vec<usize>> {
    let plane = target.plane().expect("a planar target");
    let q = &plane.points_in_plane_m;
    let pts = target.points();
    let n = q.len();
    let spread = target.principal_spreads_m()[0];
    let tol = 1e-6 * spread.max(1e-3);
    let same_d = |a: usize, b: usize| match (pts[a].diameter_m, pts[b].diameter_m) {
        (Some(x), Some(y)) => (x - y).abs() <= 1e-9,
        (None, None) => true,
        _ => false,
    };
    // Point 0 and the point farthest from it fix a motion.
    let far = (0..n)
        .max_by(|&a, &b| (q[a] - q[0]).norm().total_cmp(&(q[b] - q[0]).norm()))
        .unwrap();
    let d0 = (q[far] - q[0]).norm();
    let mut found = Vec::new();
    for a in 0..n {
        for b in 0..n {
            if a == b || ((q[b] - q[a]).norm() - d0).abs() > tol || !same_d(a, 0) {
                continue;
            }
            // The rotation taking q[far] - q[0] onto q[b] - q[a] (proper: no mirror).
            let (u, v) = (q[far] - q[0], q[b] - q[a]);
            let angle = v.y.atan2(v.x) - u.y.atan2(u.x);
            let r = nalgebra::Rotation2::new(angle);
            let perm: Option<Vec<usize>> = (0..n)
                .map(|i| {
                    let moved = r * (q[i] - q[0]) + q[a];
                    (0..n).find(|&j| (q[j] - moved).norm() < 1e3 * tol && same_d(i, j))
                })
                .collect();
            if let Some(perm) = perm
                && !found.contains(&perm)
            {
                found.push(perm);
            }
        }
    }
    found
}

/// What a photograph's detection came to.
#[derive(Debug, Clone)]
struct Check {
    /// The labelling: the returned point of index i shows the target point of index perm[i].
    perm: Vec<usize>,
    points: usize,
    ambiguous: bool,
    /// Mean and largest distance from each returned centre to the truth centre of the point it shows (px).
    mean_px: f64,
    max_px: f64,
    /// Position error over the distance, rotation error (deg).
    position_rel: f64,
    rotation_deg: f64,
}

/// Checks a detection against the truth: every returned point is the image of the point whose id it carries
/// (within `tol_px` of its truth centre), or, if the result says it is ambiguous, of the point a symmetry of the
/// target takes it to, the same symmetry for every point; the pose agrees. Panics with `name` if not.
fn check(
    name: &str,
    scene: &PhotoScene,
    photo: &RenderedPhoto,
    found: &PhotoDetection,
    tol_px: f64,
) -> Check {
    let target = &scene.target;
    let pts = target.points();
    let truth_px: Vec<Option<Vector2<f64>>> = photo.truth.iter().map(|t| t.centre_px).collect();
    let index = |id: u32| target.index_of(id).unwrap();
    // Which labelling (permutation: returned index -> shown index), the identity or a symmetry of the target, puts
    // every returned point nearest the truth: the labelling is right if each point is then within a quarter of the
    // closest spacing of the circles' images (a wrong label is a whole spacing off), and the centres are accurate if
    // each is within `tol_px`.
    let syms = symmetries(target);
    let worst = |perm: &Vec<usize>| {
        found
            .points
            .iter()
            .map(|p| {
                truth_px[perm[index(p.id)]].map_or(f64::INFINITY, |t| (t - p.centre_px).norm())
            })
            .fold(0.0, f64::max)
    };
    let spacing_px = truth_px
        .iter()
        .enumerate()
        .flat_map(|(i, a)| {
            truth_px[i + 1..]
                .iter()
                .map(move |b| (a.unwrap() - b.unwrap()).norm())
        })
        .fold(f64::INFINITY, f64::min);
    let identity: Vec<usize> = (0..pts.len()).collect();
    let perm = if worst(&identity) < 0.25 * spacing_px {
        identity.clone()
    } else {
        let best = syms
            .iter()
            .min_by(|a, b| worst(a).total_cmp(&worst(b)))
            .unwrap();
        if worst(best) >= 0.25 * spacing_px {
            let far = found
                .points
                .iter()
                .map(|p| {
                    let t = truth_px[index(p.id)];
                    (p.id, t.map(|t| (t - p.centre_px).norm()))
                })
                .filter(|(_, d)| d.is_none_or(|d| d >= tol_px))
                .take(6)
                .collect::<Vec<_>>();
            panic!(
                "{name}: WRONG labelling (ambiguous {}, {} points): (id, distance to its truth px) {far:?}",
                found.ambiguous,
                found.points.len()
            );
        }
        assert!(
            found.ambiguous,
            "{name}: labelled by a symmetry of the target but not flagged ambiguous"
        );
        best.clone()
    };
    let off = worst(&perm);
    assert!(
        off < tol_px,
        "{name}: labelling right (ambiguous {}), but a centre is {off:.3} px from the truth",
        found.ambiguous
    );
    if found.ambiguous {
        assert!(
            syms.len() > 1,
            "{name}: flagged ambiguous, but the target has no symmetry"
        );
    }
    // The pose: the detected pose D labels point i where the truth T puts point perm[i]: D = T S with S the
    // symmetry (p_i -> p_perm[i]), so T = D S⁻¹ .
    let (s_r, s_t) = if perm == identity {
        (Rotation3::identity(), Vector3::zeros())
    } else {
        rigid_motion(target, &perm)
    };
    let d = &found.state;
    let r_truth = d.cam_r_obj * s_r.inverse();
    let t_truth = d.cam_t_obj_m - r_truth * s_t;
    let distance = scene.cam_t_obj_m.norm();
    let position_rel = (t_truth - scene.cam_t_obj_m).norm() / distance;
    let rotation_deg = so3::angle_between(&r_truth, &scene.cam_r_obj).to_degrees();
    let errors: Vec<f64> = found
        .points
        .iter()
        .map(|p| (truth_px[perm[index(p.id)]].unwrap() - p.centre_px).norm())
        .collect();
    let result = Check {
        perm: perm.clone(),
        points: found.points.len(),
        ambiguous: found.ambiguous,
        mean_px: errors.iter().sum::<f64>() / errors.len().max(1) as f64,
        max_px: errors.iter().copied().fold(0.0, f64::max),
        position_rel,
        rotation_deg,
    };
    assert!(
        position_rel < 0.01 && rotation_deg < 0.5,
        "{name}: pose off by {:.3} % of the distance and {rotation_deg:.3} deg",
        100.0 * position_rel
    );
    result
}

/// The rigid motion of the object frame that takes each point i to point perm[i] (least squares; exact for a
/// symmetry).
fn rigid_motion(target: &Target, perm: &[usize]) -> (Rotation3<f64>, Vector3<f64>) {
    let pts = target.points();
    let n = pts.len() as f64;
    let a_mean = pts.iter().map(|p| p.point_in_obj_m).sum::<Vector3<f64>>() / n;
    let b_mean = a_mean; // a permutation keeps the centroid
    let mut h = nalgebra::Matrix3::zeros();
    for (i, p) in pts.iter().enumerate() {
        h += (p.point_in_obj_m - a_mean) * (pts[perm[i]].point_in_obj_m - b_mean).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = nalgebra::Matrix3::identity();
    if (v_t.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = Rotation3::from_matrix_unchecked(v_t.transpose() * d * u.transpose());
    let t = b_mean - r * a_mean;
    for (i, p) in pts.iter().enumerate() {
        assert!((r * p.point_in_obj_m + t - pts[perm[i]].point_in_obj_m).norm() < 1e-9);
    }
    (r, t)
}

/// Renders `scene`, timed.
fn render(scene: &PhotoScene) -> (RenderedPhoto, f64) {
    let started = Instant::now();
    let photo = render_photo(scene).unwrap();
    (photo, started.elapsed().as_secs_f64())
}

/// Detects with `polarity` in a photograph of `scene` and checks the result; panics if the detection fails or is
/// wrong, or used the wrong polarity.
fn run_on(
    name: &str,
    scene: &PhotoScene,
    (photo, render_s): (&RenderedPhoto, f64),
    polarity: PolarityChoice,
    tol_px: f64,
) -> (Check, PhotoDetection) {
    let started = Instant::now();
    let options = PhotoOptions {
        polarity,
        ..PhotoOptions::default()
    };
    let found = detect_target(&scene.camera, &scene.target, &photo.frame, &options)
        .unwrap_or_else(|e| panic!("{name}: not found: {e}"));
    let detect_s = started.elapsed().as_secs_f64();
    let expected = match scene.shade() {
        CircleShade::DarkOnLight => Polarity::Dark,
        CircleShade::BrightOnDark => Polarity::Bright,
    };
    assert_eq!(found.polarity, expected, "{name}: polarity");
    let c = check(name, scene, photo, &found, tol_px);
    let visible = photo.truth.iter().filter(|t| t.fully_visible).count();
    eprintln!(
        "{name:<52} {:>3}/{visible:<3} pts {} mean {:.3} max {:.3} px, pose {:.4} % {:.3} deg, rms {:.3} px, \
         render {render_s:.2} s, detect {detect_s:.2} s",
        c.points,
        if c.ambiguous { "ambig" } else { "exact" },
        c.mean_px,
        c.max_px,
        100.0 * c.position_rel,
        c.rotation_deg,
        found.reprojection_rms_px,
    );
    (c, found)
}

/// [`run_on`] a photograph of `scene` rendered here.
fn run(
    name: &str,
    scene: &PhotoScene,
    polarity: PolarityChoice,
    tol_px: f64,
) -> (Check, RenderedPhoto, PhotoDetection) {
    let (photo, render_s) = render(scene);
    let (c, found) = run_on(name, scene, (&photo, render_s), polarity, tol_px);
    (c, photo, found)
}

/// [`run`] for a photograph of the whole target: also checks that the result is flagged ambiguous exactly when the
/// target has a symmetry, and that an ambiguous labelling is the canonical one (the lowest id at the smallest u + v
/// its symmetric images have).
fn run_whole(name: &str, scene: &PhotoScene, polarity: PolarityChoice) -> Check {
    let (photo, render_s) = render(scene);
    run_whole_on(name, scene, (&photo, render_s), polarity)
}

/// [`run_whole`] on a photograph rendered already.
fn run_whole_on(
    name: &str,
    scene: &PhotoScene,
    rendered: (&RenderedPhoto, f64),
    polarity: PolarityChoice,
) -> Check {
    let photo = rendered.0;
    let (c, found) = run_on(name, scene, rendered, polarity, 1.0);
    let target = &scene.target;
    let syms = symmetries(target);
    assert_eq!(
        c.ambiguous,
        syms.len() > 1,
        "{name}: ambiguous flag against the target's {} symmetries",
        syms.len()
    );
    assert_eq!(c.points, target.len(), "{name}: points found");
    if c.ambiguous {
        let lowest = (0..target.len())
            .min_by_key(|&i| target.points()[i].id)
            .unwrap();
        let at = found
            .points
            .iter()
            .find(|p| p.id == target.points()[lowest].id)
            .unwrap()
            .centre_px;
        let best = syms
            .iter()
            .map(|s| {
                let t = photo.truth[s[lowest]].centre_px.unwrap();
                t.x + t.y
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            at.x + at.y <= best + 1.0,
            "{name}: the canonical labelling puts the lowest id at u + v = {:.1}, one of its images is at {best:.1}",
            at.x + at.y
        );
    }
    c
}

// ---------------------------------------------------------------------------------------------------------------
// 1. Identification across conditions

#[test]
fn square_grids_are_identified_up_to_their_symmetry() {
    let canonical = CameraModel::canonical();
    let g66 = grid(6, 6, 0.03, 0.015, GridLayout::Square);
    let g810 = grid(8, 10, 0.025, 0.012, GridLayout::Square);
    assert_eq!(symmetries(&g66).len(), 4);
    assert_eq!(symmetries(&g810).len(), 2);

    let scene = PhotoScene::facing(canonical.clone(), g66.clone(), 0.8, tilt(20.0, 30.0, 10.0));
    run_whole("square 6x6, 20 deg, clean", &scene, PolarityChoice::Auto);
    let scene = PhotoScene::facing(canonical.clone(), g66.clone(), 0.9, tilt(50.0, 100.0, 75.0))
        .harsh()
        .with_seed(11);
    run_whole("square 6x6, 50 deg, harsh", &scene, PolarityChoice::Auto);
    let scene = PhotoScene::facing(canonical.clone(), g66, 0.8, tilt(35.0, -40.0, 200.0))
        .harsh()
        .with_shade(CircleShade::BrightOnDark)
        .with_bit_depth(16)
        .with_seed(12);
    run_whole(
        "square 6x6, 35 deg, harsh, bright, 16 bit",
        &scene,
        PolarityChoice::Auto,
    );
    let scene = PhotoScene::facing(
        CameraModel::wide_angle_example(),
        g810.clone(),
        0.55,
        tilt(45.0, 60.0, -20.0),
    )
    .harsh()
    .with_seed(13);
    run_whole(
        "square 8x10, 45 deg, wide lens, harsh",
        &scene,
        PolarityChoice::Auto,
    );
    // A shadow across the target, strong vignetting and gradient, busy clutter touching the board on a textured
    // background, blur and noise, 12 bits. (With more noise and blur in a darker shadow the detector loses circles:
    // see `circles_in_a_dark_shadow_are_found`.)
    let mut scene = shaded(
        PhotoScene::facing(camera_xga(), g810, 0.7, tilt(30.0, 10.0, 5.0)),
        0.4,
        40.0,
    );
    scene.clutter = Clutter::busy(120);
    scene.background = Background::Texture {
        mean_level: 0.5,
        contrast: 0.4,
        scale_px: 40.0,
    };
    scene.blur_sigma_px = 1.3;
    scene.noise_sigma = 0.015;
    scene.bit_depth = 12;
    scene.seed = 14;
    run_whole(
        "square 8x10, 30 deg, shadow, clutter, blur, 12 bit",
        &scene,
        PolarityChoice::Auto,
    );
}

#[test]
fn hexagonal_grids_are_identified_up_to_their_symmetry() {
    let hex810 = grid(8, 10, 0.025, 0.012, GridLayout::Hexagonal);
    let hex_large = grid(16, 22, 0.015, 0.008, GridLayout::Hexagonal);
    assert_eq!(hex810.len(), 40);
    assert_eq!(hex_large.len(), 176);
    let scene = PhotoScene::facing(
        CameraModel::wide_angle_example(),
        hex810.clone(),
        0.6,
        tilt(35.0, 120.0, 30.0),
    )
    .harsh()
    .with_seed(21);
    run_whole(
        "hex 8x10, 35 deg, wide lens, harsh",
        &scene,
        PolarityChoice::Auto,
    );
    let scene = PhotoScene::facing(
        CameraModel::canonical(),
        hex810,
        0.75,
        tilt(50.0, -15.0, 95.0),
    )
    .harsh()
    .with_shade(CircleShade::BrightOnDark)
    .with_bit_depth(12)
    .with_seed(22);
    run_whole(
        "hex 8x10, 50 deg, harsh, bright, 12 bit",
        &scene,
        PolarityChoice::Auto,
    );
    let mut scene = shaded(
        PhotoScene::facing(
            CameraModel::canonical(),
            hex_large.clone(),
            0.75,
            tilt(30.0, 45.0, 160.0),
        ),
        0.4,
        40.0,
    );
    scene.clutter = Clutter::busy(80);
    scene.noise_sigma = 0.01;
    scene.blur_sigma_px = 1.0;
    scene.seed = 23;
    run_whole(
        "hex 16x22, 30 deg, shadow, clutter",
        &scene,
        PolarityChoice::Auto,
    );
    let scene = PhotoScene::facing(
        CameraModel::wide_angle_example(),
        hex_large,
        0.7,
        tilt(40.0, 200.0, -60.0),
    )
    .harsh()
    .with_bit_depth(16)
    .with_seed(24);
    run_whole(
        "hex 16x22, 40 deg, wide lens, harsh, 16 bit",
        &scene,
        PolarityChoice::Auto,
    );
}

/// Four and six circles in no symmetric layout.
fn sparse(n: usize) -> Target {
    let xy: &[(f64, f64, f64)] = match n {
        4 => &[
            (0.0, 0.0, 0.015),
            (0.09, 0.01, 0.015),
            (0.07, 0.07, 0.015),
            (0.015, 0.055, 0.015),
        ],
        6 => &[
            (0.0, 0.0, 0.012),
            (0.05, -0.01, 0.012),
            (0.11, 0.01, 0.012),
            (0.1, 0.07, 0.012),
            (0.04, 0.08, 0.012),
            (0.055, 0.035, 0.012),
        ],
        _ => unreachable!(),
    };
    Target::new(
        xy.iter()
            .enumerate()
            .map(|(i, &(x, y, d))| TargetPoint {
                id: 100 + 7 * i as u32,
                point_in_obj_m: Vector3::new(x, y, 0.0),
                diameter_m: Some(d),
            })
            .collect(),
    )
    .unwrap()
}

#[test]
fn keyed_and_sparse_targets_are_identified_exactly() {
    let canonical = CameraModel::canonical();
    let wide = CameraModel::wide_angle_example();
    for t in [Target::grid4x4(), sparse(4), sparse5(), sparse(6)] {
        assert_eq!(symmetries(&t).len(), 1);
    }
    // grid4x4: its key blob 0 (9 mm against 6 mm) breaks the grid's symmetry, every way round.
    for (k, roll) in [0.0, 90.0, 180.0, 270.0].into_iter().enumerate() {
        let scene = PhotoScene::facing(
            canonical.clone(),
            Target::grid4x4(),
            0.5,
            tilt(50.0, 70.0 + 40.0 * k as f64, roll + 15.0),
        )
        .harsh()
        .with_seed(30 + k as u64);
        run_whole(
            &format!("grid4x4, 50 deg, roll {roll}, harsh"),
            &scene,
            PolarityChoice::Auto,
        );
    }
    let scene = PhotoScene::facing(
        wide.clone(),
        Target::grid4x4(),
        0.45,
        tilt(40.0, 10.0, 120.0),
    )
    .harsh()
    .with_shade(CircleShade::BrightOnDark)
    .with_bit_depth(16)
    .with_seed(35);
    run_whole(
        "grid4x4, 40 deg, wide lens, harsh, bright, 16 bit",
        &scene,
        PolarityChoice::Auto,
    );
    for (name, target, distance) in [
        ("sparse 4", sparse(4), 0.6),
        ("sparse 5", sparse5(), 0.6),
        ("sparse 6", sparse(6), 0.6),
    ] {
        let scene = PhotoScene::facing(
            canonical.clone(),
            target.clone(),
            distance,
            tilt(40.0, -30.0, 200.0),
        )
        .harsh()
        .with_seed(36);
        run_whole(
            &format!("{name}, 40 deg, harsh"),
            &scene,
            PolarityChoice::Auto,
        );
        // Circles 25 to 40 px across: a wide penumbra (see `shaded`).
        let mut scene = shaded(
            PhotoScene::facing(wide.clone(), target, distance, tilt(50.0, 80.0, 20.0)),
            0.5,
            200.0,
        )
        .with_shade(CircleShade::BrightOnDark)
        .with_bit_depth(16)
        .with_seed(37);
        scene.clutter = Clutter::busy(60);
        scene.noise_sigma = 0.01;
        run_whole(
            &format!("{name}, 50 deg, wide lens, shadow, bright, 16 bit"),
            &scene,
            PolarityChoice::Auto,
        );
    }
}

/// The polarity asked for is the one used; `Auto` says which it took. Asking for the wrong one finds nothing (or,
/// if it finds something, finds it right).
#[test]
fn polarity_is_chosen_and_reported() {
    let target = grid(6, 7, 0.025, 0.012, GridLayout::Square);
    for shade in [CircleShade::DarkOnLight, CircleShade::BrightOnDark] {
        let scene = PhotoScene::facing(
            CameraModel::canonical(),
            target.clone(),
            0.7,
            tilt(25.0, 0.0, 0.0),
        )
        .harsh()
        .with_shade(shade)
        .with_seed(40);
        let (right, wrong) = match shade {
            CircleShade::DarkOnLight => (PolarityChoice::Dark, PolarityChoice::Bright),
            CircleShade::BrightOnDark => (PolarityChoice::Bright, PolarityChoice::Dark),
        };
        let (photo, render_s) = render(&scene);
        run_whole_on(
            &format!("{shade:?}, auto"),
            &scene,
            (&photo, render_s),
            PolarityChoice::Auto,
        );
        run_whole_on(
            &format!("{shade:?}, {right:?}"),
            &scene,
            (&photo, 0.0),
            right,
        );
        let options = PhotoOptions {
            polarity: wrong,
            ..PhotoOptions::default()
        };
        match detect_target(&scene.camera, &target, &photo.frame, &options) {
            Err(e) => eprintln!("{shade:?}, {wrong:?}: refused: {e}"),
            Ok(found) => {
                check(
                    &format!("{shade:?}, {wrong:?}"),
                    &scene,
                    &photo,
                    &found,
                    1.0,
                );
            }
        }
    }
}

/// Sharing the work between two threads (the default) changes nothing: the same blobs in the same order, the same
/// identification and pose, for both polarities and for one polarity asked for, on photographs large enough for the
/// second thread.
#[test]
fn two_threads_find_exactly_what_one_finds() {
    let target = grid(8, 10, 0.025, 0.015, GridLayout::Square);
    for (shade, seed) in [
        (CircleShade::DarkOnLight, 7),
        (CircleShade::BrightOnDark, 8),
        (CircleShade::DarkOnLight, 9),
    ] {
        let scene = PhotoScene::facing(camera_xga(), target.clone(), 0.6, tilt(30.0, 90.0, 5.0))
            .harsh()
            .with_shade(shade)
            .with_seed(seed);
        let photo = render_photo(&scene).unwrap();
        for polarity in [
            PolarityChoice::Auto,
            PolarityChoice::Dark,
            PolarityChoice::Bright,
        ] {
            let found = |threads: usize| {
                let mut options = PhotoOptions {
                    polarity,
                    ..PhotoOptions::default()
                };
                options.blobs.threads = threads;
                detect_target(&scene.camera, &target, &photo.frame, &options)
            };
            let (one, two) = (found(1), found(2));
            assert_eq!(
                format!("{one:?}"),
                format!("{two:?}"),
                "{shade:?} seed {seed}, {polarity:?}"
            );
            if polarity == PolarityChoice::Auto {
                assert!(one.is_ok(), "{shade:?} seed {seed}: {one:?}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// 2. Centre accuracy

/// On clean photographs (0.7 px blur, 0.3 % noise, 12 bits) the returned centres (corrected for the perspective
/// displacement of a disk's centre) are within hundredths of a pixel of the true centres; the blobs' raw centroids
/// are as close to the true area centroids of the circles' images, which lie tenths of a pixel away from the centres
/// under tilt.
#[test]
fn centres_are_accurate_on_clean_photographs() {
    let canonical = CameraModel::canonical();
    let g66 = grid(6, 6, 0.03, 0.015, GridLayout::Square);
    let small = grid(8, 10, 0.02, 0.008, GridLayout::Square);
    let scenes = [
        (
            "square 6x6, 28 px, facing",
            PhotoScene::facing(canonical.clone(), g66.clone(), 0.8, Rotation3::identity()),
        ),
        (
            "square 6x6, 28 px, 30 deg",
            PhotoScene::facing(canonical.clone(), g66.clone(), 0.8, tilt(30.0, 20.0, 10.0)),
        ),
        (
            "square 6x6, 32 px, 45 deg",
            PhotoScene::facing(canonical.clone(), g66, 0.7, tilt(45.0, 110.0, -25.0)),
        ),
        (
            "hex 8x10, 30 px, 35 deg, wide lens",
            PhotoScene::facing(
                CameraModel::wide_angle_example(),
                grid(8, 10, 0.025, 0.012, GridLayout::Hexagonal),
                0.6,
                tilt(35.0, -60.0, 40.0),
            ),
        ),
        (
            "square 8x10, 12 px, 30 deg",
            PhotoScene::facing(canonical.clone(), small, 1.0, tilt(30.0, 70.0, 5.0)),
        ),
        (
            "grid4x4, 18-27 px, 40 deg, bright",
            PhotoScene::facing(canonical, Target::grid4x4(), 0.5, tilt(40.0, 0.0, 30.0))
                .with_shade(CircleShade::BrightOnDark),
        ),
    ];
    let (mut all_centre, mut all_raw, mut all_shift) = (Vec::new(), Vec::new(), Vec::new());
    for (name, scene) in scenes {
        let mut scene = scene.with_bit_depth(12).with_seed(50);
        scene.blur_sigma_px = 0.7;
        scene.noise_sigma = 0.003;
        let (c, photo, found) = run(name, &scene, PolarityChoice::Auto, 1.0);
        assert_eq!(c.points, scene.target.len(), "{name}");
        let index = |id: u32| scene.target.index_of(id).unwrap();
        let (mut centre, mut raw, mut shift) = (Vec::new(), Vec::new(), Vec::new());
        for p in &found.points {
            let truth = &photo.truth[c.perm[index(p.id)]];
            let blob = &found.blobs[p.blob];
            let area = truth.area_centroid_px.unwrap();
            centre.push((p.centre_px - truth.centre_px.unwrap()).norm());
            raw.push((Vector2::new(blob.u_px, blob.v_px) - area).norm());
            shift.push((area - truth.centre_px.unwrap()).norm());
        }
        let stats = |e: &[f64]| {
            (
                e.iter().sum::<f64>() / e.len() as f64,
                e.iter().copied().fold(0.0, f64::max),
            )
        };
        let ((cm, cx), (rm, rx), (sm, sx)) = (stats(&centre), stats(&raw), stats(&shift));
        eprintln!(
            "  {name}: centre - truth centre: mean {cm:.4} max {cx:.4} px; blob centroid - truth area centroid: \
             mean {rm:.4} max {rx:.4} px; (area centroid - centre: mean {sm:.3} max {sx:.3} px)"
        );
        all_centre.extend(centre);
        all_raw.extend(raw);
        all_shift.extend(shift);
    }
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
    let max = |e: &[f64]| e.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "all {} circles: centre mean {:.4} max {:.4} px; raw centroid mean {:.4} max {:.4} px; perspective shift \
         mean {:.3} max {:.3} px",
        all_centre.len(),
        mean(&all_centre),
        max(&all_centre),
        mean(&all_raw),
        max(&all_raw),
        mean(&all_shift),
        max(&all_shift),
    );
    assert!(mean(&all_centre) < 0.05 && max(&all_centre) < 0.15);
    assert!(mean(&all_raw) < 0.05 && max(&all_raw) < 0.15);
    // The correction matters: the perspective shift is larger than the error left.
    assert!(mean(&all_shift) > 2.0 * mean(&all_centre));
}

// ---------------------------------------------------------------------------------------------------------------
// 3. Partial views

/// The target cut by one border of the image, in random poses, with clutter and uneven light: the detection is
/// either right (every returned point the one it says, up to the target's symmetry) or an error; never a wrong
/// labelling. (A view of grid4x4 without its key blob is refused, rightly: a 3 x 4 block of equal circles is either
/// rows 1-3 or, turned a quarter, columns 1-3. A sparse target needs all its circles.)
#[test]
fn partial_views_are_right_or_refused() {
    use rand::{Rng, SeedableRng};
    let camera = CameraModel::new(
        "vga",
        640,
        480,
        roitrack_core::camera::PinholeIntrinsics {
            fx_px: 700.0,
            fy_px: 700.0,
            skew_px: 0.0,
            cx_px: 319.5,
            cy_px: 239.5,
        },
        roitrack_core::camera::PlumbBob::from_coefficients([-0.12, 0.05, 0.0, 0.0, 0.0]),
    )
    .unwrap();
    let targets = [
        ("square 6x8", grid(6, 8, 0.03, 0.015, GridLayout::Square)),
        ("hex 8x10", grid(8, 10, 0.025, 0.012, GridLayout::Hexagonal)),
        ("grid4x4", Target::grid4x4()),
        ("sparse 5", sparse5()),
    ];
    let trials_per_target = [8, 8, 8, 4];
    let (mut ok, mut refused, mut partial_ok) = (0, 0, 0);
    let started = Instant::now();
    for (t, (tname, target)) in targets.iter().enumerate() {
        for k in 0..trials_per_target[t] {
            let seed = 1000 + 100 * t as u64 + k as u64;
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let pts = target.points();
            let extent = pts
                .iter()
                .flat_map(|a| {
                    pts.iter()
                        .map(move |b| (a.point_in_obj_m - b.point_in_obj_m).norm())
                })
                .fold(0.0, f64::max);
            // The target about 55 % of the image's width across.
            let distance = 700.0 * extent / (0.55 * 640.0);
            let rotation = tilt(
                rng.random_range(0.0..45.0),
                rng.random_range(0.0..360.0),
                rng.random_range(0.0..360.0),
            );
            let mut scene = PhotoScene::facing(camera.clone(), target.clone(), distance, rotation)
                .harsh()
                .with_seed(seed);
            if let Some(shadow) = &mut scene.illumination.shadow {
                shadow.softness_px = 120.0;
            }
            // Cut by one border: a fraction of the target's image beyond it.
            let px: Vec<Vector2<f64>> = pts
                .iter()
                .map(|p| {
                    scene
                        .camera
                        .raw_pixel_from_cam(
                            &(scene.cam_r_obj * p.point_in_obj_m + scene.cam_t_obj_m),
                        )
                        .unwrap()
                })
                .collect();
            let (umin, umax) = px
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.x), b.max(p.x)));
            let (vmin, vmax) = px
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.y), b.max(p.y)));
            let cut: f64 = rng.random_range(0.1..0.6);
            let border = k % 4;
            let (du, dv) = match border {
                0 => (-umin - cut * (umax - umin), 0.0),
                1 => (640.0 - umax + cut * (umax - umin), 0.0),
                2 => (0.0, -vmin - cut * (vmax - vmin)),
                _ => (0.0, 480.0 - vmax + cut * (vmax - vmin)),
            };
            scene.cam_t_obj_m.x += du * distance / 700.0;
            scene.cam_t_obj_m.y += dv * distance / 700.0;
            let photo = render_photo(&scene).unwrap();
            let visible = photo.truth.iter().filter(|p| p.fully_visible).count();
            let lowest_seen = photo.truth[0].fully_visible;
            let name = format!(
                "{tname}, seed {seed}, border {border}, {:.0} % cut, {visible}/{} visible{}",
                100.0 * cut,
                target.len(),
                if lowest_seen {
                    ""
                } else {
                    ", the first point cut"
                }
            );
            match detect_target(
                &scene.camera,
                target,
                &photo.frame,
                &PhotoOptions::default(),
            ) {
                Ok(found) => {
                    let c = check(&name, &scene, &photo, &found, 1.0);
                    ok += 1;
                    if visible < target.len() {
                        partial_ok += 1;
                    }
                    eprintln!(
                        "  {name}: found {} points{}",
                        c.points,
                        if c.ambiguous { " (ambiguous)" } else { "" }
                    );
                }
                Err(e) => {
                    refused += 1;
                    eprintln!("  {name}: refused: {e}");
                }
            }
        }
    }
    eprintln!(
        "partial views: {ok} right ({partial_ok} of them with circles cut off), {refused} refused, 0 wrong, {:.1} s",
        started.elapsed().as_secs_f64()
    );
    assert!(partial_ok >= 5, "too few partial views identified");
}

// ---------------------------------------------------------------------------------------------------------------
// 4. Failures are errors

#[test]
fn failures_are_errors_not_panics() {
    let camera = CameraModel::canonical();
    let targets = [
        grid(6, 6, 0.03, 0.015, GridLayout::Square),
        grid(8, 10, 0.025, 0.012, GridLayout::Hexagonal),
        Target::grid4x4(),
        sparse5(),
    ];
    let options = PhotoOptions::default();
    // A frame of the wrong size.
    let small = Frame::new(640, 480, 8);
    assert_eq!(
        detect_target(&camera, &targets[0], &small, &options),
        Err(PhotoError::ImageSize {
            image_width: 640,
            image_height: 480,
            camera_width: 1024,
            camera_height: 1024,
        })
    );
    // Blank frames (black, grey, full scale) and pure noise (on a small camera: noise makes many components), 8 and
    // 16 bits, each polarity.
    let small_camera = CameraModel::new(
        "small",
        256,
        192,
        roitrack_core::camera::PinholeIntrinsics {
            fx_px: 300.0,
            fy_px: 300.0,
            skew_px: 0.0,
            cx_px: 128.0,
            cy_px: 96.0,
        },
        roitrack_core::camera::PlumbBob::default(),
    )
    .unwrap();
    let mut frames = Vec::new();
    for bit_depth in [8u8, 16] {
        let full = ((1u32 << bit_depth) - 1) as u16;
        for level in [0, full / 2, full] {
            let mut f = Frame::new(1024, 1024, bit_depth);
            f.pixels.fill(level);
            frames.push((format!("blank {level} of {full}"), &camera, f));
        }
        let mut noise = Frame::new(256, 192, bit_depth);
        let mut x = 0x9e37_79b9_7f4a_7c15_u64;
        for p in &mut noise.pixels {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            *p = (x % (u64::from(full) + 1)) as u16;
        }
        frames.push((format!("noise, {bit_depth} bit"), &small_camera, noise));
    }
    for (name, camera, frame) in &frames {
        for (k, target) in targets.iter().enumerate() {
            let polarities: &[PolarityChoice] = if k == 0 {
                &[
                    PolarityChoice::Auto,
                    PolarityChoice::Bright,
                    PolarityChoice::Dark,
                ]
            } else {
                &[PolarityChoice::Auto]
            };
            for &polarity in polarities {
                let options = PhotoOptions {
                    polarity,
                    ..PhotoOptions::default()
                };
                let r = detect_target(camera, target, frame, &options);
                assert!(
                    r.is_err(),
                    "{name}, {} points, {polarity:?}: found",
                    target.len()
                );
            }
        }
    }
    // Only clutter: the board out of view, a busy textured scene.
    for (k, target) in targets.iter().enumerate() {
        let mut scene =
            PhotoScene::facing(camera.clone(), target.clone(), 0.6, tilt(20.0, 0.0, 0.0))
                .harsh()
                .with_seed(60 + k as u64);
        scene.cam_t_obj_m.x += 3.0;
        scene.clutter = Clutter::busy(250);
        let photo = render_photo(&scene).unwrap();
        assert!(photo.truth.iter().all(|t| !t.fully_visible));
        match detect_target(&camera, target, &photo.frame, &options) {
            Err(e) => eprintln!("clutter only, {} points: {e}", target.len()),
            Ok(found) => panic!(
                "clutter only, {} points: found {} points (rms {:.2} px)",
                target.len(),
                found.points.len(),
                found.reprojection_rms_px
            ),
        }
    }
    // Another target in the photograph.
    for (shown, target) in targets.iter().enumerate() {
        let scene = PhotoScene::facing(camera.clone(), target.clone(), 0.6, tilt(25.0, 30.0, 15.0))
            .harsh()
            .with_seed(70);
        let photo = render_photo(&scene).unwrap();
        for (sought, other) in targets.iter().enumerate().filter(|&(k, _)| k != shown) {
            match detect_target(&camera, other, &photo.frame, &options) {
                Err(e) => eprintln!("target {shown} shown, {sought} sought: {e}"),
                Ok(found) => panic!(
                    "target {shown} shown, {sought} sought: found {} points (rms {:.2} px)",
                    found.points.len(),
                    found.reprojection_rms_px
                ),
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// 5. A shadow edge across circles

/// A shadow's edge across a circle leaves its centre in place: the centre comes from the circle's outline, not from
/// grey-level moments (which the light weights: before commit 132ec57 a sharp edge moved the centre of a 28 px circle
/// by 1.9 px towards the lit side, and a 40 px penumbra moved bright 30-40 px circles by 2-3 px, pushing the residual
/// over the acceptance limit).
#[test]
fn a_shadow_edge_across_a_circle_leaves_its_centre_in_place() {
    // A sharp edge (1 px penumbra, light 0.4) through the centre of circle 14 (row 2, column 2) of a 6 x 6 grid
    // facing the camera: the whole column 2 is half in shadow.
    let target = grid(6, 6, 0.03, 0.015, GridLayout::Square);
    let mut scene =
        PhotoScene::facing(CameraModel::canonical(), target, 0.8, Rotation3::identity());
    let centre = render_photo(&scene).unwrap().truth[14].centre_px.unwrap();
    scene.illumination.shadow = Some(Shadow::half_plane(centre, Vector2::new(1.0, 0.0), 0.4, 1.0));
    let (c, _, _) = run(
        "square 6x6, sharp shadow edge across a column",
        &scene,
        PolarityChoice::Auto,
        1.0,
    );
    assert!(c.max_px < 0.25, "{c:?}");
    // Bright circles 27-42 px across under a steep penumbra (40 px, light 0.4), wide lens, 50 degrees.
    let mut scene = shaded(
        PhotoScene::facing(
            CameraModel::wide_angle_example(),
            sparse5(),
            0.6,
            tilt(50.0, 80.0, 20.0),
        ),
        0.4,
        40.0,
    )
    .with_shade(CircleShade::BrightOnDark)
    .with_bit_depth(16)
    .with_seed(37);
    scene.clutter = Clutter::busy(60);
    scene.noise_sigma = 0.01;
    // Within a pixel (0.73 px at most at commit 132ec57, the circle of 42 px in the penumbra's middle).
    run(
        "sparse 5, 40 px penumbra across large circles",
        &scene,
        PolarityChoice::Auto,
        1.0,
    );
}

// ---------------------------------------------------------------------------------------------------------------
// Weaknesses found by these tests, fixed

/// Two stray blobs on the grid's lattice just beyond the target (printed marks in the board's margin lined up with
/// a row, say) and a fully visible grid4x4 is not found at all: "no match hypothesis fits ... 0 of 16 points
/// matched". The lattice grown through the blobs takes in the strays (18 nodes), and `placements(.., 0.9)` lays a
/// grown lattice on the target only if at most floor(10 %) of its nodes (here 1) fall off it; as every blob is then
/// covered by that lattice, no other seed grows the target's own. The same with 4 strays beside a 6 x 6 grid. Seen in
/// a rendered photograph: `PhotoScene::facing(camera, Target::grid4x4(), 0.45, tilt(35.0, 60.0, 20.0)).harsh()
/// .with_seed(1)` (camera 1024 x 768, f 1200 px, centre (515, 380), plumb_bob [-0.15, 0.08, 5e-4, -3e-4, 0]): all 16
/// circles detected within 0.07 px, two blobs of a board mark near row -1 (576.2, 276.6) and (614.0, 292.8).
/// Fixed: when no placement with nearly every grown blob on the target verifies, placements leaving up to half of
/// them off it are tried.
#[test]
fn stray_blobs_on_the_lattice_beyond_the_target_do_not_hide_it() {
    use roitrack_detect::matching::DetectedBlob;
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    let state =
        roitrack_core::MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.5));
    // A blob of diameter d (m) at column c, row r of grid4x4's lattice (20 mm pitch, centred on the origin).
    let blob = |c: f64, r: f64, d: f64| {
        let p = Vector3::new((c - 1.5) * 0.02, (r - 1.5) * 0.02, 0.0);
        let px = camera
            .raw_pixel_from_cam(&state.point_in_cam_at(&p, 0.0))
            .unwrap();
        let d_px = 1500.0 * d / 0.5;
        DetectedBlob {
            u_px: px.x,
            v_px: px.y,
            area_px: std::f64::consts::FRAC_PI_4 * d_px * d_px,
        }
    };
    let mut blobs: Vec<DetectedBlob> = (0..16u32)
        .map(|id| {
            let d = if id == 0 { 0.009 } else { 0.006 };
            blob(f64::from(id % 4), f64::from(id / 4), d)
        })
        .collect();
    assert!(roitrack_detect::identify(&camera, &target, &blobs).is_ok());
    // Two strays in row -1, above columns 2 and 3.
    blobs.push(blob(2.0, -1.0, 0.006));
    blobs.push(blob(3.0, -1.0, 0.006));
    let found = roitrack_detect::identify(&camera, &target, &blobs)
        .unwrap_or_else(|e| panic!("with two strays: {e}"));
    assert_eq!(found.pairs.len(), 16);
    assert!(!found.ambiguous);
}

/// Circles plainly visible in a dark shadow are lost: 18 of the 80 circles (19 px across, contrast 23 % of full
/// scale against 2 % read noise, 1.6 px blur) are not detected and the target is not found. The default 8 threshold
/// levels spread over the whole image's range leave one or two across a shadowed circle's contrast, and with noise on
/// its outline those components fail the runs-per-row shape filter (1.25), leaving fewer than `min_levels` (2): with
/// `levels: 24` or `max_runs_per_row: 2.0` all 80 are found (16 levels: 5 missed; `min_levels: 1`: 3 missed).
/// Fixed: the filter allows 2 runs per row (rings, crosses and merged pairs still fail the ellipse fill).
#[test]
fn circles_in_a_dark_shadow_are_found() {
    let target = grid(8, 10, 0.025, 0.012, GridLayout::Square);
    let mut scene = PhotoScene::facing(camera_xga(), target, 0.7, tilt(30.0, 10.0, 5.0));
    scene.illumination.shadow = Some(Shadow::half_plane(
        Vector2::new(512.0, 384.0),
        Vector2::new(0.8, 0.6),
        0.3,
        12.0,
    ));
    scene.blur_sigma_px = 1.6;
    scene.noise_sigma = 0.02;
    scene.bit_depth = 12;
    scene.seed = 14;
    let photo = render_photo(&scene).unwrap();
    let blobs = roitrack_image::detect_photo_blobs(
        &photo.frame.pixels,
        photo.frame.width,
        photo.frame.height,
        photo.frame.bit_depth,
        Polarity::Dark,
        &roitrack_image::PhotoBlobOptions::default(),
        &mut roitrack_image::PhotoScratch::default(),
    );
    let missed: Vec<u32> = photo
        .truth
        .iter()
        .filter(|t| {
            !blobs
                .iter()
                .any(|b| (Vector2::new(b.u_px, b.v_px) - t.centre_px.unwrap()).norm() < 1.0)
        })
        .map(|t| t.id)
        .collect();
    assert!(missed.is_empty(), "circles not detected: {missed:?}");
    run_whole("square 8x10 in a dark shadow", &scene, PolarityChoice::Auto);
}
