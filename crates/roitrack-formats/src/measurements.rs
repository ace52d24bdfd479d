//! Measurements CSV (docs/model.md): header `t,id,u,v`, one measured blob centroid per row, rows in time order.
//!
//! `t` is the time of the exposure midpoint (seconds, any origin), `id` the target point id, `u v` the centroid in raw
//! (distorted) pixels: `u` to the right, `v` down, pixel centres at integer coordinates.

use std::collections::HashSet;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use csv::StringRecord;
use roitrack_core::Measurement;

use crate::FormatError;
use crate::csv_util::{Row, csv_reader, read_header, read_row};
use crate::limits::{Limited, open_file};
use crate::row_writer::RowWriter;

const COLUMNS: [&str; 4] = ["t", "id", "u", "v"];
/// What the file should be, for errors.
const WHAT: &str = "a measurements CSV (t,id,u,v)";

/// How far (px) a centroid may lie beyond the sensor's edge (at -0.5 and size - 0.5) before
/// [`MeasurementChecks::with_image_size`] refuses it: centroid noise on a blob cut by the edge.
pub const CENTROID_EDGE_TOLERANCE_PX: f64 = 1.0;

/// A field of a [`Measurement`], as a [`MeasurementProblem`] names it; each reader names it its own way (a CSV
/// column `t`, `id`, `u`, `v`; a bag message's array `dt_s`, `point_ids`, `u_px`, `v_px`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeasurementField {
    /// `t_s`: the time (s).
    Time,
    /// `id`: the target point id.
    Id,
    /// `u_px`: the centroid's column (raw pixels).
    U,
    /// `v_px`: the centroid's row (raw pixels).
    V,
}

/// What is wrong with a measurement, as [`MeasurementChecks::check`] finds it. Its text (`Display`) says what is
/// wrong and not where: each reader adds the place its own way (a file's line and column, a bag's message index and
/// array entry).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MeasurementProblem {
    /// A time or centroid that is NaN or infinite.
    NotFinite {
        /// The field ([`MeasurementField::Time`], [`MeasurementField::U`] or [`MeasurementField::V`]).
        field: MeasurementField,
        /// Its value.
        value: f64,
    },
    /// An id the target does not have (with [`MeasurementChecks::with_known_ids`]).
    UnknownId {
        /// The id.
        id: u32,
    },
    /// A centroid more than [`CENTROID_EDGE_TOLERANCE_PX`] off the image (with
    /// [`MeasurementChecks::with_image_size`]).
    OffImage {
        /// [`MeasurementField::U`] or [`MeasurementField::V`].
        field: MeasurementField,
        /// The centroid's coordinate (px).
        value_px: f64,
        /// The image's width (for `u`) or height (for `v`), px.
        size_px: u32,
    },
    /// A time earlier than the previous measurement's.
    OutOfOrder {
        /// The measurement's time (s).
        t_s: f64,
        /// The previous measurement's time (s).
        previous_t_s: f64,
    },
    /// A point measured a second time at the same time: a row given twice, which would count as two independent
    /// measurements (twice the estimates, a covariance too small).
    Duplicate {
        /// The point id.
        id: u32,
        /// The time (s).
        t_s: f64,
    },
}

impl MeasurementProblem {
    /// The field the problem is in.
    pub fn field(&self) -> MeasurementField {
        match *self {
            Self::NotFinite { field, .. } | Self::OffImage { field, .. } => field,
            Self::UnknownId { .. } | Self::Duplicate { .. } => MeasurementField::Id,
            Self::OutOfOrder { .. } => MeasurementField::Time,
        }
    }
}

