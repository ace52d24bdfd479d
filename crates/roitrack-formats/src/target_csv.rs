//! Target CSV (docs/model.md): header `id,x,y,z` with an optional trailing `diameter` column.
//!
//! One model point per row: its id (as in the measurements) and its position in the object frame, in metres; the
//! optional `diameter` is the blob's diameter in metres (an empty cell means unknown).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::path::Path;

use nalgebra::Vector3;
use roitrack_core::{Target, TargetError, TargetPoint};

use crate::csv_util::{csv_reader, for_each_row, read_header};
use crate::limits::{Limited, MAX_TARGET_FILE_BYTES, open_file};
use crate::{AtomicFile, FormatError};

const COLUMNS: [&str; 4] = ["id", "x", "y", "z"];
const DIAMETER: &str = "diameter";
/// What the file should be, for errors.
const WHAT: &str = "a target CSV (id,x,y,z[,diameter])";

/// Reads a target CSV and validates the target (see [`parse_target_csv`]).
pub fn read_target_csv(path: impl AsRef<Path>) -> Result<Target, FormatError> {
    let path = path.as_ref();
    let file = open_file(path, WHAT, Some(MAX_TARGET_FILE_BYTES))?;
    parse_target_csv(file, path)
}

/// Parses a target CSV from any byte source; `path` names it in errors.
///
/// Refuses, naming line and field: a wrong header, missing or extra fields, non-numbers, non-finite coordinates, a
/// non-positive diameter, an id seen on an earlier line. Then, naming only the file: an empty file, fewer than 4
/// points, points all on one line. A line longer than [`MAX_LINE_BYTES`](crate::MAX_LINE_BYTES) or more than
/// [`MAX_TARGET_FILE_BYTES`](crate::MAX_TARGET_FILE_BYTES) in all is refused as it is met.
pub fn parse_target_csv<R: Read>(reader: R, path: impl AsRef<Path>) -> Result<Target, FormatError> {
    let path = path.as_ref();
    let mut csv = csv_reader(Limited::new(reader, WHAT, Some(MAX_TARGET_FILE_BYTES)));
    let columns = read_header(&mut csv, path, &COLUMNS, Some(DIAMETER))?;
    let mut points = Vec::new();
    let mut line_of_id: HashMap<u32, u64> = HashMap::new();
    for_each_row(&mut csv, path, &columns, |row| {
        let id = row.id(0)?;
        let point_in_obj_m = Vector3::new(row.finite(1)?, row.finite(2)?, row.finite(3)?);
        let diameter_m = if columns.len() > COLUMNS.len() && !row.text(4).is_empty() {
            let d = row.finite(4)?;
            if d <= 0.0 {
                return Err(row.error(4, format!("must be positive (metres), got {d}")));
            }
            Some(d)
        } else {
            None
        };
        if let Some(first) = line_of_id.insert(id, row.line) {
            return Err(row.error(
                0,
                format!("duplicate point id {id}: already on line {first}"),
            ));
        }
        points.push(TargetPoint {
            id,
            point_in_obj_m,
            diameter_m,
        });
        Ok(())
    })?;
    Target::new(points).map_err(|e| target_error(e, path, &line_of_id))
}

/// A [`TargetError`] (of the whole set of points) as a [`FormatError`]; per-point errors name the point's line.
fn target_error(error: TargetError, path: &Path, line_of_id: &HashMap<u32, u64>) -> FormatError {
    let message = error.to_string();
    match error {
        TargetError::NotFinite { id, field, .. } => FormatError::new(path, message)
            .with_line(line_of_id.get(&id).copied())
            .with_field(field),
        TargetError::NotPositiveDiameter { id, .. } => FormatError::new(path, message)
            .with_line(line_of_id.get(&id).copied())
            .with_field(DIAMETER),
        TargetError::DuplicateId { id } => FormatError::new(path, message)
            .with_line(line_of_id.get(&id).copied())
            .with_field("id"),
        TargetError::Coincident { second_id, .. } => FormatError::new(path, message)
            .with_line(line_of_id.get(&second_id).copied())
            .with_field("x"),
        TargetError::TooFewPoints { .. }
        | TargetError::Collinear { .. }
        | TargetError::CircleGrid(_) => FormatError::new(path, message),
    }
}

/// The target as CSV text: header `id,x,y,z` (plus `diameter` if any point has one), full round-trip precision.
pub fn target_csv_string(target: &Target) -> String {
    let with_diameter = target.points().iter().any(|p| p.diameter_m.is_some());
    let mut text = String::from(if with_diameter {
        "id,x,y,z,diameter\n"
    } else {
        "id,x,y,z\n"
    });
    for p in target.points() {
        let q = &p.point_in_obj_m;
        // Writing to a String cannot fail.
        let _ = write!(text, "{},{},{},{}", p.id, q.x, q.y, q.z);
        if with_diameter {
            text.push(',');
            if let Some(d) = p.diameter_m {
                let _ = write!(text, "{d}");
            }
        }
        text.push('\n');
    }
    text
}

