//! The estimation thread of the loop: each queued measurement to the tracker, each estimate back as a [`Predictor`].

use std::sync::atomic::{AtomicBool, Ordering};

use roitrack_core::Measurement;
use roitrack_estimators::{Estimate, Estimator, Tracker};

use super::known_acceleration::KnownAccelerationReceiver;
use super::{Event, LoopConfig, backoff, full_frame_covariance};
use crate::scheduler::Predictor;

/// The estimation thread's ends of the two queues, and the camera side's signal that it is done.
pub(super) struct EstimationQueues<'a> {
    pub(super) measurements: &'a mut rtrb::Consumer<Event>,
    pub(super) predictors: &'a mut rtrb::Producer<Predictor>,
    pub(super) camera_done: &'a AtomicBool,
    pub(super) known_acceleration: Option<&'a mut KnownAccelerationReceiver>,
}

/// What the estimation thread hands back when the camera side is done and the queue is empty.
pub(super) struct EstimationSide {
    pub(super) estimates: Vec<Estimate>,
    pub(super) latencies_us: Vec<f64>,
    pub(super) refused: usize,
    pub(super) known_accelerations: usize,
    pub(super) refused_known_accelerations: usize,
    pub(super) measured: Vec<Measurement>,
}

/// The estimation thread: feeds each queued measurement to the tracker and sends each estimate back as a
/// [`Predictor`], until the camera side is done and the queue is empty. Its vectors are sized before the run (the
/// steady state does not allocate); estimates beyond `expected_estimates` reach `on_estimate` but are not kept.
pub(super) fn run_estimation(
    tracker: &mut Tracker,
    queues: EstimationQueues<'_>,
    config: &LoopConfig,
    expected_estimates: usize,
    on_estimate: &mut (dyn FnMut(&Estimate) + Send),
) -> EstimationSide {
    let mut estimates = Vec::with_capacity(expected_estimates);
    let mut latencies_us = Vec::with_capacity(expected_estimates);
    let mut refused = 0usize;
    let mut measured = Vec::with_capacity(if config.keep_measurements {
        config.roi_slots
    } else {
        0
    });
    let EstimationQueues {
        measurements,
        predictors,
        camera_done,
        mut known_acceleration,
    } = queues;
    let (mut told, mut refused_known) = (0usize, 0usize);
    let mut spins = 0u32;
    loop {
        // Every known acceleration sent so far, before the next measurement: the control thread sent it before the
        // camera side queued what follows, so its input is in the prediction of the measurements after it.
        if let Some(receiver) = known_acceleration.as_deref_mut() {
            while let Some(input) = receiver.pop() {
                match tracker.set_known_acceleration(input.t_s, input.acceleration) {
                    Ok(()) => told += 1,
                    Err(_) => refused_known += 1,
                }
            }
        }
        match measurements.pop() {
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
                        // If the camera side has not taken the previous ones, this one is skipped: it will get the
                        // next.
                        let _ = predictors.push(Predictor {
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
            Ok(Event::Passed { .. }) => {}
            Err(_) => {
                if camera_done.load(Ordering::Acquire) && measurements.is_empty() {
                    break;
                }
                backoff(&mut spins);
            }
        }
    }
    EstimationSide {
        estimates,
        latencies_us,
        refused,
        known_accelerations: told,
        refused_known_accelerations: refused_known,
        measured,
    }
}