impl std::fmt::Display for MeasurementProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Self::NotFinite { value, .. } => write!(f, "must be a finite number, got {value}"),
            Self::UnknownId { id } => {
                write!(f, "unknown point id {id}: the target has no such point")
            }
            Self::OffImage {
                field,
                value_px,
                size_px,
            } => {
                let axis = if field == MeasurementField::U {
                    "wide"
                } else {
                    "high"
                };
                write!(
                    f,
                    "{value_px} px is outside the image, which is {size_px} px {axis} (0 to {} px, from the \
                     camera): the measurements are not from this camera, or their pixels are scaled or offset (a \
                     ROI's own coordinates instead of the image's?)",
                    size_px.saturating_sub(1)
                )
            }
            Self::OutOfOrder { t_s, previous_t_s } => write!(
                f,
                "time {t_s} s is earlier than {previous_t_s} s, the previous measurement's: measurements must be \
                 in time order"
            ),
            Self::Duplicate { id, t_s } => write!(
                f,
                "point {id} is measured twice at t = {t_s} s: a point has one centroid at a time (a row given \
                 twice?)"
            ),
        }
    }
}

/// The checks every measurement gets, whichever reader it comes from ([`MeasurementReader`], the ROS 2 bag reader):
/// time and centroid finite; with [`with_known_ids`](Self::with_known_ids), an id of the target; with
/// [`with_image_size`](Self::with_image_size), the centroid on the image; the time not before the previous
/// measurement's; no point measured twice at one time. [`check`](Self::check) says what is wrong, so that each reader
/// names the place its own way.
///
/// ```
/// use roitrack_core::Measurement;
/// use roitrack_formats::{MeasurementChecks, MeasurementField};
///
/// let mut checks = MeasurementChecks::new().with_known_ids([1, 2]).with_image_size(640, 480);
/// let m = Measurement { t_s: 0.5, id: 1, u_px: 320.0, v_px: 240.0 };
/// assert!(checks.check(&m).is_ok());
/// let problem = checks.check(&Measurement { t_s: 0.25, ..m }).unwrap_err();
/// assert_eq!(problem.field(), MeasurementField::Time);
/// assert!(problem.to_string().starts_with("time 0.25 s is earlier than 0.5 s"));
/// let problem = checks.check(&Measurement { id: 9, ..m }).unwrap_err();
/// assert_eq!(problem.to_string(), "unknown point id 9: the target has no such point");
/// let problem = checks.check(&m).unwrap_err();
/// assert!(problem.to_string().starts_with("point 1 is measured twice at t = 0.5 s"));
/// ```
#[derive(Debug, Clone, Default)]
pub struct MeasurementChecks {
    known_ids: Option<HashSet<u32>>,
    /// The image (px) every centroid must lie on.
    image_size: Option<(u32, u32)>,
    /// The time (s) of the last measurement that passed.
    previous_t_s: Option<f64>,
    /// The points measured at that time.
    ids_at_time: HashSet<u32>,
}

impl MeasurementChecks {
    /// Checks that accept any id, any finite centroid and times that never go back.
    pub fn new() -> Self {
        Self::default()
    }

    /// Makes an id outside `ids` (the target's point ids) a problem.
    #[must_use]
    pub fn with_known_ids(mut self, ids: impl IntoIterator<Item = u32>) -> Self {
        self.known_ids = Some(ids.into_iter().collect());
        self
    }

    /// Makes a centroid off an image of `width_px` x `height_px` (the camera's) a problem. A centroid may lie up to
    /// [`CENTROID_EDGE_TOLERANCE_PX`] beyond the sensor's edge (noise on a blob cut by the edge), not more.
    #[must_use]
    pub fn with_image_size(mut self, width_px: u32, height_px: u32) -> Self {
        self.image_size = Some((width_px, height_px));
        self
    }

