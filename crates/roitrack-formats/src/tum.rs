//! TUM trajectories (docs/model.md), the format evo reads: one pose per line, `t tx ty tz qx qy qz qw`,
//! space-separated.
//!
//! Each line is camera_T_object at time `t` (seconds): the translation `tx ty tz` (metres) is the object origin in
//! the camera frame, `qx qy qz qw` the Hamilton unit quaternion of c_R_o (scalar last). Blank lines and lines
//! starting with `#` are skipped, as evo does.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use roitrack_core::PoseSample;

use crate::FormatError;
use crate::csv_util::{check_time_order, parse_finite};
use crate::limits::{DEFAULT_MAX_TRAJECTORY_FILE_BYTES, Limited, open_file, read_error};
use crate::row_writer::RowWriter;
use crate::units::{POSITION, check_plausible, check_trajectory_time};

const FIELDS: [&str; 8] = ["t", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];
/// What the file should be, for errors.
const WHAT: &str = "a TUM trajectory (t tx ty tz qx qy qz qw)";

/// How far from 1 the norm of a quaternion in a file may be (it is then normalised).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Reads a TUM trajectory (see [`parse_tum`]) of at most
/// [`DEFAULT_MAX_TRAJECTORY_FILE_BYTES`](crate::DEFAULT_MAX_TRAJECTORY_FILE_BYTES).
pub fn read_tum(path: impl AsRef<Path>) -> Result<Vec<PoseSample>, FormatError> {
    read_tum_limited(path, DEFAULT_MAX_TRAJECTORY_FILE_BYTES)
}

/// Reads a TUM trajectory of at most `max_file_bytes` (a larger file is refused before it is read).
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("poses.tum");
/// std::fs::write(&path, "0 0 0 1 0 0 0 1\n").unwrap();
/// assert_eq!(roitrack_formats::read_tum_limited(&path, 1000).unwrap().len(), 1);
/// let e = roitrack_formats::read_tum_limited(&path, 10).unwrap_err().to_string();
/// assert!(e.contains("at most 10 bytes"), "{e}");
/// ```
pub fn read_tum_limited(
    path: impl AsRef<Path>,
    max_file_bytes: u64,
) -> Result<Vec<PoseSample>, FormatError> {
    let path = path.as_ref();
    let file = open_file(path, WHAT, Some(max_file_bytes))?;
    parse_tum_limited(file, path, max_file_bytes)
}

/// Parses a TUM trajectory from any byte source; `path` names it in errors.
///
/// Every pose line has exactly 8 finite numbers; the times increase strictly and are at most
/// [`MAX_PLAUSIBLE_TIME_S`](crate::MAX_PLAUSIBLE_TIME_S) (larger ones are refused as milliseconds or nanoseconds);
/// each coordinate of the position is at most [`MAX_PLAUSIBLE_DISTANCE_M`](crate::MAX_PLAUSIBLE_DISTANCE_M); the
/// quaternion's norm is within [`QUATERNION_NORM_TOLERANCE`] of 1 (it is then normalised). A file with no pose line holds an empty trajectory.
/// A leading byte-order mark is skipped. Lines are at most [`MAX_LINE_BYTES`](crate::MAX_LINE_BYTES), the whole at
/// most [`DEFAULT_MAX_TRAJECTORY_FILE_BYTES`](crate::DEFAULT_MAX_TRAJECTORY_FILE_BYTES).
pub fn parse_tum<R: Read>(
    reader: R,
    path: impl AsRef<Path>,
) -> Result<Vec<PoseSample>, FormatError> {
    parse_tum_limited(reader, path.as_ref(), DEFAULT_MAX_TRAJECTORY_FILE_BYTES)
}

fn parse_tum_limited<R: Read>(
    reader: R,
    path: &Path,
    max_file_bytes: u64,
) -> Result<Vec<PoseSample>, FormatError> {
    let mut reader = BufReader::new(Limited::new(reader, WHAT, Some(max_file_bytes)));
    let mut buffer = Vec::new();
    let mut poses = Vec::new();
    let mut previous = None;
    let mut line: u64 = 0;
    loop {
        buffer.clear();
        let n = reader
            .read_until(b'\n', &mut buffer)
            .map_err(|e| read_error(path, e, Some(line + 1)))?;
        if n == 0 {
            return Ok(poses);
        }
        line += 1;
        let mut bytes = &buffer[..];
        if line == 1 {
            bytes = bytes.strip_prefix("\u{feff}".as_bytes()).unwrap_or(bytes);
        }
        let text = std::str::from_utf8(bytes)
            .map_err(|_| FormatError::new(path, "not valid UTF-8").with_line(line))?
            .trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let pose = parse_pose_line(text, path, line)?;
        check_time_order(previous, pose.t_s, true, path, line, "t")?;
        previous = Some((pose.t_s, line));
        poses.push(pose);
    }
}

