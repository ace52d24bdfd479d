//! Units of the input files, and the checks that catch files in the wrong ones.
//!
//! roitrack's files are in metres and seconds. A target file in millimetres, or measurement times in milliseconds,
//! would otherwise be taken at face value and give poses hundreds of metres away or velocities a thousand times too
//! small. The readers here refuse files that look like that, with the option that reads them as they are
//! (`--target-units`, `--time-units`); saying the unit, metres and seconds included, turns the check off.

use std::collections::VecDeque;
use std::fs::File;
use std::io::Read;
use std::path::Path;

use roitrack_core::{Measurement, Target, TargetPoint};

use crate::{FormatError, MeasurementReader, parse_target_csv};

/// A unit of length for target files (`--target-units`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LengthUnit {
    /// Metres.
    M,
    /// Centimetres.
    Cm,
    /// Millimetres.
    Mm,
}

impl LengthUnit {
    /// Metres in one unit.
    pub fn metres(self) -> f64 {
        match self {
            Self::M => 1.0,
            Self::Cm => 0.01,
            Self::Mm => 0.001,
        }
    }

    /// Its name as the option takes it (`m`, `cm`, `mm`).
    pub fn name(self) -> &'static str {
        match self {
            Self::M => "m",
            Self::Cm => "cm",
            Self::Mm => "mm",
        }
    }
}

/// A unit of time for measurement files (`--time-units`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeUnit {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
    /// Nanoseconds.
    Ns,
}

impl TimeUnit {
    /// Seconds in one unit.
    pub fn seconds(self) -> f64 {
        match self {
            Self::S => 1.0,
            Self::Ms => 1e-3,
            Self::Us => 1e-6,
            Self::Ns => 1e-9,
        }
    }

    /// Its name as the option takes it (`s`, `ms`, `us`, `ns`).
    pub fn name(self) -> &'static str {
        match self {
            Self::S => "s",
            Self::Ms => "ms",
            Self::Us => "us",
            Self::Ns => "ns",
        }
    }
}

/// A target wider than this (m) is taken for one in millimetres or centimetres unless the unit is said.
pub const MAX_PLAUSIBLE_TARGET_SPAN_M: f64 = 2.0;
/// A blob wider than this (m) is taken for one in millimetres or centimetres unless the unit is said.
pub const MAX_PLAUSIBLE_BLOB_DIAMETER_M: f64 = 0.2;

/// Reads a target CSV in `units` (converted to metres), or, with `None`, in metres, refusing a target that looks like
/// millimetres or centimetres: points spanning more than [`MAX_PLAUSIBLE_TARGET_SPAN_M`] or blobs wider than
/// [`MAX_PLAUSIBLE_BLOB_DIAMETER_M`]. The error names the likely unit and the option to give.
///
/// ```
/// use roitrack_formats::{LengthUnit, read_target_csv_in};
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("target.csv");
/// std::fs::write(&path, "id,x,y,z,diameter\n0,0,0,0,6\n1,60,0,0,6\n2,0,60,0,6\n3,60,60,0,6\n").unwrap();
/// let e = read_target_csv_in(&path, None).unwrap_err().to_string();
/// assert!(e.contains("--target-units mm"), "{e}");
/// let target = read_target_csv_in(&path, Some(LengthUnit::Mm)).unwrap();
/// assert_eq!(target.points()[1].point_in_obj_m.x, 0.06);
/// ```
pub fn read_target_csv_in(
    path: impl AsRef<Path>,
    units: Option<LengthUnit>,
) -> Result<Target, FormatError> {
    let path = path.as_ref();
    let file = File::open(path).map_err(|e| FormatError::io(path, "cannot open for reading", e))?;
    parse_target_csv_in(file, path, units)
}

/// [`read_target_csv_in`] on any byte source; `path` names it in errors.
pub fn parse_target_csv_in<R: Read>(
    reader: R,
    path: impl AsRef<Path>,
    units: Option<LengthUnit>,
) -> Result<Target, FormatError> {
    let path = path.as_ref();
    let target = parse_target_csv(reader, path)?;
    match units {
        Some(LengthUnit::M) => Ok(target),
        Some(unit) => {
            let scale = unit.metres();
            let points = target
                .points()
                .iter()
                .map(|p| TargetPoint {
                    id: p.id,
                    point_in_obj_m: p.point_in_obj_m * scale,
                    diameter_m: p.diameter_m.map(|d| d * scale),
                })
                .collect();
            Target::new(points).map_err(|e| FormatError::new(path, e.to_string()))
        }
        None => {
            check_target_units(&target, path)?;
            Ok(target)
        }
    }
}

