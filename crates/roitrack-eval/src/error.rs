//! What can go wrong when evaluating an estimate against ground truth.

/// Why [`evaluate`](crate::evaluate) could not compare an estimate with the truth.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A required series has no samples.
    #[error("no {what}: nothing to evaluate")]
    Empty {
        /// Which series.
        what: &'static str,
    },

    /// A time stamp is NaN or infinite.
    #[error("{what}: the time at index {index} is not finite ({t_s})")]
    NonFiniteTime {
        /// Which series.
        what: &'static str,
        /// The sample's index in it.
        index: usize,
        /// Its time.
        t_s: f64,
    },

    /// Times do not increase strictly.
    #[error(
        "{what}: times must increase strictly, but index {index} has t = {t_s} s after t = {previous_s} s"
    )]
    NonIncreasingTime {
        /// Which series.
        what: &'static str,
        /// The sample's index in it.
        index: usize,
        /// The time of the sample before it.
        previous_s: f64,
        /// Its time.
        t_s: f64,
    },

    /// An estimate matches no truth sample and cannot be interpolated because it lies outside the truth.
    #[error(
        "the estimate at t = {t_s} s lies outside the truth's time span [{start_s}, {end_s}] s (index {index})"
    )]
    OutsideTruthSpan {
        /// The estimate's index.
        index: usize,
        /// Its time.
        t_s: f64,
        /// The truth's first time.
        start_s: f64,
        /// The truth's last time.
        end_s: f64,
    },

    /// A twist series has not as many samples as its pose series.
    #[error(
        "{what}: {twists} twists for {poses} poses; twists must be at the same times as the poses"
    )]
    TwistCountMismatch {
        /// Which series.
        what: &'static str,
        /// Its poses.
        poses: usize,
        /// Its twists.
        twists: usize,
    },

    /// A twist is not at the time of the pose with the same index.
    #[error(
        "{what}: twist {index} is at t = {twist_t_s} s but pose {index} is at t = {pose_t_s} s"
    )]
    TwistTimeMismatch {
        /// Which series.
        what: &'static str,
        /// The index of the pose and the twist.
        index: usize,
        /// The pose's time.
        pose_t_s: f64,
        /// The twist's time.
        twist_t_s: f64,
    },

    /// An [`EvalOptions`](crate::EvalOptions) field is out of its domain.
    #[error("invalid option {name} = {value}: {reason}")]
    InvalidOption {
        /// The option's field name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What the value must be.
        reason: &'static str,
    },

    /// The estimated positions cannot determine an alignment.
    #[error("cannot align the estimates with the truth ({points} positions): {reason}")]
    DegenerateAlignment {
        /// How many positions were there to align.
        points: usize,
        /// Why they do not determine it.
        reason: &'static str,
    },

    /// No clock offset could be found between the estimates and the truth.
    #[error("cannot find the time offset between the estimates and the truth: {reason}")]
    TimeOffsetNotFound {
        /// Why.
        reason: &'static str,
    },
}
