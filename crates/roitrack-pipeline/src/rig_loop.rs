//! The real-time loop of a rig: one acquisition thread per camera (trigger, grab, centroid, each camera's ROIs
//! placed from its own track, as a single camera's loop places them) and one estimation thread, the
//! [`RigTracker`], that merges the cameras' queues in the order of their rig times and fuses every centroid.
//!
//! The cameras share no clock: each reads its slots on its own, and the estimation side takes the queued event whose
//! rig time (by the clocks as the tracker knows them now) is the earliest, once every camera still running has one
//! queued. A camera that measures nothing in a slot (the target hidden from it, a full frame that did not find it)
//! queues a heartbeat instead, so the others never wait on it; a camera that ends is left out of the merge. Free
//! running, a camera ahead of the others waits at [`LoopConfig::max_queued`] unprocessed events, so simulated and
//! fake cameras advance together; paced, the merge waits at most a slot of the slowest camera.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use roitrack_core::Target;
use roitrack_estimators::rig::{
    ClockEstimate, Rig, RigEstimate, RigMeasurement, RigTracker, RigTrackerConfig, RigTrackerReport,
};
use roitrack_image::RoiCamera;

use crate::realtime::{
    Acquisition, AcquisitionCounts, Event, LoopConfig, PipelineError, backoff,
    full_frame_covariance,
};
use crate::scheduler::Predictor;

/// What a run of a rig's loop did.
#[derive(Debug, Clone)]
pub struct RigLoopReport {
    /// The fused estimates (rig frame, rig clock), in order.
    pub estimates: Vec<RigEstimate>,
    /// Per estimate: wall time from the grab of the ROI whose centroid released it from the reorder buffer to the
    /// estimate (µs): the fused estimates' latency, [`RigTrackerConfig::reorder_latency_s`] of the rig's time
    /// behind the newest centroid; NaN for the last ones, which the end of the run released.
    pub latencies_us: Vec<f64>,
    /// Per camera (the rig's order): what its acquisition thread did.
    pub cameras: Vec<AcquisitionCounts>,
    /// Centroids the tracker refused (none expected).
    pub refused: usize,
    /// What the rig's tracker did.
    pub tracker: RigTrackerReport,
    /// Every camera's clock as learnt at the end.
    pub clocks: Vec<ClockEstimate>,
    /// Wall time of the whole run (s).
    pub wall_s: f64,
}

/// The events of one camera's queue the estimation side works with.
struct CameraQueues {
    measurements: rtrb::Consumer<Event>,
    predictors: rtrb::Producer<Predictor>,
}

