//! [`BackgroundBag`]: a [`BagWriter`] on its own thread, so that serialising, compressing and writing the bag stay
//! off the tracking thread.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use roitrack_core::estimator::Estimate;
use roitrack_core::{Measurement, MotionState, Target};
use roitrack_formats::FormatError;
use roitrack_image::{Frame, RoiImage};

use crate::BagWriter;

/// Items handed over together: one wake-up of the writing thread per batch, not per estimate (a wake-up costs the
/// tracking thread more than copying an estimate).
const BATCH: usize = 32;
/// Batches in flight between the tracking thread and the writing thread; when the writer falls this far behind, the
/// tracking thread waits (nothing is dropped).
const IN_FLIGHT: usize = 64;
/// Most centroids in one measurements message: a run whose tracker has not started yet gives no estimate to close
/// the batch at.
const MAX_MEASUREMENTS_PER_MESSAGE: usize = 256;

// Estimates travel unboxed, by batches in a `Vec`: boxing each would cost an allocation per estimate.
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
    sender: Option<SyncSender<Vec<Item>>>,
    pending: Vec<Item>,
    /// The measurements since the last message of them.
    measurements: Vec<Measurement>,
    thread: Option<JoinHandle<Result<u64, FormatError>>>,
}

impl BackgroundBag {
    /// Moves `bag` to a thread of its own. `target`, if given, is projected by each frame's state into the frame's
    /// annotations (see [`BagWriter::write_frame`]).
    pub fn spawn(bag: BagWriter, target: Option<Target>) -> Self {
        let path = bag.path().to_path_buf();
        let (sender, receiver) = sync_channel(IN_FLIGHT);
        let thread = std::thread::Builder::new()
            .name("roitrack-bag".into())
            .spawn(move || run(bag, target, receiver))
            .expect("a thread can be started");
        Self {
            path,
            sender: Some(sender),
            pending: Vec::with_capacity(BATCH),
            measurements: Vec::new(),
            thread: Some(thread),
        }
    }

    /// The bag's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn send(&mut self, item: Item) -> Result<(), FormatError> {
        self.pending.push(item);
        if self.pending.len() < BATCH {
            return Ok(());
        }
        self.flush()
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

    /// Hands the pending items over.
    fn flush(&mut self) -> Result<(), FormatError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let batch = std::mem::replace(&mut self.pending, Vec::with_capacity(BATCH));
        let sent = match &self.sender {
            Some(sender) => sender.send(batch).is_ok(),
            None => false,
        };
        if sent {
            Ok(())
        } else {
            // The writing thread stopped: its error says why.
            Err(self.join().err().unwrap_or_else(|| {
                FormatError::new(&self.path, "the bag's writing thread has stopped")
            }))
        }
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
        let flushed = self.close_measurements().and_then(|()| self.flush());
        self.sender = None;
        let joined = match self.thread.take() {
            Some(thread) => thread.join().unwrap_or_else(|_| {
                Err(FormatError::new(
                    &self.path,
                    "the bag's writing thread panicked",
                ))
            }),
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
    receiver: Receiver<Vec<Item>>,
) -> Result<u64, FormatError> {
    // On an error the bag is dropped here, which completes it up to the last message written.
    for item in receiver.into_iter().flatten() {
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
    bag.finish()
}
