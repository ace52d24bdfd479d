//! The full 12 x 12 covariance of each estimate as a CSV file: a header, then one row per estimate with its time `t`
//! and the 78 entries of the upper triangle, named `c{i}_{j}`, row by row (`i <= j`):
//!
//! ```text
//! t,c0_0,c0_1,...,c0_11,c1_1,c1_2,...,c1_11,c2_2,...,c11_11
//! ```
//!
//! Indices 0-11 are the error state `δ = (v, w, dV, dW)` of [`MotionState::corrected`], all in the camera frame:
//!
//! | index | quantity | unit |
//! | --- | --- | --- |
//! | 0-2 | position of the object's origin (x, y, z) | m |
//! | 3-5 | rotation vector (about x, y, z) | rad |
//! | 6-8 | linear velocity of the object's origin (x, y, z) | m/s |
//! | 9-11 | angular velocity (about x, y, z) | rad/s |
//!
//! The rotation perturbation is on the left, about the object's origin, in the camera frame: the true state is
//! `R = Exp(w) R̂`, `t = t̂ + v`, `V = V̂ + dV`, `W = Ŵ + dW` for the estimate `(R̂, t̂, V̂, Ŵ)`, where `w` (entries 3-5)
//! is a rotation vector. The matrix is symmetric: entry `(j, i)` is `c{i}_{j}` ([`covariance_from_upper_triangle`]
//! rebuilds it). An estimate without a covariance has `NaN` in every entry: the static baseline's (but for the one that
//! starts a track, which comes from the initialisation's 12-dof fit, whatever the estimator) and those of degenerate
//! windows of the window fits. Times are written as in the other outputs (the shortest decimal that reads back to the
//! same `f64`, e.g. `0.01025`) and increase strictly; the entries in exponent notation, also the shortest that reads
//! back to the same `f64` (`2.416856179357343e-10`, `0e0`).
//!
//! [`MotionState::corrected`]: roitrack_core::MotionState::corrected

use std::fmt;
use std::path::Path;

use roitrack_estimators::{Estimate, Matrix12};

use crate::FormatError;
use crate::row_writer::RowWriter;

/// Side of the covariance matrix: the 12 components of the error state.
pub const COVARIANCE_SIZE: usize = 12;
/// Entries of the upper triangle written per row: 12 x 13 / 2.
pub const COVARIANCE_ENTRIES: usize = COVARIANCE_SIZE * (COVARIANCE_SIZE + 1) / 2;

/// Where entry `(i, j)` (or `(j, i)`: the matrix is symmetric) is among the [`COVARIANCE_ENTRIES`] upper-triangle
/// entries of a row, not counting the time column. Panics if an index is 12 or more.
///
/// ```
/// use roitrack_formats::covariance_entry_index;
/// assert_eq!(covariance_entry_index(0, 0), 0);
/// assert_eq!(covariance_entry_index(0, 11), 11);
/// assert_eq!(covariance_entry_index(1, 1), 12);
/// assert_eq!(covariance_entry_index(3, 1), covariance_entry_index(1, 3));
/// assert_eq!(covariance_entry_index(11, 11), 77);
/// ```
pub fn covariance_entry_index(i: usize, j: usize) -> usize {
    assert!(
        i < COVARIANCE_SIZE && j < COVARIANCE_SIZE,
        "covariance index ({i}, {j}) out of 0-11"
    );
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    i * COVARIANCE_SIZE - i * (i.saturating_sub(1)) / 2 + (j - i)
}

/// The covariance CSV's header line: `t,c0_0,c0_1,...,c0_11,c1_1,...,c11_11`.
///
/// ```
/// let header = roitrack_formats::covariance_header();
/// assert!(header.starts_with("t,c0_0,c0_1,c0_2,"));
/// assert!(header.ends_with(",c10_10,c10_11,c11_11"));
/// assert_eq!(header.split(',').count(), 1 + 78);
/// ```
pub fn covariance_header() -> String {
    let mut header = String::from("t");
    for i in 0..COVARIANCE_SIZE {
        for j in i..COVARIANCE_SIZE {
            header.push_str(&format!(",c{i}_{j}"));
        }
    }
    header
}

