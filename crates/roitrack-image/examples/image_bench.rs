//! Speed and accuracy figures of roitrack-image: `cargo run --release -p roitrack-image --example image_bench`.

use std::hint::black_box;
use std::time::Instant;

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::{
    CentroidOptions, RenderScratch, Roi, RoiRenderer, SensorModel, Threshold, bench_state,
    centroid_accuracy, detect_blobs, measure_blob,
};

/// Median of `runs` timings (µs) of `f`, each averaged over `inner` calls.
fn median_us(runs: usize, inner: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..inner {
                f();
            }
            start.elapsed().as_secs_f64() * 1e6 / inner as f64
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() {
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    let renderer =
        RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut scratch = RenderScratch::new();

    let bench = bench_state();
    let moving = MotionState {
        velocity_mps: Vector3::new(1.0, 0.0, 0.0),
        angular_velocity_radps: Vector3::new(0.0, 2.0, 0.0),
        ..bench
    };
    for (name, state) in [("static", bench), ("1 m/s", moving)] {
        let state_at = |t: f64| state.predicted(t);
        let p = state.point_in_cam_at(&target.points()[5].point_in_obj_m, 0.0);
        let c = camera.raw_pixel_from_cam(&p).unwrap();
        let roi = Roi::centred(c.x, c.y, 24, 1024, 1024).unwrap();
        let mut out = vec![0u16; roi.len()];
        let us = median_us(21, 200, || {
            renderer.render_roi_with_scratch(
                &state_at,
                &roi,
                0.0,
                &mut rng,
                &mut scratch,
                &mut out,
            );
            black_box(&out);
        });
        let us_alloc = median_us(21, 200, || {
            renderer.render_roi(&state_at, &roi, 0.0, &mut rng, &mut out);
            black_box(&out);
        });
        println!(
            "render_roi 24x24, one 6 mm blob, {name}: {us:.1} us (with scratch), {us_alloc:.1} us (allocating)"
        );
        for (oname, opts) in [
            ("weighted auto", CentroidOptions::default()),
            ("binary auto", CentroidOptions::binary()),
            (
                "weighted fixed(120)",
                CentroidOptions {
                    threshold: Threshold::Fixed(120),
                    ..Default::default()
                },
            ),
        ] {
            let us = median_us(101, 2000, || {
                black_box(measure_blob(black_box(&out), &roi, &opts).ok());
            });
            println!("  measure_blob {oname}: {:.3} us", us);
        }
    }
    let state_at = |_t: f64| bench;
    let start = Instant::now();
    let frame = renderer.render_full_frame(&state_at, 0.0, &mut rng);
    let render_ms = start.elapsed().as_secs_f64() * 1e3;
    let start = Instant::now();
    let blobs = detect_blobs(&frame, 1024, 1024, &CentroidOptions::default());
    println!(
        "render_full_frame 1024x1024: {render_ms:.1} ms; detect_blobs: {:.2} ms ({} blobs)",
        start.elapsed().as_secs_f64() * 1e3,
        blobs.len()
    );

    for (oname, opts) in [
        ("weighted", CentroidOptions::default()),
        ("binary", CentroidOptions::binary()),
    ] {
        for size in [24, 32] {
            let start = Instant::now();
            let a = centroid_accuracy(&renderer, &opts, size, 4000, 7);
            println!(
                "centroid_accuracy {oname} roi {size}: n {} rejected {} bias ({:+.4}, {:+.4}) std ({:.4}, {:.4}) rms {:.4} px [{:.0} ms]",
                a.count,
                a.rejected,
                a.bias_u_px,
                a.bias_v_px,
                a.std_u_px,
                a.std_v_px,
                a.rms_px,
                start.elapsed().as_secs_f64() * 1e3
            );
        }
    }
    let quiet = RoiRenderer::new(camera.clone(), target.clone(), SensorModel::noiseless()).unwrap();
    for (oname, opts) in [
        ("weighted", CentroidOptions::default()),
        ("binary", CentroidOptions::binary()),
    ] {
        let a = centroid_accuracy(&quiet, &opts, 32, 4000, 7);
        println!(
            "noiseless {oname} roi 32: n {} rej {} bias ({:+.4}, {:+.4}) std ({:.4}, {:.4}) rms {:.4}",
            a.count, a.rejected, a.bias_u_px, a.bias_v_px, a.std_u_px, a.std_v_px, a.rms_px
        );
    }
    // Perspective: ellipse centre vs projected centre at the bench pose.
    for i in [0usize, 1, 5, 15] {
        let p = bench.point_in_cam_at(&target.points()[i].point_in_obj_m, 0.0);
        let c = camera.raw_pixel_from_cam(&p).unwrap();
        let e = quiet.disk_image_centre_px(&bench, i).unwrap();
        println!(
            "blob {i}: ellipse centre - projected centre = ({:+.4}, {:+.4}) px",
            e.x - c.x,
            e.y - c.y
        );
    }
}
