//! The tracker's options as a user names them (`--estimator paper --adapt none --every 10`, or the same as Python
//! keywords), and their one translation into a [`TrackerConfig`], shared by the command line and the Python package
//! so that both run the same filter from the same words.

use thiserror::Error;

use super::{
    EstimatorConfig, KalmanTuning, MotionModel, RobustLoss, TrackerConfig, VvsSettings, WindowMode,
};
use crate::JacobianKind;

/// Which estimator, by its user-facing name.
///
/// ```
/// use roitrack_core::estimator::EstimatorKind;
/// assert_eq!(EstimatorKind::from_name("paper"), Ok(EstimatorKind::Paper));
/// assert_eq!(EstimatorKind::Paper.name(), "paper");
/// assert!(EstimatorKind::from_name("ekf").unwrap_err().to_string().contains("kalman, exact, paper, static, batch"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EstimatorKind {
    /// Error-state Kalman filter, one update per centroid at its own time (the default).
    #[default]
    Kalman,
    /// The paper's virtual visual servoing loop with the exact Jacobian.
    Exact,
    /// The paper's virtual visual servoing loop with the paper's Jacobian (eqs. 17-24).
    Paper,
    /// Baseline: static PnP as if simultaneous, velocity by finite differences.
    Static,
    /// Baseline: Levenberg-Marquardt of the 12 parameters on the window.
    Batch,
}

/// What the Kalman filter learns online: the centroid noise, the process noise, both or neither.
///
/// ```
/// use roitrack_core::estimator::Adaptation;
/// assert_eq!(Adaptation::from_name("none"), Ok(Adaptation::None));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Adaptation {
    Both,
    Noise,
    Motion,
    None,
}

/// The Kalman filter's process model by name (see [`MotionModel`]).
///
/// ```
/// use roitrack_core::estimator::MotionModelKind;
/// assert_eq!(MotionModelKind::from_name("constant-acceleration"), Ok(MotionModelKind::ConstantAcceleration));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionModelKind {
    ConstantVelocity,
    ConstantAcceleration,
}

/// Options that set the densities of one motion model given with the other (`--motion-model constant-velocity
/// --jerk-psd 50`, say), or densities of both models at once: refused rather than one of them ignored.
///
/// ```
/// use roitrack_core::estimator::{MotionModelKind, TrackerOptions};
/// let options = TrackerOptions {
///     motion_model: Some(MotionModelKind::ConstantVelocity),
///     jerk_psd: Some(50.0),
///     ..TrackerOptions::default()
/// };
/// assert_eq!(
///     options.check().unwrap_err().to_string(),
///     "jerk-psd does not apply to the constant-velocity motion model (it is a density of constant-acceleration)"
/// );
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{given} does not apply to the {model} motion model (it is a density of {other})")]
pub struct OptionConflict {
    /// The option given (its command-line name).
    pub given: &'static str,
    /// The model in force, and the model the option belongs to.
    pub model: &'static str,
    pub other: &'static str,
}

/// A name that is not one of an option's values.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{option}: unknown value '{value}' (expected one of {expected})")]
pub struct UnknownName {
    pub option: &'static str,
    pub value: String,
    pub expected: String,
}

/// Implements `name` and `from_name` for an enum of named values.
macro_rules! named_values {
    ($ty:ty, $option:literal, [$($variant:ident => $name:literal),+ $(,)?]) => {
        impl $ty {
            /// Every value, in the order of the documentation.
            pub const ALL: &'static [Self] = &[$(Self::$variant),+];

            /// The value's name, as the command line and the Python package spell it.
            pub fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $name),+
                }
            }

            /// The value of a name; an error listing the names otherwise.
            pub fn from_name(name: &str) -> Result<Self, UnknownName> {
                Self::ALL.iter().copied().find(|v| v.name() == name).ok_or_else(|| UnknownName {
                    option: $option,
                    value: name.to_string(),
                    expected: Self::ALL.iter().map(|v| v.name()).collect::<Vec<_>>().join(", "),
                })
            }
        }
    };
}

named_values!(EstimatorKind, "estimator", [
    Kalman => "kalman", Exact => "exact", Paper => "paper", Static => "static", Batch => "batch",
]);
named_values!(Adaptation, "adapt", [
    Both => "both", Noise => "noise", Motion => "motion", None => "none",
]);
named_values!(MotionModelKind, "motion-model", [
    ConstantVelocity => "constant-velocity", ConstantAcceleration => "constant-acceleration",
]);
named_values!(RobustLoss, "robust", [None => "none", Huber => "huber", Tukey => "tukey"]);

