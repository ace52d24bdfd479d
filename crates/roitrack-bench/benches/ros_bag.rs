//! Criterion benchmark of the ROS 2 bag output (`track --mcap`) against tracking itself: writing the bag must cost at
//! most 10 % of the tracking time.
//!
//! - `ros_bag/track_orthoglide`: the default estimator over the orthoglide scenario's measurements (seed 1, 4 kHz,
//!   about 19,700 measurements, 1,963 estimates), estimates kept in memory.
//! - `ros_bag/track_orthoglide_with_bag`: the same, each measurement and each estimate also handed to a
//!   [`BackgroundBag`] as `track --mcap` does (pose, twist, odometry, tf and status per estimate, the measurements
//!   before it as one `/roitrack/measurements` message, camera info once; uncompressed chunks, the default, written
//!   by the bag's own thread), to a new file in a temporary folder, until the bag is complete; `..._with_bag_zstd`,
//!   the same with zstd chunks.
//! - `ros_bag/write_orthoglide_zstd` and `ros_bag/write_orthoglide_uncompressed`: the measurements and estimates
//!   written by a [`BagWriter`] on the calling thread, the whole work of the bag in one thread's time.
//!
//! The ratio of the tracking with the bag to the tracking alone is printed at the end, from passes of each timed
//! alternately (best of 7): the bag's cost to a tracking run is that ratio less 1 (target at most 0.10). It needs a
//! free core for the bag's thread; on a busy machine it rises. Then the tracking thread's own CPU time (Linux's
//! `/proc/thread-self/schedstat`) over 20 passes with and without the bag: what handing the estimates over costs it,
//! whatever the load.
//!
//! Then the ROI path (`track --rois`): the orthoglide scenario's ROI images (rendered in memory as `simulate --rois`
//! renders them, 40 x 40 px, 8 bits) centroided and tracked by `track_rois_with` alone, with the bag (measurements
//! and estimates) and with `--mcap-rois` (every ROI's image, camera info and annotation too), best of 5 each, timed
//! alternately, with the tracking thread's CPU time of each over 3 passes.
//! `cargo bench -p roitrack-bench --bench ros_bag` (about 40 s); `-- --quick` for a shorter run.

use std::time::{Duration, Instant};

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use roitrack_bench::cpu_time_of;
use roitrack_core::{CameraModel, Measurement, Target};
use roitrack_estimators::{Estimate, Tracker, TrackerConfig, track};
use roitrack_image::{CentroidOptions, RoiImage};
use roitrack_pipeline::offline::{RoiEvent, track_rois_with};
use roitrack_ros::{BackgroundBag, BagOptions, BagWriter};
use roitrack_sim::{
    Scenario, ScenarioKind, SensorModel, SimulationOptions, render_roi_images, simulate,
};

/// The writing's share of the tracking time allowed (10 %).
const TARGET_RATIO: f64 = 0.10;

struct Scene {
    camera: CameraModel,
    target: Target,
    measurements: Vec<Measurement>,
}

fn track_all(scene: &Scene) -> Vec<Estimate> {
    let mut tracker = Tracker::new(
        scene.camera.clone(),
        scene.target.clone(),
        TrackerConfig::default(),
    )
    .expect("a valid tracker");
    let mut estimates = Vec::with_capacity(scene.measurements.len() / 8);
    track(
        &mut tracker,
        scene.measurements.iter().map(|m| Ok::<_, ()>(*m)),
        |e: &Estimate| {
            estimates.push(*e);
            Ok::<_, ()>(())
        },
    )
    .expect("the scenario tracks");
    estimates
}

fn track_with_bag(scene: &Scene, path: &std::path::Path) -> u64 {
    track_with_bag_compressed(scene, path, None, true)
}

