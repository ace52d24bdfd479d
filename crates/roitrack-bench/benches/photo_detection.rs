//! Criterion benchmark of finding the target in a photograph (`roitrack detect`'s work): a synthetic 640 x 480
//! photograph (roitrack-sim's `render_photo`) of an 8 x 10 grid of dark circles, 25 mm apart, tilted 30° at 0.45 m,
//! under harsh light (gradient, vignetting, a shadow, glare, noise, JPEG-like quantisation) with clutter around:
//! about 100 candidate blobs. `detect_photo_dark` detects and identifies with the polarity given,
//! `detect_photo_auto` tries both; `photo_blobs_dark` is the blob detection alone.
//!
//! `cargo bench -p roitrack-bench --bench photo_detection` (about 10 s).

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Rotation3, Vector3};
use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, Target};
use roitrack_image::{PhotoScratch, Polarity, detect_photo_blobs};
use roitrack_pipeline::photo::{PhotoOptions, PolarityChoice, detect_target};
use roitrack_sim::photo::{PhotoScene, render_photo};

fn photo_detection(c: &mut Criterion) {
    let intrinsics = PinholeIntrinsics {
        fx_px: 620.0,
        fy_px: 620.0,
        skew_px: 0.0,
        cx_px: 319.5,
        cy_px: 239.5,
    };
    let distortion = PlumbBob::from_coefficients([-0.12, 0.05, 0.0, 0.0, 0.0]);
    let camera = CameraModel::new("bench 640x480", 640, 480, intrinsics, distortion).unwrap();
    let grid = CircleGrid {
        rows: 8,
        cols: 10,
        spacing_m: 0.025,
        diameter_m: 0.015,
        layout: GridLayout::Square,
    };
    let target = Target::circle_grid(&grid).unwrap();
    let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians());
    let scene = PhotoScene::facing(camera.clone(), target.clone(), 0.45, tilt)
        .harsh()
        .with_seed(7);
    let frame = render_photo(&scene).unwrap().frame;
    let dark = PhotoOptions {
        polarity: PolarityChoice::Dark,
        ..PhotoOptions::default()
    };
    let found = detect_target(&camera, &target, &frame, &dark).unwrap();
    assert_eq!(found.points.len(), 80);
    let mut scratch = PhotoScratch::default();
    c.bench_function("photo_blobs_dark", |b| {
        b.iter(|| {
            detect_photo_blobs(
                &frame.pixels,
                frame.width,
                frame.height,
                frame.bit_depth,
                Polarity::Dark,
                &dark.blobs,
                &mut scratch,
            )
        })
    });
    c.bench_function("detect_photo_dark", |b| {
        b.iter(|| detect_target(&camera, &target, &frame, &dark))
    });
    c.bench_function("detect_photo_auto", |b| {
        b.iter(|| detect_target(&camera, &target, &frame, &PhotoOptions::default()))
    });
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .sample_size(30)
}

criterion_group! {
    name = benches;
    config = config();
    targets = photo_detection
}
criterion_main!(benches);
