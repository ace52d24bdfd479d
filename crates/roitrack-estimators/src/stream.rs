//! Running an estimator over a stream of measurements: [`track`] (constant memory, estimates handed on as they
//! come, the readouts of a frame pushed whole) and [`track_all`] for measurements held in memory.

use roitrack_core::{CameraModel, Measurement, Target};
use thiserror::Error;

use crate::{
    ConfigError, Emit, Estimate, Estimator, EstimatorReport, TrackError, Tracker, TrackerConfig,
};

/// Why [`track`] stopped: a measurement could not be read (`S`), was refused, or an estimate could not be handed on
/// (`K`).
#[derive(Debug, Error)]
pub enum StreamError<S, K = S> {
    /// The source of measurements failed (a file that cannot be read, say).
    #[error(transparent)]
    Source(S),
    /// The estimator refused measurement number `index` (0-based) of the stream.
    #[error("measurement {index}: {source}")]
    Refused {
        /// The measurement's index in the stream (0-based).
        index: usize,
        /// Why the estimator refused it.
        #[source]
        source: TrackError,
    },
    /// The sink of estimates failed (a file that cannot be written, say).
    #[error(transparent)]
    Sink(K),
}

/// Runs `estimator` over a stream of measurements (times not decreasing), handing every estimate to `sink` as it
/// comes: constant memory whatever the stream's length. Returns the estimator's report.
///
/// Consecutive measurements that share a time (the blobs of a global-shutter frame) are one readout, pushed whole
/// ([`Estimator::push_batch`]): its estimate comes after the last of them, so no two estimates share a time and none
/// rests on half a frame, and the Kalman filter fits a readout of three or more together, as the frame tracker's
/// does. A readout of several measurements gives one estimate ([`Emit::EachBatch`]: one per frame, as the frame
/// tracker gives them, whatever [`TrackerConfig::every`] says); measurements that come one at a time (ROIs, a rolling
/// shutter's rows) one every `every` ([`Emit::Every`]). A readout longer than 4,096 measurements is pushed in
/// parts ([`Emit::Hold`] until its last), so memory stays bounded. When the estimator refuses a measurement of a readout
/// (which leaves it as it was), the ones before it are taken (as one readout, [`Estimator::first_refused`]) and the
/// error names the measurement refused by its place in the stream.
///
/// ```
/// use roitrack_estimators::{Tracker, TrackerConfig, track};
/// use roitrack_core::{CameraModel, Measurement, Target};
///
/// let mut tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), TrackerConfig::default()).unwrap();
/// let measurements = [Measurement { t_s: 0.0, id: 99, u_px: 1.0, v_px: 1.0 }];
/// let mut estimates = Vec::new();
/// let result = track(
///     &mut tracker,
///     measurements.iter().map(|m| Ok::<_, std::convert::Infallible>(*m)),
///     |e| Ok::<_, std::convert::Infallible>(estimates.push(*e)),
/// );
/// // Point 99 is not in the target: refused, with its place in the stream.
/// let error = result.unwrap_err().to_string();
/// assert!(error.starts_with("measurement 0: ") && error.contains("id 99"), "{error}");
/// ```
pub fn track<S, K>(
    estimator: &mut dyn Estimator,
    measurements: impl IntoIterator<Item = Result<Measurement, S>>,
    mut sink: impl FnMut(&Estimate) -> Result<(), K>,
) -> Result<EstimatorReport, StreamError<S, K>> {
    // Measurements that share a time are gathered; the readout they form is pushed (and an estimate given if one is
    // due) when a later time comes, or the stream ends. `first_index`: the stream index of its first measurement.
    let mut readout: Vec<Measurement> = Vec::with_capacity(64);
    let mut first_index = 0;
    // Whether the open readout holds several measurements (a frame), some of them maybe pushed already.
    let mut frame = false;
    // A frame's estimate comes with the frame, whatever `every` says (an estimate every 10 measurements would give
    // one every two or three frames of four dots); one measurement at a time, every `every`.
    let closing = |frame: bool| if frame { Emit::EachBatch } else { Emit::Every };
    for (index, m) in measurements.into_iter().enumerate() {
        let m = m.map_err(StreamError::Source)?;
        let same_time = readout.first().is_some_and(|r| r.t_s == m.t_s);
        if same_time {
            frame = true;
        }
        if !readout.is_empty() && (!same_time || readout.len() == MAX_READOUT) {
            let emit = if same_time {
                Emit::Hold
            } else {
                closing(frame)
            };
            push_readout(estimator, &readout, first_index, emit, &mut sink)?;
            readout.clear();
            frame &= same_time;
        }
        if readout.is_empty() {
            first_index = index;
        }
        readout.push(m);
    }
    if !readout.is_empty() {
        push_readout(estimator, &readout, first_index, closing(frame), &mut sink)?;
    }
    Ok(estimator.report())
}