fn track_with_bag_compressed(
    scene: &Scene,
    path: &std::path::Path,
    compression: Option<mcap::Compression>,
    measurements: bool,
) -> u64 {
    let mut tracker = Tracker::new(
        scene.camera.clone(),
        scene.target.clone(),
        TrackerConfig::default(),
    )
    .expect("a valid tracker");
    let options = BagOptions {
        compression,
        ..BagOptions::default()
    };
    let bag = BagWriter::create(path, &options, Some(scene.camera.clone())).expect("the bag opens");
    // As `track --mcap`: each measurement handed to the bag as it is read, each estimate as it comes.
    let bag = std::cell::RefCell::new(BackgroundBag::spawn(bag, None));
    track(
        &mut tracker,
        scene.measurements.iter().map(|m| {
            if measurements {
                bag.borrow_mut()
                    .write_measurements(std::slice::from_ref(m))?;
            }
            Ok::<_, roitrack_formats::FormatError>(*m)
        }),
        |e: &Estimate| bag.borrow_mut().write_estimate(e),
    )
    .expect("the scenario tracks");
    bag.into_inner().finish().expect("the bag completes")
}

fn write_all(
    scene: &Scene,
    estimates: &[Estimate],
    path: &std::path::Path,
    compression: Option<mcap::Compression>,
) -> u64 {
    let options = BagOptions {
        compression,
        ..BagOptions::default()
    };
    let mut bag =
        BagWriter::create(path, &options, Some(scene.camera.clone())).expect("the bag opens");
    // Each estimate after the measurements up to its time, as one message (the background bag's batches).
    let mut next = 0;
    for e in estimates {
        let end = next
            + scene.measurements[next..]
                .iter()
                .take_while(|m| m.t_s <= e.t_ref_s)
                .count();
        bag.write_measurements(&scene.measurements[next..end])
            .expect("the measurements are written");
        next = end;
        bag.write_estimate(e).expect("the estimate is written");
    }
    bag.write_measurements(&scene.measurements[next..])
        .expect("the measurements are written");
    bag.finish().expect("the bag completes")
}

fn best_of(passes: usize, mut pass: impl FnMut()) -> Duration {
    (0..passes)
        .map(|_| {
            let start = Instant::now();
            pass();
            start.elapsed()
        })
        .min()
        .expect("at least one pass")
}

/// How much of the bag a ROI run writes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum RoiBag {
    None,
    /// Measurements and estimates (`track --rois --mcap`).
    Estimates,
    /// And every ROI (`--mcap-rois`).
    Rois,
}

/// `track --rois` over ROI images in memory: centroided and tracked, the bag as asked; the estimates' count.
fn track_rois_run(scene: &Scene, rois: &[RoiImage], bag: RoiBag, path: &std::path::Path) -> usize {
    let mut tracker = Tracker::new(
        scene.camera.clone(),
        scene.target.clone(),
        TrackerConfig::default(),
    )
    .expect("a valid tracker");
    let mut writer = (bag != RoiBag::None).then(|| {
        let bag = BagWriter::create(path, &BagOptions::default(), Some(scene.camera.clone()))
            .expect("the bag opens");
        BackgroundBag::spawn(bag, None)
    });
    let mut estimates = Vec::with_capacity(rois.len() / 8);
    track_rois_with(
        &mut tracker,
        &CentroidOptions::default(),
        &scene.camera.time,
        rois.iter().map(|r| Ok::<_, ()>(r.clone())),
        |event| {
            let Some(writer) = &mut writer else {
                if let RoiEvent::Estimate(e) = event {
                    estimates.push(*e);
                }
                return Ok(());
            };
            match event {
                RoiEvent::Roi { image, measured } => {
                    if let Ok(m) = measured {
                        writer.write_measurements(std::slice::from_ref(m))?;
                    }
                    if bag == RoiBag::Rois {
                        writer.write_roi(image, measured.ok())?;
                    }
                    Ok(())
                }
                RoiEvent::Estimate(e) => {
                    estimates.push(*e);
                    writer.write_estimate(e)
                }
            }
        },
    )
    .expect("the ROIs track");
    if let Some(writer) = writer {
        writer.finish().expect("the bag completes");
    }
    estimates.len()
}

