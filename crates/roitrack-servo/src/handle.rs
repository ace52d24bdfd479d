//! The newest estimate for a user's control thread, read without locks or allocation: a sequence lock over a
//! fixed-size block of atomic words ([`estimate_channel`]).
//!
//! The tracker's thread publishes each estimate ([`EstimatePublisher::publish`]); any number of control threads read
//! the newest ([`EstimateReader::read`]) and predict it to their actuation instant with its covariance
//! ([`EstimateSnapshot::at`]). A read copies about a hundred words and retries if a publication overlapped it (at
//! 400 estimates a second and a read of tens of nanoseconds, rarely); the publisher never waits.
//!
//! Why a sequence lock of atomics rather than a crate: `triple_buffer` is wait-free but has one reader (its `read`
//! takes `&mut`), `arc-swap` allocates an `Arc` at every publication, and the `seqlock` crate reads its data with
//! volatile non-atomic loads, a data race in Rust's memory model. Here every word is an `AtomicU64` (the f64's bits),
//! so there is no `unsafe`, and the fences are the standard sequence-lock ones (writer: odd count, release fence,
//! relaxed stores, release count; reader: acquire count, relaxed loads, acquire fence, relaxed count).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering, fence};

use nalgebra::{Rotation3, Vector3};
use roitrack_core::MotionState;
use roitrack_estimators::{Estimate, Matrix12};

/// Words of a snapshot: t_ref, R (9), t (3), V (3), W (3), a flag, the covariance (144, column-major). The whole matrix
/// rather than its upper triangle: the reader then copies it in one slice instead of mirroring 78 entries, a sizeable
/// part of a read (measured in docs/results.md, "Design measurements behind the code").
const WORDS: usize = 1 + 9 + 3 + 3 + 3 + 1 + 144;
/// Where the covariance starts.
const COVARIANCE_AT: usize = 20;

struct Shared {
    sequence: AtomicU64,
    words: [AtomicU64; WORDS],
}

/// The tracker's end (one: publishing takes `&mut self`).
pub struct EstimatePublisher {
    shared: Arc<Shared>,
}

/// A control thread's end; clone one per thread.
#[derive(Clone)]
pub struct EstimateReader {
    shared: Arc<Shared>,
}

/// The newest estimate as read: its state at `t_ref_s`, its covariance (error state `(v, w, dV, dW)`, as
/// [`Estimate::covariance`]) and its publication number (1 for the first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateSnapshot {
    /// The time the estimate refers to (s).
    pub t_ref_s: f64,
    /// The pose and twist there (camera frame).
    pub state: MotionState,
    /// Its covariance, if the estimator gave one.
    pub covariance: Option<Matrix12>,
    /// Its publication number: 1 for the first, then one more for each.
    pub sequence: u64,
}

impl EstimateSnapshot {
    /// The state at `t_s` under the estimate's constant twist, and its covariance carried along (`F P Fᵀ`, with
    /// [`MotionState::transition_jacobian`]; without process noise: the uncertainty of the estimate itself, which a
    /// caller who knows the motion's process noise adds to).
    pub fn at(&self, t_s: f64) -> (MotionState, Option<Matrix12>) {
        let dt_s = t_s - self.t_ref_s;
        let f = self.state.transition_jacobian(dt_s);
        (
            self.state.predicted(dt_s),
            self.covariance.map(|p| f * p * f.transpose()),
        )
    }
}

