//! Criterion benchmark of finding the target in a photograph (`roitrack detect`'s work), on synthetic photographs
//! (roitrack-sim's `render_photo`), each with the polarity given (`*_dark`) and with `--polarity auto` (`*_auto`):
//!
//! - `photo`: 640 x 480, an 8 x 10 grid of dark circles, 25 mm apart, tilted 30° at 0.45 m, under harsh light
//!   (gradient, vignetting, a shadow, glare, noise, JPEG-like quantisation) with clutter around: about 100 candidate
//!   blobs; `photo_blobs_dark` is its blob detection alone;
//! - `hex336_640` and `hex336_800`: a 24 x 28 hexagonal grid of 336 circles (12 mm apart, 10 mm across, as the
//!   printed boards of `roitrack target grid --hexagonal`) under harsh light, 640 x 480 and 800 x 600;
//! - `random30`: 30 dots placed at random on a plate (no lattice), harsh light and 120 clutter items;
//!   `random30_hidden`: the same photograph, the target with a 31st dot that the photograph does not show (a dot
//!   hidden: no labelling explains every point);
//! - `outdoor`: the 8 x 10 grid of dark circles among bright specular glints (foliage, water, chrome) where the
//!   image's local contrast points to bright blobs: `auto` guesses the wrong polarity first.
//!
//! Compare `*_auto` with `*_dark` as ratios within one run: the machine is shared and its speed varies. After
//! criterion's figures, each case is run again in interleaved pairs (dark, auto; then auto, dark; ...) and the medians
//! of the process's CPU time (every thread counted) and of the wall clock are printed with their ratios: on a loaded
//! machine the CPU time is the steadier of the two.
//!
//! `cargo bench -p roitrack-bench --bench photo_detection` (about a minute); `PHOTO_BENCH_INTERLEAVED_ONLY=1` for the
//! interleaved pairs alone, `PHOTO_BENCH_PAIRS=N` pairs a case (60; 0 for none, as when profiling one benchmark),
//! `PHOTO_BENCH_DUMP=FILE` to append every detection's figures to `FILE` (to compare two builds),
//! `PHOTO_BENCH_CASES=random30,outdoor` for those cases alone (as when counting one case's instructions under
//! `valgrind --tool=callgrind`).

use std::time::Duration;

use criterion::{Criterion, criterion_group};
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, Target, TargetPoint};
use roitrack_detect::photo::{PhotoOptions, PolarityChoice, detect_target};
use roitrack_image::{Frame, PhotoScratch, Polarity, detect_photo_blobs};
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

/// Adds to `points` a dot of 8 mm at random on a 16 x 12 cm plate, none nearer another than 18 mm.
fn add_random_dot(rng: &mut rand_chacha::ChaCha8Rng, points: &mut Vec<TargetPoint>) {
    loop {
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
            return;
        }
    }
}

/// 30 dots of 8 mm at random on a 16 x 12 cm plate, none nearer another than 18 mm (a random-dot marker).
fn random_dots() -> Target {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(30);
    let mut points: Vec<TargetPoint> = Vec::new();
    while points.len() < 30 {
        add_random_dot(&mut rng, &mut points);
    }
    Target::new(points).unwrap()
}

/// `dots` and one more dot of theirs, at random on their plate as far from the others as they are from each other:
/// printed on the target, hidden in the photograph.
fn with_a_dot_not_seen(dots: &Target) -> Target {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(31);
    let mut points = dots.points().to_vec();
    add_random_dot(&mut rng, &mut points);
    Target::new(points).unwrap()
}

/// One benched photograph: the frame, its camera and target, and the fewest points `detect_target` must identify.
struct Case {
    name: &'static str,
    camera: CameraModel,
    target: Target,
    frame: Frame,
    points: usize,
}