/// Up to this many points, the span is every pair's distance (8 million pairs at most, milliseconds).
const EXACT_SPAN_POINTS: usize = 4096;

/// The largest distance between two of `points` (m): exact up to [`EXACT_SPAN_POINTS`] points; beyond (a target
/// file may hold hundreds of thousands, whose pairs would take minutes), the farthest pair found by sweeps from one
/// point to the point farthest from it and back, which is at least half the span and is the span for a point set
/// whose farthest pair is unique from both ends, as the targets of the unit check (a plane or a box of points) are.
fn span(points: &[TargetPoint]) -> f64 {
    if points.len() <= EXACT_SPAN_POINTS {
        let mut span_m: f64 = 0.0;
        for (i, a) in points.iter().enumerate() {
            for b in &points[i + 1..] {
                span_m = span_m.max((a.point_in_obj_m - b.point_in_obj_m).norm());
            }
        }
        return span_m;
    }
    let farthest_from = |from: &TargetPoint| {
        points
            .iter()
            .map(|p| (p.point_in_obj_m - from.point_in_obj_m).norm())
            .enumerate()
            .fold(
                (0, 0.0f64),
                |best, (i, d)| if d > best.1 { (i, d) } else { best },
            )
    };
    let mut span_m: f64 = 0.0;
    let mut at = 0;
    for _ in 0..4 {
        let (next, d) = farthest_from(&points[at]);
        span_m = span_m.max(d);
        at = next;
    }
    span_m
}

/// Refuses a target (read as metres) that looks like millimetres or centimetres.
fn check_target_units(target: &Target, path: &Path) -> Result<(), FormatError> {
    let points = target.points();
    let span_m = span(points);
    let widest_m = points
        .iter()
        .filter_map(|p| p.diameter_m)
        .fold(0.0, f64::max);
    if span_m <= MAX_PLAUSIBLE_TARGET_SPAN_M && widest_m <= MAX_PLAUSIBLE_BLOB_DIAMETER_M {
        return Ok(());
    }
    // Millimetres if that makes the blobs at least 1 mm across (or, without diameters, the target at least 2 cm
    // wide), else centimetres.
    let millimetres = if widest_m > 0.0 {
        widest_m * 1e-3 >= 1e-3
    } else {
        span_m * 1e-3 >= 0.02
    };
    let unit = if millimetres {
        LengthUnit::Mm
    } else {
        LengthUnit::Cm
    };
    let what = if span_m > MAX_PLAUSIBLE_TARGET_SPAN_M {
        format!("its points span {span_m:.3} m")
    } else {
        format!("a blob is {widest_m:.3} m across")
    };
    let field = if span_m > MAX_PLAUSIBLE_TARGET_SPAN_M {
        "x, y, z"
    } else {
        "diameter"
    };
    Err(FormatError::new(
        path,
        format!(
            "{what}, read as metres: the file looks like it is in {} (roitrack's target files are in metres); give \
             --target-units {} to read it so, or --target-units m if the target really is that large",
            if unit == LengthUnit::Mm { "millimetres" } else { "centimetres" },
            unit.name()
        ),
    )
    .with_field(field))
}

/// How many rows [`TimedMeasurements`] looks at to judge the time unit.
const TIME_CHECK_ROWS: usize = 1000;
/// Measurements further apart than this (median, s) are taken for times in a smaller unit unless the unit is said.
pub const MAX_PLAUSIBLE_MEDIAN_STEP_S: f64 = 0.2;
/// Times above this (s, about year 5100 as a Unix time) are taken for a smaller unit unless the unit is said.
pub const MAX_PLAUSIBLE_TIME_S: f64 = 1e11;