/// The 78 upper-triangle entries of a covariance, row by row (the order of the file's columns after `t`). An entry is
/// the mean of `(i, j)` and `(j, i)`: the symmetric part of a matrix that rounding left slightly asymmetric (a
/// symmetric matrix's entries exactly).
///
/// ```
/// use roitrack_estimators::Matrix12;
/// use roitrack_formats::{covariance_from_upper_triangle, covariance_upper_triangle};
/// let c = Matrix12::from_fn(|i, j| 1.0 / (1 + i + j) as f64);
/// let entries = covariance_upper_triangle(&c);
/// assert_eq!(entries[12], c[(1, 1)]);
/// assert_eq!(covariance_from_upper_triangle(&entries), c);
/// ```
pub fn covariance_upper_triangle(covariance: &Matrix12) -> [f64; COVARIANCE_ENTRIES] {
    let mut entries = [0.0; COVARIANCE_ENTRIES];
    let mut k = 0;
    for i in 0..COVARIANCE_SIZE {
        for j in i..COVARIANCE_SIZE {
            entries[k] = if i == j {
                covariance[(i, i)]
            } else {
                0.5 * (covariance[(i, j)] + covariance[(j, i)])
            };
            k += 1;
        }
    }
    entries
}

/// The symmetric 12 x 12 matrix of 78 upper-triangle entries in the file's order (inverse of
/// [`covariance_upper_triangle`]).
///
/// ```
/// use roitrack_formats::{COVARIANCE_ENTRIES, covariance_entry_index, covariance_from_upper_triangle};
/// let entries: [f64; COVARIANCE_ENTRIES] = std::array::from_fn(|k| k as f64);
/// let c = covariance_from_upper_triangle(&entries);
/// assert_eq!(c[(2, 5)], entries[covariance_entry_index(2, 5)]);
/// assert_eq!(c[(5, 2)], c[(2, 5)]);
/// ```
pub fn covariance_from_upper_triangle(entries: &[f64; COVARIANCE_ENTRIES]) -> Matrix12 {
    Matrix12::from_fn(|i, j| entries[covariance_entry_index(i, j)])
}

/// One row: the time, then the 78 entries (NaN without a covariance).
struct Row<'a> {
    t_s: f64,
    entries: Option<&'a [f64; COVARIANCE_ENTRIES]>,
}

impl fmt::Display for Row<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.t_s)?;
        match self.entries {
            Some(entries) => entries.iter().try_for_each(|c| write!(f, ",{c:e}")),
            None => (0..COVARIANCE_ENTRIES).try_for_each(|_| write!(f, ",{}", f64::NAN)),
        }
    }
}

/// Writes the covariance of each estimate as one CSV row (the time, then the upper triangle row by row:
/// [`covariance_header`](crate::covariance_header)), atomically: the file appears only on [`Self::finish`]. Usually part of an
/// [`EstimateWriter`](crate::EstimateWriter), see
/// [`EstimateWriter::with_covariance`](crate::EstimateWriter::with_covariance).
///
/// ```
/// use roitrack_estimators::Matrix12;
/// use roitrack_formats::CovarianceWriter;
///
/// # fn main() -> Result<(), roitrack_formats::FormatError> {
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("covariance.csv");
/// let mut writer = CovarianceWriter::create(&path)?;
/// writer.write(0.25, Some(&(Matrix12::identity() * 1e-6)))?;
/// writer.write(0.5, None)?; // no covariance: NaN entries
/// writer.finish()?;
/// let text = std::fs::read_to_string(&path).unwrap();
/// let rows: Vec<&str> = text.lines().collect();
/// assert_eq!(rows.len(), 3);
/// assert!(rows[1].starts_with("0.25,1e-6,0e0,0e0,"));
/// assert!(rows[2].starts_with("0.5,NaN,NaN,"));
/// # Ok(())
/// # }
/// ```
#[derive(Debug)]
pub struct CovarianceWriter {
    rows: RowWriter,
}

