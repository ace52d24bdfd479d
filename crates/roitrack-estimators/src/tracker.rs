//! [`Tracker`]: the estimator that [`TrackerConfig::estimator`] chooses, built at run time.

use roitrack_core::{CameraModel, Measurement, MotionState, Target};

use crate::{
    BatchEstimator, ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport,
    KalmanEstimator, StaticEstimator, TrackError, TrackerConfig, VvsEstimator, delegate_estimator,
};

/// The estimator chosen by [`TrackerConfig::estimator`], for code that picks it at run time.
///
/// ```
/// use roitrack_estimators::{EstimatorConfig, Estimator, Tracker, TrackerConfig};
/// use roitrack_core::{CameraModel, Target};
///
/// let config = TrackerConfig { estimator: EstimatorConfig::Batch, ..TrackerConfig::default() };
/// let tracker = Tracker::new(CameraModel::canonical(), Target::grid4x4(), config).unwrap();
/// assert_eq!(tracker.config().estimator.name(), "batch");
/// ```
#[derive(Debug)]
pub struct Tracker(Box<dyn Estimator>);

impl Tracker {
    /// Builds the configured estimator, refusing invalid options.
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
    ) -> Result<Self, ConfigError> {
        let estimator: Box<dyn Estimator> = match config.estimator {
            EstimatorConfig::Kalman(tuning) => {
                Box::new(KalmanEstimator::new(camera, target, config, tuning)?)
            }
            EstimatorConfig::Vvs(settings) => {
                Box::new(VvsEstimator::new(camera, target, config, settings)?)
            }
            EstimatorConfig::Batch => Box::new(BatchEstimator::new(camera, target, config)?),
            EstimatorConfig::Static => Box::new(StaticEstimator::new(camera, target, config)?),
        };
        Ok(Self(estimator))
    }
}

delegate_estimator!(Tracker);
