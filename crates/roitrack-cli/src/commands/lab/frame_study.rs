//! `roitrack lab frame-study`: the frame tracker on simulated global- and rolling-shutter sequences of bright and dark
//! blobs, and the frame-camera targets checked (see [`roitrack::experiments::frames`]).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::{Result, bail};
use clap::Args;
use roitrack::experiments::frames::{FrameStudyOptions, frame_study};

/// Render the sweep scenario as global- and rolling-shutter frames (30 Hz, 30 µs a row) of bright and dark blobs,
/// track each with the frame tracker (rolling frames with the rolling and with the global model), and print the
/// accuracy table and the targets' checks in markdown.
#[derive(Debug, Args)]
pub struct FrameStudyArgs {
    /// Seeds 1 to N: each a motion of the sweep and the noise of its frames.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub seeds: u64,
    /// Frames per sequence. Default: the whole sweep (6 s).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=roitrack::sim::MAX_FRAMES as u64))]
    pub frame_count: Option<u64>,
    /// Sequences rendered and tracked at once. Default: the machine's cores.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads: Option<u64>,
    /// Print one JSON object (description, rows, checks, every run) instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// Exit with a failure when a target does not hold (after printing everything).
    #[arg(long)]
    pub check: bool,
}

pub fn run(args: &FrameStudyArgs) -> Result<()> {
    let defaults = FrameStudyOptions::default();
    let options = FrameStudyOptions {
        seeds: (1..=args.seeds).collect(),
        frame_count: args.frame_count.map(|n| n as usize),
        threads: args.threads.map_or(defaults.threads, |n| n as usize),
        ..defaults
    };
    let total = options.total_frames()?;
    // Drawn on stderr, only when it is a terminal: the table on stdout stays clean.
    let bar = indicatif::ProgressBar::new(total as u64).with_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} frames ({elapsed}, {eta} left)",
        )
        .expect("valid progress template"),
    );
    let done = AtomicUsize::new(0);
    let finished = AtomicBool::new(false);
    let study = std::thread::scope(|scope| {
        scope.spawn(|| {
            while !finished.load(Ordering::Relaxed) {
                bar.set_position(done.load(Ordering::Relaxed) as u64);
                std::thread::sleep(Duration::from_millis(200));
            }
        });
        let study = frame_study(&options, Some(&done));
        finished.store(true, Ordering::Relaxed);
        study
    })?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", study.json());
    } else {
        print!("{}", study.markdown());
    }
    let failing = study.checks().iter().filter(|c| !c.holds).count();
    if args.check && failing > 0 {
        bail!("{failing} target(s) do not hold");
    }
    Ok(())
}