impl CovarianceWriter {
    /// Starts writing `path` (its directory must exist) and writes the header.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        Ok(Self {
            rows: RowWriter::create(path.as_ref(), Some(&covariance_header()), true)?,
        })
    }

    /// Appends the covariance of the estimate at `t_s` (times must increase strictly); `None` writes `NaN` entries.
    pub fn write(&mut self, t_s: f64, covariance: Option<&Matrix12>) -> Result<(), FormatError> {
        self.rows.check(t_s, &[])?;
        let entries = covariance.map(covariance_upper_triangle);
        self.rows.write_record(
            t_s,
            format_args!(
                "{}",
                Row {
                    t_s,
                    entries: entries.as_ref()
                }
            ),
        )
    }

    /// Appends an estimate's covariance ([`Estimate::covariance`] at [`Estimate::t_ref_s`]).
    pub fn write_estimate(&mut self, estimate: &Estimate) -> Result<(), FormatError> {
        self.write(estimate.t_ref_s, estimate.covariance.as_ref())
    }

    /// Completes the file and moves it into place.
    pub fn finish(self) -> Result<(), FormatError> {
        self.rows.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric positive-definite matrix with distinct entries.
    fn spd() -> Matrix12 {
        let a = Matrix12::from_fn(|i, j| {
            ((i * 7 + j * 3) % 11) as f64 * 1e-3 + if i == j { 1.0 } else { 0.0 }
        });
        a * a.transpose() * 1e-4
    }

    #[test]
    fn the_header_is_t_then_the_upper_triangle_row_by_row() {
        let mut expected = vec!["t".to_string()];
        for i in 0..12 {
            for j in i..12 {
                expected.push(format!("c{i}_{j}"));
            }
        }
        assert_eq!(covariance_header(), expected.join(","));
        assert!(covariance_header().starts_with(
            "t,c0_0,c0_1,c0_2,c0_3,c0_4,c0_5,c0_6,c0_7,c0_8,c0_9,c0_10,c0_11,c1_1,c1_2,"
        ));
        assert!(covariance_header().ends_with(",c9_9,c9_10,c9_11,c10_10,c10_11,c11_11"));
        assert_eq!(COVARIANCE_ENTRIES, 78);
        // The index of (i, j) is its column after t.
        let names: Vec<&str> = expected.iter().skip(1).map(String::as_str).collect();
        for i in 0..12 {
            for j in 0..12 {
                let (a, b) = (i.min(j), i.max(j));
                assert_eq!(names[covariance_entry_index(i, j)], format!("c{a}_{b}"));
            }
        }
    }

    #[test]
    fn a_written_row_maps_back_to_the_symmetric_matrix() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("covariance.csv");
        let c = spd();
        let mut writer = CovarianceWriter::create(&path).unwrap();
        writer.write(1.0 / 3.0, Some(&c)).unwrap();
        writer.write(0.5, None).unwrap();
        writer.finish().unwrap();

        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0], covariance_header());
        let fields: Vec<f64> = lines[1].split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(fields.len(), 1 + COVARIANCE_ENTRIES);
        assert_eq!(fields[0], 1.0 / 3.0);
        let entries: [f64; COVARIANCE_ENTRIES] = fields[1..].try_into().unwrap();
        // Bit for bit: the entries are written with round-trip precision.
        assert_eq!(covariance_from_upper_triangle(&entries), c);
        let fields: Vec<&str> = lines[2].split(',').collect();
        assert_eq!(fields[0], "0.5");
        assert!(fields[1..].iter().all(|&x| x == "NaN"), "{}", lines[2]);
        assert_eq!(fields.len(), 1 + COVARIANCE_ENTRIES);
    }

    #[test]
    fn a_slightly_asymmetric_matrix_is_written_as_its_symmetric_part() {
        let mut c = spd();
        c[(2, 7)] += 1e-12;
        let back = covariance_from_upper_triangle(&covariance_upper_triangle(&c));
        assert_eq!(back, back.transpose());
        assert!((back - (c + c.transpose()) * 0.5).abs().max() < 1e-20);
    }

    #[test]
    fn times_out_of_order_are_refused_naming_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("covariance.csv");
        let mut writer = CovarianceWriter::create(&path).unwrap();
        writer.write(1.0, None).unwrap();
        let e = writer.write(1.0, None).unwrap_err().to_string();
        assert!(
            e.contains("covariance.csv:3:") && e.contains("increase strictly"),
            "{e}"
        );
        let e = writer.write(f64::NAN, None).unwrap_err().to_string();
        assert!(e.contains("non-finite"), "{e}");
        drop(writer);
        assert!(!path.exists());
    }
}