/// The tracker's options by name, with the command line's defaults (`roitrack track --help`); [`Self::config`]
/// turns them into a [`TrackerConfig`].
///
/// ```
/// use roitrack_core::estimator::{Adaptation, EstimatorConfig, EstimatorKind, TrackerConfig, TrackerOptions};
///
/// // The default options are the default configuration.
/// assert_eq!(TrackerOptions::default().config(), TrackerConfig::default());
/// // A hand-tuned Kalman filter: nothing learnt online.
/// let options = TrackerOptions { adapt: Some(Adaptation::None), accel_psd: Some(5.0), ..TrackerOptions::default() };
/// let EstimatorConfig::Kalman(tuning) = options.config().estimator else { unreachable!() };
/// assert!(!tuning.adapt_noise && !tuning.adapt_motion && tuning.linear_accel_psd == 5.0);
/// let paper = TrackerOptions { estimator: EstimatorKind::Paper, gain: 0.5, ..TrackerOptions::default() };
/// assert_eq!(paper.config().estimator.name(), "vvs");
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerOptions {
    /// Which estimator.
    pub estimator: EstimatorKind,
    /// Gain λ of the VVS update δ = -λ L⁺ e (exact, paper).
    pub gain: f64,
    /// VVS iterations per control step (1 = the paper's scheme; more = Gauss-Newton).
    pub iterations: usize,
    /// Window: 0 = the newest measurement of each point (the paper), N = the last N measurements.
    pub window: usize,
    /// Control period: one estimate every `every` measurements.
    pub every: usize,
    /// Centroid noise standard deviation (px): the window fits' covariance scale, and the Kalman filter's starting
    /// value.
    pub noise_px: f64,
    /// Kalman: what the filter learns online; `None` means the default of the caller's source (both for
    /// measurements, see `FrameTrackerConfig::frame_estimator` for frames).
    pub adapt: Option<Adaptation>,
    /// Kalman: white linear acceleration spectral density ((m/s²)²/Hz); `None` for the default.
    pub accel_psd: Option<f64>,
    /// Kalman: white angular acceleration spectral density ((rad/s²)²/Hz); `None` for the default.
    pub angular_accel_psd: Option<f64>,
    /// Kalman: the process model; `None` means the default of the caller's source (constant velocity for
    /// measurements, constant acceleration for frames, see `FrameTrackerConfig::frame_estimator`), unless densities
    /// name one ([`Self::named_motion_model`]).
    pub motion_model: Option<MotionModelKind>,
    /// Kalman, constant acceleration: white linear jerk spectral density ((m/s³)²/Hz); `None` for the default.
    pub jerk_psd: Option<f64>,
    /// Kalman, constant acceleration: white angular jerk spectral density ((rad/s³)²/Hz); `None` for the default.
    pub angular_jerk_psd: Option<f64>,
    /// M-estimator of the window fits; `None` also turns off the Kalman filter's Huber weighting.
    pub robust: RobustLoss,
    /// Degeneracy gate on the window's reciprocal condition number; `None` for the default.
    pub min_conditioning: Option<f64>,
}

impl Default for TrackerOptions {
    fn default() -> Self {
        Self {
            estimator: EstimatorKind::Kalman,
            gain: 1.0,
            iterations: 1,
            window: 0,
            every: 10,
            noise_px: 0.1,
            adapt: None,
            accel_psd: None,
            angular_accel_psd: None,
            motion_model: None,
            jerk_psd: None,
            angular_jerk_psd: None,
            robust: RobustLoss::Tukey,
            min_conditioning: None,
        }
    }
}

impl TrackerOptions {
    /// The Kalman filter's process model these options name: [`Self::motion_model`], or constant acceleration when
    /// only a jerk density is given; constant velocity otherwise.
    ///
    /// ```
    /// use roitrack_core::estimator::{MotionModel, TrackerOptions};
    /// let options = TrackerOptions { jerk_psd: Some(50.0), ..TrackerOptions::default() };
    /// let MotionModel::ConstantAcceleration { linear_jerk_psd, .. } = options.kalman_motion_model() else { panic!() };
    /// assert_eq!(linear_jerk_psd, 50.0);
    /// assert_eq!(TrackerOptions::default().kalman_motion_model(), MotionModel::ConstantVelocity);
    /// ```
    pub fn kalman_motion_model(&self) -> MotionModel {
        match self.named_motion_model() {
            Some(MotionModelKind::ConstantAcceleration) => {
                MotionModel::constant_acceleration_with(self.jerk_psd, self.angular_jerk_psd)
            }
            _ => MotionModel::ConstantVelocity,
        }
    }

