//! What can go wrong when evaluating an estimate against ground truth.

/// Why [`evaluate`](crate::evaluate) could not compare an estimate with the truth.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A required series has no samples.
    #[error("no {what}: nothing to evaluate")]
    Empty { what: &'static str },

    /// A time stamp is NaN or infinite.
    #[error("{what}: the time at index {index} is not finite ({t_s})")]
    NonFiniteTime {
        what: &'static str,
        index: usize,
        t_s: f64,
    },

    /// Times do not increase strictly.
    #[error(
        "{what}: times must increase strictly, but index {index} has t = {t_s} s after t = {previous_s} s"
    )]
    NonIncreasingTime {
        what: &'static str,
        index: usize,
        previous_s: f64,
        t_s: f64,
    },

    /// An estimate matches no truth sample and cannot be interpolated because it lies outside the truth.
    #[error(
        "the estimate at t = {t_s} s lies outside the truth's time span [{start_s}, {end_s}] s (index {index})"
    )]
    OutsideTruthSpan {
        index: usize,
        t_s: f64,
        start_s: f64,
        end_s: f64,
    },

    /// A twist series has not as many samples as its pose series.
    #[error(
        "{what}: {twists} twists for {poses} poses; twists must be at the same times as the poses"
    )]
    TwistCountMismatch {
        what: &'static str,
        poses: usize,
        twists: usize,
    },

    /// A twist is not at the time of the pose with the same index.
    #[error(
        "{what}: twist {index} is at t = {twist_t_s} s but pose {index} is at t = {pose_t_s} s"
    )]
    TwistTimeMismatch {
        what: &'static str,
        index: usize,
        pose_t_s: f64,
        twist_t_s: f64,
    },

    /// An [`EvalOptions`](crate::EvalOptions) field is out of its domain.
    #[error("invalid option {name} = {value}: {reason}")]
    InvalidOption {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },

    /// The estimated positions cannot determine an alignment.
    #[error("cannot align the estimates with the truth ({points} positions): {reason}")]
    DegenerateAlignment { points: usize, reason: &'static str },

    /// No clock offset could be found between the estimates and the truth.
    #[error("cannot find the time offset between the estimates and the truth: {reason}")]
    TimeOffsetNotFound { reason: &'static str },
}
