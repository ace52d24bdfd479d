//! The frame scenes shared by the frame tests (frames.rs, rs_smoothing.rs): their rolling shutter, and the tracks
//! started at a random motion's fastest instant.

#![allow(dead_code)]

use roitrack_core::time::Readout;
use roitrack_sim::{FrameOptions, FrameSequence, Scenario};

/// The rolling shutter of the frame tests: 30 us a row.
pub const ROLLING: Readout = Readout::RollingShutter {
    line_delay_s: 30e-6,
};

/// A random motion (seed `seed`) up to 1.5 m/s and 5 rad/s.
pub fn fast_motion(seed: u64) -> Scenario {
    Scenario::random_with(seed, 1.5, 5.0, 4.0)
}

/// 30 frames of `scenario` from its fastest instant, read out by `readout`: a track that starts at its fastest.
pub fn frames_from_fastest_instant(
    scenario: &Scenario,
    readout: Readout,
    seed: u64,
) -> FrameSequence {
    let options = FrameOptions {
        readout,
        seed,
        start_s: scenario.fastest_instant_s(1.0),
        frame_count: Some(30),
        ..FrameOptions::default()
    };
    FrameSequence::new(scenario, &options).unwrap()
}