/// Writes a target CSV atomically (its directory must exist).
pub fn write_target_csv(path: impl AsRef<Path>, target: &Target) -> Result<(), FormatError> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(target_csv_string(target).as_bytes())
        .map_err(|e| file.write_error(e))?;
    file.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_err(text: &str) -> String {
        parse_target_csv(text.as_bytes(), "target.csv")
            .unwrap_err()
            .to_string()
    }

    const SQUARE: &str = "id,x,y,z\n0,0,0,0\n1,0.02,0,0\n2,0,0.02,0\n3,0.02,0.02,0.001\n";

    #[test]
    fn round_trip_with_and_without_diameters() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("target.csv");
        let grid = Target::grid4x4();
        write_target_csv(&path, &grid).unwrap();
        assert_eq!(read_target_csv(&path).unwrap(), grid);

        let mut points = grid.points().to_vec();
        points[3].diameter_m = None;
        points[5].point_in_obj_m.z = 0.1 + 0.2; // 0.30000000000000004
        points[7].point_in_obj_m.x = -1.234_567_890_123_456_7e-9;
        let partial = Target::new(points).unwrap();
        write_target_csv(&path, &partial).unwrap();
        assert_eq!(read_target_csv(&path).unwrap(), partial);

        let plain = parse_target_csv(SQUARE.as_bytes(), "t.csv").unwrap();
        assert_eq!(target_csv_string(&plain), SQUARE);
        assert!(plain.points().iter().all(|p| p.diameter_m.is_none()));
    }

    #[test]
    fn missing_and_extra_columns() {
        let e = parse_err("id,x,y,z\n0,0,0,0\n1,0.02,0\n");
        assert!(e.starts_with("target.csv:3: field 'z': missing"), "{e}");
        let e = parse_err("id,x,y,z\n0,0,0,0,5\n");
        assert!(e.starts_with("target.csv:2: field 'column 5': "), "{e}");
        let e = parse_err("id,x,y\n0,0,0\n");
        assert!(
            e.starts_with("target.csv:1: field 'z': missing column"),
            "{e}"
        );
        let e = parse_err("id,x,y,z,diameter,colour\n");
        assert!(e.starts_with("target.csv:1: field 'colour': "), "{e}");
        let e = parse_err("id,x,z,y\n");
        assert!(e.starts_with("target.csv:1: field 'y': "), "{e}");
    }

    #[test]
    fn non_numbers_and_non_finite_values() {
        let e = parse_err("id,x,y,z\n0,0,0,0\n1,0.02,zero,0\n");
        assert_eq!(e, "target.csv:3: field 'y': not a number: \"zero\"");
        let e = parse_err("id,x,y,z\n0,0,0,NaN\n");
        assert!(
            e.starts_with("target.csv:2: field 'z': must be a finite"),
            "{e}"
        );
        let e = parse_err("id,x,y,z\n0,0,0,-inf\n");
        assert!(e.starts_with("target.csv:2: field 'z': "), "{e}");
        let e = parse_err("id,x,y,z\nfirst,0,0,0\n");
        assert!(e.starts_with("target.csv:2: field 'id': "), "{e}");
    }

    #[test]
    fn bad_diameters() {
        let e = parse_err("id,x,y,z,diameter\n0,0,0,0,0.006\n1,0.02,0,0,-0.006\n");
        assert!(
            e.starts_with("target.csv:3: field 'diameter': must be positive"),
            "{e}"
        );
        let e = parse_err("id,x,y,z,diameter\n0,0,0,0,0\n");
        assert!(e.starts_with("target.csv:2: field 'diameter': "), "{e}");
    }

    #[test]
    fn duplicate_id_names_both_lines() {
        let e = parse_err("id,x,y,z\n0,0,0,0\n1,0.02,0,0\n2,0,0.02,0\n1,0.02,0.02,0\n");
        assert!(
            e.starts_with("target.csv:5: field 'id': duplicate point id 1"),
            "{e}"
        );
        assert!(e.contains("line 3"), "{e}");
    }

    #[test]
    fn whole_file_errors_name_the_file() {
        let e = parse_err("id,x,y,z\n0,0,0,0\n1,0.02,0,0\n");
        assert!(e.starts_with("target.csv: "), "{e}");
        assert!(e.contains("at least 3 points, got 2"), "{e}");
        let e = parse_err("id,x,y,z\n0,0,0,0\n1,0.02,0,0\n2,0,0.02,0\n3,0.02,0,0\n");
        assert!(
            e.starts_with("target.csv:5: field 'x': points 1 and 3 are at one place"),
            "{e}"
        );
        let e = parse_err(
            "id,x,y,z\n0,0,0,0\n1,0.01,0.01,0.01\n2,0.02,0.02,0.02\n3,-0.01,-0.01,-0.01\n",
        );
        assert!(e.starts_with("target.csv: "), "{e}");
        assert!(e.contains("collinear"), "{e}");
        let e = parse_err("");
        assert!(e.starts_with("target.csv: empty file"), "{e}");
        let e = parse_err("id,x,y,z\n");
        assert!(e.contains("got 0"), "{e}");
    }
}
