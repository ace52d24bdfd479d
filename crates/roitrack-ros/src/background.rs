//! [`BackgroundBag`]: a [`BagWriter`] on its own thread, so that serialising, compressing and writing the bag stay
//! off the tracking thread.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use roitrack_core::{Measurement, MotionState, Target};
use roitrack_estimators::Estimate;
use roitrack_formats::FormatError;
use roitrack_image::{Frame, RoiImage};

use crate::BagWriter;

/// Items in flight between the tracking thread and the writing thread (an estimate is about 1.4 KB); when the writer
/// falls this far behind, the tracking thread waits (nothing is dropped).
const IN_FLIGHT: usize = 1024;
/// Frames in flight, whatever room the ring has: a frame is megabytes, and a writer slower than the tracker must not
/// hold a thousand of them.
const FRAMES_IN_FLIGHT: usize = 8;
/// How long the writing thread sleeps when it has written everything handed over. It is never woken by the
/// tracking thread while there is room: a wake-up (a futex call and, on a virtual machine, an interrupt to the other
/// core) cost the tracking thread more than the whole hand-over when the queue was a channel woken per batch.
const IDLE_SLEEP: Duration = Duration::from_millis(1);
/// Most centroids in one measurements message: a run whose tracker has not started yet gives no estimate to close
/// the batch at.
const MAX_MEASUREMENTS_PER_MESSAGE: usize = 256;

// Estimates travel unboxed in a ring allocated once: boxing each would cost an allocation per estimate.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum Item {
    Estimate(Estimate),
    Frame(Box<Frame>, Option<MotionState>, Vec<Measurement>),
    Measurements(Vec<Measurement>),
    Roi(RoiImage, Option<Measurement>),
}

/// A [`BagWriter`] driven from another thread: [`write_estimate`](Self::write_estimate) and
/// [`write_frame`](Self::write_frame) hand a copy over a bounded queue, the writing thread serialises and writes it.
/// Messages keep their order. An error of the writing thread (a full disk) is reported by the next estimate, frame or
/// ROI handed over (centroids are only gathered until then) or by [`finish`](Self::finish), and every call after
/// that says it again; the bag is completed (chunks, summary) by `finish`, or when this is dropped (an early
/// return, a panic), after every message handed over so far.
///
/// ```
/// use roitrack_ros::{BackgroundBag, BagOptions, BagWriter};
/// use roitrack_estimators::{Estimate, TrackStatus};
/// use roitrack_core::{CameraModel, MotionState};
///
/// let dir = tempfile::tempdir().unwrap();
/// let bag = BagWriter::create(dir.path().join("run.mcap"), &BagOptions::default(), Some(CameraModel::canonical()));
/// let mut bag = BackgroundBag::spawn(bag.unwrap(), None);
/// let state = MotionState::at_rest(Default::default(), nalgebra::Vector3::new(0.0, 0.0, 0.6));
/// let estimate = Estimate {
///     t_ref_s: 0.5, state, residual_rms_px: 0.1, inverse_condition: 0.2, measurements_used: 16,
///     iterations: 1, status: TrackStatus::Tracking, covariance: None, noise_px: 0.1, acceleration: None,
/// };
/// bag.write_estimate(&estimate).unwrap();
/// assert_eq!(bag.finish().unwrap(), 6);
/// ```
#[derive(Debug)]
pub struct BackgroundBag {
    path: PathBuf,
    queue: rtrb::Producer<Item>,
    /// Set when nothing more will be handed over: the writing thread then empties the queue and completes the bag.
    closed: Arc<AtomicBool>,
    /// The measurements since the last message of them.
    measurements: Vec<Measurement>,
    /// Frames handed over and not yet written.
    frames_in_flight: Arc<AtomicUsize>,
    thread: Option<JoinHandle<Result<u64, FormatError>>>,
    /// Why the writing thread stopped, once its error has been reported: what later calls report.
    stopped: Option<String>,
}

impl BackgroundBag {
    /// Moves `bag` to a thread of its own. `target`, if given, is projected by each frame's state into the frame's
    /// annotations (see [`BagWriter::write_frame`]).
    pub fn spawn(bag: BagWriter, target: Option<Target>) -> Self {
        let path = bag.path().to_path_buf();
        let (queue, receiver) = rtrb::RingBuffer::new(IN_FLIGHT);
        let closed = Arc::new(AtomicBool::new(false));
        let frames_in_flight = Arc::new(AtomicUsize::new(0));
        let thread = {
            let closed = Arc::clone(&closed);
            let frames_in_flight = Arc::clone(&frames_in_flight);
            std::thread::Builder::new()
                .name("roitrack-bag".into())
                .spawn(move || run(bag, target, receiver, &closed, &frames_in_flight))
                .expect("a thread can be started")
        };
        Self {
            path,
            queue,
            closed,
            measurements: Vec::new(),
            frames_in_flight,
            thread: Some(thread),
            stopped: None,
        }
    }

