//! The real-time loop: an acquisition thread (trigger, grab, centroid: the camera side) and an estimation thread
//! (the tracker), joined by a lock-free single-producer single-consumer queue of measurements; the estimates flow
//! back through a second queue as [`Predictor`]s that place the next ROIs.
//!
//! The camera side can be paced to a ROI rate (the paper: 4 kHz, one trigger every 250 µs) or free-running. Nothing
//! allocates in the steady state: buffers and queues are sized when the loop starts. Dropped measurements (queue
//! full), late triggers (paced mode), rejected blobs, camera errors and re-initialisations are counted. A camera that
//! ends (disconnected, or the end of a recording) ends the run; what was estimated until then is kept.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use roitrack_core::estimator::{Estimate, Estimator, Matrix12, Tracker, TrackerConfig};
use roitrack_core::{CameraModel, Measurement, MotionState, Target};
use roitrack_image::{
    CentroidOptions, Frame, GrabError, RejectionCounts, RoiCamera, RoiImage, RoiTrigger,
    measure_roi,
};
use thiserror::Error;

use crate::matching::{MatchError, find_target};
use crate::scheduler::{Predictor, RoiScheduler, SchedulerConfig};

/// Options of the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopConfig {
    /// ROI trigger rate (Hz): ROI k is exposed at `t_start_s + k / rate_hz`.
    pub rate_hz: f64,
    /// Wait for each trigger time on the wall clock (a real camera's trigger); otherwise run as fast as possible.
    pub paced: bool,
    /// Number of ROI slots to run.
    pub roi_slots: usize,
    pub t_start_s: f64,
    /// ROI slots a full-frame read costs (its readout time).
    pub full_frame_slots: usize,
    /// Capacity of the measurement queue.
    pub queue_capacity: usize,
    /// Free-running only: the camera side waits while more than this many measurements are queued, unprocessed.
    /// Without it a camera faster than the estimator would place its ROIs from ever staler estimates; a paced camera
    /// cannot wait, and the queue absorbs (or drops) what the estimator does not keep up with.
    pub max_queued: usize,
    pub scheduler: SchedulerConfig,
    pub centroid: CentroidOptions,
    /// Keep every measurement handed to the estimator in [`LoopReport::measured`] (for a record of what the tracker
    /// saw, the ROS 2 bag's `/roitrack/measurements`); room for `roi_slots` is reserved before the run, so the loop
    /// still does not allocate. Default: false.
    pub keep_measurements: bool,
}

impl LoopConfig {
    /// Refuses a rate that is not positive and finite, and queues or ROI sizes that cannot work.
    pub fn validate(&self) -> Result<(), PipelineError> {
        let check = |field, value: f64, expected, ok: bool| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(PipelineError::LoopConfig {
                    field,
                    expected,
                    value,
                })
            }
        };
        check("rate_hz", self.rate_hz, "positive", self.rate_hz > 0.0)?;
        check("t_start_s", self.t_start_s, "finite", true)?;
        check(
            "queue_capacity",
            self.queue_capacity as f64,
            "at least 2",
            self.queue_capacity >= 2,
        )?;
        let s = &self.scheduler;
        check(
            "scheduler.max_size_px",
            f64::from(s.max_size_px),
            "in [min_size_px, 64]",
            s.max_size_px >= s.min_size_px && s.max_size_px <= roitrack_image::MAX_ROI_WIDTH,
        )?;
        check(
            "scheduler.min_size_px",
            f64::from(s.min_size_px),
            "at least 1",
            s.min_size_px >= 1,
        )
    }
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            rate_hz: 4000.0,
            paced: false,
            roi_slots: 4000,
            t_start_s: 0.0,
            full_frame_slots: 4,
            queue_capacity: 1024,
            max_queued: 16,
            scheduler: SchedulerConfig::default(),
            centroid: CentroidOptions::default(),
            keep_measurements: false,
        }
    }
}

