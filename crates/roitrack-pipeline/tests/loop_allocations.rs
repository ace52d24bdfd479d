//! The real-time loop allocates nothing per ROI or per control step: two runs of N and 2N ROIs through the same
//! loop (replayed, pre-rendered ROIs, both threads), after a first run, make exactly the same number of heap
//! allocations, all of them set-up (threads, queues, buffers sized up front, the full-frame initialisation).

use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_estimators::{EstimatorConfig, TrackerConfig, VvsSettings};
use roitrack_pipeline::realtime::{LoopConfig, run_loop};
use roitrack_sim::camera::prerendered_replay;
use roitrack_sim::{Scenario, ScenarioKind};
use roitrack_testkit::alloc::{CountingAllocator, allocations_in_all_threads as allocations};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn steady_state_loop_does_not_allocate() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let renderer = scenario.roi_renderer().unwrap();
    let truth = |t: f64| scenario.state_at(t);
    let order = bit_reversed_indices(16);
    let n = 3000;
    // ROI k is exposed at 0.3 s + (k + 1) / 4 kHz: slot 0 is the full frame.
    let replay = prerendered_replay(
        &renderer,
        &truth,
        &order,
        32,
        0.3 + 1.0 / 4000.0,
        4000.0,
        2 * n + 8,
        5,
    );
    for (name, estimator) in [
        ("kalman", EstimatorConfig::default()),
        ("vvs", EstimatorConfig::Vvs(VvsSettings::default())),
    ] {
        let tracker = TrackerConfig {
            estimator,
            ..Default::default()
        };
        let mut counts = Vec::new();
        // A first run, not counted: the identification keeps what it derives from the target for the next
        // whole-frame search on the same thread, which the first run of the process computes and later ones reuse.
        for slots in [n, n, 2 * n] {
            let mut camera = replay.clone();
            camera.rewind();
            let config = LoopConfig {
                roi_slots: slots,
                t_start_s: 0.3,
                // The replay holds no ROIs for the full-frame slots: start with them.
                full_frame_slots: 1,
                ..Default::default()
            };
            let before = allocations();
            let report = run_loop(
                &mut camera,
                &scenario.camera,
                &scenario.target,
                tracker,
                &config,
            )
            .unwrap();
            let allocations = allocations() - before;
            assert!(
                report.estimates.len() > slots / 10 - 5,
                "{name}: {} estimates",
                report.estimates.len()
            );
            assert_eq!(report.acquisition.dropped, 0);
            counts.push((allocations, report.acquisition.rois));
        }
        assert_eq!(
            counts[1].0, counts[2].0,
            "{name}: allocations grow with the number of ROIs: {counts:?} (allocations, ROIs)"
        );
    }
}