    /// Checks `m`, the measurement after those that passed before, and returns its first problem (in the order of
    /// [`MeasurementProblem`]'s variants). A measurement that passes becomes the previous one for the time order.
    pub fn check(&mut self, m: &Measurement) -> Result<(), MeasurementProblem> {
        for (field, value) in [
            (MeasurementField::Time, m.t_s),
            (MeasurementField::U, m.u_px),
            (MeasurementField::V, m.v_px),
        ] {
            if !value.is_finite() {
                return Err(MeasurementProblem::NotFinite { field, value });
            }
        }
        if let Some(known) = &self.known_ids
            && !known.contains(&m.id)
        {
            return Err(MeasurementProblem::UnknownId { id: m.id });
        }
        if let Some((width_px, height_px)) = self.image_size {
            for (field, value_px, size_px) in [
                (MeasurementField::U, m.u_px, width_px),
                (MeasurementField::V, m.v_px, height_px),
            ] {
                let edge = -0.5 - CENTROID_EDGE_TOLERANCE_PX;
                if !(edge..=f64::from(size_px) - edge - 1.0).contains(&value_px) {
                    return Err(MeasurementProblem::OffImage {
                        field,
                        value_px,
                        size_px,
                    });
                }
            }
        }
        if let Some(previous_t_s) = self.previous_t_s
            && m.t_s < previous_t_s
        {
            return Err(MeasurementProblem::OutOfOrder {
                t_s: m.t_s,
                previous_t_s,
            });
        }
        if self.previous_t_s != Some(m.t_s) {
            self.ids_at_time.clear();
        }
        if !self.ids_at_time.insert(m.id) {
            return Err(MeasurementProblem::Duplicate {
                id: m.id,
                t_s: m.t_s,
            });
        }
        self.previous_t_s = Some(m.t_s);
        Ok(())
    }
}

/// A streaming reader of a measurements CSV: one [`Measurement`] per row, in constant memory.
///
/// It checks every row: four fields, `t`, `u`, `v` finite numbers, `id` a non-negative integer, then the
/// [`MeasurementChecks`] (with [`Self::with_known_ids`], an id of the target; with [`Self::with_image_size`], a
/// centroid on the image; times not decreasing). The first error is returned as an `Err` item naming the line and
/// field, after which the iterator ends.
#[derive(Debug)]
pub struct MeasurementReader<R: Read> {
    csv: csv::Reader<Limited<R>>,
    record: StringRecord,
    path: PathBuf,
    checks: MeasurementChecks,
    /// The line of the last row read (0 before the first).
    line: u64,
    /// The points and lines of the rows at the last row's time, to name the first of a duplicate.
    lines_at_time: Vec<(u32, u64)>,
    time_of_lines: Option<f64>,
    done: bool,
}

impl MeasurementReader<File> {
    /// Opens a measurements CSV and checks its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let path = path.as_ref();
        // Read in constant memory: no limit on the file's size, only on its lines (in `from_reader`).
        let file = open_file(path, WHAT, None)?;
        Self::from_reader(file, path)
    }
}

impl<R: Read> MeasurementReader<R> {
    /// Reads measurements from any byte source; `path` names it in errors. Checks the header. A line longer than
    /// [`MAX_LINE_BYTES`](crate::MAX_LINE_BYTES) is an error, so that a source without line breaks (`/dev/zero`) is
    /// refused after that many bytes instead of filling memory.
    pub fn from_reader(reader: R, path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let path = path.as_ref().to_path_buf();
        let mut csv = csv_reader(Limited::new(reader, WHAT, None));
        read_header(&mut csv, &path, &COLUMNS, None)?;
        Ok(Self {
            csv,
            record: StringRecord::new(),
            path,
            checks: MeasurementChecks::new(),
            line: 0,
            lines_at_time: Vec::new(),
            time_of_lines: None,
            done: false,
        })
    }

    /// Makes an id outside `ids` (the target's point ids) an error (see [`MeasurementChecks::with_known_ids`]).
    #[must_use]
    pub fn with_known_ids(mut self, ids: impl IntoIterator<Item = u32>) -> Self {
        self.checks = self.checks.with_known_ids(ids);
        self
    }