/// The longest readout (measurements that share a time) that [`track`] pushes at once; a longer one goes in parts.
const MAX_READOUT: usize = 4096;

/// Pushes one readout of [`track`]'s stream (`first_index`: the stream index of its first measurement) and hands on
/// its estimate.
fn push_readout<S, K>(
    estimator: &mut dyn Estimator,
    readout: &[Measurement],
    first_index: usize,
    emit: Emit,
    sink: &mut impl FnMut(&Estimate) -> Result<(), K>,
) -> Result<(), StreamError<S, K>> {
    let refused_at = |index: usize| move |source| StreamError::Refused { index, source };
    let last_index = first_index + readout.len().saturating_sub(1);
    let result = match estimator.push_batch(readout, emit) {
        // A measurement was refused before any was taken: the ones before it are taken (as one readout) and the
        // error names it.
        Err(error) if !matches!(error, TrackError::ImplausibleFirstPose { .. }) => {
            let offset = estimator
                .first_refused(readout)
                .map_or(0, |(offset, _)| offset);
            if offset > 0 {
                estimator
                    .push_batch(&readout[..offset], Emit::Hold)
                    .map_err(refused_at(first_index + offset - 1))?;
            }
            return Err(refused_at(first_index + offset)(error));
        }
        // Taken; or taken and the estimate it closes refused (a first pose out of range): the readout's last.
        result => result,
    };
    match result.map_err(refused_at(last_index))? {
        Some(estimate) => sink(&estimate).map_err(StreamError::Sink),
        None => Ok(()),
    }
}

/// Runs the estimator that `config` chooses over measurements held in memory; returns every estimate and the report.
///
/// ```
/// use roitrack_estimators::{TrackerConfig, track_all};
/// use roitrack_core::{CameraModel, Target};
///
/// let (estimates, report) =
///     track_all(&CameraModel::canonical(), &Target::grid4x4(), TrackerConfig::default(), &[]).unwrap();
/// assert!(estimates.is_empty() && report.measurements == 0);
/// ```
pub fn track_all(
    camera: &CameraModel,
    target: &Target,
    config: TrackerConfig,
    measurements: &[Measurement],
) -> Result<(Vec<Estimate>, EstimatorReport), TrackAllError> {
    let mut tracker = Tracker::new(camera.clone(), target.clone(), config)?;
    let mut estimates = Vec::with_capacity(measurements.len() / config.every.max(1) + 1);
    let report = track(
        &mut tracker,
        measurements
            .iter()
            .map(|m| Ok::<_, std::convert::Infallible>(*m)),
        |e| {
            estimates.push(*e);
            Ok::<_, std::convert::Infallible>(())
        },
    )
    .map_err(|e| match e {
        StreamError::Refused { index, source } => TrackAllError::Refused { index, source },
        StreamError::Source(never) | StreamError::Sink(never) => match never {},
    })?;
    Ok((estimates, report))
}

/// Why [`track_all`] failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrackAllError {
    /// The tracker's configuration was refused.
    #[error("invalid tracker options: {0}")]
    Config(#[from] ConfigError),
    /// The estimator refused a measurement.
    #[error("measurement {index}: {source}")]
    Refused {
        /// The measurement's index in the slice (0-based).
        index: usize,
        /// Why the estimator refused it.
        #[source]
        source: TrackError,
    },
}
