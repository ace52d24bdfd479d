//! The camera side of the loop: each slot a full frame (no track to follow) or one ROI placed from the latest
//! [`Predictor`], its blob centroided and queued for the estimation side.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use roitrack_core::{CameraModel, Target};
use roitrack_detect::matching::{MatchError, find_target};
use roitrack_image::{
    Frame, GrabError, RejectionCounts, RoiCamera, RoiImage, RoiTrigger, measure_roi,
};

use super::{Event, LoopConfig, backoff, full_frame_covariance};
use crate::scheduler::{Predictor, RoiScheduler};

/// What one step of the camera side did with the ROI slots: go on after this many, or end the run.
enum Slots {
    Advance(usize),
    Stop,
}

/// The acquisition thread's state: the camera, the scheduler placing each ROI from the latest [`Predictor`], the
/// buffers a grab fills (sized before the run), the counters, and its ends of the two queues.
pub(crate) struct Acquisition<'a, C> {
    camera: &'a mut C,
    camera_model: &'a CameraModel,
    target: &'a Target,
    config: &'a LoopConfig,
    scheduler: RoiScheduler,
    image: RoiImage,
    frame: Frame,
    /// The latest estimate to place ROIs from; none before the first full frame or after a failed one.
    predictor: Option<Predictor>,
    /// The time of the last full-frame restart: older estimates describe the old track.
    restart_t_s: f64,
    pub(crate) counters: AcquisitionCounts,
    measurement_tx: rtrb::Producer<Event>,
    predictor_rx: rtrb::Consumer<Predictor>,
    /// Whether a slot that queues nothing queues an [`Event::Passed`].
    heartbeats: bool,
}

impl<'a, C: RoiCamera> Acquisition<'a, C> {
    /// The camera side before its first slot: no track yet, the ROI buffer sized for the largest ROI, and the
    /// acquisition ends of the measurement and predictor queues.
    pub(crate) fn new(
        camera: &'a mut C,
        camera_model: &'a CameraModel,
        target: &'a Target,
        config: &'a LoopConfig,
        noise_px: f64,
        (measurement_tx, predictor_rx): (rtrb::Producer<Event>, rtrb::Consumer<Predictor>),
    ) -> Self {
        let max_side = config.scheduler.max_size_px as usize;
        Self {
            scheduler: RoiScheduler::new(
                camera_model.clone(),
                target.clone(),
                config.scheduler,
                noise_px,
            ),
            image: RoiImage::with_capacity(max_side * max_side),
            frame: Frame::default(),
            predictor: None,
            restart_t_s: f64::NEG_INFINITY,
            counters: AcquisitionCounts::default(),
            measurement_tx,
            predictor_rx,
            heartbeats: false,
            camera,
            camera_model,
            target,
            config,
        }
    }

    /// The camera side of a rig's camera: every slot that queues no measurement and no restart queues an
    /// [`Event::Passed`] (if the queue has room: a full queue holds events of this camera already).
    pub(crate) fn with_heartbeats(mut self) -> Self {
        self.heartbeats = true;
        self
    }

    /// The camera side: `config.roi_slots` slots from `start`, each a full frame (when there is no track to follow)
    /// or one ROI, until the slots are done or the camera ends.
    pub(crate) fn run(
        &mut self,
        start: Instant,
        progress: Option<&std::sync::atomic::AtomicUsize>,
    ) {
        let period = Duration::from_secs_f64(1.0 / self.config.rate_hz);
        let mut slot = 0usize;
        while slot < self.config.roi_slots {
            if let Some(progress) = progress
                && slot.is_multiple_of(256)
            {
                progress.store(slot, Ordering::Relaxed);
            }
            self.wait_for_slot(start, slot, period);
            if self.config.paced && self.config.skip_late_slots {
                let now_slot = (start.elapsed().as_secs_f64() * self.config.rate_hz) as usize;
                if now_slot > slot {
                    self.counters.skipped += now_slot - slot;
                    slot = now_slot;
                    if slot >= self.config.roi_slots {
                        break;
                    }
                }
            }
            let t_s = self.config.t_start_s + slot as f64 / self.config.rate_hz;
            while let Ok(p) = self.predictor_rx.pop() {
                // Estimates from before the last re-initialisation describe the old track.
                if p.t_ref_s >= self.restart_t_s {
                    self.predictor = Some(p);
                }
            }
            let queued = self.counters.measurements + self.counters.initialisations;
            let step = if self.predictor.is_none() || self.scheduler.needs_reinitialisation() {
                self.initialise(t_s)
            } else {
                self.read_roi(t_s)
            };
            if self.heartbeats
                && self.counters.measurements + self.counters.initialisations == queued
            {
                let _ = self.measurement_tx.push(Event::Passed { t_s });
            }
            match step {
                Slots::Advance(n) => slot += n,
                Slots::Stop => break,
            }
        }
    }

    /// Paced: waits for the trigger time of `slot` (counting a trigger reached more than a `period` late).
    /// Free-running: waits while more than `max_queued` measurements are unprocessed.
    fn wait_for_slot(&mut self, start: Instant, slot: usize, period: Duration) {
        let mut spins = 0;
        if self.config.paced {
            let due = start + period * slot as u32;
            while Instant::now() < due {
                backoff(&mut spins);
            }
            if Instant::now() > due + period {
                self.counters.late += 1;
            }
        } else {
            while self.measurement_tx.buffer().capacity() - self.measurement_tx.slots()
                > self.config.max_queued
            {
                backoff(&mut spins);
            }
        }
    }

