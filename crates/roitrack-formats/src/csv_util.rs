//! Shared machinery of the CSV readers: strict header check, row reading with line numbers, field parsing.

use std::io::Read;
use std::path::Path;

use csv::{ErrorKind, StringRecord};

use crate::FormatError;

/// A strict CSV reader: comma-separated, one header line, every row as many fields as the header, whitespace around
/// fields trimmed, blank lines skipped.
pub(crate) fn csv_reader<R: Read>(reader: R) -> csv::Reader<R> {
    csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .trim(csv::Trim::All)
        .from_reader(reader)
}

/// Reads and checks the header: exactly `columns`, optionally followed by `optional_last`. Returns the column names
/// actually present. A completely empty input is an error naming the file.
pub(crate) fn read_header<R: Read>(
    reader: &mut csv::Reader<R>,
    path: &Path,
    columns: &[&'static str],
    optional_last: Option<&'static str>,
) -> Result<Vec<&'static str>, FormatError> {
    let expected_text = match optional_last {
        Some(opt) => format!("`{}` (optionally followed by `,{opt}`)", columns.join(",")),
        None => format!("`{}`", columns.join(",")),
    };
    let header = reader
        .headers()
        .map_err(|e| csv_error(e, path, columns))?
        .clone();
    let line = header.position().map_or(1, |p| p.line());
    if header.is_empty() || (header.len() == 1 && header[0].is_empty()) {
        return Err(FormatError::new(
            path,
            format!("empty file: expected the header line {expected_text}"),
        ));
    }
    let mut all: Vec<&'static str> = columns.to_vec();
    if header.len() > columns.len()
        && let Some(opt) = optional_last
    {
        all.push(opt);
    }
    for (i, &name) in all.iter().enumerate() {
        match header.get(i) {
            Some(got) if got == name => {}
            Some(got) => {
                return Err(FormatError::new(
                    path,
                    format!(
                        "expected column '{name}', got '{got}': the header must be {expected_text}"
                    ),
                )
                .with_line(line)
                .with_field(name));
            }
            None => {
                return Err(FormatError::new(
                    path,
                    format!("missing column: the header must be {expected_text}"),
                )
                .with_line(line)
                .with_field(name));
            }
        }
    }
    if let Some(extra) = header.get(all.len()) {
        return Err(FormatError::new(
            path,
            format!("unexpected column: the header must be {expected_text}"),
        )
        .with_line(line)
        .with_field(extra));
    }
    Ok(all)
}

/// Calls `each` with every row after the header, in order, as a [`Row`] of `columns`; stops at the end of the input
/// or at the first error, the reader's or `each`'s, which it returns.
pub(crate) fn for_each_row<R: Read>(
    reader: &mut csv::Reader<R>,
    path: &Path,
    columns: &[&'static str],
    mut each: impl FnMut(&Row<'_>) -> Result<(), FormatError>,
) -> Result<(), FormatError> {
    let mut record = StringRecord::new();
    while let Some(line) = read_row(reader, &mut record, path, columns)? {
        each(&Row {
            record: &record,
            line,
            path,
            columns,
        })?;
    }
    Ok(())
}

/// Reads the next row into `record`; `Ok(None)` at the end of the input, else the row's 1-based line.
pub(crate) fn read_row<R: Read>(
    reader: &mut csv::Reader<R>,
    record: &mut StringRecord,
    path: &Path,
    columns: &[&'static str],
) -> Result<Option<u64>, FormatError> {
    match reader.read_record(record) {
        Ok(true) => Ok(Some(record.position().map_or(0, |p| p.line()))),
        Ok(false) => Ok(None),
        Err(e) => Err(csv_error(e, path, columns)),
    }
}

/// A csv crate error as a [`FormatError`] with line and column.
fn csv_error(error: csv::Error, path: &Path, columns: &[&'static str]) -> FormatError {
    let line = error.position().map(|p| p.line());
    match error.into_kind() {
        ErrorKind::Io(e) => crate::limits::read_error(path, e, line),
        ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => {
            let len = usize::try_from(len).unwrap_or(usize::MAX);
            let expected = usize::try_from(expected_len).unwrap_or(usize::MAX);
            let header = columns.join(",");
            if len < expected {
                let field = columns.get(len).copied().unwrap_or("?");
                FormatError::new(
                    path,
                    format!(
                        "missing: the row has {len} fields but the header has {expected} (truncated line?)"
                    ),
                )
                .with_line(line)
                .with_field(field)
            } else {
                FormatError::new(
                    path,
                    format!(
                        "unexpected extra field: the row has {len} fields but the header has {expected} ({header})"
                    ),
                )
                .with_line(line)
                .with_field(format!("column {}", expected.saturating_add(1)))
            }
        }
        ErrorKind::Utf8 { err, .. } => {
            let field = columns.get(err.field()).copied().unwrap_or("?");
            FormatError::new(path, "not valid UTF-8")
                .with_line(line)
                .with_field(field)
        }
        other => FormatError::new(path, format!("malformed CSV: {other:?}")).with_line(line),
    }
}

/// One CSV row being decoded: its fields, its line and the column names, for precise errors.
pub(crate) struct Row<'a> {
    pub(crate) record: &'a StringRecord,
    pub(crate) line: u64,
    pub(crate) path: &'a Path,
    pub(crate) columns: &'a [&'static str],
}

impl Row<'_> {
    /// An error about column `i` of this row.
    pub(crate) fn error(&self, i: usize, message: impl Into<String>) -> FormatError {
        FormatError::new(self.path, message)
            .with_line(self.line)
            .with_field(self.columns.get(i).copied().unwrap_or("?"))
    }

    /// The raw text of column `i` (empty if absent).
    pub(crate) fn text(&self, i: usize) -> &str {
        self.record.get(i).unwrap_or("")
    }

    /// Column `i` as a finite number.
    pub(crate) fn finite(&self, i: usize) -> Result<f64, FormatError> {
        parse_finite(self.text(i)).map_err(|m| self.error(i, m))
    }

    /// Column `i` as a point id (a non-negative integer that fits in 32 bits).
    pub(crate) fn id(&self, i: usize) -> Result<u32, FormatError> {
        let text = self.text(i);
        text.parse::<u32>().map_err(|_| {
            self.error(
                i,
                format!(
                    "not a point id (an integer from 0 to {}): {text:?}",
                    u32::MAX
                ),
            )
        })
    }
}

/// A finite number, or a message saying why the text is not one.
pub(crate) fn parse_finite(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(format!("must be a finite number, got {v}")),
        Err(_) => Err(format!("not a number: {text:?}")),
    }
}

/// Checks that time `t_s` (on `line`) comes after the previous row's; `strict` refuses equal times.
pub(crate) fn check_time_order(
    previous: Option<(f64, u64)>,
    t_s: f64,
    strict: bool,
    path: &Path,
    line: u64,
    field: &str,
) -> Result<(), FormatError> {
    if let Some((t_prev, line_prev)) = previous {
        let message = if strict && t_s <= t_prev {
            format!(
                "time {t_s} s is not after {t_prev} s on line {line_prev}: times must increase strictly"
            )
        } else if t_s < t_prev {
            format!(
                "time {t_s} s is earlier than {t_prev} s on line {line_prev}: rows must be in time order"
            )
        } else {
            return Ok(());
        };
        return Err(FormatError::new(path, message)
            .with_line(line)
            .with_field(field));
    }
    Ok(())
}