/// The cost of the bag to `track --rois`, with and without the ROI images.
fn roi_costs(
    scene: &Scene,
    run: &roitrack_sim::SimulatedRun,
    scenario: &Scenario,
    path: &std::path::Path,
) {
    let options = SimulationOptions::default();
    let rois: Vec<RoiImage> =
        render_roi_images(scenario, &options, run, SensorModel::default(), None)
            .expect("the ROIs render")
            .collect::<Result<_, _>>()
            .expect("the ROIs render");
    let fresh = || {
        let _ = std::fs::remove_file(path);
    };
    let mut best = [Duration::MAX; 3];
    let mut sizes = [0u64; 3];
    let kinds = [RoiBag::None, RoiBag::Estimates, RoiBag::Rois];
    for _ in 0..5 {
        for (k, kind) in kinds.into_iter().enumerate() {
            fresh();
            best[k] = best[k].min(best_of(1, || {
                std::hint::black_box(track_rois_run(scene, &rois, kind, path));
            }));
            sizes[k] = std::fs::metadata(path).map_or(0, |m| m.len());
        }
    }
    let cpu: Vec<Option<Duration>> = kinds
        .into_iter()
        .map(|kind| {
            (0..3)
                .map(|_| {
                    fresh();
                    cpu_time_of(1, || {
                        std::hint::black_box(track_rois_run(scene, &rois, kind, path));
                    })
                })
                .sum::<Option<Duration>>()
        })
        .collect();
    let ratio = |a: Duration, b: Duration| 100.0 * (a.as_secs_f64() / b.as_secs_f64() - 1.0);
    eprintln!(
        "ros_bag: track --rois over {} ROIs (best of 5): alone {:.1} ms; with the bag {:.1} ms ({:+.1} %, {:.1} MB); \
         with --mcap-rois {:.1} ms ({:+.1} %, {:.1} MB, {:.2} us a ROI)",
        rois.len(),
        1e3 * best[0].as_secs_f64(),
        1e3 * best[1].as_secs_f64(),
        ratio(best[1], best[0]),
        sizes[1] as f64 / 1e6,
        1e3 * best[2].as_secs_f64(),
        ratio(best[2], best[0]),
        sizes[2] as f64 / 1e6,
        1e6 * (best[2].as_secs_f64() - best[0].as_secs_f64()) / rois.len() as f64,
    );
    if let [Some(alone), Some(bag), Some(with_rois)] = cpu[..] {
        eprintln!(
            "ros_bag: track --rois, the tracking thread's CPU time over 3 passes: alone {:.1} ms, with the bag {:.1} \
             ms ({:+.1} %), with --mcap-rois {:.1} ms ({:+.1} %)",
            1e3 * alone.as_secs_f64(),
            1e3 * bag.as_secs_f64(),
            ratio(bag, alone),
            1e3 * with_rois.as_secs_f64(),
            ratio(with_rois, alone),
        );
    }
}

