//! The frame tracker alone on a video's frames: tracks 8-bit grey frames held in memory (decoded beforehand, so that
//! no decoding is timed) as `roitrack track --images V.mp4 --shutter global --exposure-s 1e-3 --polarity auto` would,
//! frame k at k / 30 s, and prints the tracking thread's CPU time (the least and the median of the passes), the
//! frames measured in their windows, and a sum of the estimates' positions that changes if any estimate does (to
//! compare builds). Under `valgrind --tool=callgrind` with one pass it counts the tracker's instructions, which a
//! shared machine does not move (docs/results.md).
//!
//! ```text
//! ffmpeg -nostdin -v error -i V.mp4 -f rawvideo -pix_fmt gray V.gray
//! cargo run --release -p roitrack-bench --example track_raw_frames -- camera.yaml target.csv V.gray [PASSES]
//! ```
//!
//! The camera file gives the frames' size; PASSES is 3 unless given.

use std::process::ExitCode;

use roitrack_core::time::{Readout, TimeModel};
use roitrack_detect::photo::PolarityChoice;
use roitrack_image::Frame;
use roitrack_pipeline::frames::{FrameTracker, FrameTrackerConfig};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !(3..=4).contains(&args.len()) {
        eprintln!("usage: track_raw_frames CAMERA.yaml TARGET.csv FRAMES.gray [PASSES]");
        return ExitCode::from(2);
    }
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("track_raw_frames: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &[String]) -> Result<(), Box<dyn std::error::Error>> {
    let mut camera = roitrack_formats::read_camera_yaml(&args[0])?;
    let target = roitrack_formats::read_target_csv(&args[1])?;
    let bytes = std::fs::read(&args[2])?;
    let passes: usize = args.get(3).map_or(Ok(3), |s| s.parse())?;
    camera.time = TimeModel {
        readout: Readout::GlobalShutter,
        exposure_s: 1e-3,
    };
    let (width, height) = (camera.width_px, camera.height_px);
    let frames: Vec<Frame> = bytes
        .chunks_exact(width as usize * height as usize)
        .enumerate()
        .map(|(k, pixels)| Frame {
            width,
            height,
            bit_depth: 8,
            t_s: k as f64 / 30.0,
            pixels: pixels.iter().map(|&v| u16::from(v)).collect(),
        })
        .collect();
    let mut config = FrameTrackerConfig::default();
    config.detection.polarity = PolarityChoice::Auto;
    let (mut seconds, mut windows, mut sum_m) = (Vec::new(), 0, 0.0);
    for _ in 0..passes.max(1) {
        let mut tracker = FrameTracker::new(camera.clone(), target.clone(), config)?;
        let mut failed = None;
        let cpu = roitrack_bench::cpu_time_of(1, || {
            for frame in &frames {
                match tracker.process(frame) {
                    Ok(outcome) => {
                        if let Some(e) = outcome.estimate {
                            sum_m += e.state.cam_t_obj_m.sum();
                        }
                    }
                    Err(e) => {
                        failed = Some(e);
                        return;
                    }
                }
            }
        })
        .ok_or("no thread CPU clock")?;
        if let Some(e) = failed {
            return Err(e.into());
        }
        seconds.push(cpu.as_secs_f64());
        windows = tracker.report().by_windows;
    }
    seconds.sort_by(f64::total_cmp);
    println!(
        "{} frames, {windows} in windows: tracking CPU least {:.3} s, median {:.3} s ({} passes); positions' sum {sum_m:.9} m",
        frames.len(),
        seconds[0],
        seconds[seconds.len() / 2],
        seconds.len()
    );
    Ok(())
}