fn parse_pose_line(text: &str, path: &Path, line: u64) -> Result<PoseSample, FormatError> {
    let error = |field: &str, message: String| {
        FormatError::new(path, message)
            .with_line(line)
            .with_field(field)
    };
    let mut values = [0.0; 8];
    let mut tokens = text.split_whitespace();
    for (i, value) in values.iter_mut().enumerate() {
        let Some(token) = tokens.next() else {
            return Err(error(
                FIELDS[i],
                format!(
                    "missing: the line has {i} fields, a TUM pose has 8 (t tx ty tz qx qy qz qw)"
                ),
            ));
        };
        *value = parse_finite(token).map_err(|m| error(FIELDS[i], m))?;
    }
    if let Some(extra) = tokens.next() {
        return Err(error(
            "column 9",
            format!(
                "unexpected extra field {extra:?}: a TUM pose has 8 fields (t tx ty tz qx qy qz qw)"
            ),
        ));
    }
    let [t_s, tx, ty, tz, qx, qy, qz, qw] = values;
    check_trajectory_time(t_s, path, line)?;
    for (i, value) in [tx, ty, tz].into_iter().enumerate() {
        check_plausible(value, &POSITION, path, line, FIELDS[1 + i])?;
    }
    let q = Quaternion::new(qw, qx, qy, qz);
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(error(
            "qx qy qz qw",
            format!(
                "not a unit quaternion: its norm is {norm}, more than {QUATERNION_NORM_TOLERANCE} away from 1"
            ),
        ));
    }
    // Quaternions that are unit to rounding (as written by `PoseWriter`) are kept bit for bit: renormalising them
    // would only move their last bits.
    let rotation = if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::new_normalize(q)
    };
    Ok(PoseSample {
        t_s,
        cam_from_obj: Isometry3::from_parts(Translation3::new(tx, ty, tz), rotation),
    })
}

/// Writes a TUM trajectory atomically: nothing appears at the path until [`Self::finish`].
///
/// No header line is written (evo expects none). Numbers are written with full round-trip precision (shortest
/// representation that reads back to the same `f64`), never rounded to fixed decimals. Non-finite values and times
/// that do not increase are refused.
#[derive(Debug)]
pub struct PoseWriter {
    rows: RowWriter,
}

impl PoseWriter {
    /// Starts writing `path` (its directory must exist).
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        Ok(Self {
            rows: RowWriter::create(path.as_ref(), None, true)?,
        })
    }

    /// Appends one pose camera_T_object (s, m, unit quaternion).
    pub fn write(&mut self, pose: &PoseSample) -> Result<(), FormatError> {
        let t = &pose.cam_from_obj.translation.vector;
        let q = &pose.cam_from_obj.rotation;
        self.rows.check(
            pose.t_s,
            &[
                ("tx", t.x),
                ("ty", t.y),
                ("tz", t.z),
                ("qx", q.i),
                ("qy", q.j),
                ("qz", q.k),
                ("qw", q.w),
            ],
        )?;
        self.rows.write_record(
            pose.t_s,
            format_args!(
                "{} {} {} {} {} {} {} {}",
                pose.t_s, t.x, t.y, t.z, q.i, q.j, q.k, q.w
            ),
        )
    }

    /// Completes the file and moves it into place.
    pub fn finish(self) -> Result<(), FormatError> {
        self.rows.finish()
    }
}

