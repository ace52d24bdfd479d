//! Command-line values shared by several commands, and their translation into the library's types.

use std::path::PathBuf;

use anyhow::{Result, anyhow, bail};
use std::sync::OnceLock;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser, ValueParser};
use clap::{Arg, ArgAction, ArgMatches, Args, Command, ValueEnum};
use roitrack::TrackerConfig;
use roitrack::estimators::{self as estimator, TrackerOptions};
use roitrack::pipeline::ScheduleOrder;
use roitrack::sim::{Scenario, ScenarioKind};

use crate::ranges;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ScenarioArg {
    Static,
    Orthoglide,
    Spin,
    Random,
    Sweep,
}

impl From<ScenarioArg> for ScenarioKind {
    fn from(s: ScenarioArg) -> Self {
        match s {
            ScenarioArg::Static => ScenarioKind::Static,
            ScenarioArg::Orthoglide => ScenarioKind::Orthoglide,
            ScenarioArg::Spin => ScenarioKind::Spin,
            ScenarioArg::Random => ScenarioKind::Random,
            ScenarioArg::Sweep => ScenarioKind::Sweep,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ScheduleOrderArg {
    Bitrev,
    Rowmajor,
    Active,
}

impl From<ScheduleOrderArg> for ScheduleOrder {
    fn from(o: ScheduleOrderArg) -> Self {
        match o {
            ScheduleOrderArg::Bitrev => ScheduleOrder::BitReversed,
            ScheduleOrderArg::Rowmajor => ScheduleOrder::RowMajor,
            ScheduleOrderArg::Active => ScheduleOrder::Active,
        }
    }
}

/// The tracker's options (`--estimator`, `--every`, ...), shared by `track` and the commands that run the tracker:
/// one argument per entry of the library's table [`roitrack::estimators::tracker_options!`], whose docs are the help, whose
/// defaults are [`TrackerOptions::DEFAULT`] and whose checks name the value parsers of [`checks`]. Reads as the
/// [`TrackerOptions`] it holds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstimatorArgs(TrackerOptions);

impl std::ops::Deref for EstimatorArgs {
    type Target = TrackerOptions;

    fn deref(&self) -> &TrackerOptions {
        &self.0
    }
}

impl EstimatorArgs {
    /// What `--adapt` asks the Kalman filter to learn; `None` without it (the source's default).
    pub fn adaptation(&self) -> Option<estimator::Adaptation> {
        self.0.adapt
    }

    /// The options by name, checked and translated into a configuration by the library (as the Python package
    /// does).
    pub fn config(&self) -> anyhow::Result<TrackerConfig> {
        self.0.check()?;
        Ok(self.0.config())
    }
}

/// The value parsers the table's checks name: each refuses, as the command line is read, a value outside its range.
mod checks {
    pub use crate::ranges::{count, positive_up_to, within};
    use roitrack::estimators as estimator;

    /// `--window`: 0 (the newest measurement of each point) or 4 to [`estimator::MAX_WINDOW`] measurements.
    pub fn window() -> fn(&str) -> Result<usize, String> {
        |text| match text.trim().parse::<usize>() {
            Ok(0) => Ok(0),
            Ok(n) if (4..=estimator::MAX_WINDOW).contains(&n) => Ok(n),
            _ => Err(format!(
                "must be 0 (the newest measurement of each point) or from 4 to {} measurements (25 s at 4 kHz), got \
                 {text}",
                estimator::MAX_WINDOW
            )),
        }
    }
}

/// A value named by a string: its names (with their help) as the possible values, parsed by the library.
fn named_parser<T, E>(
    values: impl Iterator<Item = (&'static str, Option<&'static str>)>,
    parse: fn(&str) -> Result<T, E>,
) -> ValueParser
where
    T: Clone + Send + Sync + 'static,
    E: Into<Box<dyn std::error::Error + Send + Sync + 'static>> + 'static,
{
    let values = values.map(|(name, help)| match help {
        Some(help) => PossibleValue::new(name).help(help),
        None => PossibleValue::new(name),
    });
    ValueParser::new(PossibleValuesParser::new(values).try_map(move |name| parse(&name)))
}

/// The value parser of a table entry.
macro_rules! parser_of {
    (named $ty:ty) => {
        named_parser(<$ty>::ALL.iter().map(|v| (v.name(), v.help())), <$ty>::from_name)
    };
    (optional_named $ty:ty) => {
        parser_of!(named $ty)
    };
    (number $ty:ty, $check:ident($($arg:expr),*)) => {
        ValueParser::new(checks::$check($($arg),*))
    };
    (optional_number $ty:ty, $check:ident($($arg:expr),*)) => {
        parser_of!(number $ty, $check($($arg),*))
    };
}

/// The default `--help` shows for a table entry: none for the optional shapes (their help says the default).
macro_rules! default_text_of {
    (number, $value:expr) => {
        Some($value.to_string())
    };
    (named, $value:expr) => {
        Some($value.to_string())
    };
    (optional_number, $value:expr) => {
        None
    };
    (optional_named, $value:expr) => {
        None
    };
}

/// A table entry's value read back: the default of [`TrackerOptions::DEFAULT`] for the non-optional shapes.
macro_rules! value_of {
    (number $ty:ty, $matches:ident, $name:ident) => {
        $matches.get_one::<$ty>(stringify!($name)).copied().unwrap_or(TrackerOptions::DEFAULT.$name)
    };
    (named $ty:ty, $matches:ident, $name:ident) => {
        value_of!(number $ty, $matches, $name)
    };
    (optional_number $ty:ty, $matches:ident, $name:ident) => {
        $matches.get_one::<$ty>(stringify!($name)).copied()
    };
    (optional_named $ty:ty, $matches:ident, $name:ident) => {
        value_of!(optional_number $ty, $matches, $name)
    };
}

/// The arguments and their reading from the table.
macro_rules! estimator_arguments {
    ($($(#[doc = $doc:literal])* $name:ident : $shape:ident $ty:ty = $default:tt $(, $check:ident ($($arg:expr),*))?;)*) => {
        /// One argument per option, in the table's order.
        fn estimator_arguments() -> Vec<Arg> {
            static LABELS: OnceLock<Vec<Labels>> = OnceLock::new();
            let labels = LABELS.get_or_init(|| {
                vec![$(Labels::new(
                    stringify!($name),
                    &[$($doc),*],
                    default_text_of!($shape, TrackerOptions::DEFAULT.$name),
                )),*]
            });
            let parsers = [$(parser_of!($shape $ty $(, $check($($arg),*))?)),*];
            labels.iter().zip(parsers).map(|(labels, parser)| labels.arg(parser)).collect()
        }

        /// The options the arguments give.
        fn options_from(matches: &ArgMatches) -> TrackerOptions {
            TrackerOptions {
                $($name: value_of!($shape $ty, matches, $name),)*
            }
        }
    };
}

roitrack::estimators::tracker_options!(estimator_arguments);

/// The texts of an argument, made once.
struct Labels {
    id: &'static str,
    long: String,
    value_name: String,
    help: String,
    default: Option<String>,
}

impl Labels {
    /// The option `name` (`noise_px`: `--noise-px <NOISE_PX>`) with the help of its doc lines (joined, without the
    /// final period, as clap's derive makes it of a doc comment) and its default.
    fn new(name: &'static str, doc: &[&str], default: Option<String>) -> Self {
        let mut help = doc
            .iter()
            .map(|line| line.trim())
            .collect::<Vec<_>>()
            .join(" ");
        if help.ends_with('.') && !help.ends_with("..") {
            help.pop();
        }
        Self {
            id: name,
            long: name.replace('_', "-"),
            value_name: name.to_uppercase(),
            help,
            default,
        }
    }

    fn arg(&'static self, parser: ValueParser) -> Arg {
        let arg = Arg::new(self.id)
            .long(self.long.as_str())
            .value_name(self.value_name.as_str())
            .help(self.help.as_str())
            .action(ArgAction::Set)
            .value_parser(parser);
        match &self.default {
            Some(default) => arg.default_value(default.as_str()),
            None => arg,
        }
    }
}

impl clap::Args for EstimatorArgs {
    fn augment_args(command: Command) -> Command {
        command.args(estimator_arguments())
    }

    fn augment_args_for_update(command: Command) -> Command {
        Self::augment_args(command)
    }
}

impl clap::FromArgMatches for EstimatorArgs {
    fn from_arg_matches(matches: &ArgMatches) -> Result<Self, clap::Error> {
        Ok(Self(options_from(matches)))
    }

    fn update_from_arg_matches(&mut self, matches: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(matches)?;
        Ok(())
    }
}

/// How a frame camera reads its rows (`--shutter`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ShutterArg {
    /// Every pixel of a frame exposed over the same interval.
    Global,
    /// Rows read one after another, --line-delay-s apart.
    Rolling,
}

impl ShutterArg {
    /// `global` or `rolling`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Global => "global",
            Self::Rolling => "rolling",
        }
    }

    /// The readout of `--shutter` and `--line-delay-s`, refusing a line delay without a rolling shutter and a rolling
    /// shutter without a line delay.
    pub fn readout(self, line_delay_s: Option<f64>) -> Result<roitrack::core::time::Readout> {
        use roitrack::core::time::Readout;
        match (self, line_delay_s) {
            (Self::Global, None) => Ok(Readout::GlobalShutter),
            (Self::Global, Some(_)) => {
                bail!(
                    "--line-delay-s is for --shutter rolling (the frames are read by a global shutter)"
                )
            }
            (Self::Rolling, Some(line_delay_s)) => Ok(Readout::RollingShutter { line_delay_s }),
            (Self::Rolling, None) => bail!(
                "--shutter rolling needs --line-delay-s D, the time between two rows (s): the sensor's readout time \
                 divided by its number of rows, e.g. 30e-6 for 1,024 rows read in 30.7 ms"
            ),
        }
    }
}

/// The camera calibration, with what some files leave out (`--camera`, `--image-size`, `--camera-name`), shared by
/// every command that takes a camera.
#[derive(Debug, Clone, Args)]
pub struct CameraArgs {
    /// Camera calibration: ROS camera_info YAML (ROS 1 or 2, also as `ros2 topic echo` prints it), OpenCV
    /// FileStorage YAML or XML, or a Kalibr camchain; recognised from the content. Models: pinhole with plumb_bob,
    /// rational_polynomial, equidistant (fisheye) or no distortion. Default: none (required), but for `track
    /// --mcap-in BAG`, where it is the bag's CameraInfo.
    #[arg(long, value_name = "FILE")]
    pub camera: PathBuf,
    /// The image size for a calibration file that has none (OpenCV files may not); refused if the file says
    /// otherwise. Default: the file's.
    #[arg(long, value_name = "WxH", value_parser = parse_image_size)]
    pub image_size: Option<(u32, u32)>,
    /// Which camera of a Kalibr camchain (cam0, cam1, ...). Default: cam0.
    #[arg(long, value_name = "NAME")]
    pub camera_name: Option<String>,
}

impl CameraArgs {
    /// Reads the camera through the library's one reader of calibration files.
    pub fn read(&self) -> Result<roitrack::CameraModel> {
        let options = roitrack::formats::CameraFileOptions {
            image_size: self.image_size,
            camera_name: self.camera_name.clone(),
        };
        Ok(roitrack::formats::read_camera_file(&self.camera, &options)?)
    }
}

/// `640x480` -> (640, 480), within the image sizes a camera may have ([`roitrack::core::camera::MAX_IMAGE_SIDE_PX`]
/// a side, [`roitrack::core::camera::MAX_IMAGE_PIXELS`] in all).
pub fn parse_image_size(text: &str) -> Result<(u32, u32), String> {
    use roitrack::core::camera::{MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE_PX};
    let parsed = text
        .split_once(['x', 'X'])
        .and_then(|(w, h)| Some((w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?)));
    match parsed {
        Some((w, h))
            if w > 0
                && h > 0
                && w <= MAX_IMAGE_SIDE_PX
                && h <= MAX_IMAGE_SIDE_PX
                && u64::from(w) * u64::from(h) <= MAX_IMAGE_PIXELS =>
        {
            Ok((w, h))
        }
        Some(_) => Err(format!(
            "{text} is larger than any sensor: an image is at most {MAX_IMAGE_SIDE_PX} px a side and \
             {MAX_IMAGE_PIXELS} px in all"
        )),
        None => Err(format!(
            "expected WIDTHxHEIGHT in pixels, e.g. 1280x1024, got {text:?}"
        )),
    }
}

/// `--target-units`: the unit of a target file's coordinates and diameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LengthUnitArg {
    M,
    Cm,
    Mm,
}

impl From<LengthUnitArg> for roitrack::formats::LengthUnit {
    fn from(u: LengthUnitArg) -> Self {
        match u {
            LengthUnitArg::M => Self::M,
            LengthUnitArg::Cm => Self::Cm,
            LengthUnitArg::Mm => Self::Mm,
        }
    }
}

/// `--time-units`: the unit of a measurements file's times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TimeUnitArg {
    S,
    Ms,
    Us,
    Ns,
}