/// A publisher and a reader of the same slot, empty until the first publication.
///
/// ```
/// use roitrack_estimators::{Estimate, TrackStatus};
/// use roitrack_core::MotionState;
/// use roitrack_servo::handle::estimate_channel;
///
/// let (mut publisher, reader) = estimate_channel();
/// assert!(reader.read().is_none());
/// let mut state = MotionState::bench();
/// state.velocity_mps.x = 1.0;
/// publisher.publish(&Estimate {
///     t_ref_s: 1.0,
///     state,
///     residual_rms_px: 0.0,
///     inverse_condition: 1.0,
///     measurements_used: 16,
///     iterations: 1,
///     status: TrackStatus::Tracking,
///     covariance: None,
///     noise_px: 0.1,
///     acceleration: None,
/// });
/// let newest = reader.read().unwrap();
/// let (at_actuation, _) = newest.at(1.002);
/// assert!((at_actuation.cam_t_obj_m.x - (state.cam_t_obj_m.x + 0.002)).abs() < 1e-12);
/// ```
pub fn estimate_channel() -> (EstimatePublisher, EstimateReader) {
    let shared = Arc::new(Shared {
        sequence: AtomicU64::new(0),
        words: std::array::from_fn(|_| AtomicU64::new(0)),
    });
    (
        EstimatePublisher {
            shared: Arc::clone(&shared),
        },
        EstimateReader { shared },
    )
}

fn encode(estimate: &Estimate) -> [f64; WORDS] {
    let mut w = [0.0; WORDS];
    let s = &estimate.state;
    w[0] = estimate.t_ref_s;
    w[1..10].copy_from_slice(s.cam_r_obj.matrix().as_slice());
    w[10..13].copy_from_slice(s.cam_t_obj_m.as_slice());
    w[13..16].copy_from_slice(s.velocity_mps.as_slice());
    w[16..19].copy_from_slice(s.angular_velocity_radps.as_slice());
    if let Some(p) = &estimate.covariance {
        w[19] = 1.0;
        w[COVARIANCE_AT..].copy_from_slice(p.as_slice());
    }
    w
}

fn decode(w: &[f64; WORDS], sequence: u64) -> EstimateSnapshot {
    let covariance = (w[19] != 0.0).then(|| Matrix12::from_column_slice(&w[COVARIANCE_AT..]));
    EstimateSnapshot {
        t_ref_s: w[0],
        state: MotionState {
            cam_r_obj: Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_column_slice(
                &w[1..10],
            )),
            cam_t_obj_m: Vector3::from_column_slice(&w[10..13]),
            velocity_mps: Vector3::from_column_slice(&w[13..16]),
            angular_velocity_radps: Vector3::from_column_slice(&w[16..19]),
        },
        covariance,
        sequence,
    }
}

impl EstimatePublisher {
    /// Makes `estimate` the newest: wait-free, no allocation.
    pub fn publish(&mut self, estimate: &Estimate) {
        let words = encode(estimate);
        let shared = &self.shared;
        // Odd while writing; the release fence keeps the data stores after the odd count.
        let start = shared.sequence.fetch_add(1, Ordering::Relaxed);
        fence(Ordering::Release);
        for (slot, value) in shared.words.iter().zip(words) {
            slot.store(value.to_bits(), Ordering::Relaxed);
        }
        shared.sequence.store(start + 2, Ordering::Release);
    }
}

impl EstimateReader {
    /// The newest estimate, `None` before the first: lock-free (retries while a publication overlaps), no
    /// allocation.
    pub fn read(&self) -> Option<EstimateSnapshot> {
        let shared = &self.shared;
        let mut words = [0.0; WORDS];
        loop {
            let before = shared.sequence.load(Ordering::Acquire);
            if before == 0 {
                return None;
            }
            if before % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            for (value, slot) in words.iter_mut().zip(&shared.words) {
                *value = f64::from_bits(slot.load(Ordering::Relaxed));
            }
            fence(Ordering::Acquire);
            if shared.sequence.load(Ordering::Relaxed) == before {
                return Some(decode(&words, before / 2));
            }
        }
    }

    /// The newest estimate predicted to `t_s` with its covariance ([`EstimateSnapshot::at`]), and the time it
    /// refers to; `None` before the first.
    pub fn predicted_to(&self, t_s: f64) -> Option<(f64, MotionState, Option<Matrix12>)> {
        self.read().map(|snapshot| {
            let (state, covariance) = snapshot.at(t_s);
            (snapshot.t_ref_s, state, covariance)
        })
    }
}