/// What a run of the loop did.
#[derive(Debug, Clone)]
pub struct LoopReport {
    pub estimates: Vec<Estimate>,
    /// Per estimate: wall time from the grab of the ROI that completed it to the estimate (µs).
    pub latencies_us: Vec<f64>,
    /// ROIs read.
    pub rois: usize,
    /// Centroids sent to the estimator.
    pub measurements: usize,
    pub rejections: RejectionCounts,
    /// Measurements lost because the queue was full.
    pub dropped: usize,
    /// Paced mode: triggers the camera side reached more than one period late.
    pub late: usize,
    /// Full-frame (re-)initialisations that succeeded, and those that failed.
    pub initialisations: usize,
    pub failed_initialisations: usize,
    /// Measurements the tracker refused (none expected).
    pub refused: usize,
    /// Grabs that failed but may be retried (timeouts, dropped buffers).
    pub camera_errors: usize,
    /// The camera's end, if it ended the run before its last slot (disconnected, end of a recording).
    pub stopped_by: Option<GrabError>,
    /// Wall time of the whole run (s).
    pub wall_s: f64,
    /// With [`LoopConfig::keep_measurements`]: the measurements handed to the estimator, in order (else empty).
    pub measured: Vec<Measurement>,
}

impl LoopReport {
    /// ROIs read per second of wall time.
    pub fn rois_per_s(&self) -> f64 {
        self.rois as f64 / self.wall_s.max(1e-12)
    }

    /// The `q` quantile (nearest rank, 0 to 1) of the ROI-to-estimate latencies (µs); NaN without estimates.
    pub fn latency_quantile_us(&self, q: f64) -> f64 {
        roitrack_core::stats::quantile(&roitrack_core::stats::sorted(&self.latencies_us), q)
    }
}

