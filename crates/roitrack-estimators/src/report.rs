//! What an estimator has done since it was built: its estimates counted by status, the measurements refused and
//! why no track started.

use thiserror::Error;

#[cfg(doc)]
use crate::TrackError;
use crate::{Estimate, InitError, TrackStatus};

/// Estimates counted by status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StatusCounts {
    /// Estimates with [`TrackStatus::Converging`].
    pub converging: usize,
    /// Estimates with [`TrackStatus::Tracking`].
    pub tracking: usize,
    /// Estimates with [`TrackStatus::Degenerate`].
    pub degenerate: usize,
    /// Estimates with [`TrackStatus::Disputed`].
    pub disputed: usize,
    /// Estimates with [`TrackStatus::Lost`].
    pub lost: usize,
}

impl StatusCounts {
    /// How many estimates had `status`.
    pub fn get(&self, status: TrackStatus) -> usize {
        match status {
            TrackStatus::Converging => self.converging,
            TrackStatus::Tracking => self.tracking,
            TrackStatus::Degenerate => self.degenerate,
            TrackStatus::Disputed => self.disputed,
            TrackStatus::Lost => self.lost,
        }
    }

    /// Counts one more estimate with `status`.
    pub fn add(&mut self, status: TrackStatus) {
        *self.count_mut(status) += 1;
    }

    fn count_mut(&mut self, status: TrackStatus) -> &mut usize {
        match status {
            TrackStatus::Converging => &mut self.converging,
            TrackStatus::Tracking => &mut self.tracking,
            TrackStatus::Degenerate => &mut self.degenerate,
            TrackStatus::Disputed => &mut self.disputed,
            TrackStatus::Lost => &mut self.lost,
        }
    }

    /// Every estimate counted.
    pub fn total(&self) -> usize {
        TrackStatus::ALL.iter().map(|&s| self.get(s)).sum()
    }

    /// The statuses of `estimates`, counted.
    pub fn of(estimates: &[Estimate]) -> Self {
        let mut counts = Self::default();
        for e in estimates {
            counts.add(e.status);
        }
        counts
    }
}

/// Why the newest attempt to start a track from the measurements started none ([`EstimatorReport::start_failure`]).
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum StartFailure {
    /// No static pose from the newest centroid of each point.
    #[error("{0}")]
    NoPose(InitError),
    /// Several poses fit the measurements as well as the best, within the noise: a target of 3 points, a symmetric
    /// layout, or a small target far away whose tilt the view cannot tell from its mirror tilt. The track waits for
    /// measurements that decide.
    #[error(
        "{poses} poses fit the measurements equally well within the noise (3 points, a symmetric target, or a small \
         target far away whose tilt cannot be told from its mirror tilt)"
    )]
    Ambiguous {
        /// How many poses fit equally well (the best and its rivals).
        poses: usize,
    },
    /// A pose decided with little margin over a rival was not decided the same way by the cycle before: the track
    /// waits for views that agree.
    #[error(
        "a pose that fits only a little better than a second one was not confirmed by the cycle before"
    )]
    Unconfirmed,
    /// The 12-dof fit of the first cycles left residuals above the noise (a wrong correspondence, or bad data).
    #[error("the first cycles fit no motion: median residual {median_px:.2} px")]
    Residual {
        /// The median residual norm of the fit (px), over the bound set by the noise.
        median_px: f64,
    },
}

/// What an estimator has done since it was built.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstimatorReport {
    /// Measurements accepted.
    pub measurements: usize,
    /// Measurements refused ([`TrackError`]), which left the estimator as it was.
    pub refused: usize,
    /// Estimates emitted, by status.
    pub estimates: StatusCounts,
    /// Tracks started: initialisations from the measurements and starts from a given state.
    pub initialisations: usize,
    /// Why the newest attempt to start a track from the measurements started none (`None` once one has started).
    pub start_failure: Option<StartFailure>,
    /// Kalman: measurements rejected by the innovation gate.
    pub gated: usize,
    /// Kalman: covariance resets after runs of gated measurements.
    pub covariance_resets: usize,
}

impl EstimatorReport {
    /// Why no track started, for a run that gave no estimate: the reason of the newest failed start, or the wait for
    /// two cycles over every point when no start was tried.
    pub fn why_no_start(&self) -> String {
        match self.start_failure {
            Some(failure) => format!("the tracker could not initialise: {failure}"),
            None => "the tracker could not initialise: it needs two cycles over every target point"
                .to_string(),
        }
    }

    pub(crate) fn count(&mut self, status: TrackStatus) {
        self.estimates.add(status);
    }

    /// Takes back an estimate counted but not given (a first pose refused).
    pub(crate) fn uncount(&mut self, status: TrackStatus) {
        let count = self.estimates.count_mut(status);
        *count = count.saturating_sub(1);
    }
}
