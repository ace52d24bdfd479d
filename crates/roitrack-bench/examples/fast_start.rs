//! Tracks started while the target moves fast: `Scenario::random_with(seed, 1.5, 5.0, 4.0)` (peaks 1.5 m/s and
//! 5 rad/s), 30 frames at 30 Hz from the instant the motion is fastest, a 4 x 4 grid, with a global shutter and with
//! a rolling one (30 µs a row; smoothed, and causal), default settings. Prints per seed and shutter the position
//! RMSE over every estimate, the largest error of an estimate marked tracking or converging, and the first
//! estimates' errors and statuses (the table of docs/results.md, "Fast starts").
//!
//! `cargo run --release -p roitrack-bench --example fast_start [SEEDS]` (default 4 seeds).

use roitrack_core::time::Readout;
use roitrack_estimators::TrackStatus;
use roitrack_image::Frame;
use roitrack_pipeline::frames::{FrameTracker, FrameTrackerConfig, track_frame_stream};
use roitrack_sim::{FrameOptions, FrameSequence, Scenario};

/// Per estimate: its position error (mm) and status.
fn run(seed: u64, readout: Readout, rs_smoothing: bool) -> Vec<(f64, TrackStatus)> {
    let scenario = Scenario::random_with(seed, 1.5, 5.0, 4.0);
    let options = FrameOptions {
        readout,
        seed,
        start_s: scenario.fastest_instant_s(1.0),
        frame_count: Some(30),
        ..FrameOptions::default()
    };
    let mut source = FrameSequence::new(&scenario, &options).expect("the scene makes frames");
    // A second copy of the same deterministic sequence for the truth: the first moves to the decoding thread.
    let truth = FrameSequence::new(&scenario, &options).expect("the scene makes frames");
    let config = FrameTrackerConfig {
        rs_smoothing,
        ..FrameTrackerConfig::default()
    };
    let mut tracker = FrameTracker::new(source.camera().clone(), scenario.target.clone(), config)
        .expect("the default configuration is valid");
    let count = source.len();
    let mut k = 0;
    let next = move |frame: &mut Frame| {
        (k < count).then(|| {
            source.render(k, frame);
            k += 1;
            Ok::<usize, ()>(k - 1)
        })
    };
    let mut errors = Vec::new();
    track_frame_stream(&mut tracker, next, |_, outcome, _| {
        if let Some(e) = &outcome.estimate {
            let at = truth.state_at(e.t_ref_s);
            errors.push((
                1e3 * (e.state.cam_t_obj_m - at.cam_t_obj_m).norm(),
                e.status,
            ));
        }
        Ok::<(), ()>(())
    })
    .expect("simulated frames track");
    errors
}

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .map_or(4, |s| s.parse().expect("SEEDS is a number"));
    let rolling = Readout::RollingShutter {
        line_delay_s: 30e-6,
    };
    for seed in 1..=seeds {
        for (name, readout, smoothing) in [
            ("global", Readout::GlobalShutter, true),
            ("rolling, smoothed", rolling, true),
            ("rolling, causal", rolling, false),
        ] {
            let errors = run(seed, readout, smoothing);
            let rmse_mm =
                (errors.iter().map(|e| e.0 * e.0).sum::<f64>() / errors.len() as f64).sqrt();
            let vouched_mm = errors
                .iter()
                .filter(|e| matches!(e.1, TrackStatus::Tracking | TrackStatus::Converging))
                .map(|e| e.0)
                .fold(0.0, f64::max);
            let first: Vec<String> = errors
                .iter()
                .take(6)
                .map(|(mm, status)| format!("{mm:.2} {status:?}"))
                .collect();
            println!(
                "seed {seed}, {name}: {} estimates, RMSE {rmse_mm:.3} mm, largest vouched {vouched_mm:.2} mm; first: {}",
                errors.len(),
                first.join(", ")
            );
        }
    }
}
