//! Reading back what `track` wrote beside its poses and twists: the diagnostics CSV (status, residual, sigmas) and the
//! covariance CSV (the 78 upper-triangle entries of each estimate's 12 x 12 covariance). Formats: see
//! [`crate::EstimateWriter`] and [`crate::CovarianceWriter`].

use std::io::Read;
use std::path::Path;

use roitrack_estimators::{Matrix12, TrackStatus};

use crate::FormatError;
use crate::covariance::{COVARIANCE_ENTRIES, covariance_from_upper_triangle, covariance_header};
use crate::csv_util::{Row, check_time_order, csv_reader, for_each_row, read_header};
use crate::limits::{DEFAULT_MAX_TRAJECTORY_FILE_BYTES, Limited, open_file};

const DIAGNOSTICS_COLUMNS: [&str; 12] = [
    "t",
    "status",
    "residual_rms_px",
    "inverse_condition",
    "measurements_used",
    "iterations",
    "sigma_x_m",
    "sigma_y_m",
    "sigma_z_m",
    "sigma_vx_mps",
    "sigma_vy_mps",
    "sigma_vz_mps",
];

/// One row of a diagnostics CSV.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiagnosticsRow {
    /// The estimate's time (s).
    pub t_s: f64,
    /// Its status.
    pub status: TrackStatus,
    /// RMS residual of its measurements (px).
    pub residual_rms_px: f64,
    /// The inverse condition number of its fit (1: well posed, near 0: degenerate).
    pub inverse_condition: f64,
    /// Measurements it used.
    pub measurements_used: u32,
    /// Solver iterations it took.
    pub iterations: u32,
    /// 1-sigma of the position of the object's origin (m, camera frame); `NaN` without a covariance.
    pub sigma_position_m: [f64; 3],
    /// 1-sigma of its velocity (m/s, camera frame); `NaN` without a covariance.
    pub sigma_velocity_mps: [f64; 3],
}

/// A number that may be `NaN` (an absent figure), but not infinite.
fn number_or_nan(row: &Row, i: usize) -> Result<f64, FormatError> {
    let text = row.text(i);
    match text.parse::<f64>() {
        Ok(v) if !v.is_infinite() => Ok(v),
        Ok(v) => Err(row.error(i, format!("must be a number or NaN, got {v}"))),
        Err(_) => Err(row.error(i, format!("not a number: {text:?}"))),
    }
}

fn count(row: &Row, i: usize) -> Result<u32, FormatError> {
    let text = row.text(i);
    text.parse::<u32>()
        .map_err(|_| row.error(i, format!("not a count (a non-negative integer): {text:?}")))
}

/// Reads a diagnostics CSV as `track --diagnostics` writes it; times must increase strictly.
///
/// ```
/// let text = "t,status,residual_rms_px,inverse_condition,measurements_used,iterations,sigma_x_m,sigma_y_m,\
///     sigma_z_m,sigma_vx_mps,sigma_vy_mps,sigma_vz_mps\n0.5,tracking,0.1,0.2,16,1,1e-4,1e-4,3e-4,NaN,NaN,NaN\n";
/// let rows = roitrack_formats::parse_diagnostics_csv(text.as_bytes(), "d.csv").unwrap();
/// assert_eq!(rows[0].status, roitrack_estimators::TrackStatus::Tracking);
/// assert!(rows[0].sigma_velocity_mps[0].is_nan());
/// let bad = text.replace("tracking", "fine");
/// let err = roitrack_formats::parse_diagnostics_csv(bad.as_bytes(), "d.csv").unwrap_err().to_string();
/// assert!(err.contains("d.csv:2") && err.contains("status"), "{err}");
/// ```
pub fn parse_diagnostics_csv<R: Read>(
    reader: R,
    path: impl AsRef<Path>,
) -> Result<Vec<DiagnosticsRow>, FormatError> {
    let path = path.as_ref();
    // Lines bounded whatever the source; the file's size is bounded by the `_limited` readers.
    let mut csv = csv_reader(Limited::new(reader, "a diagnostics CSV", None));
    read_header(&mut csv, path, &DIAGNOSTICS_COLUMNS, None)?;
    let mut rows = Vec::new();
    let mut previous = None;
    for_each_row(&mut csv, path, &DIAGNOSTICS_COLUMNS, |row| {
        let t_s = row.finite(0)?;
        check_time_order(previous, t_s, true, path, row.line, "t")?;
        previous = Some((t_s, row.line));
        let status_text = row.text(1);
        let status = TrackStatus::ALL
            .into_iter()
            .find(|s| s.name() == status_text)
            .ok_or_else(|| {
                row.error(
                    1,
                    format!(
                        "unknown status {status_text:?} (one of converging, tracking, degenerate, disputed, lost)"
                    ),
                )
            })?;
        let mut sigmas = [0.0; 6];
        for (k, sigma) in sigmas.iter_mut().enumerate() {
            *sigma = number_or_nan(row, 6 + k)?;
        }
        rows.push(DiagnosticsRow {
            t_s,
            status,
            residual_rms_px: number_or_nan(row, 2)?,
            inverse_condition: number_or_nan(row, 3)?,
            measurements_used: count(row, 4)?,
            iterations: count(row, 5)?,
            sigma_position_m: [sigmas[0], sigmas[1], sigmas[2]],
            sigma_velocity_mps: [sigmas[3], sigmas[4], sigmas[5]],
        });
        Ok(())
    })?;
    Ok(rows)
}

