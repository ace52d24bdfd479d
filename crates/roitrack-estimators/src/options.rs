//! The tracker's options as a user names them (`--estimator paper --adapt none --every 10`, or the same as Python
//! keywords), and their one translation into a [`TrackerConfig`], shared by the command line and the Python package
//! so that both run the same filter from the same words.

use thiserror::Error;

use super::{
    EstimatorConfig, KalmanTuning, MotionModel, RobustLoss, TrackerConfig, VvsSettings, WindowMode,
};
use roitrack_core::JacobianKind;

/// Which estimator, by its user-facing name.
///
/// ```
/// use roitrack_estimators::EstimatorKind;
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
/// use roitrack_estimators::Adaptation;
/// assert_eq!(Adaptation::from_name("none"), Ok(Adaptation::None));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Adaptation {
    /// The centroid noise and the process noise ([`KalmanTuning::adapt_noise`] and
    /// [`KalmanTuning::adapt_motion`]).
    Both,
    /// The centroid noise only; the process noise stays as configured.
    Noise,
    /// The process noise only; the centroid noise stays as configured.
    Motion,
    /// Neither: the configured noise and densities are taken as the truth (a hand-tuned filter).
    None,
}

/// The Kalman filter's process model by name (see [`MotionModel`]).
///
/// ```
/// use roitrack_estimators::MotionModelKind;
/// assert_eq!(MotionModelKind::from_name("constant-acceleration"), Ok(MotionModelKind::ConstantAcceleration));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionModelKind {
    /// [`MotionModel::ConstantVelocity`]: the twist drifts under white acceleration.
    ConstantVelocity,
    /// [`MotionModel::ConstantAcceleration`]: the accelerations are states too, drifting under white jerk.
    ConstantAcceleration,
}

/// Options that set the densities of one motion model given with the other (`--motion-model constant-velocity
/// --jerk-psd 50`, say), or densities of both models at once: refused rather than one of them ignored.
///
/// ```
/// use roitrack_estimators::{MotionModelKind, TrackerOptions};
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
    /// The motion model in force (`constant-velocity` or `constant-acceleration`).
    pub model: &'static str,
    /// The motion model the option is a density of.
    pub other: &'static str,
}

/// A name that is not one of an option's values.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{option}: unknown value '{value}' (expected one of {expected})")]
pub struct UnknownName {
    /// The option (its command-line name: `estimator`, `adapt`, ...).
    pub option: &'static str,
    /// The name given.
    pub value: String,
    /// The option's names, joined by commas.
    pub expected: String,
}

/// A value's help, if the list gives one.
macro_rules! value_help {
    () => {
        None
    };
    ($help:literal) => {
        Some($help)
    };
}