    /// The bag's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Waits for the writing thread to end and says why it stopped: its own error the first time, then what that
    /// error said.
    fn stopped_error(&mut self) -> FormatError {
        let error = match self.thread.take() {
            Some(thread) => match thread.join() {
                Ok(Err(e)) => e,
                Ok(Ok(_)) => FormatError::new(&self.path, "the bag's writing thread has stopped"),
                Err(_) => FormatError::new(&self.path, "the bag's writing thread panicked"),
            },
            None => FormatError::new(
                &self.path,
                match &self.stopped {
                    Some(why) => format!("the bag's writing thread stopped earlier: {why}"),
                    None => "the bag was already completed".into(),
                },
            ),
        };
        self.stopped.get_or_insert_with(|| error.to_string());
        error
    }

    /// Waits a little for the writer: wakes it first if it sleeps.
    fn wait_for_writer(&self, waits: &mut u32) {
        if *waits == 0
            && let Some(thread) = &self.thread
        {
            thread.thread().unpark();
        }
        if *waits < 64 {
            std::hint::spin_loop();
        } else {
            std::thread::sleep(Duration::from_micros(50));
        }
        *waits = waits.saturating_add(1);
    }

    fn send(&mut self, mut item: Item) -> Result<(), FormatError> {
        let mut waits = 0u32;
        loop {
            if self.queue.is_abandoned() {
                // The writing thread stopped: its error says why.
                return Err(self.stopped_error());
            }
            match self.queue.push(item) {
                Ok(()) => return Ok(()),
                Err(rtrb::PushError::Full(back)) => {
                    // The writer is behind: wait for room.
                    item = back;
                    self.wait_for_writer(&mut waits);
                }
            }
        }
    }

    /// Closes the open batch of measurements: one message of them.
    fn close_measurements(&mut self) -> Result<(), FormatError> {
        if self.measurements.is_empty() {
            return Ok(());
        }
        // The next batch starts at this one's size: one allocation per message.
        let capacity = self.measurements.capacity();
        let batch = std::mem::replace(&mut self.measurements, Vec::with_capacity(capacity));
        self.send(Item::Measurements(batch))
    }

    /// Hands an estimate over (see [`BagWriter::write_estimate`]), after the measurements handed over before it as
    /// one message.
    pub fn write_estimate(&mut self, estimate: &Estimate) -> Result<(), FormatError> {
        self.close_measurements()?;
        self.send(Item::Estimate(*estimate))
    }

    /// Adds measured centroids to the open batch of `/roitrack/measurements`: a batch is written as one message
    /// (see [`BagWriter::write_measurements`]) when the next estimate or frame is handed over, when it holds 256
    /// centroids, and at the end.
    pub fn write_measurements(&mut self, measurements: &[Measurement]) -> Result<(), FormatError> {
        self.measurements.extend_from_slice(measurements);
        if self.measurements.len() >= MAX_MEASUREMENTS_PER_MESSAGE {
            self.close_measurements()?;
        }
        Ok(())
    }

    /// Hands a frame over, with the state of its estimate if it has one and the centroids measured in it (see
    /// [`BagWriter::write_frame`]); the measurements handed over before it are closed into one message first.
    pub fn write_frame(
        &mut self,
        frame: Frame,
        state: Option<&MotionState>,
        measured: &[Measurement],
    ) -> Result<(), FormatError> {
        self.close_measurements()?;
        let mut waits = 0u32;
        while self.frames_in_flight.load(Ordering::Acquire) >= FRAMES_IN_FLIGHT {
            if self.queue.is_abandoned() {
                return Err(self.stopped_error());
            }
            self.wait_for_writer(&mut waits);
        }
        self.frames_in_flight.fetch_add(1, Ordering::AcqRel);
        self.send(Item::Frame(
            Box::new(frame),
            state.copied(),
            measured.to_vec(),
        ))
    }

    /// Hands a ROI image over with the centroid measured in it, if any (see [`BagWriter::write_roi`]).
    pub fn write_roi(
        &mut self,
        image: &RoiImage,
        measured: Option<&Measurement>,
    ) -> Result<(), FormatError> {
        self.send(Item::Roi(image.clone(), measured.copied()))
    }

    fn join(&mut self) -> Result<u64, FormatError> {
        // A refused hand-over already carries the writing thread's own error.
        let flushed = self.close_measurements();
        self.closed.store(true, Ordering::Release);
        if let Some(thread) = &self.thread {
            thread.thread().unpark();
        }
        let joined = match self.thread.take() {
            Some(thread) => thread.join().unwrap_or_else(|_| {
                Err(FormatError::new(
                    &self.path,
                    "the bag's writing thread panicked",
                ))
            }),
            None => Err(self.stopped_error()),
        };
        flushed.and(joined)
    }