/// Writes all `poses` to a TUM trajectory, atomically.
pub fn write_tum(path: impl AsRef<Path>, poses: &[PoseSample]) -> Result<(), FormatError> {
    let mut writer = PoseWriter::create(path)?;
    for pose in poses {
        writer.write(pose)?;
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn parse_err(text: &str) -> String {
        parse_tum(text.as_bytes(), "poses.tum")
            .unwrap_err()
            .to_string()
    }

    fn poses() -> Vec<PoseSample> {
        (0..100)
            .map(|i| {
                let x = i as f64;
                PoseSample {
                    t_s: 1.7e9 + x * 1e-3 + 1e-7,
                    cam_from_obj: Isometry3::new(
                        Vector3::new(0.01 * x.sin(), -1e-12 * x, 0.5 + 1e-13 * x),
                        Vector3::new(0.3 * x.cos(), 0.1 + 0.2, -0.7 * x.sin()),
                    ),
                }
            })
            .collect()
    }

    #[test]
    fn round_trip_keeps_full_precision() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses.tum");
        let poses = poses();
        write_tum(&path, &poses).unwrap();
        let back = read_tum(&path).unwrap();
        assert_eq!(back.len(), poses.len());
        for (a, b) in back.iter().zip(&poses) {
            assert_eq!(a.t_s.to_bits(), b.t_s.to_bits());
            let bits = |p: &PoseSample| {
                let (t, q) = (
                    p.cam_from_obj.translation.vector,
                    p.cam_from_obj.rotation.coords,
                );
                [t.x, t.y, t.z, q.x, q.y, q.z, q.w].map(f64::to_bits)
            };
            assert_eq!(bits(a), bits(b));
        }
        // Writing what was read gives the same bytes.
        let text = std::fs::read_to_string(&path).unwrap();
        write_tum(&path, &back).unwrap();
        assert!(std::fs::read_to_string(&path).unwrap() == text);
    }

    #[test]
    fn comments_blank_lines_and_normalisation() {
        let text = "# timestamp tx ty tz qx qy qz qw\n\n  \t\n1.0 1 2 3 0 0 0 1.0005\r\n# done\n2.0\t1 2 3 0 0 0.7071067811865476 0.7071067811865476";
        let poses = parse_tum(text.as_bytes(), "p.tum").unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].cam_from_obj.rotation, UnitQuaternion::identity());
        assert_eq!(
            poses[1].cam_from_obj.translation.vector,
            Vector3::new(1.0, 2.0, 3.0)
        );
        assert!(parse_tum("".as_bytes(), "p.tum").unwrap().is_empty());
    }

    #[test]
    fn malformed_lines() {
        let e = parse_err("# header\n0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n");
        assert!(e.starts_with("poses.tum:3: field 'qw': missing"), "{e}");
        let e = parse_err("0 0 0 0 0 0 0 1 5\n");
        assert!(e.starts_with("poses.tum:1: field 'column 9': "), "{e}");
        let e = parse_err("0 0 0 0 0 0 0 1\n1 0 0 0 0.5 0 0 1\n");
        assert!(
            e.starts_with("poses.tum:2: field 'qx qy qz qw': not a unit quaternion"),
            "{e}"
        );
        let e = parse_err("0 0 0 0 0 0 0 0\n");
        assert!(e.starts_with("poses.tum:1: field 'qx qy qz qw': "), "{e}");
        let e = parse_err("0 0 0 0 0 NaN 0 1\n");
        assert!(
            e.starts_with("poses.tum:1: field 'qy': must be a finite"),
            "{e}"
        );
        let e = parse_err("0 0 0 zero 0 0 0 1\n");
        assert_eq!(e, "poses.tum:1: field 'tz': not a number: \"zero\"");
        let e = parse_err("1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n");
        assert!(e.starts_with("poses.tum:2: field 't': "), "{e}");
        let e = parse_tum(&b"0 0 0 0 0 0 0 1\n\xfe\n"[..], "p.tum").unwrap_err();
        assert_eq!(e.line(), Some(2));
    }

    #[test]
    fn implausible_times_and_positions_are_refused_by_line_and_field() {
        // Unix times in seconds are plausible; in nanoseconds or milliseconds they are not.
        assert_eq!(
            parse_tum("1700000000.5 0 0 1 0 0 0 1\n".as_bytes(), "p.tum")
                .unwrap()
                .len(),
            1
        );
        let e = parse_err("0 0 0 1 0 0 0 1\n1700000000000000000 0 0 1 0 0 0 1\n");
        assert!(
            e.starts_with("poses.tum:2: field 't': ") && e.contains("nanoseconds"),
            "{e}"
        );
        let e = parse_err("1700000000000 0 0 1 0 0 0 1\n");
        assert!(
            e.contains("milliseconds") && e.contains("divide by 1e3"),
            "{e}"
        );
        // A position a million metres off, any coordinate.
        assert!(parse_tum("0 -1e6 0 1 0 0 0 1\n".as_bytes(), "p.tum").is_ok());
        let e = parse_err("0 0 0 1 0 0 0 1\n1 0 2e6 1 0 0 0 1\n");
        assert!(
            e.starts_with("poses.tum:2: field 'ty': 2000000 m is not a plausible position"),
            "{e}"
        );
        let e = parse_err("0 0 0 -1e300 0 0 0 1\n");
        assert!(e.starts_with("poses.tum:1: field 'tz': "), "{e}");
    }

    #[test]
    fn writer_is_atomic_and_checks_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses.tum");
        let poses = poses();
        write_tum(&path, &poses[..3]).unwrap();
        let before = std::fs::read_to_string(&path).unwrap();
        let mut w = PoseWriter::create(&path).unwrap();
        w.write(&poses[5]).unwrap();
        let e = w.write(&poses[4]).unwrap_err();
        assert!(e.to_string().contains("poses.tum:2: field 't'"), "{e}");
        drop(w);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), before);
    }
}
