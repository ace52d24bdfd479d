//! A known control input of the Kalman filter's prediction: the target's acceleration as whoever drives it commands
//! it ([`KnownAcceleration`]), used in every prediction as `x' = F x + B u`.

use super::*;
use thiserror::Error;

/// The most entries a `KnownAcceleration` holds ahead of the filter: a controller at 4 kHz whose commands act a
/// few ticks after they are given keeps a handful; a caller that gives commands and no measurements is told
/// ([`KnownAccelerationError::TooMany`]) instead of growing the schedule without bound.
pub const KNOWN_ACCELERATION_CAPACITY: usize = 4096;

/// Why [`crate::Estimator::set_known_acceleration`] refused an input. The estimator is unchanged.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum KnownAccelerationError {
    /// The time or a component of the acceleration is NaN or infinite.
    #[error("known acceleration from t = {t_s} s: not finite")]
    NotFinite {
        /// The time given (s).
        t_s: f64,
    },
    /// The time is before that of the newest input given (inputs come in time order; one at the same time
    /// replaces it).
    #[error("known acceleration from t = {t_s} s: before the newest one given, from {newest_s} s")]
    OutOfOrder {
        /// The time given (s).
        t_s: f64,
        /// The newest input's time (s).
        newest_s: f64,
    },
    /// [`KNOWN_ACCELERATION_CAPACITY`] inputs are already waiting for the measurements to reach them.
    #[error(
        "known acceleration from t = {t_s} s: {capacity} inputs already wait for the measurements to reach them"
    )]
    TooMany {
        /// The time given (s).
        t_s: f64,
        /// [`KNOWN_ACCELERATION_CAPACITY`].
        capacity: usize,
    },
    /// The estimator has no prediction to give it to (only the Kalman filter has).
    #[error("the {estimator} estimator takes no known acceleration (only the Kalman filter does)")]
    Unsupported {
        /// The estimator's name.
        estimator: &'static str,
    },
}

/// The target's acceleration known from outside the filter (a control input), piecewise constant: each entry holds
/// from its time until the next one's. Before the first entry the known acceleration is zero.
///
/// The filter predicts with it on top of its own motion model: a constant-velocity filter moves its state with
/// the known acceleration (`t + V dt + ½ u dt²`, `V + u dt`, and the same for the rotation); a constant-acceleration
/// filter with the sum of its estimated acceleration and the known one, so that its own acceleration estimates what
/// the input does not explain. The process noise is unchanged: it now stands for the difference between the input and
/// the target's true acceleration. The covariance's propagation `F P Fᵀ + Q` is unchanged by a linear input (`F` does
/// not depend on the linear acceleration); an angular input enters `F` through the rotation increment
/// `W dt + ½ Α dt²` (see `Transition`).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct KnownAcceleration {
    /// (from time, acceleration) in time order; the first one may have started before the filter's time.
    entries: Vec<(f64, Acceleration)>,
}

impl KnownAcceleration {
    /// Whether no input was given (the filter predicts as it always did).
    pub(crate) fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Adds `acceleration` from `t_s` on (replacing an entry of the same time).
    pub(crate) fn set(
        &mut self,
        t_s: f64,
        acceleration: Acceleration,
    ) -> Result<(), KnownAccelerationError> {
        let finite = t_s.is_finite()
            && acceleration
                .linear_mps2
                .iter()
                .chain(acceleration.angular_radps2.iter())
                .all(|x| x.is_finite());
        if !finite {
            return Err(KnownAccelerationError::NotFinite { t_s });
        }
        match self.entries.last_mut() {
            Some((newest_s, _)) if t_s < *newest_s => {
                return Err(KnownAccelerationError::OutOfOrder {
                    t_s,
                    newest_s: *newest_s,
                });
            }
            Some((newest_s, newest)) if t_s == *newest_s => {
                *newest = acceleration;
                return Ok(());
            }
            _ => {}
        }
        if self.entries.len() >= KNOWN_ACCELERATION_CAPACITY {
            return Err(KnownAccelerationError::TooMany {
                t_s,
                capacity: KNOWN_ACCELERATION_CAPACITY,
            });
        }
        self.entries.push((t_s, acceleration));
        Ok(())
    }

    /// Forgets every input.
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
    }

    /// Drops the entries that no prediction from `t_s` on can use: all before the one in force at `t_s`.
    pub(crate) fn forget_before(&mut self, t_s: f64) {
        let in_force = self.entries.partition_point(|(from_s, _)| *from_s <= t_s);
        if in_force > 1 {
            self.entries.drain(..in_force - 1);
        }
    }

    /// The known acceleration at `t_s` (zero before the first entry).
    pub(crate) fn at(&self, t_s: f64) -> Acceleration {
        let in_force = self.entries.partition_point(|(from_s, _)| *from_s <= t_s);
        in_force
            .checked_sub(1)
            .map_or_else(zero_acceleration, |i| self.entries[i].1)
    }

    /// The pieces of the interval from `t0_s` to `t0_s + dt_s` (`dt_s` of either sign) on which the known
    /// acceleration is constant, in the order a prediction over it crosses them: `f(duration, acceleration)` once per
    /// piece, the durations signed as `dt_s`. A single piece is `dt_s` itself, to the bit; cut pieces are the
    /// differences of the breakpoints' offsets from `t0_s`, ending at `dt_s`.
    pub(crate) fn for_each_piece(
        &self,
        t0_s: f64,
        dt_s: f64,
        mut f: impl FnMut(f64, &Acceleration),
    ) {
        let t1_s = t0_s + dt_s;
        let (low, high) = if dt_s >= 0.0 {
            (t0_s, t1_s)
        } else {
            (t1_s, t0_s)
        };
        // The entries' times strictly inside the interval are its breakpoints.
        let first = self.entries.partition_point(|(from_s, _)| *from_s <= low);
        let last = self.entries.partition_point(|(from_s, _)| *from_s < high);
        let inside = &self.entries[first..last.max(first)];
        let mut from = 0.0;
        let mut piece = |to: f64| {
            if to != from {
                f(to - from, &self.at(t0_s + 0.5 * (from + to)));
            }
            from = to;
        };
        if dt_s >= 0.0 {
            inside.iter().for_each(|(t, _)| piece(t - t0_s));
        } else {
            inside.iter().rev().for_each(|(t, _)| piece(t - t0_s));
        }
        piece(dt_s);
    }
}

/// No acceleration.
pub(crate) fn zero_acceleration() -> Acceleration {
    Acceleration {
        linear_mps2: Vector3::zeros(),
        angular_radps2: Vector3::zeros(),
    }
}

/// `a + b`, component by component.
pub(crate) fn sum(a: &Acceleration, b: &Acceleration) -> Acceleration {
    Acceleration {
        linear_mps2: a.linear_mps2 + b.linear_mps2,
        angular_radps2: a.angular_radps2 + b.angular_radps2,
    }
}

/// `a - b`, component by component.
pub(crate) fn difference(a: &Acceleration, b: &Acceleration) -> Acceleration {
    Acceleration {
        linear_mps2: a.linear_mps2 - b.linear_mps2,
        angular_radps2: a.angular_radps2 - b.angular_radps2,
    }
}