impl From<TimeUnitArg> for roitrack::formats::TimeUnit {
    fn from(u: TimeUnitArg) -> Self {
        match u {
            TimeUnitArg::S => Self::S,
            TimeUnitArg::Ms => Self::Ms,
            TimeUnitArg::Us => Self::Us,
            TimeUnitArg::Ns => Self::Ns,
        }
    }
}

/// The target file and its unit (`--target`, `--target-units`), shared by every command that reads a target.
#[derive(Debug, Clone, Args)]
pub struct TargetArgs {
    /// Target model: CSV id,x,y,z[,diameter] in the object frame, in metres unless --target-units says otherwise.
    #[arg(long, value_name = "FILE.csv")]
    pub target: PathBuf,
    /// The unit of the target file's coordinates and diameters. Default: metres, and a target spanning more than
    /// 2 m or with blobs wider than 0.2 m is refused as likely millimetres or centimetres (give m to read it as
    /// metres anyway).
    #[arg(long, value_enum, value_name = "UNIT")]
    pub target_units: Option<LengthUnitArg>,
}

impl TargetArgs {
    /// Reads the target through the library's reader, in the unit given (or checked for a likely unit mistake).
    pub fn read(&self) -> Result<roitrack::Target> {
        read_target(&self.target, self.target_units)
    }
}

