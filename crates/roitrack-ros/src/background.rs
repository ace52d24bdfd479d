//! [`BackgroundBag`]: a [`BagWriter`] on its own thread, so that serialising, compressing and writing the bag stay
//! off the tracking thread.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use roitrack_core::estimator::Estimate;
use roitrack_core::{Measurement, MotionState, Target};
use roitrack_formats::FormatError;
use roitrack_image::{Frame, RoiImage};

use crate::BagWriter;

/// Items in flight between the tracking thread and the writing thread (about 1.4 KB each); when the writer falls
/// this far behind, the tracking thread waits (nothing is dropped).
const IN_FLIGHT: usize = 1024;
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
/// Messages keep their order. An error of the writing thread (a full disk) is reported by the next call or by
/// [`finish`](Self::finish); the bag is completed (chunks, summary) by `finish`, or when this is dropped (an early
/// return, a panic), after every message handed over so far.
///
/// ```
/// use roitrack_ros::{BackgroundBag, BagOptions, BagWriter};
/// use roitrack_core::estimator::{Estimate, TrackStatus};
/// use roitrack_core::{CameraModel, MotionState};
///
/// let dir = tempfile::tempdir().unwrap();
/// let bag = BagWriter::create(dir.path().join("run.mcap"), &BagOptions::default(), Some(CameraModel::canonical()));
/// let mut bag = BackgroundBag::spawn(bag.unwrap(), None);
/// let state = MotionState::at_rest(Default::default(), nalgebra::Vector3::new(0.0, 0.0, 0.6));
/// let estimate = Estimate {
///     t_ref_s: 0.5, state, residual_rms_px: 0.1, inverse_condition: 0.2, measurements_used: 16,
///     iterations: 1, status: TrackStatus::Tracking, covariance: None, noise_px: 0.1,
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
    thread: Option<JoinHandle<Result<u64, FormatError>>>,
}

impl BackgroundBag {
    /// Moves `bag` to a thread of its own. `target`, if given, is projected by each frame's state into the frame's
    /// annotations (see [`BagWriter::write_frame`]).
    pub fn spawn(bag: BagWriter, target: Option<Target>) -> Self {
        let path = bag.path().to_path_buf();
        let (queue, receiver) = rtrb::RingBuffer::new(IN_FLIGHT);
        let closed = Arc::new(AtomicBool::new(false));
        let thread = {
            let closed = Arc::clone(&closed);
            std::thread::Builder::new()
                .name("roitrack-bag".into())
                .spawn(move || run(bag, target, receiver, &closed))
                .expect("a thread can be started")
        };
        Self {
            path,
            queue,
            closed,
            measurements: Vec::new(),
            thread: Some(thread),
        }
    }

    /// The bag's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn send(&mut self, mut item: Item) -> Result<(), FormatError> {
        let mut waits = 0u32;
        loop {
            if self.queue.is_abandoned() {
                // The writing thread stopped: its error says why.
                return Err(self.join().err().unwrap_or_else(|| {
                    FormatError::new(&self.path, "the bag's writing thread has stopped")
                }));
            }
            match self.queue.push(item) {
                Ok(()) => return Ok(()),
                Err(rtrb::PushError::Full(back)) => {
                    item = back;
                    // The writer is behind: wake it if it sleeps, then wait for room.
                    if waits == 0
                        && let Some(thread) = &self.thread
                    {
                        thread.thread().unpark();
                    }
                    if waits < 64 {
                        std::hint::spin_loop();
                    } else {
                        std::thread::sleep(Duration::from_micros(50));
                    }
                    waits = waits.saturating_add(1);
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
        let flushed = self.close_measurements();
        self.closed.store(true, Ordering::Release);
        let joined = match self.thread.take() {
            Some(thread) => {
                thread.thread().unpark();
                thread.join().unwrap_or_else(|_| {
                    Err(FormatError::new(
                        &self.path,
                        "the bag's writing thread panicked",
                    ))
                })
            }
            None => Err(FormatError::new(
                &self.path,
                "the bag was already completed",
            )),
        };
        // The writing thread's own error says more than a refused hand-over.
        match (flushed, joined) {
            (_, Err(e)) | (Err(e), Ok(_)) => Err(e),
            (Ok(()), Ok(messages)) => Ok(messages),
        }
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
                    bag.write_frame(&frame, projection, &measured)?;
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