    /// Waits for every message to be written, completes the bag and says how many messages it holds.
    pub fn finish(mut self) -> Result<u64, FormatError> {
        self.join()
    }
}

impl Drop for BackgroundBag {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.join();
        }
    }
}

fn run(
    mut bag: BagWriter,
    target: Option<Target>,
    mut queue: rtrb::Consumer<Item>,
    closed: &AtomicBool,
    frames_in_flight: &AtomicUsize,
) -> Result<u64, FormatError> {
    // On an error the bag is dropped here, which completes it up to the last message written.
    loop {
        // Read before emptying the queue: what was handed over before the close is then written too.
        let last = closed.load(Ordering::Acquire);
        while let Ok(item) = queue.pop() {
            match item {
                Item::Estimate(estimate) => bag.write_estimate(&estimate)?,
                Item::Frame(frame, state, measured) => {
                    let projection = state.as_ref().zip(target.as_ref());
                    let written = bag.write_frame(&frame, projection, &measured);
                    frames_in_flight.fetch_sub(1, Ordering::AcqRel);
                    written?;
                }
                Item::Measurements(batch) => bag.write_measurements(&batch)?,
                Item::Roi(image, measured) => bag.write_roi(&image, measured.as_ref())?,
            }
        }
        if last {
            return bag.finish();
        }
        std::thread::park_timeout(IDLE_SLEEP);
    }
}

#[cfg(test)]
mod tests {
    use roitrack_core::{CameraModel, MotionState};
    use roitrack_estimators::TrackStatus;
    use roitrack_image::Roi;

    use super::*;
    use crate::BagOptions;

    fn estimate_at(t_ref_s: f64) -> Estimate {
        Estimate {
            t_ref_s,
            state: MotionState::at_rest(Default::default(), nalgebra::Vector3::new(0.0, 0.0, 0.6)),
            residual_rms_px: 0.1,
            inverse_condition: 0.2,
            measurements_used: 16,
            iterations: 1,
            status: TrackStatus::Tracking,
            covariance: None,
            noise_px: 0.1,
            acceleration: None,
        }
    }

    /// A bag whose writing thread has failed: an estimate at -1 s cannot be a ROS stamp.
    fn failed_bag(dir: &tempfile::TempDir) -> BackgroundBag {
        let bag = BagWriter::create(
            dir.path().join("run.mcap"),
            &BagOptions::default(),
            Some(CameraModel::canonical()),
        )
        .unwrap();
        let mut bag = BackgroundBag::spawn(bag, None);
        bag.write_estimate(&estimate_at(-1.0)).unwrap();
        // The writer sleeps up to 1 ms between looks at its queue: wait until it has seen the estimate and stopped.
        while !bag.queue.is_abandoned() {
            std::thread::sleep(Duration::from_millis(1));
        }
        bag
    }

    fn a_measurement() -> Measurement {
        Measurement {
            t_s: 0.0,
            id: 0,
            u_px: 1.0,
            v_px: 1.0,
        }
    }

    fn is_the_stamp_error(error: &FormatError) -> bool {
        let text = error.to_string();
        text.contains("run.mcap") && text.contains("stamp") && !text.contains("already completed")
    }

    #[test]
    fn the_writing_threads_error_is_what_finish_reports_with_measurements_pending() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = failed_bag(&dir);
        let m = a_measurement();
        // Measurements are only gathered (no check per centroid, which would cost the tracking thread): the next
        // estimate handed over reports the writer's error.
        bag.write_measurements(&[m]).unwrap();
        let refused = bag.write_estimate(&estimate_at(1.0)).unwrap_err();
        assert!(is_the_stamp_error(&refused), "{refused}");
        // Later calls say what it said.
        let later = bag.write_estimate(&estimate_at(2.0)).unwrap_err();
        assert!(
            later.to_string().contains("stopped earlier") && later.to_string().contains("stamp"),
            "{later}"
        );
        let finished = bag.finish().unwrap_err();
        assert!(finished.to_string().contains("stamp"), "{finished}");
    }

    #[test]
    fn finish_reports_the_writing_threads_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = failed_bag(&dir);
        bag.measurements.push(a_measurement());
        let error = bag.finish().unwrap_err();
        assert!(is_the_stamp_error(&error), "{error}");
    }

    #[test]
    fn a_roi_handed_over_after_a_failure_reports_it() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = failed_bag(&dir);
        let image = RoiImage {
            t_s: 0.0,
            point_id: 0,
            roi: Roi::new(0, 0, 4, 4),
            bit_depth: 8,
            pixels: vec![0; 16],
        };
        let error = bag.write_roi(&image, None).unwrap_err();
        assert!(is_the_stamp_error(&error), "{error}");
    }
}