/// Reads a target file (in `units`, or checked for a likely unit mistake) and notes on the standard error what its
/// pose's ambiguity costs, if it has one (3 points, a symmetric layout).
pub fn read_target(
    path: &std::path::Path,
    units: Option<LengthUnitArg>,
) -> Result<roitrack::Target> {
    let target = roitrack::formats::read_target_csv_in(path, units.map(Into::into))?;
    if let Some(ambiguity) = target.ambiguity() {
        eprintln!("roitrack: note: {}: {ambiguity}", path.display());
    }
    Ok(target)
}

/// The camera file a command was given, if any (some sources carry their own camera).
pub trait CameraPath {
    fn camera_path(&self) -> Option<&std::path::Path>;
}

impl CameraPath for CameraArgs {
    fn camera_path(&self) -> Option<&std::path::Path> {
        Some(&self.camera)
    }
}

impl CameraPath for Option<CameraArgs> {
    fn camera_path(&self) -> Option<&std::path::Path> {
        self.as_ref().map(|c| c.camera.as_path())
    }
}

/// The longest simulated run (`--duration-s`, s): a day. The ROIs of a run are bounded too
/// ([`roitrack::sim::MAX_SIMULATED_ROIS`]), and a frame sequence's frames ([`roitrack::sim::MAX_FRAMES`]).
pub const MAX_DURATION_S: f64 = 86_400.0;