/// Implements `name`, `from_name`, `help` and `Display` for an enum of named values; a value's help (after `:`) is
/// what `--help` prints beside its name.
macro_rules! named_values {
    ($ty:ty, $option:literal, [$($variant:ident => $name:literal $(: $help:literal)?),+ $(,)?]) => {
        impl $ty {
            /// Every value, in the order of the documentation.
            pub const ALL: &'static [Self] = &[$(Self::$variant),+];

            /// The value's name, as the command line and the Python package spell it.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $name),+
                }
            }

            /// What the value does, in a line (`None` where the name says it).
            pub const fn help(self) -> Option<&'static str> {
                match self {
                    $(Self::$variant => value_help!($($help)?)),+
                }
            }

            /// The value of a name; an error listing the names otherwise.
            pub fn from_name(name: &str) -> Result<Self, UnknownName> {
                Self::named(name).ok_or_else(|| UnknownName {
                    option: $option,
                    value: name.to_string(),
                    expected: Self::ALL.iter().map(|v| v.name()).collect::<Vec<_>>().join(", "),
                })
            }

            /// [`Self::from_name`] at compile time: the table's default names are checked as the crate builds.
            const fn named(name: &str) -> Option<Self> {
                let mut k = 0;
                while k < Self::ALL.len() {
                    if same_text(Self::ALL[k].name(), name) {
                        return Some(Self::ALL[k]);
                    }
                    k += 1;
                }
                None
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

/// `a == b` for strings, in a `const fn`.
const fn same_text(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut k = 0;
    while k < a.len() {
        if a[k] != b[k] {
            return false;
        }
        k += 1;
    }
    true
}

named_values!(EstimatorKind, "estimator", [
    Kalman => "kalman": "Error-state Kalman filter, one update per centroid at its own time (default)",
    Exact => "exact": "The paper's virtual visual servoing loop with the exact Jacobian",
    Paper => "paper": "The paper's virtual visual servoing loop with the paper's Jacobian (eqs. 17-24)",
    Static => "static": "Baseline: static PnP as if simultaneous, velocity by finite differences",
    Batch => "batch": "Baseline: Levenberg-Marquardt of the 12 parameters on the window",
]);
named_values!(Adaptation, "adapt", [
    Both => "both", Noise => "noise", Motion => "motion", None => "none",
]);
named_values!(MotionModelKind, "motion-model", [
    ConstantVelocity => "constant-velocity": "The twist drifts under white acceleration",
    ConstantAcceleration => "constant-acceleration": "The accelerations are states too, drifting under white jerk",
]);
named_values!(RobustLoss, "robust", [None => "none", Huber => "huber", Tukey => "tukey"]);

/// The tracker's options, the one table from which follow [`TrackerOptions`] (its fields, docs and defaults), the
/// command line's arguments (`roitrack track --help`: the docs are the help, the checks its value parsers) and the
/// Python package's keyword arguments (`Tracker(...)`, `track(...)`: names and defaults).
///
/// `tracker_options!(callback)` calls `callback! { ENTRY* }` (with `tracker_options!(callback [TOKENS])`,
/// `callback! { [TOKENS] ENTRY* }`), each entry
///
/// ```text
/// /// help text, as `--help` prints it
/// name: SHAPE Type = DEFAULT, check(arguments);
/// ```
///
/// - `name`: the field, the Python keyword, and with `-` for `_` the command-line option;
/// - `SHAPE`: `number` (a value, `DEFAULT` a number), `named` (a value named by a string, `DEFAULT` its name),
///   `optional_number` or `optional_named` (`Option<Type>`, `DEFAULT` `None`: the source's default, which the help
///   says);
/// - `check(arguments)` (numbers only): the range the command line refuses outside as it reads the value, one of the
///   CLI's value parsers `within(range, unit, why)`, `positive_up_to(max, unit, why)`, `count(range, why)` or
///   `window()`, on the bounds of this crate (`MAX_ITERATIONS`, ...) that [`TrackerConfig::validate`] enforces from
///   every front end.
///
/// Named values name their type's values (`named_values!` above: names, help).
///
/// ```
/// macro_rules! names {
///     ($($(#[doc = $doc:literal])* $name:ident : $shape:ident $ty:ty = $default:tt $(, $check:ident ($($arg:expr),*))?;)*) => {
///         [$(stringify!($name)),*]
///     };
/// }
/// let names = roitrack_estimators::tracker_options!(names);
/// assert_eq!(names[..3], ["estimator", "every", "gain"]);
/// ```
#[macro_export]
macro_rules! tracker_options {
    ($callback:ident $([$($extra:tt)*])?) => {
        $callback! {
            $([$($extra)*])?
            /// Which estimator.
            estimator: named $crate::EstimatorKind = "kalman";
            /// Control period k: one estimate every K measurements (at most 100,000). Measurements that share a time (the
            /// blobs of a frame) give one estimate per frame instead.
            every: number usize = 10, count(1..=100_000, "one estimate every 25 s at 4 kHz");
            /// Gain λ of the VVS update δ = -λ L⁺ e (exact, paper), in (0, 2].
            gain: number f64 = 1.0, positive_up_to(2.0, "", "beyond 2 the update overshoots");
            /// VVS iterations per control step (1 = the paper's scheme; more = Gauss-Newton), at most 100.
            iterations: number usize = 1,
                count(1..=$crate::MAX_ITERATIONS, "Gauss-Newton converges in a handful");
            /// Window: 0 = the newest measurement of each point (the paper), N = the last N measurements (4 to 100,000).
            window: number usize = 0, window();
            /// Centroid noise standard deviation (px, at most 100): the window fits' covariance scale, and the Kalman filter's
            /// starting value (it estimates the noise online unless --adapt leaves the noise out).
            noise_px: number f64 = 0.1, positive_up_to(
                $crate::MAX_NOISE_PX,
                " px",
                "more than a ROI's half-width is no centroid"
            );
            /// Kalman: what the filter learns online: the centroid noise and the process noise (both), one of them, or none
            /// (--noise-px, --accel-psd and --angular-accel-psd taken as the truth: a hand-tuned filter). Default: both for
            /// measurements and ROI recordings; for --images, the noise, learnt from global-shutter frames and held for
            /// rolling-shutter ones (a process noise that follows the motion chases the jitter between frames at frame rates).
            /// Frames whose blobs share one instant never adapt the process noise, and with --images the twist covariance is
            /// never calibrated against the poses around each estimate, whatever --adapt says.
            adapt: optional_named $crate::Adaptation = None;
            /// Kalman: white linear acceleration spectral density ((m/s²)²/Hz); larger = less lag, more noise. Default: 1
            /// (crate::KalmanTuning's), a starting value that the filter adapts unless --adapt leaves the
            /// motion out.
            accel_psd: optional_number f64 = None, within(
                $crate::PSD_RANGE,
                "",
                "from no motion to 20,000 m/s² between estimates"
            );
            /// Kalman: white angular acceleration spectral density ((rad/s²)²/Hz). Default: 10, a starting value as for
            /// --accel-psd.
            angular_accel_psd: optional_number f64 = None, within(
                $crate::PSD_RANGE,
                "",
                "from no motion to 20,000 m/s² between estimates"
            );
            /// Kalman: the process model. constant-velocity: the twist drifts under white acceleration (--accel-psd,
            /// --angular-accel-psd). constant-acceleration: the state also carries the linear and angular accelerations, which
            /// drift under white jerk (--jerk-psd, --angular-jerk-psd); about 1.45 times the work per update. Default: constant
            /// velocity for measurements and ROI recordings, constant acceleration for --images (frames tens of
            /// milliseconds apart, where the twist changes from one frame to the next). A jerk density given alone means
            /// constant acceleration, an acceleration density constant velocity; the other model's densities are refused.
            motion_model: optional_named $crate::MotionModelKind = None;
            /// Kalman, constant acceleration: white linear jerk spectral density ((m/s³)²/Hz). Default: 100 (1000 for
            /// rolling-shutter frames), a starting value that the filter adapts where it adapts the process noise (see
            /// --adapt).
            jerk_psd: optional_number f64 = None, within(
                $crate::PSD_RANGE,
                "",
                "from no motion to 20,000 m/s² between estimates"
            );
            /// Kalman, constant acceleration: white angular jerk spectral density ((rad/s³)²/Hz). Default: 300 (3000 for
            /// rolling-shutter frames), a starting value as for --jerk-psd.
            angular_jerk_psd: optional_number f64 = None, within(
                $crate::PSD_RANGE,
                "",
                "from no motion to 20,000 m/s² between estimates"
            );
            /// M-estimator against outliers: tukey (default), huber (window fits; the Kalman filter uses Huber either way)
            /// or none (plain least squares, and no Huber weighting in the Kalman filter).
            robust: named $crate::RobustLoss = "tukey";
            /// Degeneracy gate: windows whose column-scaled Jacobian has a reciprocal condition number below this are not
            /// used for an update (the estimate is flagged degenerate and the window widened). Default: 3e-3
            /// (TrackerConfig's).
            min_conditioning: optional_number f64 = None, within(0.0..=1.0, "", "a reciprocal condition number");
        }
    };
}

/// The type of a field of the table: `Option<Type>` for the optional shapes.
macro_rules! option_type {
    (number $ty:ty) => { $ty };
    (named $ty:ty) => { $ty };
    (optional_number $ty:ty) => { Option<$ty> };
    (optional_named $ty:ty) => { Option<$ty> };
}

/// The default of a field of the table, a named value looked up as the crate builds (an unknown name stops the
/// build).
macro_rules! option_default {
    (number $ty:ty, $default:tt) => {
        $default
    };
    (named $ty:ty, $default:tt) => {
        match <$ty>::named($default) {
            Some(value) => value,
            None => panic!(concat!("tracker_options!: no value named ", $default)),
        }
    };
    (optional_number $ty:ty, None) => {
        None
    };
    (optional_named $ty:ty, None) => {
        None
    };
}

/// [`TrackerOptions`] from the table.
macro_rules! define_tracker_options {
    ($($(#[doc = $doc:literal])* $name:ident : $shape:ident $ty:ty = $default:tt $(, $check:ident ($($arg:expr),*))?;)*) => {
        /// The tracker's options by name, with the command line's defaults (`roitrack track --help`, whose help is
        /// the fields' docs); [`Self::config`] turns them into a [`TrackerConfig`]. The fields, their defaults, the
        /// command-line arguments and the Python keywords all follow from one table, [`tracker_options!`].
        ///
        /// ```
        /// use roitrack_estimators::{Adaptation, EstimatorConfig, EstimatorKind, TrackerConfig, TrackerOptions};
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
            $($(#[doc = $doc])* pub $name: option_type!($shape $ty),)*
        }

        impl TrackerOptions {
            /// The defaults of the table (an `Option` field's `None`: the default of the caller's source, which its
            /// doc says).
            pub const DEFAULT: Self = Self {
                $($name: option_default!($shape $ty, $default),)*
            };
        }
    };
}

tracker_options!(define_tracker_options);

impl Default for TrackerOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl TrackerOptions {
    /// The Kalman filter's process model these options name: [`Self::motion_model`], or constant acceleration when
    /// only a jerk density is given; constant velocity otherwise.
    ///
    /// ```
    /// use roitrack_estimators::{MotionModel, TrackerOptions};
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
    /// use roitrack_estimators::{MotionModelKind, TrackerOptions};
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