/// The benched photographs (see the file's documentation).
fn cases() -> Vec<Case> {
    let camera640 = camera(640, 480);
    let grid80 = grid(8, 10, 0.025, 0.015, GridLayout::Square);
    let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians());
    let scene = PhotoScene::facing(camera640.clone(), grid80.clone(), 0.45, tilt)
        .harsh()
        .with_seed(7);
    let mut cases = vec![Case {
        name: "photo",
        camera: camera640.clone(),
        target: grid80.clone(),
        frame: render_photo(&scene).unwrap().frame,
        points: 80,
    }];

    let hex = grid(24, 28, 0.012, 0.01, GridLayout::Hexagonal);
    let hex_tilt = Rotation3::from_euler_angles(0.25, -0.3, 0.1);
    for (name, width, height) in [("hex336_640", 640, 480), ("hex336_800", 800, 600)] {
        let camera = camera(width, height);
        let scene = PhotoScene::facing(camera.clone(), hex.clone(), 0.42, hex_tilt)
            .harsh()
            .with_seed(11);
        let frame = render_photo(&scene).unwrap().frame;
        cases.push(Case {
            name,
            camera,
            target: hex.clone(),
            frame,
            points: 336,
        });
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
    let random30_frame = render_photo(&scene).unwrap().frame;
    // The same photograph identified with a 31st dot in the target that is not on the plate: to the search, a marker
    // with one dot hidden, which no labelling of every point explains (`random30_hidden`, after the others).
    let hidden = with_a_dot_not_seen(&dots);
    cases.push(Case {
        name: "random30",
        camera: camera640.clone(),
        target: dots,
        frame: random30_frame.clone(),
        points: 30,
    });

    let scene = PhotoScene::facing(camera640.clone(), grid80.clone(), 0.5, tilt)
        .harsh()
        .with_seed(5);
    let mut rendered = render_photo(&scene).unwrap();
    add_glints(&mut rendered, 400, 5);
    cases.push(Case {
        name: "outdoor",
        camera: camera640.clone(),
        target: grid80,
        frame: rendered.frame,
        points: 80,
    });
    cases.push(Case {
        name: "random30_hidden",
        camera: camera640,
        target: hidden,
        frame: random30_frame,
        points: 30,
    });
    // The cases asked for, if any (all of them are rendered: each scene's seed makes it, not the order).
    if let Ok(names) = std::env::var("PHOTO_BENCH_CASES") {
        cases.retain(|case| names.split(',').any(|name| name == case.name));
    }
    cases
}

fn dark() -> PhotoOptions {
    PhotoOptions {
        polarity: PolarityChoice::Dark,
        ..PhotoOptions::default()
    }
}

