//! Criterion benchmarks of tracking from frames, against the speed targets of frame streams: tracking 16 blobs on
//! 640 x 480 frames at 5,000 frames/s or more excluding decoding, and tracking from PNG files end to end within 1.2
//! times the time of decoding them alone. The scene is [`roitrack_bench::frame_bench`]'s: `grid4x4` swept before a
//! 640 x 480 camera (fx = 700 px) at 30 Hz, bright blobs, default sensor, pre-rendered in memory before any timing.
//!
//! - `frame_tracking/track_640x480_16_blobs` (global shutter) and `frame_tracking/track_640x480_16_blobs_rolling`
//!   (rolling shutter, 60 µs a row): one frame processed by a tracker in its steady state, each blob measured in its
//!   predicted window; frames that fall back to the whole-frame search are processed but not timed (checked
//!   before timing: at least 90 % of the frames by windows, 16 blobs each, every estimate within 1 mm of the truth;
//!   the counts are printed). `frame_tracking/track_640x480_16_blobs_all_frames`: every frame after the warm-up
//!   timed, fallbacks included. Throughput in frames/s (criterion's `elem/s`).
//! - `frame_tracking/decode_png_640x480` and `frame_tracking/track_png_640x480_end_to_end`: a pass over 120 frames
//!   written as 8-bit PNG files, decoded by `FrameSource` alone, and decoded on its own thread beside the tracker
//!   (`track_frame_stream`, a new tracker per pass). Throughput in frames/s. The ratio of the two is printed at the
//!   end, from passes of each timed alternately (best of 7), with the windows path's frames/s timed again for 2 s.
//!   The end-to-end pass runs two threads: it needs two free cores, and on a busy machine its ratio rises.
//!
//! `cargo bench -p roitrack-bench --bench frame_tracking` (about 40 s with the rendering and the PNG files);
//! `-- --quick` for a shorter run.

use std::time::Duration;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use roitrack_bench::frame_bench::{
    END_TO_END_TARGET_RATIO, FrameBench, TRACKING_TARGET_FRAMES_PER_S, WARM_UP_FRAMES, decode_all,
    rolling_shutter, stream,
};
use roitrack_core::time::Readout;
use roitrack_formats::{FrameSource, FrameTiming, write_frame_png};
use roitrack_image::Frame;

/// Every frame of the 6 s sweep at 30 Hz: the tracking benches' passes (176 timed frames each).
const TRACKING_FRAMES: usize = 181;
/// Frames of the PNG benches' passes.
const PNG_FRAMES: usize = 120;

fn frame_tracking(c: &mut Criterion) {
    let mut group = c.benchmark_group("frame_tracking");
    group.throughput(Throughput::Elements(1));
    let mut global = None;
    for (id, readout) in [
        ("track_640x480_16_blobs", Readout::GlobalShutter),
        ("track_640x480_16_blobs_rolling", rolling_shutter()),
    ] {
        let bench = FrameBench::new(readout, TRACKING_FRAMES).expect("the sweep renders");
        let check = bench.check();
        eprintln!(
            "{id}: of {} frames per pass after the warm-up, {} measured in their windows (the others by whole-frame \
             search), at least {} blobs each, position error RMS {:.3} mm, worst {:.3} mm",
            check.steady_frames,
            check.by_windows,
            check.min_blobs,
            check.rms_position_error_m * 1e3,
            check.max_position_error_m * 1e3
        );
        check.ensure().expect("the timed path is the windows path");
        group.bench_function(id, |b| {
            b.iter_custom(|iters| bench.time_steady(iters as usize))
        });
        if readout == Readout::GlobalShutter {
            group.bench_function(format!("{id}_all_frames"), |b| {
                b.iter_custom(|iters| bench.time_all(iters as usize))
            });
            global = Some(bench);
        }
    }
    let global = global.expect("the global-shutter frames");

    let bench = FrameBench::new(Readout::GlobalShutter, PNG_FRAMES).expect("the sweep renders");
    let dir = tempfile::tempdir().expect("a temporary folder");
    for (k, frame) in bench.frames().iter().enumerate() {
        write_frame_png(dir.path().join(format!("frame_{k:05}.png")), frame).expect("PNG written");
    }
    let timing = FrameTiming {
        fps: Some(roitrack_bench::frame_bench::FPS_HZ),
        ..FrameTiming::default()
    };
    let open = || FrameSource::open(dir.path(), &timing).expect("the PNG files open");
    // The decoded frames are the rendered ones, at their times.
    let (mut source, mut frame) = (open(), Frame::default());
    for (k, rendered) in bench.frames().iter().enumerate() {
        source
            .next_frame(&mut frame)
            .expect("a frame")
            .expect("decoded");
        assert_eq!(frame.pixels, rendered.pixels, "frame {k}");
        assert!((frame.t_s - rendered.t_s).abs() < 1e-12, "frame {k}");
    }
    // Tracked from the files exactly as from memory.
    let mut source = open();
    let report = stream(&mut bench.tracker(), move |f: &mut Frame| {
        source.next_frame(f)
    })
    .expect("the stream runs to its end");
    let mut tracker = bench.tracker();
    for frame in bench.frames() {
        tracker.process(frame).expect("the frames are in order");
    }
    assert_eq!(report, tracker.report());
    assert_eq!(report.estimates, PNG_FRAMES, "{report:?}");

    // A pass decodes 120 files: fewer, longer samples.
    group.throughput(Throughput::Elements(PNG_FRAMES as u64));
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(4));
    group.bench_function("decode_png_640x480", |b| {
        b.iter_batched(
            || (open(), Frame::default()),
            |(mut source, mut frame)| decode_all(|f: &mut Frame| source.next_frame(f), &mut frame),
            BatchSize::PerIteration,
        )
    });
    group.bench_function("track_png_640x480_end_to_end", |b| {
        b.iter_batched(
            || (bench.tracker(), open()),
            |(mut tracker, mut source)| {
                let report = stream(&mut tracker, move |f: &mut Frame| source.next_frame(f))
                    .expect("the stream runs to its end");
                assert_eq!(report.frames, PNG_FRAMES);
                report
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();

    let figures = bench.decode_and_track(
        || {
            let mut source = open();
            move |f: &mut Frame| source.next_frame(f)
        },
        7,
    );
    let tracking = global.tracking_frames_per_s(Duration::from_secs(2));
    eprintln!(
        "tracking without decoding: {tracking:.0} frames/s (target {TRACKING_TARGET_FRAMES_PER_S:.0}, first \
         {WARM_UP_FRAMES} frames of each pass untimed, frames measured in their windows)"
    );
    eprintln!(
        "{} PNG frames: decoding alone {:.2} ms/frame, end to end {:.2} ms/frame: ratio {:.3} (target {:.1})",
        figures.frames,
        figures.decode_s * 1e3 / figures.frames as f64,
        figures.end_to_end_s * 1e3 / figures.frames as f64,
        figures.ratio(),
        END_TO_END_TARGET_RATIO
    );
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .sample_size(20)
}

criterion_group! {
    name = benches;
    config = config();
    targets = frame_tracking
}
criterion_main!(benches);