/// Measurements of a [`MeasurementReader`] with their times in `units` converted to seconds, or, with `None`, in
/// seconds, refusing times that look like milliseconds, microseconds or nanoseconds: a median step between
/// successive distinct times over the first 1,000 rows above [`MAX_PLAUSIBLE_MEDIAN_STEP_S`] (slower than 5 Hz), or
/// times above [`MAX_PLAUSIBLE_TIME_S`]. Reads ahead at most 1,000 rows: the memory stays constant.
///
/// ```
/// use roitrack_formats::{MeasurementReader, TimeUnit, TimedMeasurements};
///
/// let text = "t,id,u,v\n0,0,500,500\n0.25,1,510,500\n0.5,2,520,500\n0.75,3,530,500\n";
/// let reader = MeasurementReader::from_reader(text.as_bytes(), "m.csv").unwrap();
/// let e = TimedMeasurements::new(reader, None).collect::<Result<Vec<_>, _>>().unwrap_err().to_string();
/// assert!(e.contains("--time-units ms"), "{e}");
/// let reader = MeasurementReader::from_reader(text.as_bytes(), "m.csv").unwrap();
/// let ms: Vec<_> = TimedMeasurements::new(reader, Some(TimeUnit::Ms)).collect::<Result<_, _>>().unwrap();
/// assert_eq!(ms[3].t_s, 0.75e-3);
/// ```
#[derive(Debug)]
pub struct TimedMeasurements<R: Read> {
    reader: MeasurementReader<R>,
    units: Option<TimeUnit>,
    /// Rows read ahead for the check, and an error met while reading them (given after them).
    ahead: VecDeque<(Measurement, u64)>,
    ahead_error: Option<FormatError>,
    checked: bool,
    done: bool,
}

impl<R: Read> TimedMeasurements<R> {
    /// The measurements of `reader`, their times in `units`; `None`: in seconds, and refused, naming the likely
    /// unit, when their spacing says otherwise.
    pub fn new(reader: MeasurementReader<R>, units: Option<TimeUnit>) -> Self {
        Self {
            reader,
            checked: units.is_some(),
            units,
            ahead: VecDeque::new(),
            ahead_error: None,
            done: false,
        }
    }

    fn check(&mut self) -> Result<(), FormatError> {
        while self.ahead.len() < TIME_CHECK_ROWS {
            match self.reader.next() {
                Some(Ok(m)) => {
                    let line = self.reader.line();
                    self.ahead.push_back((m, line));
                }
                Some(Err(e)) => {
                    self.ahead_error = Some(e);
                    break;
                }
                None => break,
            }
        }
        let times: Vec<(f64, u64)> = self.ahead.iter().map(|(m, line)| (m.t_s, *line)).collect();
        check_time_unit(&times, self.reader.path(), "measurements")
    }
}

/// Refuses `times` (each with its line; the first rows of a file, in order) that look like milliseconds,
/// microseconds or nanoseconds read as seconds: a time above [`MAX_PLAUSIBLE_TIME_S`], or a median step between
/// successive distinct times above [`MAX_PLAUSIBLE_MEDIAN_STEP_S`]. `things` names the rows in the message
/// (`measurements`, `frames`); the error names the line and the field `t`, the likely unit and the option.
pub(crate) fn check_time_unit(
    times: &[(f64, u64)],
    path: &Path,
    things: &str,
) -> Result<(), FormatError> {
    let error = |line: u64, message: String| {
        FormatError::new(path, message)
            .with_line(line)
            .with_field("t")
    };
    if let Some((t_s, line)) = times
        .iter()
        .find(|(t_s, _)| t_s.abs() > MAX_PLAUSIBLE_TIME_S)
    {
        let unit = likely_time_unit(*t_s);
        return Err(error(
            *line,
            format!(
                "t = {t_s} read as seconds is past the year 5000: the times look like {}; give --time-units {} \
                 (or --time-units s if they really are seconds)",
                unit_words(unit),
                unit.name()
            ),
        ));
    }
    let mut steps: Vec<(f64, u64)> = times
        .iter()
        .zip(times.iter().skip(1))
        .filter(|(a, b)| b.0 > a.0)
        .map(|(a, b)| (b.0 - a.0, b.1))
        .collect();
    if steps.is_empty() {
        return Ok(());
    }
    let line = steps[0].1;
    let mid = steps.len() / 2;
    let median = steps
        .select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0))
        .1
        .0;
    if median <= MAX_PLAUSIBLE_MEDIAN_STEP_S {
        return Ok(());
    }
    let unit = [TimeUnit::Ms, TimeUnit::Us, TimeUnit::Ns]
        .into_iter()
        .find(|u| median * u.seconds() <= MAX_PLAUSIBLE_MEDIAN_STEP_S)
        .unwrap_or(TimeUnit::Ns);
    Err(error(
        line,
        format!(
            "successive {things} are {median} apart (the median over the first {} rows): {:.3} Hz if the \
             times are seconds; they look like {} ({}); give --time-units {} to read them so, or \
             --time-units s if they really are seconds",
            times.len(),
            1.0 / median,
            unit_words(unit),
            format_rate(1.0 / (median * unit.seconds())),
            unit.name()
        ),
    ))
}