    /// Reads a full frame at `t_s` and finds the target in it with no prior; on success restarts the track (the
    /// scheduler here, the tracker through the queue). A full frame costs `full_frame_slots` slots.
    fn initialise(&mut self, t_s: f64) -> Slots {
        let config = self.config;
        let frame_slots = Slots::Advance(config.full_frame_slots.max(1));
        if let Err(e) = self.camera.grab_full_frame(t_s, &mut self.frame) {
            if !e.is_transient() {
                self.counters.stopped_by = Some(e);
                return Slots::Stop;
            }
            self.counters.camera_errors += 1;
            return frame_slots;
        }
        match find_target(
            self.camera_model,
            self.target,
            &self.frame,
            &config.centroid,
        ) {
            Ok(found) => {
                // The frame's own time, not the pose's (a rolling shutter's middle row, later): the next ROI slots
                // must not come before the restart.
                let restart_s = self.frame.t_s;
                self.predictor = Some(Predictor {
                    t_ref_s: restart_s,
                    state: found.state,
                    covariance: Some(full_frame_covariance()),
                });
                self.restart_t_s = restart_s;
                self.scheduler.reset();
                let mut spins = 0;
                let mut event = Event::Restart {
                    t_s: restart_s,
                    state: found.state,
                };
                loop {
                    match self.measurement_tx.push(event) {
                        Ok(()) => break,
                        Err(rtrb::PushError::Full(back)) => {
                            event = back;
                            backoff(&mut spins);
                        }
                    }
                }
                self.counters.initialisations += 1;
            }
            // Frames of another size than the camera model's will never match it: stop, saying so.
            Err(MatchError::FrameSize {
                frame_width,
                frame_height,
                camera_width,
                camera_height,
            }) => {
                self.counters.stopped_by = Some(GrabError::FrameSize {
                    width: frame_width,
                    height: frame_height,
                    expected_width: camera_width,
                    expected_height: camera_height,
                });
                return Slots::Stop;
            }
            Err(_) => {
                self.predictor = None;
                self.counters.failed_initialisations += 1;
            }
        }
        frame_slots
    }

    /// Places the next ROI from the latest predictor, reads it at `t_s`, measures its blob and queues the
    /// measurement for the estimator. One slot.
    fn read_roi(&mut self, t_s: f64) -> Slots {
        let Some(p) = self.predictor else {
            return Slots::Advance(1);
        };
        let Some(request) = self.scheduler.next(&p, t_s) else {
            self.counters.rejections.absent += 1;
            return Slots::Advance(1);
        };
        let trigger = RoiTrigger {
            point_id: self.target.points()[request.point_index].id,
            roi: request.roi,
            t_s,
        };
        let image = &mut self.image;
        let grab = self.camera.grab_roi(&trigger, image).and_then(|()| {
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
                self.counters.stopped_by = Some(e);
                return Slots::Stop;
            }
            // A point whose ROIs keep failing counts as lost, so the camera side re-initialises.
            self.scheduler.report(request.point_index, false);
            self.counters.camera_errors += 1;
            return Slots::Advance(1);
        }
        let grabbed = Instant::now();
        self.counters.rois += 1;
        if self.config.crop_to_request && self.image.point_id == trigger.point_id {
            self.image.crop_to(&request.roi, &self.camera_model.time);
        }
        // The point the camera says it read (a replay may not follow the schedule).
        let point_index = if self.image.point_id == trigger.point_id {
            request.point_index
        } else {
            self.target
                .index_of(self.image.point_id)
                .unwrap_or(request.point_index)
        };
        match measure_roi(&self.image, &self.config.centroid, &self.camera_model.time) {
            Ok(m) => {
                self.scheduler.report(point_index, true);
                if self
                    .measurement_tx
                    .push(Event::Measurement { m, grabbed })
                    .is_err()
                {
                    self.counters.dropped += 1;
                } else {
                    self.counters.measurements += 1;
                }
            }
            Err(r) => {
                self.scheduler.report(point_index, false);
                self.counters.rejections.count(&r);
            }
        }
        Slots::Advance(1)
    }
}

/// What the camera side of a loop did (a single camera's are in [`super::LoopReport::acquisition`]; a rig's, one per
/// camera, in [`crate::rig_loop::RigLoopReport::cameras`]).
///
/// ```
/// let counts = roitrack_pipeline::AcquisitionCounts::default();
/// assert_eq!((counts.rois, counts.measurements), (0, 0));
/// ```
#[derive(Debug, Clone, Default)]
pub struct AcquisitionCounts {
    /// ROIs read.
    pub rois: usize,
    /// Centroids sent to the estimator.
    pub measurements: usize,
    /// ROIs that gave no centroid, by reason; `absent` also counts the slots in which the scheduler placed no ROI
    /// ([`crate::scheduler::RoiScheduler::next`] gave `None`).
    pub rejections: RejectionCounts,
    /// Measurements lost because the queue was full.
    pub dropped: usize,
    /// Paced mode: triggers the camera side reached more than one period late.
    pub late: usize,
    /// With [`LoopConfig::skip_late_slots`]: slots skipped because the camera side reached them late.
    pub skipped: usize,
    /// Full-frame (re-)initialisations that found the target and restarted the track.
    pub initialisations: usize,
    /// Full frames in which the target was not found ([`roitrack_detect::matching::find_target`] failed): the loop
    /// reads another full frame next.
    pub failed_initialisations: usize,
    /// Grabs that failed but may be retried (timeouts, dropped buffers).
    pub camera_errors: usize,
    /// The camera's end, if it ended the run before its last slot (disconnected, end of a recording).
    pub stopped_by: Option<GrabError>,
}