    /// The process model these options name: [`Self::motion_model`], else the one whose densities are given (a jerk
    /// density means constant acceleration, an acceleration density constant velocity), else `None` (the source's
    /// default). [`Self::check`] refuses options that name both.
    ///
    /// ```
    /// use roitrack_core::estimator::{MotionModelKind, TrackerOptions};
    /// let options = TrackerOptions { accel_psd: Some(5.0), ..TrackerOptions::default() };
    /// assert_eq!(options.named_motion_model(), Some(MotionModelKind::ConstantVelocity));
    /// assert_eq!(TrackerOptions::default().named_motion_model(), None);
    /// ```
    pub fn named_motion_model(&self) -> Option<MotionModelKind> {
        let jerk = self.jerk_psd.is_some() || self.angular_jerk_psd.is_some();
        let accel = self.accel_psd.is_some() || self.angular_accel_psd.is_some();
        self.motion_model.or(match (jerk, accel) {
            (true, _) => Some(MotionModelKind::ConstantAcceleration),
            (false, true) => Some(MotionModelKind::ConstantVelocity),
            (false, false) => None,
        })
    }

    /// Refuses densities of the motion model not in force (see [`OptionConflict`]).
    pub fn check(&self) -> Result<(), OptionConflict> {
        let jerk = [
            ("jerk-psd", self.jerk_psd),
            ("angular-jerk-psd", self.angular_jerk_psd),
        ];
        let accel = [
            ("accel-psd", self.accel_psd),
            ("angular-accel-psd", self.angular_accel_psd),
        ];
        let (model, other, foreign) = match self.named_motion_model() {
            Some(MotionModelKind::ConstantAcceleration) => {
                ("constant-acceleration", "constant-velocity", accel)
            }
            Some(MotionModelKind::ConstantVelocity) => {
                ("constant-velocity", "constant-acceleration", jerk)
            }
            None => return Ok(()),
        };
        match foreign.iter().find(|(_, value)| value.is_some()) {
            Some(&(given, _)) => Err(OptionConflict {
                given,
                model,
                other,
            }),
            None => Ok(()),
        }
    }

    /// The configuration these options name ([`TrackerConfig::validate`] checks the values).
    pub fn config(&self) -> TrackerConfig {
        let defaults = KalmanTuning::default();
        let kalman = KalmanTuning {
            linear_accel_psd: self.accel_psd.unwrap_or(defaults.linear_accel_psd),
            angular_accel_psd: self.angular_accel_psd.unwrap_or(defaults.angular_accel_psd),
            huber_sigma: if self.robust == RobustLoss::None {
                f64::INFINITY
            } else {
                defaults.huber_sigma
            },
            adapt_noise: matches!(
                self.adapt,
                None | Some(Adaptation::Both | Adaptation::Noise)
            ),
            adapt_motion: matches!(
                self.adapt,
                None | Some(Adaptation::Both | Adaptation::Motion)
            ),
            motion_model: self.kalman_motion_model(),
            ..defaults
        };
        let vvs = |jacobian| VvsSettings {
            jacobian,
            gain: self.gain,
            iterations: self.iterations,
        };
        let defaults = TrackerConfig::default();
        TrackerConfig {
            estimator: match self.estimator {
                EstimatorKind::Kalman => EstimatorConfig::Kalman(kalman),
                EstimatorKind::Exact => EstimatorConfig::Vvs(vvs(JacobianKind::Exact)),
                EstimatorKind::Paper => EstimatorConfig::Vvs(vvs(JacobianKind::Paper)),
                EstimatorKind::Static => EstimatorConfig::Static,
                EstimatorKind::Batch => EstimatorConfig::Batch,
            },
            window: match self.window {
                0 => WindowMode::NewestPerPoint,
                n => WindowMode::Last(n),
            },
            every: self.every,
            noise_px: self.noise_px,
            min_inverse_condition: self
                .min_conditioning
                .unwrap_or(defaults.min_inverse_condition),
            robust: self.robust,
            ..defaults
        }
    }
}