    /// Makes a centroid off an image of `width_px` x `height_px` (the camera's) an error naming its line and field
    /// (see [`MeasurementChecks::with_image_size`]).
    #[must_use]
    pub fn with_image_size(mut self, width_px: u32, height_px: u32) -> Self {
        self.checks = self.checks.with_image_size(width_px, height_px);
        self
    }

    /// The file, as named by the caller.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The line of the last row read (0 before the first).
    pub fn line(&self) -> u64 {
        self.line
    }

    fn next_measurement(&mut self) -> Result<Option<Measurement>, FormatError> {
        let Some(line) = read_row(&mut self.csv, &mut self.record, &self.path, &COLUMNS)? else {
            return Ok(None);
        };
        let row = Row {
            record: &self.record,
            line,
            path: &self.path,
            columns: &COLUMNS,
        };
        let m = Measurement {
            t_s: row.finite(0)?,
            id: row.id(1)?,
            u_px: row.finite(2)?,
            v_px: row.finite(3)?,
        };
        if let Err(problem) = self.checks.check(&m) {
            let column = match problem.field() {
                MeasurementField::Time => 0,
                MeasurementField::Id => 1,
                MeasurementField::U => 2,
                MeasurementField::V => 3,
            };
            let message = match problem {
                MeasurementProblem::OffImage { .. } => {
                    format!("centroid {} = {problem}", COLUMNS[column])
                }
                // As every CSV file of roitrack words it: the earlier row by its line.
                MeasurementProblem::OutOfOrder { t_s, previous_t_s } => format!(
                    "time {t_s} s is earlier than {previous_t_s} s on line {}: rows must be in time order",
                    self.line
                ),
                MeasurementProblem::Duplicate { id, t_s } => {
                    let first = self
                        .lines_at_time
                        .iter()
                        .find(|(seen, _)| *seen == id)
                        .map_or(0, |(_, line)| *line);
                    format!(
                        "point {id} at t = {t_s} s is already on line {first}: a point has one centroid at a time \
                         (a row given twice?)"
                    )
                }
                _ => problem.to_string(),
            };
            return Err(row.error(column, message));
        }
        if self.time_of_lines != Some(m.t_s) {
            self.lines_at_time.clear();
            self.time_of_lines = Some(m.t_s);
        }
        self.lines_at_time.push((m.id, line));
        self.line = line;
        Ok(Some(m))
    }
}

impl<R: Read> Iterator for MeasurementReader<R> {
    type Item = Result<Measurement, FormatError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.next_measurement().transpose();
        if !matches!(item, Some(Ok(_))) {
            self.done = true;
        }
        item
    }
}

/// Reads a whole measurements CSV into memory (see [`MeasurementReader`] for the checks and for streaming).
pub fn read_measurements_csv(path: impl AsRef<Path>) -> Result<Vec<Measurement>, FormatError> {
    MeasurementReader::open(path)?.collect()
}

/// Writes a measurements CSV atomically: nothing appears at the path until [`Self::finish`].
///
/// Numbers are written with full round-trip precision. Values that the reader would refuse (non-finite, times going
/// backwards) are refused here.
#[derive(Debug)]
pub struct MeasurementWriter {
    rows: RowWriter,
}

impl MeasurementWriter {
    /// Starts writing `path` (its directory must exist) and writes the header `t,id,u,v`.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        Ok(Self {
            rows: RowWriter::create(path.as_ref(), Some("t,id,u,v"), false)?,
        })
    }

    /// Appends one measurement (t in seconds, raw pixels).
    pub fn write(&mut self, m: &Measurement) -> Result<(), FormatError> {
        self.rows.check(m.t_s, &[("u", m.u_px), ("v", m.v_px)])?;
        self.rows.write_record(
            m.t_s,
            format_args!("{},{},{},{}", m.t_s, m.id, m.u_px, m.v_px),
        )
    }

    /// Completes the file and moves it into place.
    pub fn finish(self) -> Result<(), FormatError> {
        self.rows.finish()
    }
}