/// The unit a time above [`MAX_PLAUSIBLE_TIME_S`] read as seconds most likely is in.
fn likely_time_unit(t_s: f64) -> TimeUnit {
    if t_s.abs() < 1e14 {
        TimeUnit::Ms
    } else if t_s.abs() < 1e17 {
        TimeUnit::Us
    } else {
        TimeUnit::Ns
    }
}

/// The farthest a pose in a file may put the target from the camera (m, any coordinate): beyond, no camera sees it,
/// and the file is in another unit or broken.
pub const MAX_PLAUSIBLE_DISTANCE_M: f64 = 1e6;
/// The fastest a twist in a file may move the target (m/s, any coordinate): beyond, the file is in another unit or
/// broken (a diverged estimate is marked lost well before).
pub const MAX_PLAUSIBLE_SPEED_MPS: f64 = 1e6;
/// The fastest a twist in a file may turn the target (rad/s, any coordinate): 160,000 turns a second.
pub const MAX_PLAUSIBLE_ANGULAR_SPEED_RADPS: f64 = 1e6;

/// Refuses a time of a trajectory file (poses, twists) past [`MAX_PLAUSIBLE_TIME_S`], naming the likely unit; such a
/// file has no unit option, so the way past is to convert it.
pub(crate) fn check_trajectory_time(t_s: f64, path: &Path, line: u64) -> Result<(), FormatError> {
    if t_s.abs() <= MAX_PLAUSIBLE_TIME_S {
        return Ok(());
    }
    let unit = likely_time_unit(t_s);
    Err(FormatError::new(
        path,
        format!(
            "t = {t_s} read as seconds is past the year 5000: the times look like {}; convert them to seconds \
             (divide by {:e})",
            unit_words(unit),
            1.0 / unit.seconds()
        ),
    )
    .with_line(line)
    .with_field("t"))
}

/// What a value of a trajectory file is, for [`check_plausible`]: its name, unit and largest magnitude.
pub(crate) struct Plausible {
    pub what: &'static str,
    pub unit: &'static str,
    pub max: f64,
}

pub(crate) const POSITION: Plausible = Plausible {
    what: "position of the target in the camera frame",
    unit: "m",
    max: MAX_PLAUSIBLE_DISTANCE_M,
};
pub(crate) const SPEED: Plausible = Plausible {
    what: "velocity",
    unit: "m/s",
    max: MAX_PLAUSIBLE_SPEED_MPS,
};
pub(crate) const ANGULAR_SPEED: Plausible = Plausible {
    what: "angular velocity",
    unit: "rad/s",
    max: MAX_PLAUSIBLE_ANGULAR_SPEED_RADPS,
};

/// Refuses a value of a trajectory file beyond its largest plausible magnitude, naming the line, the field, the value
/// and the bound.
pub(crate) fn check_plausible(
    value: f64,
    kind: &Plausible,
    path: &Path,
    line: u64,
    field: &str,
) -> Result<(), FormatError> {
    let Plausible { what, unit, max } = kind;
    if value.abs() <= *max {
        return Ok(());
    }
    // 1e300, not three hundred digits.
    let value = if value.abs() < 1e7 {
        value.to_string()
    } else {
        format!("{value:e}")
    };
    Err(FormatError::new(
        path,
        format!(
            "{value} {unit} is not a plausible {what}: at most {max:e} {unit} in magnitude (is the file in {unit}?)"
        ),
    )
    .with_line(line)
    .with_field(field))
}

fn unit_words(unit: TimeUnit) -> &'static str {
    match unit {
        TimeUnit::S => "seconds",
        TimeUnit::Ms => "milliseconds",
        TimeUnit::Us => "microseconds",
        TimeUnit::Ns => "nanoseconds",
    }
}

fn format_rate(hz: f64) -> String {
    if hz >= 1e3 {
        format!("{:.3} kHz", hz / 1e3)
    } else {
        format!("{hz:.3} Hz")
    }
}

impl<R: Read> Iterator for TimedMeasurements<R> {
    type Item = Result<Measurement, FormatError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if !self.checked {
            self.checked = true;
            if let Err(e) = self.check() {
                self.done = true;
                return Some(Err(e));
            }
        }
        let item = match self.ahead.pop_front() {
            Some((m, _)) => Some(Ok(m)),
            None => match self.ahead_error.take() {
                Some(e) => Some(Err(e)),
                None => self.reader.next(),
            },
        };
        match item {
            Some(Ok(mut m)) => {
                if let Some(unit) = self.units {
                    m.t_s *= unit.seconds();
                }
                Some(Ok(m))
            }
            other => {
                self.done = true;
                other
            }
        }
    }
}
