//! The frame-tracking benchmark's scene (16 blobs close together on 640 x 480 frames) is tracked in its windows:
//! a window sized for an uncertain prediction holds the rims of the neighbouring blobs, and the tracker must still
//! measure each point's own blob there rather than fall back on whole-frame association or take a neighbour.

use roitrack_bench::frame_bench::{FrameBench, rolling_shutter};
use roitrack_core::time::Readout;

#[test]
fn the_dense_scene_is_tracked_in_its_windows() {
    for readout in [Readout::GlobalShutter, rolling_shutter()] {
        let bench = FrameBench::new(readout, 180).expect("the sweep renders");
        let check = bench.check();
        let mut tracker = bench.tracker();
        for frame in bench.frames() {
            tracker.process(frame).unwrap();
        }
        let report = tracker.report();
        eprintln!(
            "{readout:?}: {} frames, {} neighbours' blobs left out of windows, window rejections {:?}",
            report.frames, report.neighbour_blobs, report.window_rejections
        );
        assert_eq!(
            check.by_windows, check.steady_frames,
            "{readout:?}: {check:?}"
        );
        check.ensure().unwrap();
        let limit_m = match readout {
            Readout::GlobalShutter => 0.1e-3,
            _ => 0.3e-3,
        };
        assert!(
            check.rms_position_error_m < limit_m,
            "{readout:?}: {check:?}"
        );
    }
}