/// Writes all `measurements` to a measurements CSV, atomically.
pub fn write_measurements_csv(
    path: impl AsRef<Path>,
    measurements: &[Measurement],
) -> Result<(), FormatError> {
    let mut writer = MeasurementWriter::create(path)?;
    for m in measurements {
        writer.write(m)?;
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<Measurement>, FormatError> {
        MeasurementReader::from_reader(text.as_bytes(), "measurements.csv")?.collect()
    }

    fn parse_err(text: &str) -> String {
        parse(text).unwrap_err().to_string()
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("measurements.csv");
        let ms: Vec<Measurement> = (0..200u32)
            .map(|i| Measurement {
                t_s: 0.1 * (i / 3) as f64 + 1e-13,
                id: i % 16,
                u_px: 512.0 + (i as f64).sin() * 123.456_789_012_345_67,
                v_px: -3.0e-9 * i as f64 + 1e6 * (i as f64).cos(),
            })
            .collect();
        write_measurements_csv(&path, &ms).unwrap();
        let back = read_measurements_csv(&path).unwrap();
        assert_eq!(back, ms);
        let mut reader = MeasurementReader::open(&path)
            .unwrap()
            .with_known_ids(0..16);
        assert_eq!(reader.next().unwrap().unwrap(), ms[0]);
        assert_eq!(reader.count(), 199);
    }

    #[test]
    fn accepts_header_only_whitespace_and_equal_times() {
        assert!(parse("t,id,u,v\n").unwrap().is_empty());
        assert!(parse("t,id,u,v").unwrap().is_empty());
        let ms = parse(" t , id,u,v\r\n0.5, 3 ,1.5,2\n\n0.5,4,1e3,-2.25\n").unwrap();
        assert_eq!(ms.len(), 2);
        assert_eq!(
            ms[1],
            Measurement {
                t_s: 0.5,
                id: 4,
                u_px: 1000.0,
                v_px: -2.25
            }
        );
    }

    #[test]
    fn byte_order_mark_is_ignored() {
        let ms = parse("\u{feff}t,id,u,v\n0,1,2,3\n").unwrap();
        assert_eq!(ms.len(), 1);
    }

    #[test]
    fn completely_empty_file_is_an_error_naming_the_file() {
        let e = parse_err("");
        assert!(e.starts_with("measurements.csv: "), "{e}");
        assert!(e.contains("empty"), "{e}");
    }

    #[test]
    fn time_going_backwards_names_the_line_and_both_times() {
        let e = parse_err("t,id,u,v\n0.5,1,1,1\n0.75,2,1,1\n0.25,3,1,1\n");
        assert!(e.starts_with("measurements.csv:4: field 't': "), "{e}");
        assert!(
            e.contains("0.25") && e.contains("0.75") && e.contains("line 3"),
            "{e}"
        );
    }

    #[test]
    fn nan_u_is_refused() {
        let e = parse_err("t,id,u,v\n0,1,1,1\n0.1,1,NaN,1\n");
        assert!(e.starts_with("measurements.csv:3: field 'u': "), "{e}");
        assert!(e.contains("finite"), "{e}");
        let e = parse_err("t,id,u,v\n0,1,abc,1\n");
        assert_eq!(e, "measurements.csv:2: field 'u': not a number: \"abc\"");
        let e = parse_err("t,id,u,v\ninf,1,1,1\n");
        assert!(e.starts_with("measurements.csv:2: field 't': "), "{e}");
    }

    #[test]
    fn unknown_and_invalid_ids_are_refused() {
        let text = "t,id,u,v\n0,1,1,1\n0.1,42,1,1\n";
        assert_eq!(parse(text).unwrap().len(), 2);
        let e = MeasurementReader::from_reader(text.as_bytes(), "measurements.csv")
            .unwrap()
            .with_known_ids([0, 1, 2])
            .collect::<Result<Vec<_>, _>>()
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("measurements.csv:3: field 'id': "), "{e}");
        assert!(e.contains("42"), "{e}");
        for bad in ["-1", "1.5", "x", "", "4294967296"] {
            let e = parse_err(&format!("t,id,u,v\n0,{bad},1,1\n"));
            assert!(e.starts_with("measurements.csv:2: field 'id': "), "{e}");
        }
    }

    #[test]
    fn truncated_last_line_is_an_error_naming_the_line() {
        let e = parse_err("t,id,u,v\n0,1,1,1\n0.1,2,3");
        assert!(
            e.starts_with("measurements.csv:3: field 'v': missing"),
            "{e}"
        );
        let e = parse_err("t,id,u,v\n0,1,1,1,7\n");
        assert!(
            e.starts_with("measurements.csv:2: field 'column 5': "),
            "{e}"
        );
    }

    #[test]
    fn wrong_header_is_refused() {
        let e = parse_err("t,id,x,v\n");
        assert!(e.starts_with("measurements.csv:1: field 'u': "), "{e}");
        let e = parse_err("t,id,u\n");
        assert!(
            e.starts_with("measurements.csv:1: field 'v': missing column"),
            "{e}"
        );
        let e = parse_err("t,id,u,v,w\n");
        assert!(
            e.starts_with("measurements.csv:1: field 'w': unexpected"),
            "{e}"
        );
        // No header at all: the first data row is taken as one and refused.
        let e = parse_err("0,1,1,1\n");
        assert!(e.starts_with("measurements.csv:1: field 't': "), "{e}");
    }

    #[test]
    fn a_point_measured_twice_at_one_time_names_both_lines() {
        // Distinct points at one time (a frame) are fine; the same point again is a row given twice.
        let text = "t,id,u,v\n0,1,1,1\n0.5,1,1,1\n0.5,2,1,1\n0.5,3,1,1\n0.5,2,1,1\n";
        let e = parse_err(text);
        assert_eq!(
            e,
            "measurements.csv:6: field 'id': point 2 at t = 0.5 s is already on line 4: a point has one centroid \
             at a time (a row given twice?)"
        );
        assert_eq!(
            parse("t,id,u,v\n0,1,1,1\n0,2,1,1\n0.5,1,1,1\n0.5,2,1,1\n")
                .unwrap()
                .len(),
            4
        );
    }

    #[test]
    fn iteration_stops_after_the_first_error() {
        let mut reader =
            MeasurementReader::from_reader("t,id,u,v\n0,1,x,1\n0,1,1,1\n".as_bytes(), "m.csv")
                .unwrap();
        assert!(reader.next().unwrap().is_err());
        assert!(reader.next().is_none());
    }

    #[test]
    fn invalid_utf8_names_the_line() {
        let bytes = b"t,id,u,v\n0,1,1,1\n0,1,\xff,1\n";
        let e = MeasurementReader::from_reader(&bytes[..], "m.csv")
            .unwrap()
            .collect::<Result<Vec<_>, _>>()
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("m.csv:3: "), "{e}");
    }

    #[test]
    fn missing_file_is_an_error_naming_it() {
        let e = read_measurements_csv("/nonexistent-dir/meas.csv").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent-dir/meas.csv: cannot open")
        );
        assert!(e.io_error().is_some());
    }

    #[test]
    fn writer_refuses_what_the_reader_would_refuse() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.csv");
        let mut w = MeasurementWriter::create(&path).unwrap();
        let m = Measurement {
            t_s: 1.0,
            id: 0,
            u_px: 1.0,
            v_px: 2.0,
        };
        w.write(&m).unwrap();
        let e = w.write(&Measurement { t_s: 0.5, ..m }).unwrap_err();
        assert!(e.to_string().contains("m.csv:3: field 't'"), "{e}");
        let e = w
            .write(&Measurement {
                u_px: f64::INFINITY,
                ..m
            })
            .unwrap_err();
        assert!(e.to_string().contains("m.csv:3: field 'u'"), "{e}");
        drop(w);
        assert!(!path.exists());
    }
}
