//! Twists CSV (docs/model.md): header `t,vx,vy,vz,wx,wy,wz`, one twist per row, times strictly increasing.
//!
//! `t` in seconds; `vx vy vz` the velocity V of the object origin (m/s) and `wx wy wz` the angular velocity W
//! (rad/s), both expressed in the camera frame (docs/model.md). The rows have the same times as the poses.

use std::io::Read;
use std::path::Path;

use nalgebra::Vector3;
use roitrack_core::TwistSample;

use crate::FormatError;
use crate::csv_util::{check_time_order, csv_reader, for_each_row, read_header};
use crate::limits::{DEFAULT_MAX_TRAJECTORY_FILE_BYTES, Limited, open_file};
use crate::row_writer::RowWriter;
use crate::units::{ANGULAR_SPEED, SPEED, check_plausible, check_trajectory_time};

const COLUMNS: [&str; 7] = ["t", "vx", "vy", "vz", "wx", "wy", "wz"];
/// What the file should be, for errors.
const WHAT: &str = "a twists CSV";

/// Reads a twists CSV (see [`parse_twists_csv`]) of at most
/// [`DEFAULT_MAX_TRAJECTORY_FILE_BYTES`](crate::DEFAULT_MAX_TRAJECTORY_FILE_BYTES).
pub fn read_twists_csv(path: impl AsRef<Path>) -> Result<Vec<TwistSample>, FormatError> {
    read_twists_csv_limited(path, DEFAULT_MAX_TRAJECTORY_FILE_BYTES)
}

/// Reads a twists CSV of at most `max_file_bytes` (a larger file is refused before it is read).
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("twists.csv");
/// std::fs::write(&path, "t,vx,vy,vz,wx,wy,wz\n0,0,0,0,0,0,0\n").unwrap();
/// assert_eq!(roitrack_formats::read_twists_csv_limited(&path, 1000).unwrap().len(), 1);
/// let e = roitrack_formats::read_twists_csv_limited(&path, 10).unwrap_err().to_string();
/// assert!(e.contains("at most 10 bytes"), "{e}");
/// ```
pub fn read_twists_csv_limited(
    path: impl AsRef<Path>,
    max_file_bytes: u64,
) -> Result<Vec<TwistSample>, FormatError> {
    let path = path.as_ref();
    let file = open_file(path, WHAT, Some(max_file_bytes))?;
    parse_twists(file, path, max_file_bytes)
}

/// Parses a twists CSV from any byte source; `path` names it in errors. Every value must be a finite number, the
/// times must increase strictly and be at most [`MAX_PLAUSIBLE_TIME_S`](crate::MAX_PLAUSIBLE_TIME_S), the velocities
/// at most [`MAX_PLAUSIBLE_SPEED_MPS`](crate::MAX_PLAUSIBLE_SPEED_MPS) and
/// [`MAX_PLAUSIBLE_ANGULAR_SPEED_RADPS`](crate::MAX_PLAUSIBLE_ANGULAR_SPEED_RADPS) in each coordinate; a header-only file holds no twists, an empty one is an error. Lines are at most
/// [`MAX_LINE_BYTES`](crate::MAX_LINE_BYTES), the whole at most
/// [`DEFAULT_MAX_TRAJECTORY_FILE_BYTES`](crate::DEFAULT_MAX_TRAJECTORY_FILE_BYTES).
pub fn parse_twists_csv<R: Read>(
    reader: R,
    path: impl AsRef<Path>,
) -> Result<Vec<TwistSample>, FormatError> {
    parse_twists(reader, path.as_ref(), DEFAULT_MAX_TRAJECTORY_FILE_BYTES)
}

fn parse_twists<R: Read>(
    reader: R,
    path: &Path,
    max_file_bytes: u64,
) -> Result<Vec<TwistSample>, FormatError> {
    let mut csv = csv_reader(Limited::new(reader, WHAT, Some(max_file_bytes)));
    read_header(&mut csv, path, &COLUMNS, None)?;
    let mut twists = Vec::new();
    let mut previous = None;
    for_each_row(&mut csv, path, &COLUMNS, |row| {
        let mut values = [0.0; 7];
        for (i, value) in values.iter_mut().enumerate() {
            *value = row.finite(i)?;
        }
        let [t_s, vx, vy, vz, wx, wy, wz] = values;
        check_trajectory_time(t_s, path, row.line)?;
        for (i, value) in values.iter().enumerate().skip(1) {
            let kind = if i <= 3 { &SPEED } else { &ANGULAR_SPEED };
            check_plausible(*value, kind, path, row.line, COLUMNS[i])?;
        }
        check_time_order(previous, t_s, true, path, row.line, "t")?;
        previous = Some((t_s, row.line));
        twists.push(TwistSample {
            t_s,
            velocity_mps: Vector3::new(vx, vy, vz),
            angular_velocity_radps: Vector3::new(wx, wy, wz),
        });
        Ok(())
    })?;
    Ok(twists)
}

/// Writes a twists CSV atomically: nothing appears at the path until [`Self::finish`].
///
/// Numbers are written with full round-trip precision; non-finite values and times that do not increase are
/// refused.
#[derive(Debug)]
pub struct TwistWriter {
    rows: RowWriter,
}