/// Checks what the case's detections find (auto finds what dark finds) and prints it.
fn check(case: &Case) {
    let Case {
        name,
        camera,
        target,
        frame,
        points,
    } = case;
    let found = detect_target(camera, target, frame, &dark()).unwrap();
    assert!(
        found.points.len() >= *points,
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
    // Every figure of both detections, to compare two builds' results exactly.
    if let Some(path) = std::env::var_os("PHOTO_BENCH_DUMP") {
        use std::io::Write;
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .unwrap();
        for (kind, d) in [("dark", &found), ("auto", &auto)] {
            writeln!(
                file,
                "{name} {kind} {:?} {:?} {:?} {:?} {:?} {:?}",
                d.polarity, d.points, d.state.cam_t_obj_m, d.state.cam_r_obj, d.blobs, d.hypotheses
            )
            .unwrap();
        }
    }
}

/// `detect_target` timed with the polarity given and with `auto`.
fn bench_case(c: &mut Criterion, case: &Case) {
    let Case {
        name,
        camera,
        target,
        frame,
        ..
    } = case;
    let dark = dark();
    c.bench_function(&format!("{name}_dark"), |b| {
        b.iter(|| detect_target(camera, target, frame, &dark))
    });
    c.bench_function(&format!("{name}_auto"), |b| {
        b.iter(|| detect_target(camera, target, frame, &PhotoOptions::default()))
    });
}

fn photo_detection(c: &mut Criterion) {
    let cases = cases();
    let photo = &cases[0];
    let frame = &photo.frame;
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
    for case in &cases {
        check(case);
        bench_case(c, case);
    }
}

/// The CPU time (s) this process has used, every thread counted (the wall clock where there is no such clock).
fn process_cpu_s() -> f64 {
    #[cfg(target_os = "linux")]
    {
        #[repr(C)]
        struct Timespec {
            tv_sec: i64,
            tv_nsec: i64,
        }
        unsafe extern "C" {
            fn clock_gettime(clock: i32, time: *mut Timespec) -> i32;
        }
        const CLOCK_PROCESS_CPUTIME_ID: i32 = 2;
        let mut time = Timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `time` is a valid, writable timespec of the C layout on 64-bit Linux.
        if unsafe { clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &mut time) } == 0 {
            return time.tv_sec as f64 + 1e-9 * time.tv_nsec as f64;
        }
    }
    static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// `auto` against the polarity given, each case measured in interleaved pairs (the order alternating) by the
/// process's CPU time and by the wall clock: medians and their ratio. On a shared machine the CPU time moves far
/// less with the load than the wall clock does. `PHOTO_BENCH_PAIRS` pairs a case (default 60; 0: none).
fn interleaved_ratios(cases: &[Case]) {
    let pairs: usize = std::env::var("PHOTO_BENCH_PAIRS")
        .ok()
        .and_then(|p| p.parse().ok())
        .unwrap_or(60);
    if pairs == 0 {
        return;
    }
    println!(
        "\ninterleaved, {pairs} pairs a case, medians (ms): | case | dark CPU | auto CPU | auto / dark CPU | dark wall | auto wall | auto / dark wall |"
    );
    let (dark, auto) = (dark(), PhotoOptions::default());
    for case in cases {
        let run = |options: &PhotoOptions| {
            let (cpu, wall) = (process_cpu_s(), std::time::Instant::now());
            let found = detect_target(&case.camera, &case.target, &case.frame, options);
            let times = (
                1e3 * (process_cpu_s() - cpu),
                1e3 * wall.elapsed().as_secs_f64(),
            );
            assert!(found.is_ok(), "{}", case.name);
            times
        };
        for _ in 0..3 {
            run(&dark);
            run(&auto);
        }
        let (mut dark_cpu, mut auto_cpu, mut dark_wall, mut auto_wall) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for k in 0..pairs {
            let (d, a) = if k % 2 == 0 {
                let d = run(&dark);
                (d, run(&auto))
            } else {
                let a = run(&auto);
                (run(&dark), a)
            };
            dark_cpu.push(d.0);
            dark_wall.push(d.1);
            auto_cpu.push(a.0);
            auto_wall.push(a.1);
        }
        let (dc, ac, dw, aw) = (
            median(&mut dark_cpu),
            median(&mut auto_cpu),
            median(&mut dark_wall),
            median(&mut auto_wall),
        );
        println!(
            "| {} | {dc:.2} | {ac:.2} | {:.2} | {dw:.2} | {aw:.2} | {:.2} |",
            case.name,
            ac / dc,
            aw / dw
        );
    }
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

/// Criterion's benchmarks, then the interleaved ratios (`PHOTO_BENCH_INTERLEAVED_ONLY=1`: those alone).
/// `PHOTO_BENCH_COUNT=dark` (or `auto`) instead runs each case's detection with that polarity
/// `PHOTO_BENCH_RUNS` times (10) and nothing else, for an instruction count that the machine's load does not move:
/// `PHOTO_BENCH_COUNT=dark PHOTO_BENCH_CASES=random30 valgrind --tool=callgrind
/// target/release/deps/photo_detection-HASH --bench`, less the same with `PHOTO_BENCH_RUNS=0` (the rendering),
/// divided by the runs. Every thread is counted (the detection's own threads too, which a `--toggle-collect` on
/// `detect_target` would leave out): the CPU's work.
fn main() {
    if let Ok(polarity) = std::env::var("PHOTO_BENCH_COUNT") {
        let options = match polarity.as_str() {
            "dark" => dark(),
            "auto" => PhotoOptions::default(),
            other => panic!("PHOTO_BENCH_COUNT={other}: dark or auto"),
        };
        let runs: usize = std::env::var("PHOTO_BENCH_RUNS")
            .ok()
            .and_then(|r| r.parse().ok())
            .unwrap_or(10);
        for case in cases() {
            for _ in 0..runs {
                assert!(detect_target(&case.camera, &case.target, &case.frame, &options).is_ok());
            }
        }
        return;
    }
    if std::env::var_os("PHOTO_BENCH_INTERLEAVED_ONLY").is_none() {
        benches();
    }
    let cases = cases();
    if std::env::var_os("PHOTO_BENCH_INTERLEAVED_ONLY").is_some() {
        cases.iter().for_each(check);
    }
    interleaved_ratios(&cases);
    Criterion::default().configure_from_args().final_summary();
}