/// Reads a diagnostics CSV file (see [`parse_diagnostics_csv`]) of at most
/// [`DEFAULT_MAX_TRAJECTORY_FILE_BYTES`](crate::DEFAULT_MAX_TRAJECTORY_FILE_BYTES).
pub fn read_diagnostics_csv(path: impl AsRef<Path>) -> Result<Vec<DiagnosticsRow>, FormatError> {
    read_diagnostics_csv_limited(path, DEFAULT_MAX_TRAJECTORY_FILE_BYTES)
}

/// Reads a diagnostics CSV file of at most `max_file_bytes` (a larger file is refused before it is read).
pub fn read_diagnostics_csv_limited(
    path: impl AsRef<Path>,
    max_file_bytes: u64,
) -> Result<Vec<DiagnosticsRow>, FormatError> {
    let path = path.as_ref();
    let what = "a diagnostics CSV";
    let file = open_file(path, what, Some(max_file_bytes))?;
    parse_diagnostics_csv(Limited::new(file, what, Some(max_file_bytes)), path)
}

/// One row of a covariance CSV: the estimate's time and its covariance (`None` where the row is `NaN` throughout).
#[derive(Debug, Clone, PartialEq)]
pub struct CovarianceRow {
    /// The estimate's time (s).
    pub t_s: f64,
    /// Its covariance (error state `(v, w, dV, dW)`).
    pub covariance: Option<Matrix12>,
}

/// The covariance CSV's 79 column names, made once (the shared CSV helpers name columns by static strings).
fn covariance_columns() -> &'static [&'static str] {
    static COLUMNS: std::sync::OnceLock<Vec<&'static str>> = std::sync::OnceLock::new();
    COLUMNS.get_or_init(|| {
        let header: &'static str = Box::leak(covariance_header().into_boxed_str());
        header.split(',').collect()
    })
}

/// Reads a covariance CSV as `track --covariance` writes it: `NaN` throughout means no covariance; a row with some
/// entries `NaN` and others not is refused, as is a matrix with a negative variance.
///
/// ```
/// let header = roitrack_formats::covariance_header();
/// let row = format!("0.5{}", ",0".repeat(78));
/// let text = format!("{header}\n{row}\n0.75{}\n", ",NaN".repeat(78));
/// let rows = roitrack_formats::parse_covariance_csv(text.as_bytes(), "c.csv").unwrap();
/// assert_eq!(rows.len(), 2);
/// assert!(rows[0].covariance.is_some() && rows[1].covariance.is_none());
/// ```
pub fn parse_covariance_csv<R: Read>(
    reader: R,
    path: impl AsRef<Path>,
) -> Result<Vec<CovarianceRow>, FormatError> {
    let path = path.as_ref();
    let columns = covariance_columns();
    let mut csv = csv_reader(Limited::new(reader, "a covariance CSV", None));
    read_header(&mut csv, path, columns, None)?;
    let mut rows = Vec::new();
    let mut previous = None;
    for_each_row(&mut csv, path, columns, |row| {
        let t_s = row.finite(0)?;
        check_time_order(previous, t_s, true, path, row.line, "t")?;
        previous = Some((t_s, row.line));
        let mut entries = [0.0; COVARIANCE_ENTRIES];
        for (k, entry) in entries.iter_mut().enumerate() {
            *entry = number_or_nan(row, 1 + k)?;
        }
        let missing = entries.iter().filter(|v| v.is_nan()).count();
        let covariance = match missing {
            0 => {
                let matrix = covariance_from_upper_triangle(&entries);
                if let Some(k) = (0..12).find(|&k| matrix[(k, k)] < 0.0) {
                    let column = 1 + crate::covariance_entry_index(k, k);
                    return Err(row.error(column, "a variance must not be negative"));
                }
                Some(matrix)
            }
            COVARIANCE_ENTRIES => None,
            _ => {
                let first = entries.iter().position(|v| v.is_nan()).unwrap_or(0);
                return Err(row.error(
                    1 + first,
                    "NaN among numbers: a row is either a whole covariance or NaN throughout",
                ));
            }
        };
        rows.push(CovarianceRow { t_s, covariance });
        Ok(())
    })?;
    Ok(rows)
}

/// Reads a covariance CSV file (see [`parse_covariance_csv`]) of at most
/// [`DEFAULT_MAX_TRAJECTORY_FILE_BYTES`](crate::DEFAULT_MAX_TRAJECTORY_FILE_BYTES).
pub fn read_covariance_csv(path: impl AsRef<Path>) -> Result<Vec<CovarianceRow>, FormatError> {
    read_covariance_csv_limited(path, DEFAULT_MAX_TRAJECTORY_FILE_BYTES)
}

/// Reads a covariance CSV file of at most `max_file_bytes` (a larger file is refused before it is read).
pub fn read_covariance_csv_limited(
    path: impl AsRef<Path>,
    max_file_bytes: u64,
) -> Result<Vec<CovarianceRow>, FormatError> {
    let path = path.as_ref();
    let what = "a covariance CSV";
    let file = open_file(path, what, Some(max_file_bytes))?;
    parse_covariance_csv(Limited::new(file, what, Some(max_file_bytes)), path)
}
