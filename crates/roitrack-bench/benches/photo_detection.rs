//! Criterion benchmark of finding the target in a photograph (`roitrack detect`'s work), on synthetic photographs
//! (roitrack-sim's `render_photo`), each with the polarity given (`*_dark`) and with `--polarity auto` (`*_auto`):
//!
//! - `photo`: 640 x 480, an 8 x 10 grid of dark circles, 25 mm apart, tilted 30° at 0.45 m, under harsh light
//!   (gradient, vignetting, a shadow, glare, noise, JPEG-like quantisation) with clutter around: about 100 candidate
//!   blobs; `photo_blobs_dark` is its blob detection alone;
//! - `hex336_640` and `hex336_800`: a 24 x 28 hexagonal grid of 336 circles (12 mm apart, 10 mm across, as the
//!   printed boards of `roitrack target grid --hexagonal`) under harsh light, 640 x 480 and 800 x 600;
//! - `random30`: 30 dots placed at random on a plate (no lattice), harsh light and 120 clutter items;
//! - `outdoor`: the 8 x 10 grid of dark circles among bright specular glints (foliage, water, chrome) where the
//!   image's local contrast points to bright blobs: `auto` guesses the wrong polarity first.
//!
//! Compare `*_auto` with `*_dark` as ratios within one run: the machine is shared and its speed varies.
//!
//! `cargo bench -p roitrack-bench --bench photo_detection` (about 40 s).

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, Target, TargetPoint};
use roitrack_image::{Frame, PhotoScratch, Polarity, detect_photo_blobs};
use roitrack_pipeline::photo::{PhotoOptions, PolarityChoice, detect_target};
use roitrack_sim::glints::add_glints;
use roitrack_sim::photo::{Clutter, PhotoScene, render_photo};

/// A camera of `width_px` x `height_px` with the field of view of the 640 x 480 development photographs' (a
/// compact camera's, 620 px focal length at 640 px) and their barrel distortion.
fn camera(width_px: u32, height_px: u32) -> CameraModel {
    let scale = f64::from(width_px) / 640.0;
    let intrinsics = PinholeIntrinsics {
        fx_px: 620.0 * scale,
        fy_px: 620.0 * scale,
        skew_px: 0.0,
        cx_px: 0.5 * f64::from(width_px) - 0.5,
        cy_px: 0.5 * f64::from(height_px) - 0.5,
    };
    let distortion = PlumbBob::from_coefficients([-0.12, 0.05, 0.0, 0.0, 0.0]);
    CameraModel::new("bench", width_px, height_px, intrinsics, distortion).unwrap()
}

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

/// 30 dots of 8 mm at random on a 16 x 12 cm plate, none nearer another than 18 mm (a random-dot marker).
fn random_dots() -> Target {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(30);
    let mut points: Vec<TargetPoint> = Vec::new();
    while points.len() < 30 {
        let p = Vector3::new(
            rng.random_range(0.0..0.16),
            rng.random_range(0.0..0.12),
            0.0,
        );
        if points
            .iter()
            .all(|q| (q.point_in_obj_m - p).norm() >= 0.018)
        {
            points.push(TargetPoint {
                id: points.len() as u32,
                point_in_obj_m: p,
                diameter_m: Some(0.008),
            });
        }
    }
    Target::new(points).unwrap()
}

/// One case: the frame, its camera and target, with `detect_target` timed with the polarity given and with `auto`.
fn bench_case(
    c: &mut Criterion,
    name: &str,
    camera: &CameraModel,
    target: &Target,
    frame: &Frame,
    points: usize,
) {
    let dark = PhotoOptions {
        polarity: PolarityChoice::Dark,
        ..PhotoOptions::default()
    };
    let found = detect_target(camera, target, frame, &dark).unwrap();
    assert!(
        found.points.len() >= points,
        "{name}: {}",
        found.points.len()
    );
    let auto = detect_target(camera, target, frame, &PhotoOptions::default()).unwrap();
    assert_eq!(
        auto.points, found.points,
        "{name}: auto finds what dark finds"
    );
    println!(
        "{name}: {} points, {} blobs, auto verified {} hypotheses in {:?} (dark {})",
        found.points.len(),
        found.blobs.len(),
        auto.hypotheses,
        auto.polarities_tried,
        found.hypotheses
    );
    c.bench_function(&format!("{name}_dark"), |b| {
        b.iter(|| detect_target(camera, target, frame, &dark))
    });
    c.bench_function(&format!("{name}_auto"), |b| {
        b.iter(|| detect_target(camera, target, frame, &PhotoOptions::default()))
    });
}

fn photo_detection(c: &mut Criterion) {
    let camera640 = camera(640, 480);
    let grid80 = grid(8, 10, 0.025, 0.015, GridLayout::Square);
    let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians());
    let scene = PhotoScene::facing(camera640.clone(), grid80.clone(), 0.45, tilt)
        .harsh()
        .with_seed(7);
    let frame = render_photo(&scene).unwrap().frame;
    let mut scratch = PhotoScratch::default();
    c.bench_function("photo_blobs_dark", |b| {
        b.iter(|| {
            detect_photo_blobs(
                &frame.pixels,
                frame.width,
                frame.height,
                frame.bit_depth,
                Polarity::Dark,
                &PhotoOptions::default().blobs,
                &mut scratch,
            )
        })
    });
    bench_case(c, "photo", &camera640, &grid80, &frame, 80);

    let hex = grid(24, 28, 0.012, 0.01, GridLayout::Hexagonal);
    let hex_tilt = Rotation3::from_euler_angles(0.25, -0.3, 0.1);
    for (name, width, height) in [("hex336_640", 640, 480), ("hex336_800", 800, 600)] {
        let camera = camera(width, height);
        let scene = PhotoScene::facing(camera.clone(), hex.clone(), 0.42, hex_tilt)
            .harsh()
            .with_seed(11);
        let frame = render_photo(&scene).unwrap().frame;
        bench_case(c, name, &camera, &hex, &frame, 336);
    }

    let dots = random_dots();
    let mut scene = PhotoScene::facing(
        camera640.clone(),
        dots.clone(),
        0.5,
        Rotation3::from_euler_angles(-0.3, 0.35, 0.6),
    )
    .harsh()
    .with_seed(3);
    scene.clutter = Clutter {
        count: 120,
        ..scene.clutter
    };
    let frame = render_photo(&scene).unwrap().frame;
    bench_case(c, "random30", &camera640, &dots, &frame, 30);

    let scene = PhotoScene::facing(camera640.clone(), grid80.clone(), 0.5, tilt)
        .harsh()
        .with_seed(5);
    let mut rendered = render_photo(&scene).unwrap();
    add_glints(&mut rendered, 400, 5);
    let frame = rendered.frame;
    bench_case(c, "outdoor", &camera640, &grid80, &frame, 80);
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .sample_size(20)
}

criterion_group! {
    name = benches;
    config = config();
    targets = photo_detection
}
criterion_main!(benches);