fn ros_bag(c: &mut Criterion) {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let run = simulate(&scenario, &SimulationOptions::default()).expect("the scenario simulates");
    let scene = Scene {
        camera: run.camera.clone(),
        target: run.target.clone(),
        measurements: run.measurements.clone(),
    };
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = dir.path().join("bench.mcap");
    let estimates = track_all(&scene);
    let messages = track_with_bag(&scene, &path);
    eprintln!(
        "ros_bag: {} measurements, {} estimates, {messages} messages, {} bytes",
        scene.measurements.len(),
        estimates.len(),
        std::fs::metadata(&path).map_or(0, |m| m.len())
    );
    let mut group = c.benchmark_group("ros_bag");
    group.bench_function("track_orthoglide", |b| b.iter(|| track_all(&scene)));
    // Each pass writes a new file: the old one is removed first, untimed.
    let fresh = || {
        let _ = std::fs::remove_file(&path);
    };
    group.bench_function("track_orthoglide_with_bag", |b| {
        b.iter_batched(
            fresh,
            |()| track_with_bag(&scene, &path),
            BatchSize::PerIteration,
        )
    });
    group.bench_function("track_orthoglide_with_bag_zstd", |b| {
        b.iter_batched(
            fresh,
            |()| track_with_bag_compressed(&scene, &path, Some(mcap::Compression::Zstd), true),
            BatchSize::PerIteration,
        )
    });
    group.bench_function("write_orthoglide_zstd", |b| {
        b.iter_batched(
            fresh,
            |()| write_all(&scene, &estimates, &path, Some(mcap::Compression::Zstd)),
            BatchSize::PerIteration,
        )
    });
    group.bench_function("write_orthoglide_uncompressed", |b| {
        b.iter_batched(
            fresh,
            |()| write_all(&scene, &estimates, &path, None),
            BatchSize::PerIteration,
        )
    });
    group.finish();
    let (mut tracking, mut with_bag, mut writing) = (Duration::MAX, Duration::MAX, Duration::MAX);
    for _ in 0..7 {
        tracking = tracking.min(best_of(1, || {
            std::hint::black_box(track_all(&scene));
        }));
        fresh();
        with_bag = with_bag.min(best_of(1, || {
            std::hint::black_box(track_with_bag(&scene, &path));
        }));
        fresh();
        writing = writing.min(best_of(1, || {
            std::hint::black_box(write_all(&scene, &estimates, &path, None));
        }));
    }
    let cost = with_bag.as_secs_f64() / tracking.as_secs_f64() - 1.0;
    // What the bag costs the tracking thread itself, whatever the load: its CPU time over 20 passes of each, the
    // passes alternating (alone, the estimates only, the estimates and the measurements).
    let mut cpu = [Some(Duration::ZERO); 3];
    for _ in 0..20 {
        // The previous pass's bag is removed outside the timed part: freeing its 4.8 MB of page cache (about 3 % of
        // the whole bench's samples in `perf`) is not the tracking's work, and a run writes its bag once.
        let alone = cpu_time_of(1, || {
            std::hint::black_box(track_all(&scene));
        });
        fresh();
        let estimates_only = cpu_time_of(1, || {
            std::hint::black_box(track_with_bag_compressed(&scene, &path, None, false));
        });
        fresh();
        let beside = cpu_time_of(1, || {
            std::hint::black_box(track_with_bag(&scene, &path));
        });
        let passes = [alone, estimates_only, beside];
        for (total, pass) in cpu.iter_mut().zip(passes) {
            *total = total.zip(pass).map(|(a, b)| a + b);
        }
    }
    if let [Some(alone), Some(estimates_only), Some(beside)] = cpu {
        let ratio = |a: Duration| 100.0 * (a.as_secs_f64() / alone.as_secs_f64() - 1.0);
        eprintln!(
            "ros_bag: the tracking thread's CPU time over 20 passes: {:.1} ms alone, {:.1} ms handing every \
             estimate to the bag's thread ({:+.1} %), {:.1} ms every estimate and measurement ({:+.1} %; the bag's \
             thread works beside it)",
            1e3 * alone.as_secs_f64(),
            1e3 * estimates_only.as_secs_f64(),
            ratio(estimates_only),
            1e3 * beside.as_secs_f64(),
            ratio(beside),
        );
    }
    eprintln!(
        "ros_bag: tracking {:.2} ms, tracking with the bag {:.2} ms: the bag costs {:.1} % of the tracking time \
         (target at most {:.0} %: {}); the bag's own work (uncompressed) on one thread {:.2} ms ({:.2} us an estimate)",
        1e3 * tracking.as_secs_f64(),
        1e3 * with_bag.as_secs_f64(),
        100.0 * cost,
        100.0 * TARGET_RATIO,
        if cost <= TARGET_RATIO {
            "met"
        } else {
            "NOT met"
        },
        1e3 * writing.as_secs_f64(),
        1e6 * writing.as_secs_f64() / estimates.len() as f64,
    );
    roi_costs(&scene, &run, &scenario, &path);
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(Duration::from_secs(3));
    targets = ros_bag
}
criterion_main!(benches);
