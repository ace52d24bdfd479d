//! Speed and accuracy figures of the centroid (roitrack-image) and of the renderer on the canonical scene, kept with
//! the renderer, which makes its ROIs: `cargo run --release -p roitrack-sim --example image_bench`.
//!
//! Timings are per call, over many repetitions: the median and the minimum of the repetition means (the minimum is
//! the figure least disturbed by other processes on the machine).
//!
//! `image_bench measure_blob` times only [`measure_blob`] on the static 24 x 24 ROI, longer (a micro-benchmark);
//! `image_bench measure_blob_calls N` makes N calls and times nothing (for `valgrind --tool=callgrind`);
//! `image_bench reflections` prints what the symmetry check does against merged reflections, for blobs of 3 to 9 mm
//! (about 7 to 22 px) and two lenses ([`reflection_accuracy`]).

use std::hint::black_box;
use std::time::Instant;

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::{CentroidOptions, Roi, Threshold, detect_blobs, measure_blob};
use roitrack_sim::{
    ReflectionFault, RenderScratch, RoiRenderer, SensorModel, centroid_accuracy,
    reflection_accuracy,
};

/// (median, minimum) over `runs` repetitions of the mean time (µs) of `inner` calls of `f`.
fn time_us(runs: usize, inner: usize, mut f: impl FnMut()) -> (f64, f64) {
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
    (t[t.len() / 2], t[0])
}

/// The static bench ROI (24 x 24, blob 5) as rendered with the default sensor and seed 1.
fn bench_roi(camera: &CameraModel, target: &Target, renderer: &RoiRenderer) -> (Vec<u16>, Roi) {
    let bench = MotionState::bench();
    let p = bench.point_in_cam_at(&target.points()[5].point_in_obj_m, 0.0);
    let c = camera.raw_pixel_from_cam(&p).unwrap();
    let roi = Roi::centred(c.x, c.y, 24, 1024, 1024).unwrap();
    let mut out = vec![0u16; roi.len()];
    renderer.render_roi(
        &|_t| bench,
        &roi,
        0.0,
        &mut ChaCha8Rng::seed_from_u64(1),
        &mut out,
    );
    (out, roi)
}