impl TwistWriter {
    /// Starts writing `path` (its directory must exist) and writes the header.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        Ok(Self {
            rows: RowWriter::create(path.as_ref(), Some(&COLUMNS.join(",")), true)?,
        })
    }

    /// Appends one twist (s, m/s, rad/s; camera frame).
    pub fn write(&mut self, twist: &TwistSample) -> Result<(), FormatError> {
        let v = &twist.velocity_mps;
        let w = &twist.angular_velocity_radps;
        self.rows.check(
            twist.t_s,
            &[
                ("vx", v.x),
                ("vy", v.y),
                ("vz", v.z),
                ("wx", w.x),
                ("wy", w.y),
                ("wz", w.z),
            ],
        )?;
        self.rows.write_record(
            twist.t_s,
            format_args!(
                "{},{},{},{},{},{},{}",
                twist.t_s, v.x, v.y, v.z, w.x, w.y, w.z
            ),
        )
    }

    /// Completes the file and moves it into place.
    pub fn finish(self) -> Result<(), FormatError> {
        self.rows.finish()
    }
}

/// Writes all `twists` to a twists CSV, atomically.
pub fn write_twists_csv(path: impl AsRef<Path>, twists: &[TwistSample]) -> Result<(), FormatError> {
    let mut writer = TwistWriter::create(path)?;
    for twist in twists {
        writer.write(twist)?;
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_err(text: &str) -> String {
        parse_twists_csv(text.as_bytes(), "twists.csv")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("twists.csv");
        let twists: Vec<TwistSample> = (0..100)
            .map(|i| {
                let x = i as f64;
                TwistSample {
                    t_s: 1e3 + x / 3.0,
                    velocity_mps: Vector3::new(x.sin(), -1e-12 * x, 0.1 + 0.2),
                    angular_velocity_radps: Vector3::new(1e-300, x.cos() * 7.0, -0.0),
                }
            })
            .collect();
        write_twists_csv(&path, &twists).unwrap();
        let back = read_twists_csv(&path).unwrap();
        assert_eq!(back.len(), twists.len());
        for (a, b) in back.iter().zip(&twists) {
            assert_eq!(a.t_s.to_bits(), b.t_s.to_bits());
            for k in 0..3 {
                assert_eq!(a.velocity_mps[k].to_bits(), b.velocity_mps[k].to_bits());
                assert_eq!(
                    a.angular_velocity_radps[k].to_bits(),
                    b.angular_velocity_radps[k].to_bits()
                );
            }
        }
        assert!(
            parse_twists_csv("t,vx,vy,vz,wx,wy,wz\n".as_bytes(), "x")
                .unwrap()
                .is_empty()
        );
    }

    #[test]
    fn implausible_twists_are_refused_by_line_and_field() {
        let header = "t,vx,vy,vz,wx,wy,wz\n";
        let ok = format!("{header}0,-1e6,0,0,0,0,1e6\n");
        assert_eq!(
            parse_twists_csv(ok.as_bytes(), "twists.csv").unwrap().len(),
            1
        );
        let e = parse_err(&format!("{header}0,0,0,0,0,0,0\n1,0,0,1e300,0,0,0\n"));
        assert!(
            e.starts_with("twists.csv:3: field 'vz': 1e300 m/s is not a plausible velocity"),
            "{e}"
        );
        let e = parse_err(&format!("{header}0,0,0,0,0,-2e6,0\n"));
        assert!(
            e.starts_with(
                "twists.csv:2: field 'wy': -2000000 rad/s is not a plausible angular velocity"
            ),
            "{e}"
        );
        let e = parse_err(&format!("{header}1700000000000000,0,0,0,0,0,0\n"));
        assert!(
            e.starts_with("twists.csv:2: field 't': ") && e.contains("microseconds"),
            "{e}"
        );
    }

    #[test]
    fn malformed_twists() {
        let e = parse_err("t,vx,vy,vz,wx,wy,wz\n0,0,0,0,0,0,0\n1,0,0,fast,0,0,0\n");
        assert_eq!(e, "twists.csv:3: field 'vz': not a number: \"fast\"");
        let e = parse_err("t,vx,vy,vz,wx,wy,wz\n0,0,0,0,0,0,0\n0,0,0,0,0,0,0\n");
        assert!(e.starts_with("twists.csv:3: field 't': "), "{e}");
        assert!(e.contains("line 2"), "{e}");
        let e = parse_err("t,vx,vy,vz,wx,wy,wz\n0,0,0,0,0,0\n");
        assert!(e.starts_with("twists.csv:2: field 'wz': missing"), "{e}");
        let e = parse_err("t,vx,vy,vz,wx,wy\n");
        assert!(e.starts_with("twists.csv:1: field 'wz': "), "{e}");
        let e = parse_err("t,vx,vy,vz,wx,wy,wz\n0,0,0,0,0,NaN,0\n");
        assert!(e.starts_with("twists.csv:2: field 'wy': "), "{e}");
        let e = parse_err("");
        assert!(e.starts_with("twists.csv: empty file"), "{e}");
    }
}
