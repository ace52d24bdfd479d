//! Tracking a stream of frames: the decoding on a thread of its own beside the tracker, and, with a rolling shutter,
//! each estimate refined with the twist of the poses around it before it is handed on.

use std::sync::mpsc;

use roitrack_core::Measurement;
use roitrack_image::Frame;
use thiserror::Error;

use super::{FrameError, FrameOutcome, FrameTrackReport, FrameTracker};
use crate::rs_smoothing::RollingSmoother;

/// Why [`track_frame_stream`] stopped: the source failed (`S`: an unreadable frame, a timestamps file that does not
/// match), a frame could not be processed, or an estimate could not be handed on (`K`). The estimates handed on before
/// are kept.
#[derive(Debug, Error)]
pub enum FrameStreamError<S, K, I> {
    /// `next_frame` returned this error.
    #[error(transparent)]
    Source(S),
    /// Frame number `index` (0-based), which `next_frame` described as `info`, could not be processed.
    #[error("frame {index}: {source}")]
    Frame {
        /// The frame's position in the stream (0-based).
        index: usize,
        /// What `next_frame` returned for it.
        info: I,
        /// Why the tracker refused it.
        #[source]
        source: FrameError,
    },
    /// `sink` returned this error.
    #[error(transparent)]
    Sink(K),
    /// `next_frame` panicked on the decoding thread (the frames it decoded before were tracked and handed to
    /// `sink`).
    #[error("the decoding thread panicked")]
    DecoderPanicked,
}

/// Frames decoded ahead of the tracker: enough to ride out a slow frame, few enough to bound memory.
const FRAMES_IN_FLIGHT: usize = 4;

/// Runs `tracker` over the frames `next_frame` decodes, the decoding on a thread of its own beside the tracker (the
/// two-thread loop): `next_frame` fills the frame it is given (a reused buffer, its `t_s` set) and returns what the
/// caller wants to know of it (a file name, say), `None` at the end. `sink` gets every frame's outcome with that
/// information and the centroids measured in the frame ([`FrameTracker::measurements`]: what the tracker saw, the
/// measurements its estimate rests on), in order. Returns the tracker's report; on an error, what was handed to `sink` stays handed.
/// With a rolling shutter ([`FrameTracker::smooths_rolling_shutter`]), each frame reaches `sink` four frames late, its
/// pose refitted with the twist of the poses around it ([`RollingSmoother`]); the frames held when the source ends or
/// fails are handed over before it returns.
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::Frame;
/// use roitrack_pipeline::frames::{FrameTracker, FrameTrackerConfig, track_frame_stream};
///
/// // Three black frames: no target, no estimate, no error.
/// let mut tracker =
///     FrameTracker::new(CameraModel::canonical(), Target::grid4x4(), FrameTrackerConfig::default()).unwrap();
/// let mut k = 0;
/// let next = move |frame: &mut Frame| {
///     k += 1;
///     (k <= 3).then(|| {
///         frame.resize(1024, 1024, 8);
///         frame.pixels.fill(0);
///         frame.t_s = k as f64 / 30.0;
///         Ok::<_, std::convert::Infallible>(k)
///     })
/// };
/// let mut seen = Vec::new();
/// let report = track_frame_stream(&mut tracker, next, |k, outcome, measured| {
///     assert!(measured.is_empty());
///     seen.push((*k, outcome.estimate.is_some()));
///     Ok::<_, std::convert::Infallible>(())
/// })
/// .unwrap();
/// assert_eq!(seen, vec![(1, false), (2, false), (3, false)]);
/// assert_eq!(report.not_found, 3);
/// ```
pub fn track_frame_stream<I, S, K>(
    tracker: &mut FrameTracker,
    next_frame: impl FnMut(&mut Frame) -> Option<Result<I, S>> + Send,
    sink: impl FnMut(&I, &FrameOutcome, &[Measurement]) -> Result<(), K>,
) -> Result<FrameTrackReport, FrameStreamError<S, K, I>>
where
    I: Send,
    S: Send,
{
    track_frame_stream_leaving_out(tracker, next_frame, sink, |_, _| false)
}