/// Runs the loop of a rig: `cameras[c]` (the rig's camera `c`, its ROIs on its own clock) each on an acquisition
/// thread of its own, the [`RigTracker`] on the calling thread. Each camera starts with a full frame and reads
/// `config.roi_slots` slots from `config.t_start_s` of its own clock; a camera that ends early stops only itself
/// ([`AcquisitionCounts::stopped_by`]). `on_estimate` gets each fused estimate as it is made; it must not block.
///
/// Each camera's ROIs are placed from its own tracker's newest estimate ([`RigTracker::take_camera_estimate`]): the
/// fused estimates come a reorder buffer later. Unlike a single camera's loop this one allocates as it runs (the
/// tracker's estimates are vectors).
///
/// ```
/// use roitrack_estimators::rig::RigTrackerConfig;
/// use roitrack_pipeline::{LoopConfig, run_rig_loop};
/// use roitrack_sim::multi_camera::CameraRigScene;
/// use roitrack_sim::{Scenario, ScenarioKind};
///
/// // Two cameras, the second's clock 20 ms and 40 ppm off and left to be learnt.
/// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Orthoglide, 1).with_duration_s(1.0), 2, 3);
/// let mut cameras = scene.simulated_cameras(1).unwrap();
/// let config = LoopConfig { roi_slots: 2000, ..LoopConfig::default() };
/// let report = run_rig_loop(&mut cameras, &scene.rig_with_clocks_unknown(), &scene.scenario.target,
///     RigTrackerConfig::default(), &config, &mut |_| {}).unwrap();
/// assert!(report.cameras.iter().all(|c| c.initialisations >= 1));
/// assert!(!report.estimates.is_empty());
/// ```
pub fn run_rig_loop<C: RoiCamera>(
    cameras: &mut [C],
    rig: &Rig,
    target: &Target,
    tracker_config: RigTrackerConfig,
    config: &LoopConfig,
    on_estimate: &mut (dyn FnMut(&RigEstimate) + Send),
) -> Result<RigLoopReport, PipelineError> {
    config.validate()?;
    if cameras.len() != rig.len() {
        return Err(PipelineError::RigCameras {
            given: cameras.len(),
            rig: rig.len(),
        });
    }
    for camera in rig.cameras() {
        camera.camera.time.validate()?;
    }
    let mut tracker = RigTracker::new(rig.clone(), target.clone(), tracker_config)?;
    let noise_px = tracker_config.tracker.noise_px;
    let done: Vec<AtomicBool> = (0..cameras.len()).map(|_| AtomicBool::new(false)).collect();
    let start = Instant::now();
    let mut queues = Vec::with_capacity(cameras.len());
    let mut camera_ends = Vec::with_capacity(cameras.len());
    for _ in 0..cameras.len() {
        let (measurement_tx, measurement_rx) =
            rtrb::RingBuffer::<Event>::new(config.queue_capacity.max(2));
        let (predictor_tx, predictor_rx) = rtrb::RingBuffer::<Predictor>::new(8);
        queues.push(CameraQueues {
            measurements: measurement_rx,
            predictors: predictor_tx,
        });
        camera_ends.push((measurement_tx, predictor_rx));
    }
    let (counts, estimation) = std::thread::scope(|scope| {
        let threads: Vec<_> = cameras
            .iter_mut()
            .zip(rig.cameras())
            .zip(camera_ends)
            .zip(&done)
            .map(|(((camera, rig_camera), ends), done)| {
                scope.spawn(move || {
                    let mut acquisition = Acquisition::new(
                        camera,
                        &rig_camera.camera,
                        target,
                        config,
                        noise_px,
                        ends,
                    )
                    .with_heartbeats();
                    acquisition.run(start, None);
                    done.store(true, Ordering::Release);
                    acquisition.counters
                })
            })
            .collect();
        let estimation = merge_and_fuse(&mut tracker, &mut queues, &done, on_estimate);
        let counts: Result<Vec<_>, _> = threads.into_iter().map(|t| t.join()).collect();
        (counts, estimation)
    });
    let cameras = counts.map_err(|_| PipelineError::EstimatorPanicked)?;
    let (estimates, latencies_us, refused) = estimation;
    Ok(RigLoopReport {
        estimates,
        latencies_us,
        cameras,
        refused,
        tracker: tracker.report(),
        clocks: tracker.clocks(),
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// The estimation side: takes the earliest queued event by rig time once every running camera has one, feeds it to
/// the tracker, and sends each camera its own tracker's newest estimate; at the end, the reorder buffer's last
/// estimates. Returns the estimates, their latencies and the refused centroids.
fn merge_and_fuse(
    tracker: &mut RigTracker,
    queues: &mut [CameraQueues],
    done: &[AtomicBool],
    on_estimate: &mut (dyn FnMut(&RigEstimate) + Send),
) -> (Vec<RigEstimate>, Vec<f64>, usize) {
    let mut estimates = Vec::new();
    let mut latencies_us = Vec::new();
    let mut refused = 0usize;
    let mut spins = 0u32;
    loop {
        let mut earliest: Option<(usize, f64)> = None;
        let mut waiting = false;
        for (c, queue) in queues.iter().enumerate() {
            // The flag before the queue: a camera seen done with an empty queue has queued its last event.
            let finished = done[c].load(Ordering::Acquire);
            match queue.measurements.peek() {
                Ok(event) => {
                    let t_rig_s = tracker.rig_time_s(c, event.t_s());
                    if earliest.is_none_or(|(_, t)| t_rig_s < t) {
                        earliest = Some((c, t_rig_s));
                    }
                }
                Err(_) if !finished => waiting = true,
                Err(_) => {}
            }
        }
        let Some((c, _)) = earliest else {
            if waiting {
                backoff(&mut spins);
                continue;
            }
            break;
        };
        if waiting {
            backoff(&mut spins);
            continue;
        }
        spins = 0;
        let Ok(event) = queues[c].measurements.pop() else {
            continue;
        };
        match event {
            Event::Measurement { m, grabbed } => {
                match tracker.push(&RigMeasurement {
                    camera: c,
                    measurement: m,
                }) {
                    Ok(fused) => {
                        for e in fused {
                            on_estimate(&e);
                            latencies_us.push(grabbed.elapsed().as_secs_f64() * 1e6);
                            estimates.push(e);
                        }
                    }
                    Err(_) => refused += 1,
                }
                if let Some(e) = tracker.take_camera_estimate(c) {
                    // If the camera side has not taken the previous ones, this one is skipped: it will get the next.
                    let _ = queues[c].predictors.push(Predictor {
                        t_ref_s: e.t_ref_s,
                        state: e.state,
                        covariance: e.covariance,
                    });
                }
            }
            Event::Restart { t_s, state } => {
                tracker.restart_camera(c, t_s, state, Some(full_frame_covariance()));
            }
            Event::Passed { .. } => {}
        }
    }
    for e in tracker.finish() {
        on_estimate(&e);
        latencies_us.push(f64::NAN);
        estimates.push(e);
    }
    (estimates, latencies_us, refused)
}