/// Your own rig for a simulated scenario: camera and target files, and the motion moved, sped up or cut.
#[derive(Debug, Args)]
pub struct RigArgs {
    /// Your camera (any calibration file `track --camera` reads) instead of the built-in 1024 x 1024 one. Default:
    /// the built-in camera.
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// With --camera: the image size for a calibration file that has none. Default: the file's.
    #[arg(long, value_name = "WxH", requires = "camera", value_parser = parse_image_size)]
    pub image_size: Option<(u32, u32)>,
    /// With --camera: which camera of a Kalibr camchain. Default: cam0.
    #[arg(long, value_name = "NAME", requires = "camera")]
    pub camera_name: Option<String>,
    /// Your target (CSV id,x,y,z[,diameter], metres unless --target-units) instead of the built-in 4 x 4 grid.
    /// Default: the built-in target.
    #[arg(long, value_name = "FILE.csv")]
    pub target: Option<PathBuf>,
    /// With --target: the unit of its coordinates and diameters. Default: metres (a target that looks like
    /// millimetres or centimetres is refused).
    #[arg(long, value_enum, value_name = "UNIT", requires = "target")]
    pub target_units: Option<LengthUnitArg>,
    /// Move the motion along the optical axis so that the target is on average this far from the camera (m, at most
    /// 100). Default: the scenario's own (about 0.6 m).
    #[arg(long, value_name = "M", value_parser = ranges::positive_up_to(100.0, " m", "the farthest a first pose may be"))]
    pub distance_m: Option<f64>,
    /// Play the motion this many times faster (0.5: half the speeds, twice the duration), from 0.001 to 1000.
    /// Default: 1.
    #[arg(long, value_name = "FACTOR", default_value_t = 1.0, value_parser = ranges::within(1e-3..=1e3, "", "a thousand times slower to a thousand times faster"))]
    pub speed_scale: f64,
    /// Length of the simulation (s), at most a day (86,400 s). Default: the scenario's own (after --speed-scale).
    #[arg(long, value_name = "S", value_parser = ranges::positive_up_to(MAX_DURATION_S, " s", "a day"))]
    pub duration_s: Option<f64>,
}