/// [`track_frame_stream`] for a live source, which must go on past a frame the tracker refuses: `leave_out` gets
/// each refused frame's information and why it was refused ([`FrameTracker::process`] refuses a frame before it
/// changes anything), and says whether to leave the frame out and go on (`true`) or stop with
/// [`FrameStreamError::Frame`] (`false`). A frame left out reaches neither the tracker's state nor `sink`.
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::Frame;
/// use roitrack_pipeline::frames::{FrameError, FrameTracker, FrameTrackerConfig, track_frame_stream_leaving_out};
///
/// // Black frames at 1, 3, 2 and 4 (x 1/30 s): the third goes back in time, is left out, and the stream goes on.
/// let mut tracker =
///     FrameTracker::new(CameraModel::canonical(), Target::grid4x4(), FrameTrackerConfig::default()).unwrap();
/// let times = [1.0, 3.0, 2.0, 4.0];
/// let mut k = 0;
/// let next = move |frame: &mut Frame| {
///     k += 1;
///     (k <= times.len()).then(|| {
///         frame.resize(1024, 1024, 8);
///         frame.pixels.fill(0);
///         frame.t_s = times[k - 1] / 30.0;
///         Ok::<_, std::convert::Infallible>(k)
///     })
/// };
/// let (mut seen, mut left_out) = (Vec::new(), Vec::new());
/// let report = track_frame_stream_leaving_out(
///     &mut tracker,
///     next,
///     |k, _, _| {
///         seen.push(*k);
///         Ok::<_, std::convert::Infallible>(())
///     },
///     |k, e| {
///         left_out.push(*k);
///         matches!(e, FrameError::TimeOrder { .. })
///     },
/// )
/// .unwrap();
/// assert_eq!((seen, left_out, report.frames), (vec![1, 2, 4], vec![3], 3));
/// ```
pub fn track_frame_stream_leaving_out<I, S, K>(
    tracker: &mut FrameTracker,
    next_frame: impl FnMut(&mut Frame) -> Option<Result<I, S>> + Send,
    mut sink: impl FnMut(&I, &FrameOutcome, &[Measurement]) -> Result<(), K>,
    mut leave_out: impl FnMut(&I, &FrameError) -> bool,
) -> Result<FrameTrackReport, FrameStreamError<S, K, I>>
where
    I: Send,
    S: Send,
{
    let (full_tx, full_rx) = mpsc::sync_channel::<Result<(Frame, I), S>>(FRAMES_IN_FLIGHT);
    let (empty_tx, empty_rx) = mpsc::channel::<Frame>();
    for _ in 0..FRAMES_IN_FLIGHT + 1 {
        let _ = empty_tx.send(Frame::default());
    }
    std::thread::scope(|scope| {
        let decoder = scope.spawn(move || decode_frames(next_frame, &empty_rx, &full_tx));
        let result = track_decoded(tracker, &full_rx, &empty_tx, &mut sink, &mut leave_out);
        // Unblocks a decoder waiting for a buffer or for room in the queue.
        drop(empty_tx);
        drop(full_rx);
        if decoder.join().is_err() {
            return Err(FrameStreamError::DecoderPanicked);
        }
        result
    })?;
    Ok(tracker.report())
}

/// The decoding thread: fills each empty buffer that comes back from the tracker with the next frame and sends it
/// on, until the source ends or fails or the tracker stops taking frames.
fn decode_frames<I, S>(
    mut next_frame: impl FnMut(&mut Frame) -> Option<Result<I, S>>,
    empty_rx: &mpsc::Receiver<Frame>,
    full_tx: &mpsc::SyncSender<Result<(Frame, I), S>>,
) {
    // Buffers come back from the tracker once used; when it stops taking frames (an error), stop too.
    while let Ok(mut frame) = empty_rx.recv() {
        match next_frame(&mut frame) {
            None => break,
            Some(Ok(info)) => {
                if full_tx.send(Ok((frame, info))).is_err() {
                    break;
                }
            }
            Some(Err(e)) => {
                let _ = full_tx.send(Err(e));
                break;
            }
        }
    }
}

/// The tracking side of [`track_frame_stream`]: each decoded frame through `tracker` (its buffer sent back to the
/// decoder), its outcome to `sink`, through the rolling-shutter smoother when the tracker smooths.
fn track_decoded<I, S, K>(
    tracker: &mut FrameTracker,
    full_rx: &mpsc::Receiver<Result<(Frame, I), S>>,
    empty_tx: &mpsc::Sender<Frame>,
    sink: &mut impl FnMut(&I, &FrameOutcome, &[Measurement]) -> Result<(), K>,
    leave_out: &mut impl FnMut(&I, &FrameError) -> bool,
) -> Result<(), FrameStreamError<S, K, I>> {
    let mut result = Ok(());
    // Offline, a rolling shutter's estimates come four frames late, refined (FrameTrackerConfig::rs_smoothing).
    let mut smoother = tracker
        .smooths_rolling_shutter()
        .then(|| RollingSmoother::new(tracker.camera().clone(), tracker.target.clone()));
    for (index, item) in full_rx.iter().enumerate() {
        let (frame, info) = match item {
            Ok(item) => item,
            Err(e) => {
                result = Err(FrameStreamError::Source(e));
                break;
            }
        };
        let outcome = match tracker.process(&frame) {
            Ok(outcome) => outcome,
            Err(source) if leave_out(&info, &source) => {
                let _ = empty_tx.send(frame);
                continue;
            }
            Err(source) => {
                result = Err(FrameStreamError::Frame {
                    index,
                    info,
                    source,
                });
                break;
            }
        };
        let _ = empty_tx.send(frame);
        let sunk = match &mut smoother {
            Some(smoother) => match smoother.push(info, outcome, tracker.measurements()) {
                Some((info, outcome, measured)) => sink(&info, &outcome, &measured),
                None => Ok(()),
            },
            None => sink(&info, &outcome, tracker.measurements()),
        };
        if let Err(e) = sunk {
            result = Err(FrameStreamError::Sink(e));
            break;
        }
    }
    // The frames still held, also when the source or a frame failed: what was estimated before is kept.
    if let Some(smoother) = &mut smoother
        && !matches!(result, Err(FrameStreamError::Sink(_)))
    {
        for (info, outcome, measured) in smoother.finish() {
            if let Err(e) = sink(&info, &outcome, &measured) {
                result = Err(FrameStreamError::Sink(e));
                break;
            }
        }
    }
    result
}