#[derive(Debug, Error)]
pub enum PipelineError {
    #[error("invalid tracker options: {0}")]
    Config(#[from] roitrack_core::estimator::ConfigError),
    #[error("invalid loop option: {field} must be {expected}, got {value}")]
    LoopConfig {
        field: &'static str,
        expected: &'static str,
        value: f64,
    },
    #[error("the camera's time model: {0}")]
    TimeModel(#[from] roitrack_core::time::TimeModelError),
    #[error("the estimation thread panicked")]
    EstimatorPanicked,
}

enum Event {
    Measurement {
        m: Measurement,
        grabbed: Instant,
    },
    /// A full-frame initialisation: restart the tracker from this static pose.
    Restart {
        t_s: f64,
        state: MotionState,
    },
}

/// The broad prior of a pose from a full frame: 2 mm, 0.02 rad, 1 m/s, 10 rad/s (1 sigma).
pub(crate) fn full_frame_covariance() -> Matrix12 {
    let sigmas = [
        2e-3, 2e-3, 2e-3, 0.02, 0.02, 0.02, 1.0, 1.0, 1.0, 10.0, 10.0, 10.0,
    ];
    Matrix12::from_diagonal(&nalgebra::SVector::<f64, 12>::from_fn(|i, _| {
        sigmas[i] * sigmas[i]
    }))
}

/// Spins briefly, then yields: queues on a busy 2-core machine must not burn the other thread's core.
fn backoff(spins: &mut u32) {
    if *spins < 64 {
        std::hint::spin_loop();
    } else {
        std::thread::yield_now();
    }
    *spins = spins.saturating_add(1);
}

/// Runs the loop: `camera` on the acquisition thread (the calling one), a [`Tracker`] on the estimation thread. It
/// starts with a full frame (the target found with no prior), then reads `config.roi_slots` ROI slots; a camera that
/// ends early ends the run ([`LoopReport::stopped_by`]). The camera is borrowed: it is the caller's again after the
/// run.
///
/// ```
/// use roitrack_core::estimator::TrackerConfig;
/// use roitrack_image::{RoiRenderer, SensorModel, SimulatedCamera};
/// use roitrack_pipeline::{LoopConfig, run_loop};
/// use roitrack_sim::{Scenario, ScenarioKind};
///
/// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
/// let renderer =
///     RoiRenderer::new(scenario.camera.clone(), scenario.target.clone(), SensorModel::default()).unwrap();
/// let truth = { let s = scenario.clone(); move |t: f64| s.state_at(t) };
/// let mut camera = SimulatedCamera::new(renderer, truth, 1);
/// let config = LoopConfig { roi_slots: 800, ..LoopConfig::default() };
/// let report =
///     run_loop(&mut camera, &scenario.camera, &scenario.target, TrackerConfig::default(), &config).unwrap();
/// assert_eq!(report.initialisations, 1);
/// assert!(report.estimates.len() > 60 && report.stopped_by.is_none());
/// ```
pub fn run_loop<C: RoiCamera>(
    camera: &mut C,
    camera_model: &CameraModel,
    target: &Target,
    tracker_config: TrackerConfig,
    config: &LoopConfig,
) -> Result<LoopReport, PipelineError> {
    run_loop_with_progress(camera, camera_model, target, tracker_config, config, None)
}

/// [`run_loop`], publishing the number of ROI slots done to `progress` (every 256 slots) for a progress display.
///
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use roitrack_core::estimator::TrackerConfig;
/// use roitrack_image::{RoiRenderer, SensorModel, SimulatedCamera};
/// use roitrack_pipeline::{LoopConfig, run_loop_with_progress};
/// use roitrack_sim::{Scenario, ScenarioKind};
///
/// let scenario = Scenario::new(ScenarioKind::Static, 1);
/// let renderer =
///     RoiRenderer::new(scenario.camera.clone(), scenario.target.clone(), SensorModel::default()).unwrap();
/// let mut camera = SimulatedCamera::new(renderer, move |t: f64| scenario.state_at(t), 1);
/// let config = LoopConfig { roi_slots: 600, ..LoopConfig::default() };
/// let done = AtomicUsize::new(0);
/// let model = roitrack_core::CameraModel::canonical();
/// let target = roitrack_core::Target::grid4x4();
/// run_loop_with_progress(&mut camera, &model, &target, TrackerConfig::default(), &config, Some(&done)).unwrap();
/// assert_eq!(done.load(Ordering::Relaxed), 512);
/// ```
pub fn run_loop_with_progress<C: RoiCamera>(
    camera: &mut C,
    camera_model: &CameraModel,
    target: &Target,
    tracker_config: TrackerConfig,
    config: &LoopConfig,
    progress: Option<&std::sync::atomic::AtomicUsize>,
) -> Result<LoopReport, PipelineError> {
    run_loop_with_sink(
        camera,
        camera_model,
        target,
        tracker_config,
        config,
        progress,
        &mut |_| {},
    )
}

/// [`run_loop_with_progress`], also handing each estimate to `on_estimate` on the estimation thread as it is made
/// (a live view, for one): it must not block, or it holds the loop back.
///
/// ```
/// use roitrack_core::estimator::TrackerConfig;
/// use roitrack_image::{RoiRenderer, SensorModel, SimulatedCamera};
/// use roitrack_pipeline::{LoopConfig, run_loop_with_sink};
/// use roitrack_sim::{Scenario, ScenarioKind};
///
/// let scenario = Scenario::new(ScenarioKind::Static, 1);
/// let renderer =
///     RoiRenderer::new(scenario.camera.clone(), scenario.target.clone(), SensorModel::default()).unwrap();
/// let mut camera = SimulatedCamera::new(renderer, { let s = scenario.clone(); move |t: f64| s.state_at(t) }, 1);
/// let config = LoopConfig { roi_slots: 600, ..LoopConfig::default() };
/// let mut seen = 0;
/// let report = run_loop_with_sink(&mut camera, &scenario.camera, &scenario.target, TrackerConfig::default(),
///     &config, None, &mut |_| seen += 1).unwrap();
/// assert_eq!(seen, report.estimates.len());
/// ```
pub fn run_loop_with_sink<C: RoiCamera>(
    camera: &mut C,
    camera_model: &CameraModel,
    target: &Target,
    tracker_config: TrackerConfig,
    config: &LoopConfig,
    progress: Option<&std::sync::atomic::AtomicUsize>,
    on_estimate: &mut (dyn FnMut(&Estimate) + Send),
) -> Result<LoopReport, PipelineError> {
    config.validate()?;
    camera_model.time.validate()?;
    let mut tracker = Tracker::new(camera_model.clone(), target.clone(), tracker_config)?;
    let (mut measurement_tx, mut measurement_rx) =
        rtrb::RingBuffer::<Event>::new(config.queue_capacity.max(2));
    let (mut predictor_tx, mut predictor_rx) = rtrb::RingBuffer::<Predictor>::new(8);
    let expected_estimates = config.roi_slots / tracker_config.every.max(1) + 64;
    let camera_done = AtomicBool::new(false);
    let start = Instant::now();

    let (camera_side, estimation_side) = std::thread::scope(|scope| {
        let estimation = scope.spawn(|| {
            let mut estimates = Vec::with_capacity(expected_estimates);
            let mut latencies_us = Vec::with_capacity(expected_estimates);
            let mut refused = 0usize;
            let mut measured = Vec::with_capacity(if config.keep_measurements {
                config.roi_slots
            } else {
                0
            });
            let mut spins = 0u32;
            loop {
                match measurement_rx.pop() {
                    Ok(Event::Measurement { m, grabbed }) => {
                        spins = 0;
                        if config.keep_measurements && measured.len() < measured.capacity() {
                            measured.push(m);
                        }
                        match tracker.push(&m) {
                            Ok(Some(e)) => {
                                on_estimate(&e);
                                if estimates.len() < estimates.capacity() {
                                    latencies_us.push(grabbed.elapsed().as_secs_f64() * 1e6);
                                    estimates.push(e);
                                }
                                // If the camera side has not taken the previous ones, this one is skipped: it will
                                // get the next.
                                let _ = predictor_tx.push(Predictor {
                                    t_ref_s: e.t_ref_s,
                                    state: e.state,
                                    covariance: e.covariance,
                                });
                            }
                            Ok(None) => {}
                            Err(_) => refused += 1,
                        }
                    }
                    Ok(Event::Restart { t_s, state }) => {
                        tracker.start_from(t_s, state, Some(full_frame_covariance()));
                    }
                    Err(_) => {
                        if camera_done.load(Ordering::Acquire) && measurement_rx.is_empty() {
                            break;
                        }
                        backoff(&mut spins);
                    }
                }
            }
            (estimates, latencies_us, refused, measured)
        });

        // The acquisition side runs on this thread.
        let mut scheduler = RoiScheduler::new(
            camera_model.clone(),
            target.clone(),
            config.scheduler,
            tracker_config.noise_px,
        );
        let max_side = config.scheduler.max_size_px as usize;
        let mut image = RoiImage::with_capacity(max_side * max_side);
        let mut frame = Frame::default();
        let mut predictor: Option<Predictor> = None;
        let mut restart_t_s = f64::NEG_INFINITY;
        let mut report = Counters::default();
        let period = Duration::from_secs_f64(1.0 / config.rate_hz);
        let mut slot = 0usize;
        while slot < config.roi_slots {
            let t_s = config.t_start_s + slot as f64 / config.rate_hz;
            if let Some(progress) = progress
                && slot.is_multiple_of(256)
            {
                progress.store(slot, Ordering::Relaxed);
            }
            if config.paced {
                let due = start + period * slot as u32;
                let mut spins = 0;
                while Instant::now() < due {
                    backoff(&mut spins);
                }
                if Instant::now() > due + period {
                    report.late += 1;
                }
            } else {
                let mut spins = 0;
                while measurement_tx.buffer().capacity() - measurement_tx.slots()
                    > config.max_queued
                {
                    backoff(&mut spins);
                }
            }
            while let Ok(p) = predictor_rx.pop() {
                // Estimates from before the last re-initialisation describe the old track.
                if p.t_ref_s >= restart_t_s {
                    predictor = Some(p);
                }
            }
            if predictor.is_none() || scheduler.needs_reinitialisation() {
                if let Err(e) = camera.grab_full_frame(t_s, &mut frame) {
                    if !e.is_transient() {
                        report.stopped_by = Some(e);
                        break;
                    }
                    report.camera_errors += 1;
                    slot += config.full_frame_slots.max(1);
                    continue;
                }
                match find_target(camera_model, target, &frame, &config.centroid) {
                    Ok(found) => {
                        // The frame's own time, not the pose's (a rolling shutter's middle row, later): the next
                        // ROI slots must not come before the restart.
                        let restart_s = frame.t_s;
                        predictor = Some(Predictor {
                            t_ref_s: restart_s,
                            state: found.state,
                            covariance: Some(full_frame_covariance()),
                        });
                        restart_t_s = restart_s;
                        scheduler.reset();
                        let mut spins = 0;
                        let mut event = Event::Restart {
                            t_s: restart_s,
                            state: found.state,
                        };
                        loop {
                            match measurement_tx.push(event) {
                                Ok(()) => break,
                                Err(rtrb::PushError::Full(back)) => {
                                    event = back;
                                    backoff(&mut spins);
                                }
                            }
                        }
                        report.initialisations += 1;
                    }
                    // Frames of another size than the camera model's will never match it: stop, saying so.
                    Err(MatchError::FrameSize {
                        frame_width,
                        frame_height,
                        camera_width,
                        camera_height,
                    }) => {
                        report.stopped_by = Some(GrabError::FrameSize {
                            width: frame_width,
                            height: frame_height,
                            expected_width: camera_width,
                            expected_height: camera_height,
                        });
                        break;
                    }
                    Err(_) => {
                        predictor = None;
                        report.failed_initialisations += 1;
                    }
                }
                slot += config.full_frame_slots.max(1);
                continue;
            }
            let Some(p) = predictor else {
                slot += 1;
                continue;
            };
            let Some(request) = scheduler.next(&p, t_s) else {
                report.rejections.absent += 1;
                slot += 1;
                continue;
            };
            let trigger = RoiTrigger {
                point_id: target.points()[request.point_index].id,
                roi: request.roi,
                t_s,
            };
            let grab = camera.grab_roi(&trigger, &mut image).and_then(|()| {
                if image.is_consistent() {
                    Ok(())
                } else {
                    Err(GrabError::Dropped {
                        reason: format!(
                            "{} pixel values for a {} x {} ROI",
                            image.pixels.len(),
                            image.roi.width,
                            image.roi.height
                        ),
                    })
                }
            });
            if let Err(e) = grab {
                if !e.is_transient() {
                    report.stopped_by = Some(e);
                    break;
                }
                // A point whose ROIs keep failing counts as lost, so the camera side re-initialises.
                scheduler.report(request.point_index, false);
                report.camera_errors += 1;
                slot += 1;
                continue;
            }
            let grabbed = Instant::now();
            report.rois += 1;
            // The point the camera says it read (a replay may not follow the schedule).
            let point_index = if image.point_id == trigger.point_id {
                request.point_index
            } else {
                target
                    .index_of(image.point_id)
                    .unwrap_or(request.point_index)
            };
            match measure_roi(&image, &config.centroid, &camera_model.time) {
                Ok(m) => {
                    scheduler.report(point_index, true);
                    if measurement_tx
                        .push(Event::Measurement { m, grabbed })
                        .is_err()
                    {
                        report.dropped += 1;
                    } else {
                        report.measurements += 1;
                    }
                }
                Err(r) => {
                    scheduler.report(point_index, false);
                    report.rejections.count(&r);
                }
            }
            slot += 1;
        }
        camera_done.store(true, Ordering::Release);
        let estimation = estimation.join();
        (report, estimation)
    });
    let (estimates, latencies_us, refused, measured) =
        estimation_side.map_err(|_| PipelineError::EstimatorPanicked)?;
    Ok(LoopReport {
        estimates,
        latencies_us,
        rois: camera_side.rois,
        measurements: camera_side.measurements,
        rejections: camera_side.rejections,
        dropped: camera_side.dropped,
        late: camera_side.late,
        initialisations: camera_side.initialisations,
        failed_initialisations: camera_side.failed_initialisations,
        refused,
        camera_errors: camera_side.camera_errors,
        stopped_by: camera_side.stopped_by,
        wall_s: start.elapsed().as_secs_f64(),
        measured,
    })
}

#[derive(Debug, Default)]
struct Counters {
    rois: usize,
    measurements: usize,
    rejections: RejectionCounts,
    dropped: usize,
    late: usize,
    initialisations: usize,
    failed_initialisations: usize,
    camera_errors: usize,
    stopped_by: Option<GrabError>,
}