impl RigArgs {
    /// Refuses a run whose files in `dir` would overwrite the rig's camera or target file (through links too).
    pub fn check_outputs(&self, dir: &std::path::Path, files: &[&str]) -> Result<()> {
        let inputs: Vec<(&str, &std::path::Path)> =
            [("--camera", &self.camera), ("--target", &self.target)]
                .into_iter()
                .filter_map(|(name, path)| path.as_deref().map(|p| (name, p)))
                .collect();
        let outputs: Vec<(String, PathBuf)> = files
            .iter()
            .map(|f| (format!("--out's {f}"), dir.join(f)))
            .collect();
        let outputs: Vec<(&str, &std::path::Path)> = outputs
            .iter()
            .map(|(n, p)| (n.as_str(), p.as_path()))
            .collect();
        Ok(roitrack::formats::check_output_paths(&inputs, &outputs)?)
    }

    /// Whether any option of the rig was given (`lab compare --sweep` refuses them).
    #[cfg(feature = "lab")]
    pub fn is_given(&self) -> bool {
        self.camera.is_some()
            || self.target.is_some()
            || self.distance_m.is_some()
            || self.duration_s.is_some()
            || self.speed_scale != 1.0
    }

    /// `base` on the camera and target given, moved, sped up and cut as asked, checked to keep the target in the
    /// image.
    pub fn scenario(&self, base: Scenario) -> Result<Scenario> {
        self.scenario_within(base, |_| Ok(()))
    }

    /// [`Self::scenario`], with `limit` (a command's own bound on the scenario, such as the demo's longest run)
    /// checked before the image margin: that check samples the whole motion, minutes for a day's run.
    pub fn scenario_within(
        &self,
        base: Scenario,
        limit: impl FnOnce(&Scenario) -> Result<()>,
    ) -> Result<Scenario> {
        let mut scenario = base;
        if let Some(path) = &self.camera {
            let options = roitrack::formats::CameraFileOptions {
                image_size: self.image_size,
                camera_name: self.camera_name.clone(),
            };
            scenario = scenario.with_camera(roitrack::formats::read_camera_file(path, &options)?);
        }
        if let Some(path) = &self.target {
            scenario = scenario.with_target(read_target(path, self.target_units)?);
        }
        let positive = |name: &str, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(value)
            } else {
                Err(anyhow!("{name} must be a positive number, got {value}"))
            }
        };
        let speed = positive("--speed-scale", self.speed_scale)?;
        if speed != 1.0 {
            scenario = scenario.with_speed_scale(speed);
        }
        if let Some(distance) = self.distance_m {
            scenario = scenario.with_distance_m(positive("--distance-m", distance)?);
        }
        if let Some(duration) = self.duration_s {
            scenario = scenario.with_duration_s(positive("--duration-s", duration)?);
        }
        limit(&scenario)?;
        let margin = scenario.min_image_margin_px();
        if margin.is_infinite() && margin < 0.0 {
            return Err(anyhow!(
                "with this camera and target the {} motion takes blobs behind the camera: move the target farther with \
                 --distance-m",
                scenario.kind.name()
            ));
        }
        if margin < 0.0 {
            return Err(anyhow!(
                "with this camera and target the {} motion takes blobs out of the image, up to {:.0} px beyond the \
                 border of the {} x {} image: move the target farther with --distance-m, or use a smaller target",
                scenario.kind.name(),
                -margin,
                scenario.camera.width_px,
                scenario.camera.height_px
            ));
        }
        Ok(scenario)
    }
}
