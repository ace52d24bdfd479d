//! The targets of the study: their thresholds, each [`Goal`] and a [`Check`] of one on one case.

use serde::Serialize;

/// [`Goal::Rmse`]: the default filter's position RMSE may be at most this many times the best hand-tuned one.
///
/// ```
/// assert_eq!(roitrack_experiments::adaptive::RMSE_RATIO_LIMIT, 1.2);
/// ```
pub const RMSE_RATIO_LIMIT: f64 = 1.2;

/// [`Goal::Bounded`]: no vouched estimate may be more than this many times the nominal error off.
///
/// ```
/// assert_eq!(roitrack_experiments::adaptive::BOUND_FACTOR, 10.0);
/// ```
pub const BOUND_FACTOR: f64 = 10.0;

/// [`Goal::Lag`]: the largest velocity lag (estimator samples) on the built-in scenes.
///
/// ```
/// assert_eq!(roitrack_experiments::adaptive::MAX_LAG_SAMPLES, 1);
/// ```
pub const MAX_LAG_SAMPLES: i64 = 1;

/// The targets of the study (see the [module docs](super)).
///
/// ```
/// use roitrack_experiments::adaptive::Goal;
/// assert_eq!(Goal::ALL.len(), 5);
/// assert_eq!(Goal::Rmse.name(), "rmse");
/// assert!(Goal::Calibrated.description().contains("NEES"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Goal {
    /// Position RMSE at most [`RMSE_RATIO_LIMIT`] times the best hand-tuned.
    Rmse,
    /// No disputed or lost estimate.
    Clean,
    /// Calibrated covariance.
    Calibrated,
    /// Velocity lag at most [`MAX_LAG_SAMPLES`].
    Lag,
    /// No vouched estimate beyond [`BOUND_FACTOR`] times the nominal error.
    Bounded,
}

impl Goal {
    /// Every target, in the tables' order.
    pub const ALL: [Self; 5] = [
        Self::Rmse,
        Self::Clean,
        Self::Calibrated,
        Self::Lag,
        Self::Bounded,
    ];

    /// A short name: `rmse`, `clean`, `calibrated`, `lag`, `bounded`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Rmse => "rmse",
            Self::Clean => "clean",
            Self::Calibrated => "calibrated",
            Self::Lag => "lag",
            Self::Bounded => "bounded",
        }
    }

    /// What the target asks.
    pub fn description(&self) -> &'static str {
        match self {
            Self::Rmse => "position RMSE at most 1.2 x the best hand-tuned",
            Self::Clean => "no disputed or lost estimate",
            Self::Calibrated => {
                "mean NEES of position and velocity within 0.5-2 x 3, at least 95 % inside the 99 % bound"
            }
            Self::Lag => "velocity lag at most 1 sample (moving built-in scenes)",
            Self::Bounded => "no vouched estimate beyond 10 x the nominal error",
        }
    }
}

/// One target checked on one case.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// The case's name.
    pub case: &'static str,
    /// The target checked.
    pub goal: Goal,
    /// The figure judged, as text.
    pub figure: String,
    /// Whether the case meets the target.
    pub holds: bool,
}