/// The three option sets timed.
fn centroid_options() -> [(&'static str, CentroidOptions); 3] {
    [
        (
            "weighted, auto threshold (default)",
            CentroidOptions::default(),
        ),
        ("binary, auto threshold (paper)", CentroidOptions::binary()),
        (
            "weighted, fixed threshold",
            CentroidOptions {
                threshold: Threshold::Fixed(45),
                ..Default::default()
            },
        ),
    ]
}

/// `measure_blob` alone: a longer timing (median over more repetitions), or `calls` untimed calls (callgrind).
fn measure_blob_only(calls: Option<usize>) {
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    let renderer =
        RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
    let (pixels, roi) = bench_roi(&camera, &target, &renderer);
    let opts = CentroidOptions::default();
    if let Some(calls) = calls {
        let mut found = 0usize;
        for _ in 0..calls {
            found += usize::from(measure_blob(black_box(&pixels), black_box(&roi), &opts).is_ok());
        }
        println!(
            "{calls} calls, {found} blobs: {:?}",
            measure_blob(&pixels, &roi, &opts)
        );
        return;
    }
    println!("{:?}", measure_blob(&pixels, &roi, &opts));
    for (oname, opts) in centroid_options() {
        let (med, min) = time_us(301, 20000, || {
            black_box(measure_blob(black_box(&pixels), black_box(&roi), &opts).ok());
        });
        println!("measure_blob 24x24 {oname}: median {med:.3} us, min {min:.3} us");
    }
}

/// The symmetry check against merged reflections: blob sizes, lenses, with and without the check.
fn reflections() {
    let fault = ReflectionFault::default();
    println!("spots: {fault:?}, in every ROI; 4000 ROIs each");
    println!(
        "{:<28} {:>5} {:>6} {:>8} {:>8} {:>8} {:>9} {:>9}",
        "case", "roi", "check", "clean rj", "rejected", "captured", "moved>0.1", "worst px"
    );
    let grid_with = |diameter_m: f64| {
        let points = Target::grid4x4()
            .points()
            .iter()
            .map(|p| roitrack_core::TargetPoint {
                diameter_m: Some(diameter_m),
                ..*p
            })
            .collect();
        Target::new(points).unwrap()
    };
    for (name, camera, target, roi) in [
        (
            "6 mm blobs (15 px)",
            CameraModel::canonical(),
            Target::grid4x4(),
            32,
        ),
        (
            "3 mm blobs (7 px)",
            CameraModel::canonical(),
            grid_with(0.003),
            24,
        ),
        (
            "9 mm blobs (22 px)",
            CameraModel::canonical(),
            grid_with(0.009),
            40,
        ),
        (
            "6 mm, wide-angle lens",
            CameraModel::wide_angle_example(),
            Target::grid4x4(),
            32,
        ),
    ] {
        let renderer = RoiRenderer::new(camera, target, SensorModel::default()).unwrap();
        for (check, opts) in [
            (
                "off",
                CentroidOptions {
                    symmetry: None,
                    ..Default::default()
                },
            ),
            ("on", CentroidOptions::default()),
        ] {
            let r = reflection_accuracy(&renderer, &opts, roi, 4000, 5, &fault);
            println!(
                "{name:<28} {roi:>5} {check:>6} {:>8} {:>8} {:>8} {:>9} {:>9.3}",
                r.clean_rejected_asymmetric,
                r.reflected_rejected,
                r.reflected_captured,
                r.reflected_moved,
                r.worst_accepted_shift_px
            );
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("measure_blob") => return measure_blob_only(None),
        Some("reflections") => return reflections(),
        Some("measure_blob_calls") => {
            let calls = args.get(1).and_then(|n| n.parse().ok()).unwrap_or(100_000);
            return measure_blob_only(Some(calls));
        }
        _ => {}
    }
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    let renderer =
        RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut scratch = RenderScratch::new();

    let bench = MotionState::bench();
    let moving = MotionState {
        velocity_mps: Vector3::new(1.0, 0.0, 0.0),
        angular_velocity_radps: Vector3::new(0.0, 2.0, 0.0),
        ..bench
    };
    let fast = MotionState {
        velocity_mps: Vector3::new(1.5, 0.5, 0.3),
        angular_velocity_radps: Vector3::new(2.0, -3.0, 1.0),
        ..bench
    };
    for (name, state) in [
        ("static", bench),
        ("1 m/s, 2 rad/s", moving),
        ("1.6 m/s, 3.7 rad/s", fast),
    ] {
        let state_at = |t: f64| state.predicted(t);
        let p = state.point_in_cam_at(&target.points()[5].point_in_obj_m, 0.0);
        let c = camera.raw_pixel_from_cam(&p).unwrap();
        let roi = Roi::centred(c.x, c.y, 24, 1024, 1024).unwrap();
        let mut out = vec![0u16; roi.len()];
        let (med, min) = time_us(31, 300, || {
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
        let (med_alloc, _) = time_us(11, 300, || {
            renderer.render_roi(&state_at, &roi, 0.0, &mut rng, &mut out);
            black_box(&out);
        });
        println!(
            "render_roi 24x24, one 6 mm blob, {name}: median {med:.1} us, min {min:.1} us (kept scratch); \
             median {med_alloc:.1} us (allocating)"
        );
        if name == "static" {
            for (oname, opts) in centroid_options() {
                let (med, min) = time_us(101, 5000, || {
                    black_box(measure_blob(black_box(&out), &roi, &opts).ok());
                });
                println!("  measure_blob 24x24 {oname}: median {med:.3} us, min {min:.3} us");
            }
        }
    }
    // A strongly distorting wide-angle lens: every pixel corner near the blob is undistorted by Newton's method.
    let wide = CameraModel::wide_angle_example();
    let distorted = RoiRenderer::new(wide.clone(), target.clone(), SensorModel::default()).unwrap();
    let state_at = |_t: f64| bench;
    let p = bench.point_in_cam_at(&target.points()[5].point_in_obj_m, 0.0);
    let c = wide.raw_pixel_from_cam(&p).unwrap();
    let roi = Roi::centred(c.x, c.y, 24, 1024, 1024).unwrap();
    let mut out = vec![0u16; roi.len()];
    let (med, min) = time_us(31, 300, || {
        distorted.render_roi_with_scratch(&state_at, &roi, 0.0, &mut rng, &mut scratch, &mut out);
        black_box(&out);
    });
    println!(
        "render_roi 24x24, static, distorted camera (k1 = -0.28): median {med:.1} us, min {min:.1} us"
    );

    let start = Instant::now();
    let mut frame = roitrack_image::Frame::default();
    renderer.render_frame(
        &state_at,
        0.0,
        &mut rng,
        &mut RenderScratch::new(),
        &mut frame,
    );
    let frame = frame.pixels;
    let render_ms = start.elapsed().as_secs_f64() * 1e3;
    let start = Instant::now();
    let blobs = detect_blobs(&frame, 1024, 1024, &CentroidOptions::default());
    println!(
        "render_frame 1024x1024: {render_ms:.1} ms; detect_blobs: {:.2} ms ({} blobs)",
        start.elapsed().as_secs_f64() * 1e3,
        blobs.len()
    );

    let quiet = RoiRenderer::new(camera.clone(), target.clone(), SensorModel::noiseless()).unwrap();
    for (rname, r) in [("default sensor", &renderer), ("noiseless", &quiet)] {
        for (oname, opts) in [
            ("weighted (default)", CentroidOptions::default()),
            ("binary (paper)", CentroidOptions::binary()),
        ] {
            let start = Instant::now();
            let a = centroid_accuracy(r, &opts, 24, 1000, 2024);
            println!(
                "centroid_accuracy {rname}, {oname}, 24 px ROIs, 1000: measured {} rejected {} bias ({:+.4}, {:+.4}) \
                 std ({:.4}, {:.4}) rms {:.4} px [{:.0} ms]",
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
    // Perspective: the disks' image ellipses are not centred on the projected centres.
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
